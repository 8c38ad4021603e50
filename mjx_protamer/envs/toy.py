"""A tiny pure-JAX control problem on the env contract: a 2-D point that must reach a goal.

Compiles in a second and is solved by DDPG in a few thousand steps, so the learner's tests can demand
that it succeeds. It also emits the signals the self-touch metrics read (`self_contact`, `region_mask`,
`arm_speed`), so evaluation and logging code run unchanged on it:

- the point starts and the goal lies uniformly in [-1, 1]^2; an action in [-1, 1]^2 is a velocity,
  the point moves `max_step * action` per step (clipped to the arena);
- observation (6): position, goal, goal - position;
- reward terms: `distance` (-|goal - position|), `effort` (-|action|^2), `reach` (1 inside `reach_radius`);
- `self_contact` is 1 inside `reach_radius`; `region_mask` is one-hot in the goal's octant while reaching;
  `arm_speed` is the speed in arena units per 0.1 step (so 1 "rad/s" = moving 0.1 per step).
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp

from mjx_protamer.config import check
from mjx_protamer.envs.base import State


@dataclass(frozen=True)
class ToyEnvConfig:
    max_step: float = 0.15  # the point moves max_step x action per step (arena units; the arena is [-1, 1]^2)
    # within this distance of the goal the point counts as reaching it (the reach term, self_contact)
    reach_radius: float = 0.1
    reward_weights: tuple[float, ...] = (1.0, 0.05, 0.5)  # distance, effort, reach

    def validate(self) -> None:
        check(self.max_step > 0, "max_step", f"must be > 0, got {self.max_step}")
        check(self.reach_radius > 0, "reach_radius", f"must be > 0, got {self.reach_radius}")
        check(len(self.reward_weights) == 3, "reward_weights", f"needs 3 weights, got {self.reward_weights}")


class PointReachEnv:
    observation_size = 6
    action_size = 2
    reward_term_names = ("distance", "effort", "reach")
    region_names: tuple[str, ...] = ()  # no body: its region_mask is an octant stand-in for the metrics only

    def __init__(self, config: ToyEnvConfig | None = None):
        self.config = config or ToyEnvConfig()
        self.reward_weights = tuple(self.config.reward_weights)

    def _obs(self, pos: jax.Array, goal: jax.Array) -> jax.Array:
        return jnp.concatenate([pos, goal, goal - pos])

    def reset(self, rng: jax.Array) -> State:
        k_pos, k_goal = jax.random.split(rng)
        pos = jax.random.uniform(k_pos, (2,), minval=-1.0, maxval=1.0)
        goal = jax.random.uniform(k_goal, (2,), minval=-1.0, maxval=1.0)
        data = {"pos": pos, "goal": goal}
        zero = jnp.zeros(())
        metrics = {
            "reward_terms": jnp.zeros((3,)),
            "self_contact": zero,
            "region_mask": jnp.zeros((8,)),
            "arm_speed": zero,
            "nan_reset": zero,
        }
        return State(data=data, obs=self._obs(pos, goal), reward=zero, done=zero, metrics=metrics, info={})

    def step(self, state: State, action: jax.Array) -> State:
        action = jnp.clip(action, -1.0, 1.0)
        pos, goal = state.data["pos"], state.data["goal"]
        new_pos = jnp.clip(pos + self.config.max_step * action, -1.0, 1.0)
        dist = jnp.linalg.norm(goal - new_pos)
        reached = (dist < self.config.reach_radius).astype(jnp.float32)
        terms = jnp.stack([-dist, -jnp.sum(action**2), reached])
        reward = terms @ jnp.asarray(self.reward_weights)
        octant = jnp.floor((jnp.arctan2(goal[1], goal[0]) + jnp.pi) / (2 * jnp.pi) * 8).astype(jnp.int32) % 8
        metrics = {
            "reward_terms": terms,
            "self_contact": reached,
            "region_mask": jax.nn.one_hot(octant, 8) * reached,
            "arm_speed": jnp.linalg.norm(new_pos - pos) / 0.1,
            "nan_reset": jnp.zeros(()),
        }
        return state.replace(
            data={"pos": new_pos, "goal": goal},
            obs=self._obs(new_pos, goal),
            reward=reward,
            done=jnp.zeros(()),
            metrics=metrics,
        )
