"""Test episodes with the deterministic actor, in one jit: the per-step signals the metrics read."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from mjx_protamer.agents.ddpg.networks import Actor


def make_rollout(env, episode_length: int, actor_hidden=(400, 300)):
    """rollout(actor_params, keys (E, 2)) -> dict of (E, T, ...) signals over one episode per key."""
    actor = Actor(action_size=env.action_size, hidden=tuple(actor_hidden))

    @jax.jit
    def rollout(actor_params, keys):
        state = jax.vmap(env.reset)(keys)

        def step(state, _):
            obs = state.obs
            action = actor.apply(actor_params, obs)
            state = jax.vmap(env.step)(state, action)
            m = state.metrics
            zeros = jnp.zeros_like(state.reward)
            signals = {
                "reward": state.reward,
                "self_contact": m.get("self_contact", zeros),
                "region_mask": m.get("region_mask", jnp.zeros(state.reward.shape + (8,))),
                "arm_speed": m.get("arm_speed", zeros),
                # what a simulated teacher and the reward model read (teacher_score, r_hat_corr_test)
                "obs": obs,
                "action": action,
                "reward_terms": m["reward_terms"],
            }
            return state, signals

        _, signals = jax.lax.scan(step, state, None, length=episode_length)
        return jax.tree.map(lambda x: jnp.swapaxes(x, 0, 1), signals)

    return rollout
