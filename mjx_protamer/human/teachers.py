"""Simulated teachers: a hidden scoring rule, a giving model and a channel model, in one JAX core.

There is no human in CI; a simulated teacher stands in for one, reproducibly (seeded).

Scoring rule (hidden from the learner)
    A list of clauses over named per-step signals. A clause holds while its signal is above `above` and
    below `below`; the step's score (what the teacher wants, the `teacher_score` metric) is the clipped sum of
    the values of the clauses that hold at that step: a function of the step alone. The teacher *notices* a
    clause once it has held for `sustain` consecutive steps, and judges a step only when every clause that
    holds there has been noticed: a person reacts to a touch held for 0.1 s, not to a graze. (The score used
    to wait for `sustain` too; no function of (s, a) could then track it: on DTK's test states the best
    function of the clauses' current signals reached corr 0.44-0.78, measured, issue 8.)
    The signals (`signal_columns` resolves them against the env, `rule_signals` extracts them, the one
    implementation for the in-jit chunk, table2's test episodes and the host teacher):
    - a reward term of the env by name (e.g. "region", "contact", "movement", "joint_limit");
    - "obs:i", "action:i", and "obs_norm:a:b[,c:d]" (the L2 norm of obs slices, e.g. arm speed);
    - "region:NAME": 1.0 while that body region is touched (the env's per-step `region_mask`; NAME one of
      `env.region_names`: hip, lower_body, upper_body, head, left/right_upper_arm, left/right_lower_arm);
    - "regions_touched": how many body regions are touched this step (0-8).
    Region signals let a rule ask where to touch ("touch your head", "touch many places"); the reward model
    still learns from (s, a) only. An env without regions (the toy) rejects them as a config error.
    The default rule (self-touch, `SELF_TOUCH_RULE`): approve touching the head while moving, disapprove a
    freeze; see there why it is built that way. `reproduce table2`'s built-in default uses `LATERAL_RULE`
    (the right hand +1, the left -1), since its baseline habituates and tours, head included.

Giving model
    A step is eligible when every clause that holds has been noticed and |score| >= threshold; the teacher
    gives with probability `give_rate`, never within `min_gap_steps` of its last feedback, and not while
    silent (a two-state Markov chain with long-run silent fraction `silence_fraction` and mean silent period
    `silence_mean_s`). With
    probability `flip_prob` it gives the opposite sign (a mistake). Each given feedback has a reaction
    delay ~ max(delay_min_s, Normal(delay_mean_s, delay_std_s)) from the step it is about.

Channels (per modality)
    keyboard: exact +-1, fast (0.35 +- 0.1 s reaction, no processing latency);
    prosody: continuous, noisy: tanh(gain * score + Normal(0, noise_std)) (0.6 s reaction, 0.87 s
        utterance, 0.40 s pipeline latency);
    speech: +1 / 0 / -1 through a confusion matrix (rows intended +1/0/-1, columns recognised), longer
        latency (0.8 s reaction, 0.87 s utterance, 0.60 s transcription).
    The numbers and their sources (measured on our voice pipelines, or assumed) are in `channels.py`.

Two variants share `teacher_step`:
- `batched_teacher`: jitted `lax.scan` over a chunk of steps for a batch of envs, one teacher per env;
  a pending ring of length `max_delay_steps` delivers each feedback `delay` steps later, so the output
  is (value, valid) per step and env as a learner inside jit would receive it.
- `HostTeacher`: watches one env; after each chunk it scores the chunk's steps with the same core and
  schedules `FeedbackEvent`s at step time + delay (+ utterance and processing latency for arrival), then
  `emit_due(queue, now)` puts them into the real `FeedbackQueue`.
"""

from __future__ import annotations

import dataclasses
import heapq
import math
from typing import Literal, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mjx_protamer.config import ConfigError, check
from mjx_protamer.human.channels import ChannelConfig  # noqa: F401  (re-exported: configs name it here)
from mjx_protamer.human.events import FeedbackEvent


@dataclasses.dataclass(frozen=True)
class Clause:
    # what the clause reads: a reward term's name, region:NAME (a body region touched), regions_touched, obs:I,
    # action:I or obs_norm:A:B[,C:D] (the norm of observation slices)
    signal: str
    # what the teacher thinks of a step where the condition holds, in [-1, 1] (summed over clauses, clipped)
    value: float
    above: float | None = None  # the condition holds while above < signal < below (null: no bound on that side)
    below: float | None = None  # see above
    sustain: int = 1  # consecutive steps the condition must hold

    def validate(self) -> None:
        check(self.above is not None or self.below is not None, "above",
              f"clause on '{self.signal}' needs 'above' or 'below'")
        check(self.sustain >= 1, "sustain", f"must be >= 1, got {self.sustain}")
        check(-1.0 <= self.value <= 1.0, "value", f"must be in [-1, 1], got {self.value}")


# The default hidden rule (self-touch): "touch your head, and keep moving" (a caregiver playing "where is your
# head?"). The head is touched on 1% of the intrinsic-reward baseline's test steps (5 seeds,
# docs/results/table2_right_hand_rule/body_map_DDPG.png): the intrinsic reward does not push there, so whatever DTK
# does beyond that is the teacher's doing, and the baseline's score is near 0 on every seed rather than a coin
# toss. Each clause is visible in (s, a) (a head touch through the touch features' contact position and the arm
# posture; "frozen" is the freeze metric's own definition: arm joint speed below env.freeze_speed, 1 rad/s,
# obs 64:68,70:74 are those joints) and the teacher notices it once it has held longer than a reaction
# delay's spread. With threshold 0.5: touching the head while moving is approved (+1), a freeze is not (-1), a
# frozen head touch (0) and everything else (0) get no feedback.
# The previous default, "your right hand, not the left" (+1 / -1 / freeze -1), is measured in
# docs/experiments.md: the baseline's hand preference is a coin toss per seed (its teacher_score -0.92..0.84),
# so no improvement could exceed the seeds' spread.
SELF_TOUCH_RULE = (
    Clause("region:head", 1.0, above=0.5, sustain=20),  # a hand on the head, noticed after 0.1 s
    Clause("obs_norm:64:68,70:74", -1.0, below=1.0, sustain=60),  # arms frozen (< 1 rad/s), noticed after 0.3 s
)
# The rule of `protamer reproduce table2`'s built-in default (configs/table2_attention.yaml): "your right hand,
# not the left". With habituation the baseline tours its body and touches the head by itself, so the head rule
# no longer stands out; the hand rule does: the baseline's score is 0.20 +- 0.11 over 5 seeds (it uses both
# hands), and each hand's touch features (obs 0:26 left, 26:52 right) are visible in (s, a). Both hands at once
# score 0 (silent). docs/experiments.md, "Table II with habituation".
LATERAL_RULE = (
    Clause("obs_norm:26:52", 1.0, above=0.05, sustain=20),  # the right hand touching (> 0.05 N), after 0.1 s
    Clause("obs_norm:0:26", -1.0, above=0.05, sustain=20),  # the left hand touching
)
# (The first version's rule read reward terms: a region onset, which lasts one step, and the joint-limit
# term, which was active on 100% of training steps; a reward model could not learn it: issue 8.)

@dataclasses.dataclass(frozen=True)
class TeacherConfig:
    # the hidden rule: clauses whose values sum to the score of a step (SELF_TOUCH_RULE, LATERAL_RULE above)
    rule: tuple[Clause, ...] = SELF_TOUCH_RULE
    threshold: float = 0.5  # |score| needed to consider giving feedback
    give_rate: float = 0.5  # probability of giving feedback on a step that is eligible for it
    min_gap_steps: int = 40  # at least this many steps between two pieces of feedback (40: 0.2 s)
    flip_prob: float = 0.05  # probability that the feedback's sign is the wrong one (a teacher's mistake)
    silence_fraction: float = 0.1  # share of the time the teacher looks away and says nothing (its silent mode)
    silence_mean_s: float = 2.0  # s: the mean length of a silent spell
    channel: ChannelConfig = dataclasses.field(default_factory=ChannelConfig)

    def validate(self) -> None:
        check(len(self.rule) >= 1, "rule", "needs at least one clause")
        check(0.0 <= self.give_rate <= 1.0, "give_rate", f"must be in [0, 1], got {self.give_rate}")
        check(0.0 <= self.flip_prob <= 1.0, "flip_prob", f"must be in [0, 1], got {self.flip_prob}")
        check(0.0 <= self.silence_fraction < 1.0, "silence_fraction", f"must be in [0, 1), got {self.silence_fraction}")
        check(self.silence_mean_s > 0, "silence_mean_s", f"must be > 0, got {self.silence_mean_s}")
        check(self.min_gap_steps >= 0, "min_gap_steps", f"must be >= 0, got {self.min_gap_steps}")
        check(self.threshold >= 0, "threshold", f"must be >= 0, got {self.threshold}")

    @property
    def signals(self) -> tuple[str, ...]:
        """The signal each clause reads, in clause order (the columns `teacher_step` expects)."""
        return tuple(c.signal for c in self.rule)


def with_channel(config: TeacherConfig, kind: str) -> TeacherConfig:
    return dataclasses.replace(config, channel=dataclasses.replace(config.channel, kind=kind))


class TeacherState(NamedTuple):
    runs: jax.Array  # (C,) int32: consecutive steps each clause's condition has held
    since_give: jax.Array  # int32: steps since the last feedback given
    silent: jax.Array  # bool


class Decision(NamedTuple):
    give: jax.Array  # bool
    value: jax.Array  # float in [-1, 1]
    score: jax.Array  # the hidden score of the step
    delay_s: jax.Array  # reaction delay (s)


def teacher_init(config: TeacherConfig) -> TeacherState:
    return TeacherState(runs=jnp.zeros((len(config.rule),), jnp.int32),
                        since_give=jnp.full((), 1 << 20, jnp.int32), silent=jnp.zeros((), bool))


def teacher_step(config: TeacherConfig, dt: float, state: TeacherState, signals: jax.Array,
                 key: jax.Array) -> tuple[TeacherState, Decision]:
    """One step of one teacher: `signals` (C,) in `config.signals` order."""
    rule, ch = config.rule, config.channel
    values = jnp.asarray([c.value for c in rule])
    sustain = jnp.asarray([c.sustain for c in rule])
    runs = jnp.where(clauses_hold(rule, signals), state.runs + 1, 0)
    score = rule_scores(config, signals)
    noticed = jnp.clip(jnp.sum(jnp.where(runs >= sustain, values, 0.0)), -1.0, 1.0)

    k_silence, k_give, k_flip, k_noise, k_delay = jax.random.split(key, 5)
    p_leave = min(1.0, dt / config.silence_mean_s)
    p_enter = p_leave * config.silence_fraction / (1.0 - config.silence_fraction)
    u = jax.random.uniform(k_silence)
    silent = jnp.where(state.silent, u >= p_leave, u < p_enter)
    # it judges a step when everything the step shows has been noticed: a head touch that has just slowed
    # (score 0, the freeze not yet noticed) is not approved for the touch
    eligible = ((jnp.abs(noticed) >= max(config.threshold, 1e-6)) & (noticed == score)
                & (state.since_give >= config.min_gap_steps) & ~silent)
    give = eligible & (jax.random.uniform(k_give) < config.give_rate)

    intended = jnp.sign(noticed) * jnp.where(jax.random.uniform(k_flip) < config.flip_prob, -1.0, 1.0)
    if ch.kind == "keyboard":
        value = intended
    elif ch.kind == "prosody":
        value = jnp.tanh(ch.gain * intended * jnp.abs(noticed) + ch.get("noise_std") * jax.random.normal(k_noise))
    else:  # speech: intended +1 -> row 0, 0 -> row 1, -1 -> row 2; recognised column c -> value 1 - c
        confusion = jnp.asarray(ch.confusion_matrix, jnp.float32).reshape(3, 3)
        row = (1 - intended).astype(jnp.int32)
        value = 1.0 - jax.random.categorical(k_noise, jnp.log(confusion[row] + 1e-12)).astype(jnp.float32)
    delay = jnp.maximum(ch.get("delay_min_s"),
                        ch.get("delay_mean_s") + ch.get("delay_std_s") * jax.random.normal(k_delay))
    since = jnp.where(give, 0, state.since_give + 1)
    return TeacherState(runs, since, silent), Decision(give, value.astype(jnp.float32), score, delay)


def rule_scores(config: TeacherConfig, signals: jax.Array) -> jax.Array:
    """The hidden score of every step, signals (..., C) -> (...): what the teacher wants of that step, whether or
    not it notices or gives feedback (the `teacher_score` metric of test episodes)."""
    values = jnp.asarray([c.value for c in config.rule])
    return jnp.clip(jnp.sum(jnp.where(clauses_hold(config.rule, signals), values, 0.0), axis=-1), -1.0, 1.0)


def clauses_hold(rule: tuple[Clause, ...], signals, xp=jnp):
    """Whether each clause's condition holds, signals (..., C) -> (..., C) bool: above < signal < below."""
    above = xp.asarray([-xp.inf if c.above is None else c.above for c in rule])
    below = xp.asarray([xp.inf if c.below is None else c.below for c in rule])
    return (signals > above) & (signals < below)


def _scan_decisions(config: TeacherConfig, dt: float, state: TeacherState, signals: jax.Array, key: jax.Array):
    """Decisions of one teacher over (T, C) signals."""
    def body(s, xs):
        sig, k = xs
        return teacher_step(config, dt, s, sig, k)
    return jax.lax.scan(body, state, (signals, jax.random.split(key, signals.shape[0])))


# ------------------------------------------------------------------------------------------------
# Batched, inside jit: one teacher per env, delays realised with a pending ring.

class BatchedTeacherState(NamedTuple):
    teacher: TeacherState  # batched over envs
    pending_value: jax.Array  # (B, D)
    pending_valid: jax.Array  # (B, D) bool
    pending_about: jax.Array  # (B, D) int32: the step (global) the pending feedback is about
    step: jax.Array  # int32 global step counter (same for all envs)


def max_delay_steps(config: TeacherConfig, dt: float) -> int:
    ch = config.channel
    worst = ch.get("delay_mean_s") + 4 * ch.get("delay_std_s") + ch.get("duration_s") + ch.get("latency_s")
    return int(math.ceil(worst / dt)) + 1


def _as_channels(configs) -> tuple[TeacherConfig, ...]:
    return (configs,) if isinstance(configs, TeacherConfig) else tuple(configs)


def batched_teacher_init(configs, num_envs: int, dt: float) -> BatchedTeacherState:
    """`configs`: a TeacherConfig, or a tuple of them that differ only in their channel (see batched_teacher)."""
    d = max(max_delay_steps(c, dt) for c in _as_channels(configs))
    t = teacher_init(_as_channels(configs)[0])
    return BatchedTeacherState(
        teacher=jax.tree.map(lambda x: jnp.broadcast_to(x, (num_envs, *x.shape)), t),
        pending_value=jnp.zeros((num_envs, d)), pending_valid=jnp.zeros((num_envs, d), bool),
        pending_about=jnp.zeros((num_envs, d), jnp.int32), step=jnp.zeros((), jnp.int32))


def batched_teacher(configs, dt: float, state: BatchedTeacherState, signals: jax.Array, key: jax.Array,
                    arrival: bool = True, kind=0, active=None):
    """Run a chunk: signals (T, B, C) -> (state, out) with out["value"], out["valid"], out["about"], out["score"]
    and out["watching"] (T, B) (the teacher speaks and is not in its silent mode: the attention signal). The one
    batched teacher: the in-jit training path (`experiments.feedback_train`) runs it too.

    `configs` is one TeacherConfig, or a tuple of them that differ only in their channel; `kind` (an index,
    may be traced) picks the channel that delivers, so every channel shares one compiled program; `active`
    (B,) bool (may be traced) says which envs' teachers speak (default all). With `arrival` (default),
    feedback is delivered at the step it would reach the learner: the step it is about + (reaction delay +
    utterance + latency) / dt; `about` says which step it judged (for diagnostics: a learner must not read
    it). Without, it is returned at the judged step itself.
    """
    channels = _as_channels(configs)
    extras = jnp.asarray([c.channel.arrival_offset_s for c in channels])
    d = state.pending_value.shape[1]
    b = signals.shape[1]
    rows = jnp.arange(b)
    active = jnp.ones((b,), bool) if active is None else active

    def body(s: BatchedTeacherState, xs):
        sig, k = xs
        keys = jax.random.split(k, b)
        decs = [jax.vmap(lambda ts, x, kk, c=c: teacher_step(c, dt, ts, x, kk))(s.teacher, sig, keys)
                for c in channels]
        teacher = decs[0][0]  # the teacher's state does not depend on the channel
        value = jnp.stack([dec.value for _, dec in decs])[kind]
        delay = jnp.stack([dec.delay_s for _, dec in decs])[kind]
        give, score = decs[0][1].give & active, decs[0][1].score
        if not arrival:
            out = {"value": jnp.where(give, value, 0.0), "valid": give,
                   "about": jnp.broadcast_to(s.step, (b,)), "score": score, "watching": active & ~teacher.silent}
            return s._replace(teacher=teacher, step=s.step + 1), out
        lag = jnp.clip(jnp.round((delay + extras[kind]) / dt).astype(jnp.int32), 1, d - 1)
        slot = (s.step + lag) % d
        write = give & ~s.pending_valid[rows, slot]  # a slot already taken keeps its feedback
        pv = s.pending_value.at[rows, slot].set(jnp.where(write, value, s.pending_value[rows, slot]))
        pm = s.pending_valid.at[rows, slot].set(write | s.pending_valid[rows, slot])
        pa = s.pending_about.at[rows, slot].set(jnp.where(write, s.step, s.pending_about[rows, slot]))
        now = s.step % d
        out = {"value": jnp.where(pm[:, now], pv[:, now], 0.0), "valid": pm[:, now], "about": pa[:, now],
               "score": score, "watching": active & ~teacher.silent}
        pm = pm.at[:, now].set(False)
        return BatchedTeacherState(teacher, pv, pm, pa, s.step + 1), out

    keys = jax.random.split(key, signals.shape[0])
    return jax.lax.scan(body, state, (signals, keys))


# ------------------------------------------------------------------------------------------------
# Signals: what a rule's clauses read, resolved against the env once and extracted by one function.

RULE_FIELD = "config field 'feedback.teacher.rule'"


def _is_int(x: str) -> bool:
    return x.strip().lstrip("-").isdigit()


def obs_norm_indices(name: str, obs_size: int) -> tuple[int, ...]:
    """'obs_norm:64:68,70:74' -> the obs indices whose L2 norm is the signal (e.g. the arm joint speed)."""
    idx: list[int] = []
    for part in name[len("obs_norm:"):].split(","):
        bounds = part.split(":")
        a, b = (int(x) for x in bounds) if len(bounds) == 2 and all(_is_int(x) for x in bounds) else (0, -1)
        if not 0 <= a < b <= obs_size:
            raise ConfigError(f"{RULE_FIELD}: {name!r} is not obs_norm:a:b[,c:d] with slices inside obs "
                              f"[0, {obs_size})")
        idx += list(range(a, b))
    return tuple(idx)


class SignalColumn(NamedTuple):
    source: str  # "terms", "obs", "action", "obs_norm", "region" or "regions_touched"
    index: int | tuple[int, ...]  # the column (or obs indices for obs_norm; unused for regions_touched)


def signal_columns(names, term_names, obs_size: int, act_size: int,
                   region_names: tuple[str, ...] = ()) -> tuple[SignalColumn, ...]:
    """Resolve a rule's signal names against an env once (a ConfigError naming the bad signal otherwise).
    `region_names` are the env's body regions in region-mask order; empty for an env without regions."""
    cols = []
    for name in names:
        if name in term_names:
            cols.append(SignalColumn("terms", term_names.index(name)))
        elif name.startswith("obs_norm:"):  # L2 norm over obs slices, e.g. obs_norm:64:68,70:74 (arm speed)
            cols.append(SignalColumn("obs_norm", obs_norm_indices(name, obs_size)))
        elif name.startswith("obs:") and _is_int(name[4:]) and 0 <= int(name[4:]) < obs_size:
            cols.append(SignalColumn("obs", int(name[4:])))
        elif name.startswith("action:") and _is_int(name[7:]) and 0 <= int(name[7:]) < act_size:
            cols.append(SignalColumn("action", int(name[7:])))
        elif name.startswith("region:") or name == "regions_touched":
            if not region_names:
                raise ConfigError(f"{RULE_FIELD}: signal {name!r} reads body regions, and this env has none "
                                  "(region signals need the self-touch env)")
            if name == "regions_touched":
                cols.append(SignalColumn("regions_touched", 0))
            elif name[7:] in region_names:
                cols.append(SignalColumn("region", region_names.index(name[7:])))
            else:
                raise ConfigError(f"{RULE_FIELD}: signal {name!r} names no body region; allowed: "
                                  + ", ".join(f"region:{r}" for r in region_names))
        else:
            raise ConfigError(f"{RULE_FIELD}: signal {name!r} is not a reward term ({', '.join(term_names)}), "
                              "obs:i, obs_norm:a:b[,c:d], action:i, region:NAME or regions_touched")
    return tuple(cols)


def env_signal_columns(names, env) -> tuple[SignalColumn, ...]:
    """`signal_columns` for an env on the env contract (`region_names` is optional there)."""
    return signal_columns(names, tuple(env.reward_term_names), env.observation_size, env.action_size,
                          tuple(getattr(env, "region_names", ())))


def rule_signals(cols, obs, action, terms, region_mask=None, xp=jnp):
    """The rule's signals (..., C) from per-step obs, action, reward terms and region mask (..., dims).

    The one extraction every evaluation of a rule runs: inside jit on a chunk's emitted steps (xp = jax.numpy),
    on test episodes (table2's `teacher_score`) and on the host for `HostTeacher` (xp = numpy). The region
    mask is the env's per-step `region_mask` of the step reached, the step whose reward terms are given."""
    def column(c: SignalColumn):
        if c.source == "obs_norm":
            return xp.linalg.norm(obs[..., xp.asarray(c.index)], axis=-1)
        if c.source in ("region", "regions_touched") and region_mask is None:
            raise ValueError("the rule reads body regions and no region mask was given for these steps")
        if c.source == "region":
            return (region_mask[..., c.index] > 0).astype(xp.float32)
        if c.source == "regions_touched":
            return xp.sum(region_mask > 0, axis=-1).astype(xp.float32)
        return {"terms": terms, "obs": obs, "action": action}[c.source][..., c.index]

    return xp.stack([column(c) for c in cols], axis=-1).astype(xp.float32)


# ------------------------------------------------------------------------------------------------
# Host variant: watches one env, feeds the real queue.

class HostTeacher:
    """A simulated teacher for one env that puts timed events into a FeedbackQueue.

    `observe(first_step, step_times, signals)` after each chunk; `emit_due(queue, now)` before draining.
    The events say what they are about in `details` (step, score, channel, intended and recognised
    value) for analysis; the learner uses only the timestamps and values.
    """

    def __init__(self, config: TeacherConfig, dt: float, seed: int = 0):
        self.config = config
        self.dt = dt
        self.state = teacher_init(config)
        self.key = jax.random.PRNGKey(seed)
        self._scan = jax.jit(lambda s, x, k: _scan_decisions(config, dt, s, x, k))
        self._pending: list[tuple[float, int, FeedbackEvent]] = []
        self._n = 0
        self.given = 0
        self.emitted = 0
        self.refused = 0

    def observe(self, first_step: int, step_times, signals) -> int:
        """Score a chunk's steps; schedule the feedback given. Returns how many were scheduled."""
        self.key, k = jax.random.split(self.key)
        self.state, dec = self._scan(self.state, jnp.asarray(signals, jnp.float32), k)
        give, value, score, delay = (np.asarray(x) for x in dec)
        ch = self.config.channel
        duration, latency = ch.get("duration_s"), ch.get("latency_s")
        for i in np.flatnonzero(give):
            t0 = float(step_times[i]) + float(delay[i])
            event = FeedbackEvent(t0, t0 + duration, "simulated", float(value[i]),
                                  {"channel": ch.kind, "about_step": int(first_step + i),
                                   "score": float(score[i]), "latency": latency})
            heapq.heappush(self._pending, (t0 + duration + latency, self._n, event))
            self._n += 1
        self.given += int(give.sum())
        return int(give.sum())

    def emit_due(self, queue, now: float) -> int:
        """Put every scheduled event whose arrival time has come into the queue."""
        n = 0
        while self._pending and self._pending[0][0] <= now:
            _, _, event = heapq.heappop(self._pending)
            if queue.put(event):
                n += 1
            else:
                self.refused += 1
        self.emitted += n
        return n

    def take_scheduled(self) -> list[FeedbackEvent]:
        """Every scheduled event, earliest first, out of the schedule (a simulated speaker says them itself)."""
        events = [e for _, _, e in sorted(self._pending)]
        self._pending.clear()
        return events

    @property
    def pending(self) -> int:
        return len(self._pending)
