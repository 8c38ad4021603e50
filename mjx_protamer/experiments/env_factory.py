"""Build the env a run config names (the self-touch env on its physics backend, or the toy problem).

The self-touch env has two physics backends (`env.backend`): MJX, which runs wherever JAX runs and is
the one for accelerators, and native C MuJoCo through a callback inside the jitted step, about ten times
faster on a batch of worlds on a CPU (docs/environment.md). `auto` picks native when JAX's default device
is the CPU and the run steps at least `NATIVE_MIN_ENVS` worlds together: for fewer, the fixed cost of a
host callback per step (~0.1-0.2 ms) outweighs the faster physics, and MJX steps a single world faster.
"""

from __future__ import annotations

import dataclasses

# Measured on the 2-core CPU (docs/environment.md): native ahead from 16 worlds, behind at 1 and 4.
NATIVE_MIN_ENVS = 16


def resolve_backend(backend: str, num_envs: int | None = None) -> str:
    """'auto' -> 'native' on a CPU with >= NATIVE_MIN_ENVS worlds (or when num_envs is not given), else
    'mjx'; 'mjx' and 'native' stay as they are."""
    if backend != "auto":
        return backend
    import jax

    batched = num_envs is None or num_envs >= NATIVE_MIN_ENVS
    return "native" if jax.default_backend() == "cpu" and batched else "mjx"


def _num_envs(config) -> int | None:
    train = getattr(config, "train", None)
    return getattr(train, "num_envs", None)


def with_resolved_backend(config, announce: bool = True):
    """The run config with `env.backend` resolved (so the saved config records the choice), printed."""
    if getattr(config, "env_name", "self_touch") != "self_touch":
        return config
    chosen = resolve_backend(config.env.backend, _num_envs(config))
    if announce:
        if config.env.backend != "auto":
            how = "from the config"
        else:
            import jax

            device = "the CPU" if jax.default_backend() == "cpu" else "an accelerator"
            how = f"auto: JAX runs on {device}, {_num_envs(config)} envs"
        print(f"physics backend: {chosen} ({how})", flush=True)
    return dataclasses.replace(config, env=dataclasses.replace(config.env, backend=chosen))


def make_env(config):
    """`config` has `env_name` and the matching section (`env` for self_touch, `toy` for toy)."""
    if config.env_name == "toy":
        from mjx_protamer.envs.toy import PointReachEnv

        return PointReachEnv(config.toy)
    return make_self_touch_env(config.env, _num_envs(config))


def live_config(config, backend: str | None = None):
    """The run config for live fine-tuning (one world, a fresh env state): `env.backend` set to `backend`
    (a session's recorded choice, so a resume or replay builds the same env) or else to the backend that
    steps ONE world fastest here, whatever the checkpoint trained on. `config` is the pretrain run's.
    The session saves this config, so it records the backend actually used."""
    if getattr(config, "env_name", "self_touch") != "self_touch":
        return config
    chosen = backend or resolve_backend("auto", num_envs=1)
    return dataclasses.replace(config, env=dataclasses.replace(config.env, backend=chosen))


def make_live_env(config, backend: str | None = None):
    """(the env for live fine-tuning, the config that records its backend): see `live_config`."""
    config = live_config(config, backend)
    return make_env(config), config


def make_self_touch_env(env_config, num_envs: int | None = None):
    """The self-touch env on the backend `env_config.backend` names (auto resolved for `num_envs`)."""
    if resolve_backend(env_config.backend, num_envs) == "native":
        from mjx_protamer.envs.native_env import NativeSelfTouchEnv

        return NativeSelfTouchEnv(env_config)
    from mjx_protamer.envs.self_touch import SelfTouchEnv

    return SelfTouchEnv(env_config)
