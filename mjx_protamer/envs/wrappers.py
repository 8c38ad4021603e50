"""Wrappers: episode length, auto-reset and vmap, in the style of MuJoCo Playground / Brax."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from mjx_protamer.batch_cond import batch_any
from mjx_protamer.envs.base import State


class Wrapper:
    def __init__(self, env):
        self.env = env

    def __getattr__(self, name):
        return getattr(self.env, name)

    def reset(self, rng: jax.Array) -> State:
        return self.env.reset(rng)

    def step(self, state: State, action: jax.Array) -> State:
        return self.env.step(state, action)


class EpisodeWrapper(Wrapper):
    """Ends an episode after `episode_length` steps, marking it as a truncation."""

    def __init__(self, env, episode_length: int):
        super().__init__(env)
        if episode_length < 1:
            raise ValueError(f"episode_length must be >= 1, got {episode_length}")
        self.episode_length = episode_length

    def reset(self, rng: jax.Array) -> State:
        state = self.env.reset(rng)
        info = dict(state.info, steps=jnp.zeros((), jnp.int32), truncation=jnp.zeros((), jnp.float32))
        return state.replace(info=info)

    def step(self, state: State, action: jax.Array) -> State:
        nstate = self.env.step(state, action)
        steps = state.info["steps"] + 1
        out_of_time = steps >= self.episode_length
        # Strongly typed float32: a weak type here would change the carry's type and recompile.
        truncation = (out_of_time & (nstate.done == 0)).astype(jnp.float32)
        done = jnp.where(out_of_time, jnp.float32(1.0), nstate.done).astype(jnp.float32)
        info = dict(nstate.info, steps=steps, truncation=truncation)
        return nstate.replace(done=done, info=info)


# Info entries that describe the finished transition rather than carried state: never reset.
TRANSITION_INFO_KEYS = ("truncation",)


def _where_batch(mask: jax.Array, on_true, on_false):
    """Per-env select over a batched pytree: mask (B,) broadcast against each leaf's leading axis."""
    def pick(a, b):
        return jnp.where(mask.reshape(mask.shape + (1,) * (b.ndim - 1)), a, b)
    return jax.tree.map(pick, on_true, on_false)


class AutoResetWrapper(Wrapper):
    """Resets finished episodes of a BATCHED env (wrap a VmapWrapper) in place.

    A fresh reset (settling physics steps) is computed only when some env finished, under one
    `lax.cond` on the whole batch: inside vmap the condition would become a select and every step
    would pay for a reset. Carried state lives in `info` and is reset; what the transition produced
    lives in `metrics`, `reward` and `done` and is kept; `info["final_obs"]` is the observation the
    step reached before any reset. Reset keys are carried in `info["reset_rng"]`, so a seed fixes the
    whole sequence of episodes.
    """

    def reset(self, rng: jax.Array) -> State:
        keys = jax.vmap(jax.random.split)(rng)
        state = self.env.reset(keys[:, 0])
        info = dict(state.info, reset_rng=keys[:, 1], final_obs=state.obs,
                    episodes=jnp.zeros(state.done.shape, jnp.int32))
        return state.replace(info=info)

    def step(self, state: State, action: jax.Array) -> State:
        nstate = self.env.step(state, action)
        keys = jax.vmap(jax.random.split)(state.info["reset_rng"])
        done = nstate.done > 0

        def reset_finished(_):
            fresh = self.env.reset(keys[:, 1])
            info = {k: v for k, v in nstate.info.items()}
            for k, v in fresh.info.items():
                if k not in TRANSITION_INFO_KEYS:
                    info[k] = _where_batch(done, v, nstate.info[k])
            return _where_batch(done, fresh.data, nstate.data), _where_batch(done, fresh.obs, nstate.obs), info

        def keep(_):
            return nstate.data, nstate.obs, dict(nstate.info)

        # `batch_any`: with seeds vmapped, one reset pass serves every seed where any env finished (a seed with
        # none keeps its states under `_where_batch`), instead of a select that pays the reset at every step
        data, obs, info = jax.lax.cond(batch_any(jnp.any(done)), reset_finished, keep, None)
        info.update(reset_rng=keys[:, 0], final_obs=nstate.obs,
                    episodes=state.info["episodes"] + done.astype(jnp.int32))
        return nstate.replace(data=data, obs=obs, info=info)


class VmapWrapper(Wrapper):
    """Runs a batch of independent envs: reset takes a batch of keys, step a batch of states."""

    def reset(self, rng: jax.Array) -> State:
        return jax.vmap(self.env.reset)(rng)

    def step(self, state: State, action: jax.Array) -> State:
        return jax.vmap(self.env.step)(state, action)


def wrap_for_training(env, episode_length: int):
    """Episode limit + vmap + auto-reset: reset takes (num_envs, 2) keys, step a batch."""
    return AutoResetWrapper(VmapWrapper(EpisodeWrapper(env, episode_length)))
