"""Credit assignment: which env steps a feedback event is about, and with what weight. No JAX.

Three schemes (`CreditConfig.scheme`):

- "channel" (the default): the event's onset `t_start` came a reaction delay after the step it judges, and
  the delay has the distribution of the channel the event came through (`channels.ChannelConfig`: a key
  press 0.35 +- 0.1 s, speech onset 0.8 +- 0.25 s, ...). Step i, spanning [s_i, e_i), gets the probability
  that t_start - delay falls in it: F(t_start - s_i) - F(t_start - e_i), F the delay's CDF. At 200 Hz a key
  press credits about 50-90 steps back, where the person's judgement actually was: the authors' 15-step
  window (75 ms) lies before any human reaction, and Deep TAMER's Uniform[0.2, 4] s spreads each event over
  760 steps of which about 5% hold the judged behaviour (measured, issue 8).

- "step_window", the paper authors' code: the event lands on the step being shown at its time
  (`StepClock.step_at(event.t_start)`, step k); steps k, k-1, ..., k-14 get weights 0.9^0, ..., 0.9^14.
- "time_window", Deep TAMER as published (Warnell et al. 2018): the human's delay is Uniform[0.2, 4.0] s,
  so the probability that feedback at time t is about step i, which spans [s_i, e_i), is
  |[s_i, e_i) ∩ [t - 4.0, t - 0.2]| / 3.8. Steps with weight 0 are not credited.

With `posterior_temperature` T > 0 (any scheme) an event's weights are then reweighted by how well the
current reward model agrees with it: w_i exp(T v r_hat_i), renormalised to the event's total
(`posterior_weights`). The delay distribution is the prior over which step the teacher judged; the model's
rating is the likelihood that the teacher would say v about step i; the product is the posterior, an
online EM step. Why: within a praised stretch, the short gaps between touches get the praise around them
from the delay's spread (docs/experiments.md, "Where r_hat errs on the learner's own test states"); the
posterior moves an event's weight onto the steps that look like what it praised.

The event's time is `t_start`: the onset of the key press or of the utterance (the reaction), not the
end of a long sentence. Either scheme accepts at most one event per `min_interval_steps` (the authors'
"feedback accepted at most every 5 steps"), measured between the steps the events land on; a dropped
event is reported with its reason. The weights are the `w` of the weighted squared loss
`w * (r_hat(s, a) - h)^2` of the reward model.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Literal

import numpy as np

from mjx_protamer.config import check
from mjx_protamer.human.channels import ChannelConfig, delay_cdf, delay_quantile_span
from mjx_protamer.human.clock import StepClock
from mjx_protamer.human.events import FeedbackEvent


@dataclasses.dataclass(frozen=True)
class CreditConfig:
    # which steps an event is about: channel (the channel's delay distribution), step_window (the authors' code),
    # time_window (Deep TAMER); the module docstring says each
    scheme: Literal["channel", "step_window", "time_window"] = "channel"
    window_steps: int = 15  # step_window: how many steps back
    decay: float = 0.9  # step_window: weight 0.9^i for the i-th step back
    delay_min_s: float = 0.2  # time_window: human delay ~ Uniform[delay_min_s, delay_max_s]
    delay_max_s: float = 4.0  # time_window: the slowest human delay (see delay_min_s)
    min_interval_steps: int = 5  # at most one accepted event per this many steps
    # a step the teacher watched and said nothing about (no event arrived in its credit window) is a row with
    # target 0 weighing this many events (an event's credit weights sum to 1); 0: events alone, as Deep TAMER.
    # Why: docs/experiments.md, "What the reward model learns from silence".
    silence_weight: float = 0.0
    # a silent step is a 0 label only if the teacher watched every step whose feedback could have credited it:
    # silence while looking away is not "nothing to say" (docs/experiments.md, "What limits r_hat"). Needs an
    # attention signal: the simulated teachers' (not in their silent mode), a live session's page visibility.
    silence_needs_attention: bool = False
    # > 0: an event's credit weights times exp(T value r_hat), renormalised (`posterior_weights`); 0: the prior
    posterior_temperature: float = 0.0

    def validate(self) -> None:
        check(self.window_steps >= 1, "window_steps", f"must be >= 1, got {self.window_steps}")
        check(0.0 < self.decay <= 1.0, "decay", f"must be in (0, 1], got {self.decay}")
        check(self.delay_min_s >= 0.0, "delay_min_s", f"must be >= 0, got {self.delay_min_s}")
        check(self.delay_max_s > self.delay_min_s, "delay_max_s",
              f"must be > delay_min_s ({self.delay_min_s}), got {self.delay_max_s}")
        check(self.silence_weight >= 0, "silence_weight", f"must be >= 0, got {self.silence_weight}")
        check(self.min_interval_steps >= 0, "min_interval_steps", f"must be >= 0, got {self.min_interval_steps}")
        check(self.posterior_temperature >= 0, "posterior_temperature",
              f"must be >= 0 (0: credit by the delay alone), got {self.posterior_temperature}")


def posterior_weights(xp, weight, value, r_hat, temperature: float):
    """An event's credit weights (..., K) over its steps, times exp(temperature * value * r_hat) and
    renormalised to the same total per event (the last axis): the posterior over which step the event was
    about, the delay's credit the prior. `xp` is numpy or jax.numpy; temperature 0 returns the weights."""
    if temperature <= 0:
        return weight
    agree = temperature * value * r_hat
    agree = agree - xp.max(xp.where(weight > 0, agree, -xp.inf), axis=-1, keepdims=True)
    post = weight * xp.exp(xp.where(weight > 0, agree, 0.0))
    total = xp.sum(weight, axis=-1, keepdims=True)
    return post * (total / xp.maximum(xp.sum(post, axis=-1, keepdims=True), 1e-30))


def step_window_weights(window: int = 15, decay: float = 0.9) -> np.ndarray:
    """Weights of the steps k, k-1, ..., k-window+1 for feedback landing on step k."""
    return decay ** np.arange(window, dtype=np.float64)


def time_window_weight(start: float, end: float, t_feedback: float,
                       delay_min: float = 0.2, delay_max: float = 4.0) -> float:
    """Overlap of the step span [start, end) with [t - delay_max, t - delay_min], over the window length."""
    lo, hi = t_feedback - delay_max, t_feedback - delay_min
    return max(0.0, min(end, hi) - max(start, lo)) / (delay_max - delay_min)


@dataclasses.dataclass(frozen=True)
class Credit:
    """An accepted event and the (step, weight) pairs it credits."""

    event: FeedbackEvent
    step: int  # the step the event lands on (shown at its time)
    steps: tuple[int, ...]
    weights: tuple[float, ...]


class CreditAssigner:
    """Turns events into credited steps on a StepClock, enforcing the minimum interval."""

    def __init__(self, config: CreditConfig, clock: StepClock, channel: ChannelConfig | None = None):
        if config.scheme == "channel" and channel is None:
            raise ValueError("credit scheme 'channel' needs the channel the feedback comes through")
        self.config = config
        self.clock = clock
        self.channel = channel
        self.last_step: int | None = None
        self.dropped: dict[str, int] = {}

    def _drop(self, reason: str) -> tuple[None, str]:
        self.dropped[reason] = self.dropped.get(reason, 0) + 1
        return None, reason

    def assign(self, event: FeedbackEvent) -> tuple[Credit | None, str | None]:
        """(Credit, None) or (None, reason) when the event credits nothing or comes too soon."""
        cfg = self.config
        step = self.clock.step_at(event.t_start)
        if step is None:
            return self._drop("before the first remembered step")
        if self.last_step is not None and step - self.last_step < cfg.min_interval_steps:
            return self._drop(f"within {cfg.min_interval_steps} steps of the previous feedback")
        steps, starts, ends = self.clock.spans()
        if cfg.scheme == "step_window":
            w = step_window_weights(cfg.window_steps, cfg.decay)
            known = set(steps)
            pairs = [(step - i, float(w[i])) for i in range(cfg.window_steps) if step - i in known]
        elif cfg.scheme == "channel":
            t = event.t_start
            _, latest = delay_quantile_span(self.channel)
            pairs = []
            for s, a, b in zip(steps, starts, ends):
                if b < t - latest or a > t:
                    continue
                wt = delay_cdf(t - a, self.channel) - delay_cdf(t - b, self.channel)
                if wt > 1e-6:
                    pairs.append((s, wt))
        else:
            pairs = []
            for s, a, b in zip(steps, starts, ends):
                if a > event.t_start - cfg.delay_min_s:
                    break
                wt = time_window_weight(a, b, event.t_start, cfg.delay_min_s, cfg.delay_max_s)
                if wt > 0:
                    pairs.append((s, wt))
        if not pairs:
            return self._drop("no remembered step inside the credit window")
        self.last_step = step
        return Credit(event, step, tuple(p[0] for p in pairs), tuple(p[1] for p in pairs)), None


def silence_reach_s(config: CreditConfig, dt: float, channel: ChannelConfig | None = None) -> float:
    """Seconds after a step ends by which every event that could credit it has reached the learner: after
    that, a step no event credited was watched in silence (`StepHistory.silent_samples`)."""
    if config.scheme == "channel":
        return delay_quantile_span(channel)[1] + channel.arrival_offset_s
    if config.scheme == "step_window":
        return config.window_steps * dt
    return config.delay_max_s


class StepHistory:
    """The (obs, action) of the last `capacity` steps of the watched env, by global step (host NumPy), and
    whether a credit has read each of them."""

    def __init__(self, capacity: int, obs_size: int, action_size: int):
        self.capacity = capacity
        self.obs = np.zeros((capacity, obs_size), np.float32)
        self.action = np.zeros((capacity, action_size), np.float32)
        self.step = np.full((capacity,), -1, np.int64)
        self.credited = np.zeros((capacity,), bool)

    def record(self, first_step: int, obs: np.ndarray, action: np.ndarray) -> None:
        n = len(obs)
        idx = (first_step + np.arange(n)) % self.capacity
        self.obs[idx] = obs
        self.action[idx] = action
        self.step[idx] = first_step + np.arange(n)
        self.credited[idx] = False

    def samples(self, credit: Credit) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(obs, action, weight, target) rows for a credit; steps no longer remembered are skipped."""
        steps = np.asarray(credit.steps, np.int64)
        idx = steps % self.capacity
        ok = self.step[idx] == steps
        idx = idx[ok]
        self.credited[idx] = True
        w = np.asarray(credit.weights, np.float32)[ok]
        h = np.full(len(idx), credit.event.value, np.float32)
        return self.obs[idx], self.action[idx], w, h

    def silent_samples(self, first: int, last: int, weight: float, watched: np.ndarray | None = None):
        """(obs, action, weight, target 0) rows for the remembered steps first..last that no credit read: the
        teacher watched them and said nothing (the host twin of `batched.draw_silent_steps`; call it once a
        step's `silence_reach_s` has passed). `watched` (one bool per step first..last): only those steps."""
        steps = np.arange(first, last + 1, dtype=np.int64)
        idx = steps % self.capacity
        keep = (self.step[idx] == steps) & ~self.credited[idx]
        if watched is not None:
            keep &= np.asarray(watched, bool)
        idx = idx[keep]
        n = len(idx)
        return self.obs[idx], self.action[idx], np.full(n, weight, np.float32), np.zeros(n, np.float32)


def lag_weights(config: CreditConfig, dt: float, channel: ChannelConfig | None = None) -> np.ndarray:
    """Weights by lag j (step k - j) for feedback arriving while step k is shown, on a regular clock with
    period dt. Used by the in-jit credit, which knows arrival steps but no wall-clock times. For the
    "channel" scheme the event's onset is the arrival less the channel's utterance and pipeline latency
    (`arrival_offset_s`); the other schemes take the arrival as the event time, as the authors' code did."""
    if config.scheme == "channel":
        if channel is None:
            raise ValueError("credit scheme 'channel' needs the channel the feedback comes through")
        offset = channel.arrival_offset_s
        _, latest = delay_quantile_span(channel)
        j = np.arange(int(math.floor((latest + offset) / dt + 1e-9)) + 2)  # as the host: spans ending after t - latest
        w = np.array([delay_cdf(jj * dt - offset, channel) - delay_cdf((jj - 1) * dt - offset, channel) for jj in j])
        w = np.where(w > 1e-6, w, 0.0).astype(np.float32)
        return w[: int(np.flatnonzero(w)[-1]) + 1]
    if config.scheme == "step_window":
        return step_window_weights(config.window_steps, config.decay).astype(np.float32)
    n = int(math.ceil(config.delay_max_s / dt)) + 1
    j = np.arange(n)
    w = [time_window_weight(-jj * dt, -(jj - 1) * dt, 0.0, config.delay_min_s, config.delay_max_s) for jj in j]
    w = np.asarray(w, np.float32)
    return w[: int(np.flatnonzero(w)[-1]) + 1]
