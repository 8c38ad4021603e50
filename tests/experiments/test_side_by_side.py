"""`side_by_side.run_side_by_side`: Table II's conditions a few at a time on host threads. The jobs overlap, the
first compiles alone, results come back in the jobs' order, and one job's failure stops the others after their
current chunk without losing what finished."""

import threading

import pytest

from mjx_protamer.experiments.side_by_side import run_side_by_side


def test_jobs_run_at_once_after_the_first_chunk_and_return_in_order():
    barrier = threading.Barrier(2, timeout=10)  # both jobs inside at the same time, or BrokenBarrierError
    events = []

    def first(between_chunks):
        events.append("first chunk")
        between_chunks()  # the shared program is compiled: the second job may start
        barrier.wait()
        return "A"

    def second(between_chunks):
        events.append("second starts")
        barrier.wait()
        return "B"

    assert run_side_by_side([first, second], at_once=2) == ["A", "B"]
    assert events == ["first chunk", "second starts"]


def test_a_queue_longer_than_the_threads_runs_every_job_once():
    ran = []
    lock = threading.Lock()

    def job(i):
        def run(between_chunks):
            for _ in range(3):
                between_chunks()
            with lock:
                ran.append(i)
            return i * i
        return run

    assert run_side_by_side([job(i) for i in range(5)], at_once=2) == [0, 1, 4, 9, 16]
    assert sorted(ran) == [0, 1, 2, 3, 4]
    assert run_side_by_side([job(i) for i in range(3)], at_once=1) == [0, 1, 4]


def test_a_failing_job_stops_the_others_after_their_chunk_and_its_error_is_raised():
    started_b = threading.Event()
    chunks_b = []
    finished = []

    def fails(between_chunks):
        between_chunks()
        started_b.wait(10)
        raise RuntimeError("condition DTK: NaN in the critic")

    def long_job(between_chunks):
        started_b.set()
        for k in range(10_000):
            chunks_b.append(k)
            threading.Event().wait(0.001)
            between_chunks()  # raises Stopped once the other job failed
        finished.append("long")

    def never_started(between_chunks):
        finished.append("third")

    with pytest.raises(RuntimeError, match="NaN in the critic"):
        run_side_by_side([fails, long_job, never_started], at_once=2)
    assert 0 < len(chunks_b) < 10_000 and finished == []


