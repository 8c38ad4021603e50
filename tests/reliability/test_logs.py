"""Logs a kill cannot spoil: a torn JSONL line is ended before the next append and counted by readers; a burst
of rejected feedback is logged (one by one, then summarised by kind), never lost; a torn metrics row is
dropped on resume; and no "Failed to import warp" lines on every command."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

from mjx_protamer import jsonl
from mjx_protamer.experiments.run_log import RunLog, read_rows
from mjx_protamer.human.events import FeedbackEvent
from mjx_protamer.human.queue import FeedbackLog, FeedbackQueue

ROOT = Path(__file__).resolve().parents[2]


def _event(value: float, source: str = "keyboard") -> FeedbackEvent:
    now = time.time()
    return FeedbackEvent(now, now, source, value)


def test_append_after_a_torn_line_keeps_the_new_record(tmp_path, capsys):
    path = tmp_path / "feedback.jsonl"
    with FeedbackLog(path) as log:
        log.accepted(_event(1.0), step=1)
    with open(path, "a") as fh:  # killed in the middle of a write
        fh.write('{"status": "accepted", "t_st')
    with FeedbackLog(path) as log:  # the next run appends
        log.accepted(_event(-1.0), step=2)
    records, skipped = jsonl.read(path)
    assert [r["step"] for r in records] == [1, 2] and skipped == 1
    assert [e.value for e in FeedbackLog.read(path)] == [1.0, -1.0]
    err = capsys.readouterr().err
    assert "skipped 1 unreadable line(s)" in err and "read 2 record(s)" in err


def test_a_clean_log_reads_without_a_note(tmp_path, capsys):
    path = tmp_path / "feedback.jsonl"
    with FeedbackLog(path) as log:
        log.accepted(_event(0.5), step=3)
    with FeedbackLog(path) as log:
        log.note(event="end")
    assert [r["status"] for r in FeedbackLog.records(path)] == ["accepted", "note"]
    assert capsys.readouterr().err == ""


def test_a_burst_of_rejected_events_is_logged_or_summarised_by_kind(tmp_path):
    """More rejects than the side queue holds in one drain: the first ones are logged one by one, the rest
    in a summary by kind; every reject is accounted for in the log, and a second drain adds only what is new."""
    q = FeedbackQueue(maxsize=8, reject_maxsize=16)
    bad = [_event(5.0) for _ in range(300)] + [_event(0.0, source="telepathy") for _ in range(200)]
    assert not any(q.put(e) for e in bad)
    assert q.put(_event(0.5))
    with FeedbackLog(tmp_path / "fb.jsonl") as log:
        assert [e.value for e in q.drain(log, step=1)] == [0.5]
        for _ in range(10):
            q.put(_event(-3.0))
        q.drain(log, step=2)
    records = FeedbackLog.records(tmp_path / "fb.jsonl")
    one_by_one = [r for r in records if r["status"] == "rejected"]
    summaries = [r for r in records if r["status"] == "rejected_summary"]
    assert len(one_by_one) == 16 + 10 and {r["kind"] for r in one_by_one} == {"out_of_range"}
    assert summaries[0]["counts"] == {"out_of_range": 300 - 16, "source": 200}
    assert len(summaries) == 1  # the second drain's 10 fitted the side queue: nothing new to summarise
    logged = len(one_by_one) + sum(sum(s["counts"].values()) for s in summaries)
    assert logged == q.rejected == 510


def test_a_torn_metrics_row_is_dropped_on_resume(tmp_path, capsys):
    log = RunLog(tmp_path, tensorboard=False)
    for chunk in (1, 2, 3):
        log.write({"chunk": float(chunk), "env_steps": 100.0 * chunk, "loss": 0.5 / chunk})
    log.close()
    with open(tmp_path / "metrics.csv", "a") as fh:
        fh.write("4.0,400")  # killed mid-row
    resumed = RunLog(tmp_path, resume_chunk=2, tensorboard=False)
    assert [r["chunk"] for r in resumed.rows] == [1.0, 2.0]
    assert "skipped 1 unreadable row(s)" in capsys.readouterr().err
    rows, skipped = read_rows(tmp_path / "metrics.csv")
    assert [r["chunk"] for r in rows] == [1.0, 2.0] and skipped == 0


def test_importing_the_env_prints_no_warp_notice():
    code = "import mjx_protamer.envs.self_touch, mujoco.mjx; print('imported')"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120,
                          env={**os.environ, "JAX_PLATFORMS": "cpu"})
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout == "imported\n"
    assert "Failed to import" not in proc.stderr
