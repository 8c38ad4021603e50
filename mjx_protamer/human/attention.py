"""When a live teacher watched: the host twin of the in-jit teachers' `watching` flag.

A silent step teaches "nothing to say here" only if the teacher was looking at it (docs/experiments.md,
"What limits r_hat": 27-50% of a simulated teacher's silences fell while it was not watching, on behaviour it
would have praised). In a live session the live page reports whether it is visible (the Page Visibility
API; a closed page is not watched) as events of source "attention", value 1 (watching) or 0 (not), through
the same FeedbackQueue as the feedback itself: so the feedback log and the session record hold them, and a
replay rebuilds the same timeline. With `credit.silence_needs_attention` the learner turns a step into a 0
label only if the teacher watched throughout the time in which feedback about it could have come.

Pure Python and NumPy (no JAX): the view process imports `attention_event`.
"""

from __future__ import annotations

import bisect

import numpy as np

from mjx_protamer.human.events import FeedbackEvent

SOURCE = "attention"


def attention_event(t: float, watching: bool, via: str) -> FeedbackEvent:
    return FeedbackEvent(t, t, SOURCE, 1.0 if watching else 0.0, {"watching": bool(watching), "via": via})


def is_attention(event: FeedbackEvent) -> bool:
    return event.source == SOURCE


def describe(event: FeedbackEvent, used: bool) -> str:
    """What an attention event means to the learner (`used`: it gates silences)."""
    state = f"{'watching' if event.value else 'not watching'} ({event.details.get('via', '?')})"
    if not used:
        return f"{state}; not used (credit.silence_needs_attention is off)"
    if event.value:
        return f"{state}: silent steps count as 'nothing to say'"
    return f"{state}: silent steps teach nothing until it is back"


class AttentionTimeline:
    """The teacher's watching state over time, from attention events in any order; not watching before
    the first one (a session that never hears from its page learns from no silence)."""

    def __init__(self):
        self.times: list[float] = []
        self.watching: list[bool] = []

    def record(self, event: FeedbackEvent) -> None:
        i = bisect.bisect_right(self.times, event.t_start)
        self.times.insert(i, float(event.t_start))
        self.watching.insert(i, bool(event.value))

    def watched_throughout(self, start: np.ndarray, end: np.ndarray) -> np.ndarray:
        """Per interval [start, end]: True if the teacher was watching at `start` and did not stop before
        `end`."""
        start, end = np.asarray(start, np.float64), np.asarray(end, np.float64)
        if not self.times:
            return np.zeros(start.shape, bool)
        times = np.asarray(self.times)
        on = np.asarray(self.watching)
        stops = np.concatenate([[0], np.cumsum(~on)])  # stops[i]: changes to "not watching" among the first i
        i0 = np.searchsorted(times, start, side="right")
        i1 = np.searchsorted(times, end, side="right")
        watching_at_start = np.where(i0 > 0, on[np.maximum(i0 - 1, 0)], False)
        return watching_at_start & (stops[i1] == stops[i0])
