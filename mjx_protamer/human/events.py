"""One feedback event type for every source: keyboard, prosody, whisper and simulated teachers.

Pure Python (no JAX, no torch): the audio front end, the keyboard thread and the learner all share it.
Times are wall-clock seconds (`time.time()`); `t_start`/`t_end` bracket the utterance or key press
(equal for a key press). `details` carries what the source knows (valence, transcript, label,
latency, ...), JSON-serialisable.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from typing import Any, Literal

# "attention" is no feedback: the live page saying whether it is watched (value 1 or 0; human/attention.py).
Source = Literal["keyboard", "prosody", "whisper", "simulated", "attention"]
SOURCES: tuple[str, ...] = ("keyboard", "prosody", "whisper", "simulated", "attention")

# A clock skew allowance: events stamped this far ahead of the receiver's clock are still accepted.
MAX_FUTURE_S = 0.5


# Why an event was refused, in a word: rejected events are summarised by these when too many come to log
# each one (`FeedbackQueue.drain`).
REJECT_KINDS: tuple[str, ...] = ("malformed", "source", "not_finite", "out_of_range", "time_order", "future",
                                 "details")


class InvalidFeedback(ValueError):
    """An event that must not be used; the message says why, `kind` (one of REJECT_KINDS) says it in a word."""

    def __init__(self, message: str, kind: str = "malformed"):
        super().__init__(message)
        self.kind = kind if kind in REJECT_KINDS else "malformed"


@dataclasses.dataclass(frozen=True)
class FeedbackEvent:
    t_start: float
    t_end: float
    source: str
    value: float
    details: dict[str, Any] = dataclasses.field(default_factory=dict)

    def to_json(self) -> str:
        return json.dumps(dataclasses.asdict(self), sort_keys=True, allow_nan=False)

    @classmethod
    def from_json(cls, line: str) -> "FeedbackEvent":
        try:
            raw = json.loads(line)
        except json.JSONDecodeError as e:
            raise InvalidFeedback(f"not a JSON feedback event: {e}") from None
        if not isinstance(raw, dict):
            raise InvalidFeedback("a feedback event must be a JSON object")
        missing = {"t_start", "t_end", "source", "value"} - set(raw)
        if missing:
            raise InvalidFeedback(f"feedback event lacks {sorted(missing)}")
        return cls(
            t_start=float(raw["t_start"]),
            t_end=float(raw["t_end"]),
            source=str(raw["source"]),
            value=float(raw["value"]),
            details=dict(raw.get("details") or {}),
        )


def validate_event(event: FeedbackEvent, now: float | None = None) -> FeedbackEvent:
    """Return the event if it may be used, else raise InvalidFeedback with the reason."""
    now = time.time() if now is None else now
    if event.source not in SOURCES:
        raise InvalidFeedback(f"unknown source {event.source!r}; allowed: {', '.join(SOURCES)}", "source")
    for name in ("value", "t_start", "t_end"):
        v = getattr(event, name)
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
            raise InvalidFeedback(f"{name} must be a finite number, got {v!r}", "not_finite")
    if not -1.0 <= event.value <= 1.0:
        raise InvalidFeedback(f"value {event.value} is outside [-1, 1]", "out_of_range")
    if event.source == "attention" and event.value not in (0.0, 1.0):
        raise InvalidFeedback(f"an attention event's value is 1 (watching) or 0 (not), got {event.value}",
                              "out_of_range")
    if event.t_end < event.t_start:
        raise InvalidFeedback(f"t_end {event.t_end} is before t_start {event.t_start}", "time_order")
    if event.t_end > now + MAX_FUTURE_S:
        raise InvalidFeedback(
            f"timestamp {event.t_end:.3f} is {event.t_end - now:.3f} s in the future (clock {now:.3f})", "future"
        )
    try:
        json.dumps(event.details, allow_nan=False)
    except (TypeError, ValueError) as e:
        raise InvalidFeedback(f"details are not JSON-serialisable: {e}", "details") from None
    return event
