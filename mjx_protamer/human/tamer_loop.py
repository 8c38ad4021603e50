"""DDPG + DeepTAMER on the host: jitted DDPG chunks, and between them the feedback path.

One iteration of the loop (`TamerRun.step_chunk`):

1. `trainer.collect_chunk(state, model.params)`: `chunk_steps` DDPG iterations in one jit; the reward at
   sample time is `alpha * r_env + beta * r_hat(params, s, a)`; the params are an argument (no recompile).
2. The watched env's steps of the chunk (obs, action, reward terms) are taken from the transitions the
   chunk's scan emits ((T, B, ...), column `watch_env`).
3. Time mapping: the chunk's steps are stamped on the `StepClock` at their presentation times
   (`record_chunk(first_step, n, t0, dt)`): with a simulated teacher on a `VirtualClock` that advances
   by dt per step (real-time-equivalent), live from the wall-clock moment the chunk is shown.
4. A simulated teacher (if any) scores the steps and schedules events; those due are put into the real
   `FeedbackQueue`. Then the queue is drained (events logged), each event is credited
   (`CreditAssigner`, step or time window, minimum interval), the credited (obs, action, weight, value)
   rows go to the reward model (one update each) and the periodic replay runs (`replay_every` steps).
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

from mjx_protamer.agents.ddpg.config import PretrainConfig
from mjx_protamer.config import ConfigError, check
from mjx_protamer.human.attention import AttentionTimeline, describe, is_attention
from mjx_protamer.human.clock import StepClock, VirtualClock
from mjx_protamer.human.credit import (CreditAssigner, CreditConfig, StepHistory, posterior_weights,
                                       silence_reach_s)
from mjx_protamer.human.queue import FeedbackLog, FeedbackQueue
from mjx_protamer.human.reward_model import RewardModel, RewardModelConfig
from mjx_protamer.human.teachers import HostTeacher, TeacherConfig, env_signal_columns, rule_signals, with_channel
from mjx_protamer.human.touches import TouchWatcher


@dataclasses.dataclass(frozen=True)
class FeedbackConfig:
    """The human side of a run: credit, reward model, simulated teacher and timing."""

    credit: CreditConfig = dataclasses.field(default_factory=CreditConfig)
    reward_model: RewardModelConfig = dataclasses.field(default_factory=RewardModelConfig)
    teacher: TeacherConfig = dataclasses.field(default_factory=TeacherConfig)
    dt: float = 0.005  # presentation period of one env step (s): the env's control period in real time
    watch_env: int = 0  # the env of the batch the teacher (or human) watches
    queue_size: int = 256
    seed: int = 0

    def validate(self) -> None:
        check(self.dt > 0, "dt", f"must be > 0, got {self.dt}")
        check(self.watch_env >= 0, "watch_env", f"must be >= 0, got {self.watch_env}")
        check(self.queue_size >= 1, "queue_size", f"must be >= 1, got {self.queue_size}")


@dataclasses.dataclass(frozen=True)
class FeedbackRunConfig:
    """configs/feedback_*.yaml: a pretrain config (env, ddpg, train) plus the feedback section."""

    pretrain: PretrainConfig = dataclasses.field(default_factory=PretrainConfig)
    feedback: FeedbackConfig = dataclasses.field(default_factory=FeedbackConfig)

    def validate(self) -> None:
        check(self.feedback.watch_env < self.pretrain.train.num_envs, "feedback.watch_env",
              f"must be < train.num_envs ({self.pretrain.train.num_envs})")


def load_feedback_config(path=None, overrides=None) -> FeedbackRunConfig:
    """Load a FeedbackRunConfig; the `pretrain` section is a PretrainConfig (DDPG engineer's)."""
    from mjx_protamer.config import load_config

    return load_config(FeedbackRunConfig, path, overrides)


class TamerRun:
    """DDPG with (or without) DeepTAMER, one chunk at a time. `feedback` is one of:

    - None: DDPG alone (the reward model is not passed to DDPG);
    - "simulated:keyboard" / "simulated:prosody" / "simulated:speech": a host simulated teacher on a
      virtual clock feeds the queue;
    - "queue": events come from outside (keyboard thread, voice front end) on the wall clock.
    """

    def __init__(self, config: FeedbackRunConfig, env, feedback: str | None = None, queue: FeedbackQueue | None = None,
                 log_path: str | Path | None = None, state=None, clock: Callable[[], float] | None = None):
        from mjx_protamer.agents.ddpg.train import make_train

        self.config = config
        fc, tc = config.feedback, config.pretrain.train
        if fc.credit.silence_needs_attention and feedback is not None and feedback != "queue":
            raise ConfigError("config field 'feedback.credit.silence_needs_attention': the host's simulated teachers "
                              "report no attention; set it false here (the in-jit teachers of pretrain/reproduce "
                              "and a live session's page do)")
        self.env = env
        self.feedback = feedback
        self.use_model = feedback is not None
        self.model = RewardModel(fc.reward_model, env.observation_size, env.action_size, seed=fc.seed)
        self.trainer = make_train(config.pretrain, env, human_reward_fn=self.model.apply if self.use_model else None,
                                  devices=jax.devices()[:1])
        self.state = self.trainer.init(jax.random.PRNGKey(tc.seed)) if state is None else state
        self.commit_state()
        self.simulated = feedback is not None and feedback.startswith("simulated")
        live = feedback is not None and not self.simulated
        self.clock = clock or (time.time if live else VirtualClock(start=time.time()))
        self.queue = queue or FeedbackQueue(fc.queue_size, clock=self.clock)
        self.log = FeedbackLog(log_path) if log_path is not None else None
        history = max(4096, 2 * tc.chunk_steps + int(fc.credit.delay_max_s / fc.dt) + 64)
        self.step_clock = StepClock(fc.dt, capacity=history)
        self.history = StepHistory(history, env.observation_size, env.action_size)
        self.assigner = CreditAssigner(fc.credit, self.step_clock, fc.teacher.channel)
        self.silence_reach = silence_reach_s(fc.credit, fc.dt, fc.teacher.channel)
        self.silent_next = 0  # the first step not yet judged silent or credited
        # when the live teacher watched (its page's attention events); None: every silence counts
        self.attention = AttentionTimeline() if fc.credit.silence_needs_attention else None
        self.teacher = None
        if self.simulated:
            kind = feedback.split(":", 1)[1] if ":" in feedback else fc.teacher.channel.kind
            self.teacher = HostTeacher(with_channel(fc.teacher, kind), fc.dt, seed=fc.seed)
            self.teacher_cols = env_signal_columns(fc.teacher.signals, env)
        self.first_step = 0
        self.credited = 0
        self.events = 0
        self.human_params = self.model.params if self.use_model else None
        self.outcomes: list[tuple] = []  # (event, Credit or None, reason or None) of the last drain
        self.last_chunk: dict | None = None  # the watched env's steps of the last chunk (step_chunk)
        self.touches = TouchWatcher(env)  # the touch onsets a session records (reaction_delay.py reads them)

    def commit_state(self) -> None:
        """Put the train state (and reward-model params) on the device as committed arrays. Arrays made
        outside a jit (init, a restored checkpoint) are uncommitted, the chunk's outputs committed, and jit
        compiles once per kind: without this the second chunk would compile the whole chunk again."""
        device = jax.devices()[0]
        self.state = jax.device_put(self.state, device)
        self.model.params = jax.device_put(self.model.params, device)
        self.model.opt_state = jax.device_put(self.model.opt_state, device)

    def _watched_rows(self, steps, extras) -> dict[str, np.ndarray]:
        w = self.config.feedback.watch_env
        obs, action, terms = jax.device_get((steps.obs[:, w], steps.action[:, w], steps.reward_terms[:, w]))
        regions = np.asarray(extras["region_mask"][:, w]) if "region_mask" in extras else None
        return {"obs": obs, "action": action, "reward_terms": terms, "region_mask": regions}

    def step_chunk(self, t0: float | None = None) -> dict:
        """One DDPG chunk, then the feedback path. `t0`: presentation time of the chunk's first step
        (default: the clock now). Returns the chunk's metrics plus feedback counters."""
        tc, fc = self.config.pretrain.train, self.config.feedback
        params = self.model.params if self.use_model else None
        self.state, metrics, steps, extras = self.trainer.collect_chunk(self.state, params)
        metrics = jax.device_get(metrics)
        rows = self._watched_rows(steps, extras)
        n, first = tc.chunk_steps, self.first_step
        t0 = self.clock() if t0 is None else t0
        if len(self.step_clock):  # a chunk computed faster than real time is shown after the previous one
            t0 = max(t0, self.step_clock.time_of(self.step_clock.last_step) + fc.dt)
        times = self.step_clock.record_chunk(first, n, t0, fc.dt)
        if isinstance(self.clock, VirtualClock):
            self.clock.set(t0 + n * fc.dt)
        self.history.record(first, rows["obs"], rows["action"])
        # what a live view draws and a session record keeps: the watched env's steps and their times
        self.last_chunk = {"first_step": first, "t0": t0, "obs": rows["obs"], "action": rows["action"],
                           "touches": self.touches.changes(first, rows["obs"], rows["action"], rows["reward_terms"],
                                                           rows["region_mask"])}
        if self.teacher is not None:
            sig = rule_signals(self.teacher_cols, rows["obs"], rows["action"], rows["reward_terms"],
                               rows["region_mask"], xp=np)
            self.teacher.observe(first, times, sig)
            self.teacher.emit_due(self.queue, self.clock())
        accepted = self.process_events(step=first + n - 1)
        self.add_silent_steps(t0)
        if self.use_model:
            self.model.maybe_replay(n)
        self.first_step += n
        out = dict(metrics)
        out.update(feedback_events=len(accepted), feedback_total=self.events, credited_rows=self.credited,
                   reward_model_updates=self.model.updates, reward_model_loss=self.model.last_loss,
                   **{f"queue_{k}": v for k, v in self.queue.stats().items()})
        return out

    def process_events(self, step: int) -> list:
        """Drain, log, credit and learn from the queued events; returns the credits made. Each drained
        event's outcome (credit or the reason it credits nothing) is in `self.outcomes`."""
        credits = []
        self.outcomes = []
        for event in self.queue.drain(self.log, step=step):
            if is_attention(event):  # no feedback: when the teacher watches (logged and recorded all the same)
                if self.attention is not None:
                    self.attention.record(event)
                self.outcomes.append((event, None, describe(event, self.attention is not None)))
                continue
            self.events += 1
            credit, why = self.assigner.assign(event)
            self.outcomes.append((event, credit, why))
            if credit is None:
                if self.log is not None:
                    self.log.note(event="not credited", reason=why, t_start=event.t_start, value=event.value)
                continue
            obs, act, w, h = self.history.samples(credit)
            if self.use_model and len(w) and self.config.feedback.credit.posterior_temperature > 0:
                w = posterior_weights(np, w, h, np.asarray(self.model.predict(obs, act)).reshape(-1),
                                      self.config.feedback.credit.posterior_temperature)
            if self.use_model:
                self.model.add(obs, act, w, h)
            self.credited += len(w)
            credits.append(credit)
        return credits

    def add_silent_steps(self, now: float) -> int:
        """Steps whose credit window had closed by `now` (the time of the chunk's drain: its recorded t0, so a
        replay judges the same steps) with no event crediting them become rows with target 0 and weight
        `credit.silence_weight` (0: none, as Deep TAMER); with `credit.silence_needs_attention` only the steps
        the teacher watched from when they were shown until their window closed. Returns how many rows were
        added."""
        w = self.config.feedback.credit.silence_weight
        closed = self.step_clock.step_at(now - self.silence_reach) if len(self.step_clock) else None
        if not (self.use_model and w > 0 and closed is not None and closed > self.silent_next):
            return 0
        watched = None
        if self.attention is not None:
            shown = np.array([self._shown_at(k) for k in range(self.silent_next, closed)])
            known = np.isfinite(shown)
            watched = known & self.attention.watched_throughout(np.where(known, shown, 0.0),
                                                                np.where(known, shown, 0.0) + self.silence_reach)
        obs, act, weight, target = self.history.silent_samples(self.silent_next, closed - 1, w, watched)
        self.silent_next = closed
        self.model.add(obs, act, weight, target, update=False)  # replayed with the events' rows
        return len(weight)

    def _shown_at(self, step: int) -> float:
        try:
            return self.step_clock.time_of(step)
        except KeyError:  # older than the clock remembers: not judged watched
            return float("nan")

    def close(self) -> None:
        if self.log is not None:
            self.log.note(event="end", queue=self.queue.stats(), dropped=self.assigner.dropped)
            self.log.close()


def rollout_actions(trainer, env, actor_params, episodes: int, steps: int, seed: int) -> dict[str, np.ndarray]:
    """Deterministic-actor test episodes: per-step actions, reward terms and metrics, (E, T, ...)."""
    @jax.jit
    def run(params, keys):
        state = jax.vmap(env.reset)(keys)

        def step(s, _):
            a = trainer.act(params, s.obs)
            s = jax.vmap(env.step)(s, a)
            return s, {"action": a, "reward_terms": s.metrics["reward_terms"], "reward": s.reward}

        _, out = jax.lax.scan(step, state, None, length=steps)
        return jax.tree.map(lambda x: jnp.swapaxes(x, 0, 1), out)

    return jax.device_get(run(actor_params, jax.random.split(jax.random.PRNGKey(seed), episodes)))
