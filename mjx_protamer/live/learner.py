"""What a live session asks of a learner, and the part every learner shares: time, the queue, the outcomes.

The protocol (`Learner`): `warm_up()` compiles what a first event would stall on; `step_chunk(t0)` runs the
next `chunk_steps` steps of the one watched env and returns them as a `Chunk` stamped with the times they are
shown; `take_events(step)` drains the feedback queue and learns from what it held; `extra_updates(n)` spends
spare time (DDPG: more updates; COACH learns from corrections only); `save(out)` writes what it has learnt;
`actor_params()` is the deterministic policy as it stands (a DDPG actor's tree, what a snapshot keeps);
`status()` is what the terminal, the page and session.json report (`progress(pace)` the terminal's line of it,
`intro(spec)` what the terminal says of the learner before the first chunk). DDPG + DeepTAMER (`live/tamer.py`) and
Deep COACH (`live/coach.py`) implement it; `build_learner` (live/build.py) is the one place that chooses;
what code elsewhere must know of a learner is in its traits (live/kinds.py), never its name.

`ChunkLearner` is their shared skeleton: the step clock that maps times to steps, the queue and the feedback
log, attention events (the page's visibility, which gates silences), and the per-event outcomes a session
shows and records. A subclass says how a chunk is computed (`_run_chunk`) and what an event does (`_take`).
"""

from __future__ import annotations

import abc
import dataclasses
from pathlib import Path
from typing import Callable, Protocol

import numpy as np

from mjx_protamer.human.attention import AttentionTimeline, describe, is_attention
from mjx_protamer.human.clock import StepClock
from mjx_protamer.human.events import FeedbackEvent
from mjx_protamer.human.queue import FeedbackLog, FeedbackQueue
from mjx_protamer.human.touches import TouchWatcher


@dataclasses.dataclass
class Chunk:
    """The watched env's steps of one chunk, as they are shown."""

    first_step: int
    t0: float  # presentation time of the first step (s, on the session's clock)
    times: np.ndarray  # (n,) presentation time of each step
    obs: np.ndarray  # (n, obs)
    action: np.ndarray  # (n, act)
    reward_terms: np.ndarray  # (n, terms)
    region_mask: np.ndarray | None  # (n, regions), None for an env without regions
    metrics: dict  # contact_rate, step_reward, ...
    touches: dict | None = None  # the touches that began or ended (human/touches.py), what a session records


@dataclasses.dataclass(frozen=True)
class Outcome:
    """What became of one drained event: `got` is the learner's (a Credit, a corrected step) or None, `why` the
    reason it did nothing (None when it was used)."""

    event: FeedbackEvent
    got: object
    why: str | None
    text: str  # how the terminal and the page describe it


class Learner(Protocol):
    kind: str
    queue: FeedbackQueue
    first_step: int
    events: int
    last_chunk: Chunk | None

    def warm_up(self) -> None: ...
    def step_chunk(self, t0: float) -> Chunk: ...
    def take_events(self, step: int) -> list[Outcome]: ...
    def extra_updates(self, n: int) -> int: ...
    def save(self, out: Path) -> None: ...
    def status(self) -> dict: ...
    def progress(self, pace: dict) -> str: ...
    def intro(self, spec) -> list[str]: ...
    def actor_params(self) -> dict: ...
    def predict(self, chunk: Chunk) -> np.ndarray | None: ...
    def close(self) -> None: ...


class ChunkLearner(abc.ABC):
    """The skeleton of a session's learner: time, queue, log, attention, outcomes. Subclasses implement
    `_run_chunk(t0) -> Chunk` (times stamped by `_stamp`) and `_take(event) -> (got, why, text)`."""

    kind = "?"

    def __init__(self, env, dt: float, chunk_steps: int, clock: Callable[[], float], queue: FeedbackQueue | None,
                 queue_size: int, log_path: str | Path | None, history: int, attention: bool):
        self.env = env
        self.dt = dt
        self.chunk_steps = chunk_steps
        self.clock = clock
        self.queue = queue if queue is not None else FeedbackQueue(queue_size, clock=clock)
        self.log = FeedbackLog(log_path) if log_path is not None else None
        self.step_clock = StepClock(dt, capacity=history)
        # when the live teacher watched (its page's attention events); None: every silence counts
        self.attention = AttentionTimeline() if attention else None
        self.touches = TouchWatcher(env)  # the touch onsets a session records (reaction_delay.py reads them)
        self.first_step = 0
        self.events = 0
        self.last_chunk: Chunk | None = None

    def intro(self, spec) -> list[str]:
        """Lines the session's terminal prints of this learner before the first chunk (none by default)."""
        return []

    def _stamp(self, t0: float) -> tuple[float, np.ndarray]:
        """The chunk's steps on the step clock from `t0`; a chunk computed faster than real time is shown
        right after the previous one."""
        if len(self.step_clock):
            t0 = max(t0, self.step_clock.time_of(self.step_clock.last_step) + self.dt)
        times = self.step_clock.record_chunk(self.first_step, self.chunk_steps, t0, self.dt)
        return t0, np.asarray(times)

    def _finish_chunk(self, chunk: Chunk) -> Chunk:
        chunk.touches = self.touches.changes(chunk.first_step, chunk.obs, chunk.action, chunk.reward_terms,
                                             chunk.region_mask)
        self.last_chunk = chunk
        self.first_step += self.chunk_steps
        return chunk

    def take_events(self, step: int) -> list[Outcome]:
        """Drain and log the queue; each feedback event goes to `_take`, attention events to the timeline."""
        outcomes = []
        for event in self.queue.drain(self.log, step=step):
            if is_attention(event):  # no feedback: when the teacher watched (logged and recorded all the same)
                if self.attention is not None:
                    self.attention.record(event)
                outcomes.append(Outcome(event, None, "attention", describe(event, self.attention is not None)))
                continue
            self.events += 1
            got, why, text = self._take(event)
            if why is not None and self.log is not None:
                self.log.note(event="not used", reason=why, t_start=event.t_start, value=event.value)
            outcomes.append(Outcome(event, got, why, text if why is None else f"accepted, not used: {why}"))
        self._after_drain(outcomes)
        return outcomes

    @abc.abstractmethod
    def step_chunk(self, t0: float) -> Chunk:
        """The next chunk of the watched env, stamped from `t0` (`_stamp`) and finished (`_finish_chunk`)."""

    @abc.abstractmethod
    def _take(self, event: FeedbackEvent) -> tuple[object, str | None, str]:
        """What one feedback event does: (what it gave, None, how it reads) or (None, why not, "")."""

    def _after_drain(self, outcomes: list[Outcome]) -> None:
        pass

    def close(self) -> None:
        if self.log is not None:
            self.log.note(event="end", queue=self.queue.stats(), **self._end_note())
            self.log.close()

    def _end_note(self) -> dict:
        return {}
