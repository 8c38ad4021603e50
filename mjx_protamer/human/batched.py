"""DeepTAMER inside jit, for batched experiments: credit by lag, a device feedback buffer, r_hat updates.

The one in-jit implementation of these steps; `experiments.feedback_train` wires them into the DDPG chunk.
The batched simulated teacher (`teachers.batched_teacher`) delivers (value, valid) per step and env.
Without wall-clock times, credit is by lag from the arrival step: `credit.lag_weights` gives the weight
of step k - j for feedback arriving at step k. `draw_credited_steps` draws the credited steps of a chunk's
events; `FeedbackRing` is the 1e4-row feedback buffer in device memory; `reward_model_updates` takes the
minibatch steps of the weighted squared loss. All pure and jittable: the reward-model params and optimiser
state are carried in and out as arrays.

Every draw is by inverse CDF (`jax.random.choice` with `p`: one uniform number per draw and a search in the
cumulative weights), not Gumbel-max (`jax.random.categorical`: one Gumbel number per draw and candidate). In
Table II's chunk the Gumbel numbers were 14M per seed, a third of the chunk's time (docs/environment.md,
"Table II's wall time").
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import optax

from mjx_protamer.human.reward_model import balanced_weight, sign_factors, weighted_loss


def draw_credited_steps(value, valid, lag_w, key, max_events: int, rows_per_event: int):
    """value/valid (T, B) feedback by arrival step and env, lag_w (L,) credit weight of lag j -> credited steps.

    For each of up to `max_events` events, `rows_per_event` lags are drawn in proportion to their credit
    weight: a Monte-Carlo estimate of the weighted loss that stays cheap when a window spans hundreds of
    steps (Deep TAMER's 3.8 s at 200 Hz is 760). Returns (rel (E, K) credited step relative to the chunk's
    first step, possibly negative: an earlier chunk; env (E,); ok (E, K) the row is a real event; target
    (E, K) the event's value; n_events, which may exceed max_events: the surplus is dropped).
    """
    E, K = max_events, rows_per_event
    n_events = jnp.sum(valid)
    t_idx, b_idx = jnp.nonzero(valid, size=E, fill_value=0)
    present = jnp.arange(E) < n_events
    lags = jax.random.choice(key, lag_w.shape[0], (E, K), p=jnp.maximum(lag_w, 0.0))
    ok = present[:, None] & (jnp.sum(lag_w) > 0)
    target = jnp.broadcast_to(value[t_idx, b_idx][:, None], (E, K))
    return t_idx[:, None] - lags, b_idx, ok, target, n_events


def draw_silent_steps(arrived, active, lag_w, key, history_len: int, n_rows: int, watching=None):
    """Steps no feedback was about: the teacher watched and stayed silent through the step's whole credit window.

    `arrived` (H + T, B) bool: feedback reached the learner at that step (the carried history, then the chunk);
    `active` (B,) the env has a teacher; `lag_w` (L,) the credit weight of lag j. A step at row p can be
    credited by arrivals at rows p + j for the lags j with weight; it is silent when none arrived there. Only
    the T steps whose window closes inside this chunk are judged, so each step is judged once over a run.
    With `watching` (H + T, B) bool, the teacher's attention, a step is silent only if the teacher watched
    every step whose feedback could have arrived in its window (rows p + first - last .. p + last - first, for
    the first and last lags with weight). Draws `n_rows` of them uniformly (with replacement). Returns (rel
    (n,) the step relative to the chunk's first step, negative: an earlier chunk; env (n,); ok (n,) there was
    a silent step to draw; n_silent, how many there were: a row stands for n_silent / n_rows of them).

    Why (Loftin et al. 2014, "Learning something from nothing"): a teacher who praises right-hand touches and
    scolds left-hand ones says nothing about the states in between, so a model fitted to events alone never
    sees a 0 and rates everything near the common +1 (measured, docs/experiments.md).
    """
    HT, B = arrived.shape
    T = HT - history_len
    L = lag_w.shape[0]
    has = lag_w > 0
    first = jnp.argmax(has)
    last = L - 1 - jnp.argmax(has[::-1])
    counts = jnp.concatenate([jnp.zeros((1, B), jnp.int32), jnp.cumsum(arrived.astype(jnp.int32), axis=0)])
    p = history_len - last + jnp.arange(T)  # rows whose window's last lag lands in this chunk
    n_arrived = counts[p + last + 1] - counts[p + first]  # arrivals at rows p + first .. p + last
    silent = (n_arrived == 0) & active[None, :] & jnp.any(has)
    if watching is not None:
        away = jnp.concatenate([jnp.zeros((1, B), jnp.int32), jnp.cumsum((~watching).astype(jnp.int32), axis=0)])
        lo = jnp.clip(p + first - last, 0, HT)
        hi = jnp.clip(p + last - first + 1, 0, HT)
        silent = silent & (away[hi] - away[lo] == 0)
    idx = jax.random.choice(key, silent.size, (n_rows,), p=silent.reshape(-1).astype(jnp.float32))
    ok = jnp.broadcast_to(jnp.any(silent), (n_rows,))
    return p[idx // B] - history_len, idx % B, ok, jnp.sum(silent)


def reward_model_updates(apply, optimizer, params, opt_state, ring: "FeedbackRing", fresh_rows, key,
                         n_fresh: int, n_replay: int, batch_size: int, replay_min_rows: int,
                         balance_max: float | None = None, scale=1.0, fresh_count=None):
    """`n_fresh` minibatch steps on the newly credited rows (drawn among those with weight > 0: Deep TAMER
    updates on every feedback), then `n_replay` on uniform draws from the feedback ring (none until it holds
    `replay_min_rows`). A step whose minibatch has no weight leaves params and optimiser state unchanged.
    With `balance_max`, praise and reproach weigh the same (`reward_model.sign_factors` over the ring).
    `scale` multiplies every update (the run's step-size decay, step_size.decay_scale). `fresh_count` (traced,
    <= n_fresh): only that many of the fresh steps are taken (a live session's events per chunk vary; one
    compile). Returns (params, opt_state, losses (n,), live (n,))."""
    obs, action, weight, target = fresh_rows
    min_rows = min(replay_min_rows, ring.obs.shape[0])
    factors = (1.0, 1.0) if balance_max is None else sign_factors(jnp, ring.weight, ring.target, balance_max)

    def step(fresh: bool, carry, xs):
        # Fresh and replay steps are separate scans: a replay step never needs the fresh rows' draw.
        p, o = carry
        k, on = xs
        kf, kr = jax.random.split(k)
        if fresh:
            fi = jax.random.choice(kf, weight.shape[0], (batch_size,), p=(weight > 0).astype(jnp.float32))
            bo, ba, bw, bh = obs[fi], action[fi], weight[fi], target[fi]
        else:
            ri = jax.random.randint(kr, (batch_size,), 0, jnp.maximum(ring.size, 1))
            bo, ba, bh = ring.obs[ri], ring.action[ri], ring.target[ri]
            bw = ring.weight[ri] * (ring.size >= min_rows)
        bw = balanced_weight(jnp, factors, bw, bh)
        loss, g = jax.value_and_grad(weighted_loss)(p, apply, bo, ba, bw, bh)
        u, new_o = optimizer.update(g, o, p)
        live = (jnp.sum(bw) > 0) & on
        u = jax.tree.map(lambda x: x * scale, u)
        p = jax.tree.map(lambda a, b: jnp.where(live, a, b), optax.apply_updates(p, u), p)
        o = jax.tree.map(lambda a, b: jnp.where(live, a, b), new_o, o)
        return (p, o), (loss, live)

    n = max(n_fresh + n_replay, 1)
    n_f = max(n_fresh, n - n_replay)  # the first n_f steps are fresh
    on = jnp.ones((n,), bool) if fresh_count is None else (jnp.arange(n) >= n_fresh) | (jnp.arange(n) < fresh_count)
    keys = jax.random.split(key, n)
    carry, (losses, live) = (params, opt_state), (jnp.zeros((0,)), jnp.zeros((0,), bool))
    for fresh, part in ((True, slice(0, n_f)), (False, slice(n_f, n))):
        if part.stop > part.start:
            carry, (ls, lv) = jax.lax.scan(lambda c, xs, f=fresh: step(f, c, xs), carry, (keys[part], on[part]))
            losses, live = jnp.concatenate([losses, ls]), jnp.concatenate([live, lv])
    params, opt_state = carry
    return params, opt_state, losses, live


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
