"""Event validation, the bounded queue's overflow accounting and the crash-safe JSONL log."""

import math
import multiprocessing as mp
import time

import pytest

from mjx_protamer.human.clock import VirtualClock
from mjx_protamer.human.events import FeedbackEvent, InvalidFeedback, validate_event
from mjx_protamer.human.queue import FeedbackLog, FeedbackQueue


def ev(value=1.0, t=None, source="keyboard", **details):
    t = time.time() if t is None else t
    return FeedbackEvent(t, t, source, value, details)


@pytest.mark.parametrize(
    "event, reason",
    [
        (ev(1.5), "outside [-1, 1]"),
        (ev(-1.01), "outside [-1, 1]"),
        (ev(math.nan), "finite"),
        (ev(math.inf), "finite"),
        (ev(1.0, t=time.time() + 3600), "in the future"),
        (ev(1.0, source="telepathy"), "unknown source"),
        (FeedbackEvent(10.0, 9.0, "keyboard", 1.0), "before t_start"),
        (ev(1.0, obj=object()), "JSON"),
    ],
)
def test_invalid_events_are_rejected_with_a_reason(event, reason):
    with pytest.raises(InvalidFeedback, match=reason.replace("[", r"\[").replace("]", r"\]")):
        validate_event(event)


def test_valid_event_passes_and_round_trips():
    e = ev(-0.25, transcript="no", latency=0.4)
    assert validate_event(e) is e
    assert FeedbackEvent.from_json(e.to_json()) == e


def test_rejected_events_are_counted_and_logged_with_reason(tmp_path):
    q = FeedbackQueue(maxsize=4)
    assert q.put(ev(0.5))
    assert not q.put(ev(math.nan))
    assert "finite" in q.last_reason
    assert not q.put(ev(2.0))
    with FeedbackLog(tmp_path / "fb.jsonl") as log:
        got = q.drain(log, step=7)
    assert [e.value for e in got] == [0.5]
    records = FeedbackLog.records(tmp_path / "fb.jsonl")
    rejected = [r for r in records if r["status"] == "rejected"]
    assert len(rejected) == 2 and "finite" in rejected[0]["reason"] and "outside" in rejected[1]["reason"]
    accepted = [r for r in records if r["status"] == "accepted"]
    assert accepted[0]["step"] == 7
    assert q.stats() == {"accepted": 1, "rejected": 2, "overflow": 0, "waiting": 0}


def test_overflow_is_counted_reported_and_logged_once(tmp_path):
    q = FeedbackQueue(maxsize=3)
    results = [q.put(ev(0.1 * i)) for i in range(8)]
    assert results == [True] * 3 + [False] * 5
    assert q.overflow == 5 and "overflow" in q.last_reason
    log = FeedbackLog(tmp_path / "fb.jsonl")
    assert len(q.drain(log)) == 3
    assert q.put(ev(0.9))  # room again
    assert len(q.drain(log)) == 1
    log.close()
    overflow = [r for r in FeedbackLog.records(tmp_path / "fb.jsonl") if r["status"] == "overflow"]
    assert overflow == [{"status": "overflow", "count": 5, "total": 5, "received": overflow[0]["received"]}]


def _producer(q, n):
    for i in range(n):
        q.put(FeedbackEvent(time.time(), time.time(), "simulated", 1.0 if i % 2 else -1.0, {"i": i}))
    q.put(FeedbackEvent(time.time(), time.time(), "simulated", 7.0))  # invalid


def test_events_from_another_process_arrive_in_order(tmp_path):
    q = FeedbackQueue(maxsize=64)
    p = mp.get_context("spawn").Process(target=_producer, args=(q, 10))
    p.start()
    p.join(30)
    assert p.exitcode == 0
    with FeedbackLog(tmp_path / "fb.jsonl") as log:
        got = q.drain(log)
    assert [e.details["i"] for e in got] == list(range(10))
    assert q.rejected == 1
    assert sum(r["status"] == "rejected" for r in FeedbackLog.records(tmp_path / "fb.jsonl")) == 1


def test_log_survives_a_torn_last_line(tmp_path):
    path = tmp_path / "fb.jsonl"
    log = FeedbackLog(path)
    log.accepted(ev(1.0), step=1)
    log.accepted(ev(-1.0), step=2)
    log.close()
    with open(path, "a") as fh:  # a crash in the middle of a write
        fh.write('{"status": "accepted", "t_st')
    assert [e.value for e in FeedbackLog.read(path)] == [1.0, -1.0]


def test_virtual_clock_governs_the_future_check():
    clock = VirtualClock(start=100.0)
    q = FeedbackQueue(maxsize=4, clock=clock)
    assert not q.put(ev(1.0, t=105.0))  # 5 s ahead of the virtual clock
    clock.advance(5.0)
    assert q.put(ev(1.0, t=105.0))
    assert len(q.drain()) == 1
