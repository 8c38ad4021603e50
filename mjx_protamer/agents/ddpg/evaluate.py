"""Test episodes of the deterministic actor in one jit: the one rollout that evaluation, pictures and snapshot
selection run (pure JAX, no I/O).

`keep=` names the per-step signals a caller reads; nothing else leaves the jit (inside a caller's jit XLA drops
what the caller does not use). Per step t of an episode:
- `obs`, `action`: the observation the actor saw and the action it took;
- `reward`, `self_contact`, `region_mask` (8), `arm_speed`, `reward_terms`, `pose`: of the state that step
  reached. `pose` is the self-touch env's full `qpos`, or the toy env's (position, goal).
With `start=True` the reset state's signals come first (T + 1 rows: what a picture of the episode shows), so
only the signals of a state can be kept then.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from mjx_protamer.agents.ddpg.networks import Actor

STATE_SIGNALS = ("reward", "self_contact", "region_mask", "arm_speed", "reward_terms", "pose")
SIGNALS = ("obs", "action") + STATE_SIGNALS
METRIC_SIGNALS = ("reward", "self_contact", "region_mask", "arm_speed")  # what the paper's metrics read


def _state_signal(state, name: str):
    if name == "reward":
        return state.reward
    if name == "pose":
        if isinstance(state.data, dict):  # the toy env: position and goal
            return jnp.concatenate([state.data["pos"], state.data["goal"]], axis=-1)
        return state.data.qpos
    if name == "region_mask":
        return state.metrics.get("region_mask", jnp.zeros(state.reward.shape + (8,)))
    if name == "reward_terms":
        return state.metrics["reward_terms"]
    return state.metrics.get(name, jnp.zeros_like(state.reward))  # an env without a body has no contact


def make_rollout(env, episode_length: int, actor_hidden=(400, 300), keep=METRIC_SIGNALS, start: bool = False):
    """rollout(actor_params, keys (E, 2)) -> {name: (E, T, ...)} for every name in `keep`, one episode per key
    ((E, T + 1, ...) with `start`)."""
    keep = tuple(keep)
    allowed = STATE_SIGNALS if start else SIGNALS
    unknown = [k for k in keep if k not in allowed]
    if unknown or not keep:
        raise ValueError(f"rollout keep={keep!r}: each must be one of {', '.join(allowed)}"
                         + (" (start=True keeps a state's signals only)" if start else ""))
    actor = Actor(action_size=env.action_size, hidden=tuple(actor_hidden))
    state_keep = [k for k in keep if k in STATE_SIGNALS]

    @jax.jit
    def rollout(actor_params, keys):
        state = jax.vmap(env.reset)(keys)

        def step(state, _):
            obs = state.obs
            action = actor.apply(actor_params, obs)
            state = jax.vmap(env.step)(state, action)
            signals = {"obs": obs, "action": action, **{k: _state_signal(state, k) for k in state_keep}}
            return state, {k: signals[k] for k in keep}

        _, signals = jax.lax.scan(step, state, None, length=episode_length)
        if start:
            first = {k: _state_signal(state, k) for k in keep}
            signals = jax.tree.map(lambda a, b: jnp.concatenate([a[None], b], axis=0), first, signals)
        return jax.tree.map(lambda x: jnp.swapaxes(x, 0, 1), signals)

    return rollout
