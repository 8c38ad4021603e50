"""A ring-buffer replay memory in device memory, carried in the train state and sampled inside jit.

It stores the reward *components* (`reward_terms`), never the scalar reward: the learner computes the
reward when it samples (`losses.relabel`), so a human-reward model that keeps learning relabels every
stored transition with its current parameters.

Under data parallelism every device holds its own buffer of `capacity / devices` rows (the arrays are
sharded along their first axis); `ptr` and `size` advance identically on every device.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from flax import struct


class Transition(NamedTuple):
    obs: jax.Array  # (..., obs)
    action: jax.Array  # (..., act), the action taken (after noise and clipping)
    reward_terms: jax.Array  # (..., terms), env.metrics["reward_terms"]
    next_obs: jax.Array  # (..., obs), the observation reached (info["final_obs"] across a reset)
    terminal: jax.Array  # (...,), 1 where the episode truly ended (no bootstrap); 0 on time-limit truncation


@struct.dataclass
class ReplayBuffer:
    data: Transition  # each field (capacity, ...)
    ptr: jax.Array  # next row to write
    size: jax.Array  # rows filled so far (<= capacity)

    @property
    def capacity(self) -> int:
        return self.data.obs.shape[0]


def init(capacity: int, obs_size: int, action_size: int, num_terms: int) -> ReplayBuffer:
    z = lambda *shape: jnp.zeros((capacity, *shape), jnp.float32)
    data = Transition(z(obs_size), z(action_size), z(num_terms), z(obs_size), z())
    return ReplayBuffer(data=data, ptr=jnp.zeros((), jnp.int32), size=jnp.zeros((), jnp.int32))


def add(buffer: ReplayBuffer, batch: Transition) -> ReplayBuffer:
    """Write a batch of transitions (leading axis n <= capacity) at ptr, wrapping around."""
    n = batch.obs.shape[0]
    capacity = buffer.capacity
    if n > capacity:
        raise ValueError(f"cannot add {n} transitions to a buffer of capacity {capacity}")
    rows = (buffer.ptr + jnp.arange(n)) % capacity
    data = jax.tree.map(lambda store, new: store.at[rows].set(new.astype(store.dtype)), buffer.data, batch)
    return ReplayBuffer(
        data=data,
        ptr=(buffer.ptr + n) % capacity,
        size=jnp.minimum(buffer.size + n, capacity),
    )


def newest(buffer: ReplayBuffer, capacity: int) -> ReplayBuffer:
    """A buffer of `capacity` rows holding the most recent min(capacity, size) transitions of `buffer`, oldest
    first (a fine-tuning session's replay seeded with its pretraining run's latest experience)."""
    n = min(int(buffer.size), capacity)
    rows = (int(buffer.ptr) - n + jnp.arange(n)) % buffer.capacity
    data = jax.tree.map(lambda store: jnp.zeros((capacity, *store.shape[1:]), store.dtype).at[:n].set(store[rows]),
                        buffer.data)
    return ReplayBuffer(data=data, ptr=jnp.asarray(n % capacity, jnp.int32), size=jnp.asarray(n, jnp.int32))


def sample(buffer: ReplayBuffer, rng: jax.Array, batch_size: int) -> Transition:
    """Uniform sample with replacement from the filled rows (the buffer must hold at least one)."""
    rows = jax.random.randint(rng, (batch_size,), 0, jnp.maximum(buffer.size, 1))
    return jax.tree.map(lambda store: store[rows], buffer.data)
