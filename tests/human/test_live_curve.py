"""`reproduce live --snapshot-minutes`: the minute-by-minute statistics pair each checkpoint's sessions at the same
minute, start every curve at the checkpoint, and keep an arm that ran no session (Deep COACH's) at the start."""

from __future__ import annotations

import numpy as np
import pytest

from mjx_protamer.live.effect import METRICS, curve


def _metrics(score: float) -> dict:
    return {m: (score if m == "teacher_score" else 0.0) for m in METRICS}


def _row(start: float, none: list[float], keyboard: list[float], extra_minute: bool = False) -> dict:
    snaps = lambda values: [{"step": 12_000 * (j + 1), "minutes": float(j + 1), **_metrics(v)}
                            for j, v in enumerate(values)]
    row = {"start": _metrics(start), "none": {**_metrics(none[-1]), "snapshots": snaps(none)},
           "keyboard": {**_metrics(keyboard[-1]), "snapshots": snaps(keyboard)}}
    if extra_minute:  # a session that ran longer: its extra snapshot is not in every session, so it is left out
        row["keyboard"]["snapshots"].append({"step": 12_000 * 9, "minutes": 9.0, **_metrics(5.0)})
    return row


def test_the_curve_pairs_sessions_minute_by_minute_from_the_checkpoint():
    rows = [_row(0.1, [0.1, 0.0], [0.3, 0.6], extra_minute=True), _row(0.5, [0.4, 0.5], [0.5, 0.9]),
            _row(-0.2, [-0.2, -0.3], [0.1, 0.2])]
    c = curve(rows, ("none", "keyboard"), ("keyboard",))
    assert c["minutes"] == [0.0, 1.0, 2.0]
    assert c["per_checkpoint"]["keyboard"]["teacher_score"] == [[0.1, 0.3, 0.6], [0.5, 0.5, 0.9], [-0.2, 0.1, 0.2]]
    paired = c["paired"]["keyboard"]["teacher_score"]
    assert paired[0] is None  # minute 0: both arms are the checkpoint
    diffs = {1: [0.2, 0.1, 0.3], 2: [0.6, 0.4, 0.5]}
    for j, d in diffs.items():
        assert paired[j]["mean"] == pytest.approx(np.mean(d))
        assert paired[j]["seed_values"] == pytest.approx(d)
    assert c["pooled"]["none"]["teacher_score"][0]["mean"] == pytest.approx(np.mean([0.1, 0.5, -0.2]))


def test_an_arm_without_sessions_stays_at_the_start():
    rows = [_row(0.1, [0.1, 0.0], [0.3, 0.6]), _row(0.5, [0.4, 0.5], [0.5, 0.9])]
    for r in rows:  # Deep COACH: its no-feedback arm is the start, no session ran
        r["none"] = {**r["start"], "snapshots": None}
    c = curve(rows, ("none", "keyboard"), ("keyboard",))
    assert c["per_checkpoint"]["none"]["teacher_score"] == [[0.1] * 3, [0.5] * 3]
    assert c["paired"]["keyboard"]["teacher_score"][2]["seed_values"] == pytest.approx([0.5, 0.4])
