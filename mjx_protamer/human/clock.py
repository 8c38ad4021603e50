"""Clocks and the explicit mapping from feedback time to env steps. Pure Python, no JAX.

Time model
----------
Feedback events carry wall-clock seconds (`t_start`, `t_end`). Env steps run inside jitted chunks, so
the learner cannot stamp each step as it is computed; instead it stamps each step with the time it was
*presented* to whoever gives feedback, and records that in a `StepClock`:

- live use (`protamer finetune`): the learner runs a chunk of `n` steps, then presents it at real-time
  pace, so step `k` of the chunk presented from wall time `t0` gets time `t0 + k * dt` (dt = the env's
  control period). `StepClock.record_chunk(first_step, n, t0, dt)` stores exactly that.
- simulated teachers: a `VirtualClock` stands in for the wall clock and advances by `dt` per step, as if
  the run were shown in real time; the teacher stamps its events on the same clock and the queue
  validates them against it (`FeedbackQueue(clock=virtual_clock)`).

Step `i` occupies the time span `[time(i), time(i) + dt)`. `StepClock.step_at(t)` is the step being
shown at time `t` (the last step whose span starts at or before `t`); `StepClock.spans()` gives the
spans of the remembered steps for the time-window credit (`credit.time_window_weights`).
"""

from __future__ import annotations

import bisect
import multiprocessing as mp
import time
from collections import deque


class WallClock:
    """`time.time()`, as a picklable object."""

    def __call__(self) -> float:
        return time.time()


class VirtualClock:
    """A settable clock shared across processes (backed by a multiprocessing double).

    Simulated runs advance it by the env's control period per step, so feedback timing is in
    presented (real-time-equivalent) seconds whatever the simulation speed.
    """

    def __init__(self, start: float = 0.0, ctx: mp.context.BaseContext | None = None):
        ctx = ctx or mp.get_context("spawn")
        self._t = ctx.Value("d", float(start))

    def __call__(self) -> float:
        return self._t.value

    def set(self, t: float) -> None:
        with self._t.get_lock():
            self._t.value = float(t)

    def advance(self, dt: float) -> float:
        with self._t.get_lock():
            self._t.value += float(dt)
            return self._t.value


class StepClock:
    """The presentation time of each recent env step; maps an event time to steps.

    Keeps the last `capacity` steps (enough for the longest credit window: 4 s at 200 Hz = 800).
    Steps are global, increasing integers; chunks must be recorded in order.
    """

    def __init__(self, dt: float, capacity: int = 2048):
        if dt <= 0:
            raise ValueError(f"dt must be > 0, got {dt}")
        self.dt = float(dt)
        self._steps: deque[int] = deque(maxlen=capacity)
        self._times: deque[float] = deque(maxlen=capacity)

    def record_chunk(self, first_step: int, n_steps: int, t0: float, dt: float | None = None) -> list[float]:
        """Stamp steps first_step .. first_step+n_steps-1 at t0, t0+dt, ...; returns their times."""
        dt = self.dt if dt is None else float(dt)
        if self._steps and first_step <= self._steps[-1]:
            raise ValueError(f"chunk starts at step {first_step}, but step {self._steps[-1]} is recorded")
        if self._times and t0 < self._times[-1]:
            raise ValueError(f"chunk starts at t={t0}, before the last recorded step time {self._times[-1]}")
        times = [t0 + k * dt for k in range(n_steps)]
        self._steps.extend(range(first_step, first_step + n_steps))
        self._times.extend(times)
        return times

    def record_step(self, step: int, t: float) -> None:
        self.record_chunk(step, 1, t)

    def __len__(self) -> int:
        return len(self._steps)

    @property
    def last_step(self) -> int | None:
        return self._steps[-1] if self._steps else None

    def time_of(self, step: int) -> float:
        i = step - self._steps[0] if self._steps else -1
        if not 0 <= i < len(self._steps) or self._steps[i] != step:
            raise KeyError(f"step {step} is not remembered")
        return self._times[i]

    def step_at(self, t: float) -> int | None:
        """The step being shown at time t (None when t is before every remembered step)."""
        i = bisect.bisect_right(self._times, t) - 1
        return None if i < 0 else self._steps[i]

    def spans(self) -> tuple[list[int], list[float], list[float]]:
        """(steps, starts, ends) of the remembered steps; a step's span ends where the next begins
        (or dt after its start for the last one)."""
        steps = list(self._steps)
        starts = list(self._times)
        ends = starts[1:] + [starts[-1] + self.dt] if starts else []
        # A gap between chunks (a pause) must not stretch the previous step's span.
        ends = [min(e, s + self.dt) for s, e in zip(starts, ends)]
        return steps, starts, ends
