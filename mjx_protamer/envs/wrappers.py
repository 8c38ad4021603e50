"""Wrappers: episode length, auto-reset and vmap, in the style of MuJoCo Playground / Brax."""

from __future__ import annotations

import jax
import jax.numpy as jnp

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
        info = dict(state.info, steps=jnp.zeros((), jnp.int32), truncation=jnp.zeros(()))
        return state.replace(info=info)

    def step(self, state: State, action: jax.Array) -> State:
        nstate = self.env.step(state, action)
        steps = state.info["steps"] + 1
        out_of_time = steps >= self.episode_length
        truncation = jnp.where(out_of_time & (nstate.done == 0), 1.0, 0.0)
        done = jnp.where(out_of_time, 1.0, nstate.done)
        info = dict(nstate.info, steps=steps, truncation=truncation)
        return nstate.replace(done=done, info=info)


# Info entries that describe the finished transition rather than carried state: never reset.
TRANSITION_INFO_KEYS = ("truncation",)


class AutoResetWrapper(Wrapper):
    """Resets a finished episode in place; `info["final_obs"]` keeps the observation reached.

    Carried state lives in `info` and is reset; what a transition produced lives in `metrics`
    (reward terms, contact signals) and is kept. The reset uses a key carried in `info["reset_rng"]`, so batched envs reset independently and a
    seed fixes the whole sequence of episodes.
    """

    def reset(self, rng: jax.Array) -> State:
        rng, carry = jax.random.split(rng)
        state = self.env.reset(rng)
        info = dict(state.info, reset_rng=carry, final_obs=state.obs, episodes=jnp.zeros((), jnp.int32))
        return state.replace(info=info)

    def step(self, state: State, action: jax.Array) -> State:
        nstate = self.env.step(state, action)
        rng, reset_rng = jax.random.split(state.info["reset_rng"])
        fresh = self.env.reset(reset_rng)
        done = nstate.done > 0
        where_done = lambda reset_value, current: jnp.where(done, reset_value, current)

        data = jax.tree.map(where_done, fresh.data, nstate.data)
        info = dict(nstate.info)
        for k, v in fresh.info.items():
            if k not in TRANSITION_INFO_KEYS:
                info[k] = jax.tree.map(where_done, v, nstate.info[k])
        info.update(
            reset_rng=rng,
            final_obs=nstate.obs,
            episodes=state.info["episodes"] + done.astype(jnp.int32),
        )
        obs = where_done(fresh.obs, nstate.obs)
        # reward, done and metrics describe the step just taken and are kept as they are.
        return nstate.replace(data=data, obs=obs, info=info)


class VmapWrapper(Wrapper):
    """Runs a batch of independent envs: reset takes a batch of keys, step a batch of states."""

    def reset(self, rng: jax.Array) -> State:
        return jax.vmap(self.env.reset)(rng)

    def step(self, state: State, action: jax.Array) -> State:
        return jax.vmap(self.env.step)(state, action)


def wrap_for_training(env, episode_length: int):
    """Episode limit + auto-reset + vmap: reset takes (num_envs, 2) keys."""
    return VmapWrapper(AutoResetWrapper(EpisodeWrapper(env, episode_length)))
