"""How many extra DDPG updates a live chunk gets: the time it is shown and not computed, spent on learning.

A paced session shows each chunk for `chunk_steps * dt` seconds. Computing it (env steps, the chunk's own
updates, the feedback path, the view's snapshot) takes less on most machines; the rest used to be slept away.
`UpdatePacer` measures both per chunk (the base cost, and the cost of one extra update from the last chunk that
made some) and gives the next chunk `spare_fraction` of the spare time in extra updates, within
`max_updates_per_step` per shown step in all. Unpaced (`reproduce live`, a session shown as fast as it is
computed) every chunk gets the fixed `unpaced_updates_per_step`. On the person's clock
(`session.updates_per_event`) the count is what the chunk's events bought, within the same limits. The count is
recorded with the chunk: a replay makes the same updates whatever its machine.
"""

from __future__ import annotations

import math


class UpdatePacer:
    def __init__(self, chunk_steps: int, dt: float, updates_per_step: int, max_updates_per_step: float,
                 spare_fraction: float, unpaced_updates_per_step: float, paced: bool, updates_per_event: float = 0.0):
        self.per_event = updates_per_event
        # updates the person's events have bought and the pace has not yet allowed (host state: a resumed session
        # starts without a backlog; a replay makes the recorded counts)
        self.owed = 0.0
        self.shown_s = chunk_steps * dt
        self.max_extra = max(0, int(math.floor((max_updates_per_step - updates_per_step) * chunk_steps)))
        self.unpaced_extra = max(0, int(round((unpaced_updates_per_step - updates_per_step) * chunk_steps)))
        self.base_per_chunk = updates_per_step * chunk_steps
        self.spare_fraction = spare_fraction
        self.paced = paced
        self.chunk_steps = chunk_steps
        self.base_s: float | None = None  # EMA of a chunk's cost without its extra updates
        self.update_s: float | None = None  # EMA of one extra update's cost
        self.total_extra = 0
        self.chunks = 0

    def next(self) -> int:
        """Extra updates for the coming chunk (with `updates_per_event`, the most it may make: `settle`)."""
        if not self.paced:
            return self.max_extra if self.per_event > 0 else self.unpaced_extra
        if self.base_s is None:
            return 0  # the first chunk measures the base cost
        if self.update_s is None:
            return min(self.max_extra, self.chunk_steps // 2)  # a probe, to measure one update's cost
        spare = self.shown_s - self.base_s
        return max(0, min(self.max_extra, int(self.spare_fraction * spare / self.update_s)))

    def settle(self, cap: int, taught: int) -> int:
        """The chunk's extra updates once its drain is known: `cap` by the clock, or with `updates_per_event` what
        the `taught` events (and the backlog) have bought, within `cap`."""
        if self.per_event <= 0:
            return cap
        self.owed += self.per_event * taught
        n = min(cap, int(self.owed))
        self.owed -= n
        return n

    def observe(self, base_s: float, extra: int, extra_s: float) -> None:
        """A chunk's measured cost: without its extra updates, and of its `extra` updates."""
        ema = lambda old, new: new if old is None else 0.8 * old + 0.2 * new
        self.base_s = ema(self.base_s, base_s)
        if extra > 0:
            self.update_s = ema(self.update_s, extra_s / extra)
        self.total_extra += extra
        self.chunks += 1

    def costs(self) -> dict:
        """The measured costs the pacer decides by (moving averages, ms): a chunk without its extra updates, and
        one extra update; what bounds the updates a shown step can get on this machine."""
        ms = lambda s: None if s is None else round(1000 * s, 2)
        return {"chunk_base_ms": ms(self.base_s), "extra_update_ms": ms(self.update_s),
                "shown_chunk_ms": round(1000 * self.shown_s, 2)}

    def updates_per_step(self) -> float:
        """Updates per shown step so far, the chunks' own and the extra ones."""
        if not self.chunks:
            return 0.0
        return (self.base_per_chunk * self.chunks + self.total_extra) / (self.chunk_steps * self.chunks)
