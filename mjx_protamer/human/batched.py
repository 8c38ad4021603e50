"""DeepTAMER inside jit, for batched experiments: credit by lag, a device feedback buffer, r_hat updates.

The batched simulated teacher (`teachers.batched_teacher`) delivers (value, valid) per step and env.
Without wall-clock times, credit is by lag from the arrival step: `credit.lag_weights` gives the weight
of step k - j for feedback arriving at step k (0.9^j for the step window; the overlap / 3.8 of the time
window on a regular clock). `credit_windows` gathers, for up to `max_events` feedbacks of a chunk, the
(obs, action) of their windows; steps before the chunk's first step are not available and get weight 0
(chunks are much longer than the window in batched runs). `FeedbackRing` is the 1e4-row feedback buffer
in device memory; `tamer_update` adds a chunk's credited rows and takes `n_updates` minibatch steps of the
weighted squared loss. All pure and jittable: the reward-model params and optimiser state are carried in
and out as arrays.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import optax

from mjx_protamer.human.reward_model import weighted_loss


def credit_windows(obs, action, value, valid, lag_w, max_events: int):
    """obs (T, B, O), action (T, B, A), value/valid (T, B), lag_w (L,) -> rows (E*L, ...) with weights.

    Returns (obs, action, weight, target, n_events); rows of absent events or of steps before the
    chunk have weight 0. Events beyond `max_events` in a chunk are dropped (count them with n_events).
    """
    T = obs.shape[0]
    L = lag_w.shape[0]
    t_idx, b_idx = jnp.nonzero(valid, size=max_events, fill_value=0)
    n_events = jnp.sum(valid)
    present = jnp.arange(max_events) < n_events
    steps = t_idx[:, None] - jnp.arange(L)[None, :]  # (E, L)
    ok = (steps >= 0) & present[:, None]
    s = jnp.clip(steps, 0, T - 1)
    b = jnp.broadcast_to(b_idx[:, None], s.shape)
    w = jnp.where(ok, lag_w[None, :], 0.0)
    h = jnp.broadcast_to(value[t_idx, b_idx][:, None], s.shape)
    flat = lambda x: x.reshape(max_events * L, *x.shape[2:])
    return flat(obs[s, b]), flat(action[s, b]), flat(w), flat(h), n_events


class FeedbackRing(NamedTuple):
    obs: jax.Array
    action: jax.Array
    weight: jax.Array
    target: jax.Array
    ptr: jax.Array
    size: jax.Array


def ring_init(capacity: int, obs_size: int, action_size: int) -> FeedbackRing:
    z = lambda *s: jnp.zeros((capacity, *s), jnp.float32)
    return FeedbackRing(z(obs_size), z(action_size), z(), z(), jnp.zeros((), jnp.int32), jnp.zeros((), jnp.int32))


def ring_add(ring: FeedbackRing, obs, action, weight, target) -> FeedbackRing:
    """Append the rows with weight > 0 (compacted; the rest are dropped)."""
    cap = ring.obs.shape[0]
    n = weight.shape[0]
    keep = weight > 0
    (idx,) = jnp.nonzero(keep, size=n, fill_value=0)
    count = jnp.minimum(jnp.sum(keep), cap)
    rows = (ring.ptr + jnp.arange(n)) % cap
    live = jnp.arange(n) < count
    rows = jnp.where(live, rows, cap)  # out of bounds: dropped by mode="drop"
    put = lambda store, new: store.at[rows].set(new[idx], mode="drop")
    return FeedbackRing(put(ring.obs, obs), put(ring.action, action), put(ring.weight, weight),
                        put(ring.target, target), (ring.ptr + count) % cap, jnp.minimum(ring.size + count, cap))


def tamer_update(apply, optimizer, params, opt_state, ring: FeedbackRing, rows, key, n_updates: int,
                 batch_size: int = 64):
    """Add credited rows to the ring, then n_updates minibatch steps on uniform ring samples."""
    ring = ring_add(ring, *rows)

    def step(carry, k):
        p, o = carry
        r = jax.random.randint(k, (batch_size,), 0, jnp.maximum(ring.size, 1))
        w = ring.weight[r] * (ring.size > 0)
        loss, g = jax.value_and_grad(weighted_loss)(p, apply, ring.obs[r], ring.action[r], w, ring.target[r])
        u, o = optimizer.update(g, o, p)
        return (optax.apply_updates(p, u), o), loss

    (params, opt_state), losses = jax.lax.scan(step, (params, opt_state), jax.random.split(key, n_updates))
    return params, opt_state, ring, jnp.mean(losses)
