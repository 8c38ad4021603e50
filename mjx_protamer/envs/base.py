"""The environment contract, in the shape of MuJoCo Playground: a pure reset/step on a pytree State.

An env is written for ONE world. Batching, episode length and auto-reset are wrappers
(`mjx_protamer.envs.wrappers`). Learners rely only on this contract:

- `env.observation_size`, `env.action_size` (actions live in [-1, 1]);
- `env.reward_term_names` and `env.reward_weights`: the reward is
  `metrics["reward_terms"] @ weights`, so a learner can store the terms and relabel at sample time;
- `env.region_names` (optional; empty or absent for an env without a body): the body regions, in the
  order of `metrics["region_mask"]`, which teacher rules may read (`region:NAME`, `regions_touched`);
- `state.metrics` holds what the transition produced (reward terms, contact signals): wrappers
  never reset it; `state.info` holds carried state (reset on auto-reset);
- `state.info["truncation"]` is 1.0 where an episode ended by its time limit (bootstrap through it),
  `state.done` is 1.0 where it ended for any reason, and after auto-reset `state.info["final_obs"]`
  holds the observation the step actually reached (the learner's next observation).
"""

from __future__ import annotations

from typing import Any, Protocol

import jax
from flax import struct


@struct.dataclass
class State:
    data: Any  # physics state (mjx.Data for the self-touch env), or any pytree
    obs: jax.Array
    reward: jax.Array
    done: jax.Array
    metrics: dict[str, jax.Array]
    info: dict[str, Any]


class Env(Protocol):
    observation_size: int
    action_size: int
    reward_term_names: tuple[str, ...]
    reward_weights: tuple[float, ...]

    def reset(self, rng: jax.Array) -> State: ...

    def step(self, state: State, action: jax.Array) -> State: ...
