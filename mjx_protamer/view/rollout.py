"""Test episodes of the deterministic actor that keep what a picture needs (pure JAX, no I/O).

Like `agents.ddpg.evaluate.make_rollout`, plus the pose of every step: the self-touch env's full `qpos`,
or the toy env's (position, goal).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from mjx_protamer.agents.ddpg.networks import Actor


def _pose(state):
    if isinstance(state.data, dict):  # the toy env: position and goal
        return jnp.concatenate([state.data["pos"], state.data["goal"]], axis=-1)
    return state.data.qpos


def make_pose_rollout(env, episode_length: int, actor_hidden=(400, 300)):
    """rollout(actor_params, keys (E, 2)) -> dict of (E, T + 1, ...) arrays: the start and every step's pose,
    region mask (8) and self_contact (0 at the start)."""
    actor = Actor(action_size=env.action_size, hidden=tuple(actor_hidden))

    @jax.jit
    def rollout(actor_params, keys):
        state = jax.vmap(env.reset)(keys)

        def signals(s):
            m = s.metrics
            return {"pose": _pose(s), "region_mask": m["region_mask"], "self_contact": m["self_contact"],
                    "reward": s.reward}

        def step(s, _):
            s = jax.vmap(env.step)(s, actor.apply(actor_params, s.obs))
            return s, signals(s)

        first = signals(state)
        _, out = jax.lax.scan(step, state, None, length=episode_length)
        out = jax.tree.map(lambda a, b: jnp.concatenate([a[None], b], axis=0), first, out)
        return jax.tree.map(lambda x: jnp.swapaxes(x, 0, 1), out)

    return rollout
