"""What a watcher of a finetune session sees happen: which touches are on at each shown step, as changes.

A session records, per chunk, the steps at which each visible touch begins and ends
(`session_chunks.jsonl`, key "touches"), so that a person's reaction delay can be measured afterwards from
their feedback's onsets against the touches they reacted to (`reaction_delay.py`, `protamer reaction-delay`).
The touches are the lateral rule's two hands (`teachers.LATERAL_RULE`: a hand's touch features above
0.05 N) and the env's body regions (its `region_mask`), the things a person is asked to react to and the
page's caption names. An env without regions (the toy) records none. Host NumPy on the chunk's watched
steps (the signals through `teachers.rule_signals`, the one extraction of rule signals); `shown_touches` reads
them back from a recorded session.
"""

from __future__ import annotations

import math

import numpy as np

HANDS = ("left_hand", "right_hand")


def touch_signals(region_names) -> tuple[tuple[str, str, float], ...]:
    """(name, rule signal, threshold) of each visible touch; empty for an env without regions."""
    if not region_names:
        return ()
    from mjx_protamer.human.teachers import LATERAL_RULE  # the hands as the lateral rule sees them

    right, left = LATERAL_RULE
    return (("left_hand", left.signal, float(left.above)), ("right_hand", right.signal, float(right.above)),
            *((r, f"region:{r}", 0.5) for r in region_names))


class TouchChanges:
    """Turns each chunk's per-step touch flags (n, K) into the steps where a touch turns on or off. The
    state before the first chunk is 'no touch'; chunks must come in order."""

    def __init__(self, names):
        self.names = tuple(names)
        self._last = np.zeros(len(self.names), bool)

    def update(self, first_step: int, flags) -> dict[str, list[list[int]]]:
        """{name: [[step, 1 (on) | 0 (off)], ...]} for the touches that changed in this chunk."""
        flags = np.asarray(flags, bool).reshape(-1, len(self.names))
        before = np.vstack([self._last[None], flags[:-1]])
        out: dict[str, list[list[int]]] = {}
        for k, name in enumerate(self.names):
            changed = np.flatnonzero(flags[:, k] != before[:, k])
            if len(changed):
                out[name] = [[int(first_step + i), int(flags[i, k])] for i in changed]
        if len(flags):
            self._last = flags[-1].copy()
        return out


class TouchWatcher:
    """The touches of one watched env, chunk by chunk: `changes(first_step, obs, action, terms, region_mask)`.
    `names` is empty (and every chunk records nothing) for an env without regions."""

    def __init__(self, env):
        from mjx_protamer.human.teachers import env_signal_columns

        sigs = touch_signals(tuple(getattr(env, "region_names", ())))
        self.names = tuple(s[0] for s in sigs)
        self._cols = env_signal_columns([s[1] for s in sigs], env) if sigs else ()
        self._above = np.array([s[2] for s in sigs], np.float32)
        self._changes = TouchChanges(self.names)

    def changes(self, first_step: int, obs, action, terms, region_mask) -> dict[str, list[list[int]]]:
        if not self.names:
            return {}
        from mjx_protamer.human.teachers import rule_signals

        flags = rule_signals(self._cols, obs, action, terms, region_mask, xp=np) > self._above
        return self._changes.update(first_step, flags)


# --------------------------------------------------------------------------- reading a recorded session

def shown_touches(records: list[dict], dt: float, chunk_steps: int) -> tuple[dict[str, list[tuple]], float]:
    """({touch name: [(t_on, t_off, began), ...]}, seconds shown) from a session's chunk records, on the
    presentation clock.

    A session process records its chunks from index 0; a resume starts again at 0 (and a fresh TouchChanges,
    which assumes no touch is on). So each stretch of index 0, 1, ... is one process's showing: its first chunk
    was computed before the view and the feedback sources started (nobody saw it), so it counts neither as shown
    time nor for onsets, and a touch on during it has `began` False; a new stretch closes the touches open at
    the end of the previous one. The seconds shown count the shown chunks' own durations, not the pauses
    between chunks (a voice listener loading, a stop before a resume). Raises ValueError when the clock goes
    backwards (a simulated session resumed on a new virtual clock: its stretches cannot be joined)."""
    open_at: dict[str, tuple[float, bool]] = {}
    out: dict[str, list[tuple]] = {}
    shown, prev_end = 0, None
    for r in (r for r in records if "first_step" in r):
        first, t0 = int(r["first_step"]), float(r["t0"])
        if prev_end is not None and t0 < prev_end - 1e-6:
            raise ValueError(f"the session's clock goes backwards at step {first} ({t0 - prev_end:+.3f} s): "
                             "a simulated session resumed on a new clock; its stretches cannot be joined")
        unseen = int(r.get("chunk", 0)) == 0  # a process's first chunk: a new stretch, never shown
        if unseen and prev_end is not None:
            for name, (t_on, began) in open_at.items():
                out.setdefault(name, []).append((t_on, prev_end, began))
            open_at.clear()
        shown += 0 if unseen else 1
        for name, changes in (r.get("touches") or {}).items():
            for step, on in changes:
                t = t0 + (int(step) - first) * dt
                if on and name not in open_at:
                    open_at[name] = (t, not unseen)
                elif not on and name in open_at:
                    t_on, began = open_at.pop(name)
                    out.setdefault(name, []).append((t_on, t, began))
        prev_end = t0 + chunk_steps * dt
    for name, (t_on, began) in open_at.items():
        out.setdefault(name, []).append((t_on, math.inf, began))
    return {k: sorted(v) for k, v in out.items()}, shown * chunk_steps * dt


def touch_onsets(intervals: list[tuple], min_gap_s: float) -> np.ndarray:
    """The times a touch was seen to begin after at least `min_gap_s` without it (shorter gaps are one touch).
    `intervals` are (t_on, t_off[, began]); one not seen to begin still ends the gap before the next."""
    onsets, last_off = [], -math.inf
    for on, off, *began in sorted(intervals):
        if on - last_off >= min_gap_s and (not began or began[0]):
            onsets.append(on)
        last_off = max(last_off, off)
    return np.asarray(onsets, np.float64)
