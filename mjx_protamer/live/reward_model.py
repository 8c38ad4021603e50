"""DeepTAMER's reward model in a live session: the batched path's ring buffer and jitted updates, a batch of one.

A session credits events on the host (by wall-clock time, `human.credit.CreditAssigner`: a person's feedback
carries times, not arrival steps); what the credited steps then do is the batched path's, through the same
functions (`human.batched`): each event's steps are drawn `rows_per_event` times in proportion to their credit
weight (as `batched.draw_credited_steps`), weighted by the posterior over the judged step when
`credit.posterior_temperature` > 0, stored in the device `FeedbackRing` with the steps the teacher watched in
silence (target 0, each weighing `credit.silence_weight` events), and `batched.reward_model_updates` takes
`updates_per_feedback` minibatch steps per event on the chunk's new rows and `chunk_steps // replay_every`
replay minibatches. One jitted call per chunk, one compile (the event count is a traced value).
"""

from __future__ import annotations

import functools
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from mjx_protamer.human.batched import FeedbackRing, reward_model_updates, ring_add, ring_init
from mjx_protamer.human.credit import CreditConfig, posterior_weights
from mjx_protamer.human.reward_model import RewardModelConfig, reward_nets


class RewardModelState(NamedTuple):
    params: Any
    opt_state: Any
    ring: FeedbackRing
    key: jax.Array
    updates: jax.Array  # int32: minibatch steps taken


class SessionRewardModel:
    """r_hat of a session: its state on the device, the rows of each chunk absorbed in one jitted call."""

    def __init__(self, config: RewardModelConfig, credit: CreditConfig, obs_size: int, action_size: int,
                 seed: int, chunk_steps: int, max_events: int, rows_per_event: int):
        self.config, self.credit = config, credit
        self.obs_size, self.action_size = obs_size, action_size
        self.max_events, self.rows_per_event = max_events, rows_per_event
        self.max_silent = 2 * chunk_steps  # silent steps absorbed per chunk (more after a pause: subsampled)
        nets = reward_nets(config)
        self.apply = nets.apply
        optimizer = optax.adam(config.learning_rate)
        # the batched runs' initialisation for a seed (experiments/feedback_train.py init)
        k_net, k_run = jax.random.split(jax.random.fold_in(jax.random.PRNGKey(seed), 0x7A3E))
        params = nets.net.init(k_net, jnp.zeros((1, obs_size)), jnp.zeros((1, action_size)))
        self.state = RewardModelState(params, optimizer.init(params),
                                      ring_init(config.buffer_size, obs_size, action_size), k_run,
                                      jnp.zeros((), jnp.int32))
        self.rng = np.random.default_rng([seed, 0x5E55])  # host draws of each event's credited steps
        n_replay = chunk_steps // config.replay_every if config.replay_every else 0
        self._absorb = jax.jit(functools.partial(
            _absorb, nets.fit, nets.apply, optimizer, config, credit.posterior_temperature,
            config.updates_per_feedback * max_events, n_replay), donate_argnums=0)
        self._predict = jax.jit(nets.apply)
        self.last_loss = float("nan")

    @property
    def params(self):
        return self.state.params

    @property
    def updates(self) -> int:
        return int(self.state.updates)

    def commit(self, device) -> None:
        self.state = jax.device_put(self.state, device)

    def draw(self, obs: np.ndarray, action: np.ndarray, weight: np.ndarray):
        """An event's credited steps -> `rows_per_event` of them drawn in proportion to their weight (with
        replacement, each row weighing 1: the Monte-Carlo estimate of the event's weighted loss)."""
        idx = self.rng.choice(len(weight), self.rows_per_event, p=weight / weight.sum())
        return obs[idx], action[idx]

    def absorb(self, events: list[tuple[np.ndarray, np.ndarray, float]], silent) -> int:
        """`events`: (obs (K, O), action (K, A), value) of each credited event (at most max_events, as drawn
        by `draw`); `silent`: (obs, action) of the steps watched in silence. Returns the updates taken."""
        E, K, S = self.max_events, self.rows_per_event, self.max_silent
        ev_obs = np.zeros((E, K, self.obs_size), np.float32)
        ev_act = np.zeros((E, K, self.action_size), np.float32)
        ev_w = np.zeros((E, K), np.float32)
        ev_h = np.zeros((E, K), np.float32)
        for i, (o, a, v) in enumerate(events):
            ev_obs[i], ev_act[i], ev_w[i], ev_h[i] = o, a, 1.0, v
        s_obs = np.zeros((S, self.obs_size), np.float32)
        s_act = np.zeros((S, self.action_size), np.float32)
        s_w = np.zeros((S,), np.float32)
        n_silent = len(silent[0])
        if n_silent and self.credit.silence_weight > 0:
            take = np.arange(n_silent) if n_silent <= S else np.sort(self.rng.choice(n_silent, S, replace=False))
            s_obs[:len(take)], s_act[:len(take)] = silent[0][take], silent[1][take]
            # a silent step weighs silence_weight events (an event's K rows weigh 1 each); a row stands for
            # n_silent / len(take) of them
            s_w[:len(take)] = self.credit.silence_weight * K * n_silent / len(take)
        before = int(self.state.updates)
        self.state, loss = self._absorb(self.state, ev_obs, ev_act, ev_w, ev_h, np.int32(len(events)),
                                        s_obs, s_act, s_w)
        loss = float(loss)
        if np.isfinite(loss):
            self.last_loss = loss
        return int(self.state.updates) - before

    def predict(self, obs, action) -> np.ndarray:
        return np.asarray(self._predict(self.state.params, jnp.asarray(obs, jnp.float32),
                                        jnp.asarray(action, jnp.float32)))


def feedback_rows(inputs, key, n: int, sign: float):
    """`n` rows (obs, action, weight) of what the person praised (`sign` +1) or reproached (-1), for DDPG's
    `praise_imitation_coef` and `reproach_avoid_coef`: drawn from the session's feedback ring `inputs[1]` in
    proportion to weight x |value| among its rows of that sign (a stronger word counts more; never a silence),
    each weighing 1; all weigh 0 until the person has said something of that sign."""
    ring = inputs[1]
    cap = ring.weight.shape[0]
    mass = jnp.where((jnp.arange(cap) < ring.size) & (sign * ring.target > 0), ring.weight * sign * ring.target, 0.0)
    cdf = jnp.cumsum(mass)
    idx = jnp.clip(jnp.searchsorted(cdf, jax.random.uniform(key, (n,)) * cdf[-1], side="right"), 0, cap - 1)
    return ring.obs[idx], ring.action[idx], jnp.full((n,), jnp.where(cdf[-1] > 0, 1.0, 0.0))


def _absorb(fit, apply, optimizer, config: RewardModelConfig, temperature: float, n_fresh_max: int, n_replay: int,
            state: RewardModelState, ev_obs, ev_act, ev_w, ev_h, n_events, s_obs, s_act, s_w):
    E, K = ev_w.shape
    obs_size, act_size = ev_obs.shape[-1], ev_act.shape[-1]
    ev_obs, ev_act = ev_obs.reshape(E * K, obs_size), ev_act.reshape(E * K, act_size)
    if temperature > 0:  # the model's agreement moves each event's weight among its rows (credit.py)
        ev_w = posterior_weights(jnp, ev_w, ev_h, apply(state.params, ev_obs, ev_act).reshape(E, K), temperature)
    obs = jnp.concatenate([ev_obs, s_obs])
    action = jnp.concatenate([ev_act, s_act])
    weight = jnp.concatenate([ev_w.reshape(-1), s_w])
    target = jnp.concatenate([ev_h.reshape(-1), jnp.zeros_like(s_w)])
    ring = ring_add(state.ring, obs, action, weight, target)
    key, k = jax.random.split(state.key)
    params, opt_state, losses, live = reward_model_updates(
        fit, optimizer, state.params, state.opt_state, ring, (obs, action, weight, target), k, n_fresh_max, n_replay,
        config.batch_size, config.replay_min_rows, config.balance_max if config.balance_signs else None,
        fresh_count=config.updates_per_feedback * n_events)
    n_live = jnp.sum(live)
    loss = jnp.where(n_live > 0, jnp.sum(jnp.where(live, losses, 0.0)) / jnp.maximum(n_live, 1), jnp.nan)
    return RewardModelState(params, opt_state, ring, key, state.updates + n_live.astype(jnp.int32)), loss
