"""Jobs that share one compiled program, run a few at a time on host threads of one process.

Why: on a CPU the batched trainer's chunk keeps the cores busy for only part of its time (the update's small
matmuls, the physics callback and the selects between them leave gaps: 1.66-1.69 cores of 2 on the 5-seed Table II
chunk). A second job's chunk fills those gaps, since XLA and MuJoCo release the GIL while they run. Measured on
the 2-core machine (two Table II conditions, 5 seeds each, 6 chunks each, alternately one after the other and at
once): the pair took 0.78-0.83 of its sequential wall time at 1.94-1.95 cores busy.

Each job computes what it would alone: the programs are the same and deterministic, and the threads share
nothing but the physics engine, whose calls are serialised by its own lock and depend only on their inputs.
"""
from __future__ import annotations

import threading
from typing import Callable, Sequence, TypeVar

T = TypeVar("T")


class Stopped(Exception):
    """Raised inside a job, between its chunks, once another job failed or the run was interrupted."""


def run_side_by_side(jobs: Sequence[Callable[[Callable[[], None]], T]], at_once: int) -> list[T]:
    """Run `jobs` in order, at most `at_once` at a time; their results in the jobs' order.

    A job is `job(between_chunks)` and calls `between_chunks()` after each chunk: there it learns that it must
    stop (it raises `Stopped`). The first job runs alone until its first chunk is done, so that it compiles the
    shared programs once rather than every thread at the same time. When a job raises, the others stop after
    their current chunk and the first error is raised here; an interrupt (Ctrl-C) stops them the same way. What a
    job wrote before it stopped (a finished condition) is kept."""
    if at_once <= 1 or len(jobs) <= 1:
        return [job(lambda: None) for job in jobs]
    stop, first_chunk, take = threading.Event(), threading.Event(), threading.Lock()
    results: list = [None] * len(jobs)
    errors: list[BaseException] = []
    queue = iter(range(len(jobs)))

    def between_chunks() -> None:
        first_chunk.set()
        if stop.is_set():
            raise Stopped()

    def worker(k: int) -> None:
        if k > 0:
            first_chunk.wait()
        while not stop.is_set():
            with take:
                i = None if stop.is_set() else next(queue, None)
            if i is None:
                return
            try:
                results[i] = jobs[i](between_chunks)
            except Stopped:
                return
            except BaseException as e:  # noqa: BLE001 - handed to the calling thread below
                errors.append(e)
                stop.set()
                first_chunk.set()
                return
            first_chunk.set()  # a job without chunks still lets the others start

    threads = [threading.Thread(target=worker, args=(k,), name=f"side-by-side-{k}", daemon=True)
               for k in range(min(at_once, len(jobs)))]
    for t in threads:
        t.start()
    try:
        for t in threads:
            while t.is_alive():
                t.join(0.25)  # a timed join: an interrupt reaches this thread while it waits
    except BaseException:
        stop.set()
        first_chunk.set()
        for t in threads:
            t.join()
        raise
    if errors:
        raise errors[0]
    return results
