"""What a watcher of a finetune session sees happen: which touches are on at each shown step, as changes.

A live session records, per chunk, the steps at which each visible touch begins and ends
(`session_chunks.jsonl`, key "touches"), so that a person's reaction delay can be measured afterwards from
their feedback's onsets against the touches they reacted to (`reaction_delay.py`, `protamer reaction-delay`).
The touches are the lateral rule's two hands (`teachers.LATERAL_RULE`: a hand's touch features above
0.05 N) and the env's body regions (its `region_mask`), the things a person is asked to react to and the
page's caption names. An env without regions (the toy) records none. Host NumPy on the chunk's watched
steps (the signals through `teachers.rule_signals`, the one extraction of rule signals).
"""

from __future__ import annotations

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
