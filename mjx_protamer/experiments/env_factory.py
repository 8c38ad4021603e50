"""Build the env a run config names (the self-touch env on its physics backend, or the toy problem).

The self-touch env has two physics backends (`env.backend`): MJX, which runs wherever JAX runs and is
the one for accelerators, and native C MuJoCo through a callback inside the jitted step, about ten times
faster on a CPU (docs/environment.md). `auto` picks native when JAX's default device is the CPU.
"""

from __future__ import annotations

import dataclasses


def resolve_backend(backend: str) -> str:
    """'auto' -> 'native' on a CPU, 'mjx' on an accelerator; 'mjx' and 'native' stay as they are."""
    if backend != "auto":
        return backend
    import jax

    return "native" if jax.default_backend() == "cpu" else "mjx"


def with_resolved_backend(config, announce: bool = True):
    """The run config with `env.backend` resolved (so the saved config records the choice), printed."""
    if getattr(config, "env_name", "self_touch") != "self_touch":
        return config
    chosen = resolve_backend(config.env.backend)
    if announce:
        how = "auto: JAX runs on the " + ("CPU" if chosen == "native" else "accelerator") \
            if config.env.backend == "auto" else "from the config"
        print(f"physics backend: {chosen} ({how})", flush=True)
    return dataclasses.replace(config, env=dataclasses.replace(config.env, backend=chosen))


def make_env(config):
    """`config` has `env_name` and the matching section (`env` for self_touch, `toy` for toy)."""
    if config.env_name == "toy":
        from mjx_protamer.envs.toy import PointReachEnv

        return PointReachEnv(config.toy)
    return make_self_touch_env(config.env)


def make_self_touch_env(env_config):
    """The self-touch env on the backend `env_config.backend` names (auto resolved here)."""
    if resolve_backend(env_config.backend) == "native":
        from mjx_protamer.envs.native_env import NativeSelfTouchEnv

        return NativeSelfTouchEnv(env_config)
    from mjx_protamer.envs.self_touch import SelfTouchEnv

    return SelfTouchEnv(env_config)
