"""A bounded feedback queue between host processes (keyboard, voice, teachers) and the learner.

Producers call `put(event)` from any process: the event is validated, and a full queue counts an
overflow instead of blocking or dropping silently. The learner calls `drain(log)` between jitted chunks;
every accepted event goes to an append-only JSONL log (`mjx_protamer.jsonl`: flushed and fsynced per line,
a torn last line ended before appending, so a crash loses at most the line being written). Events rejected
by a producer travel to the learner on a side queue with their reason and are logged by `drain` one by one;
when a burst fills that queue, the rest are counted by kind (`REJECT_KINDS`) in shared memory and `drain`
logs one "rejected_summary" record with those counts. Overflows since the last drain are logged as one
"overflow" record. Nothing is dropped without a count and a log line.

Pure Python (no JAX): the audio front end imports this module.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import queue as queue_lib
import time
from pathlib import Path
from typing import Callable

from mjx_protamer import jsonl
from mjx_protamer.human.events import REJECT_KINDS, FeedbackEvent, InvalidFeedback, validate_event


class FeedbackLog:
    """Append-only JSONL log of accepted and rejected feedback; each line is durable once written.

    Record kinds (`status`): "accepted" (the event's fields + `step`, the env step it was drained at),
    "rejected" (`reason`, `kind`, `raw`), "rejected_summary" (`counts` by kind of the rejected events that
    were not logged one by one, `total`), "overflow" (`count` new since the last record, `total`), and
    free-form "note" records (run start/end).
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._fh = jsonl.open_append(self.path)

    def _write(self, record: dict) -> None:
        jsonl.append(self._fh, record)

    def accepted(self, event: FeedbackEvent, step: int | None = None) -> None:
        record = json.loads(event.to_json())
        record.update(status="accepted", received=time.time(), step=step)
        self._write(record)

    def rejected(self, raw: object, reason: str, kind: str = "malformed") -> None:
        raw_text = raw if isinstance(raw, str) else repr(raw)
        self._write({"status": "rejected", "reason": reason, "kind": kind, "received": time.time(), "raw": raw_text})

    def rejected_summary(self, counts: dict[str, int], total: int) -> None:
        self._write({"status": "rejected_summary", "counts": counts, "total": int(total), "received": time.time()})

    def overflow(self, count: int, total: int) -> None:
        self._write({"status": "overflow", "count": int(count), "total": int(total), "received": time.time()})

    def note(self, **fields) -> None:
        self._write({"status": "note", "received": time.time(), **fields})

    def close(self) -> None:
        if not self._fh.closed:
            self._fh.close()

    def __enter__(self) -> "FeedbackLog":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @staticmethod
    def records(path: str | Path) -> list[dict]:
        """Every complete record of a log; unreadable lines (a torn write) are skipped and counted on stderr."""
        return jsonl.read_reporting(path)

    @staticmethod
    def read(path: str | Path) -> list[FeedbackEvent]:
        """The accepted events of a log; unreadable lines (a torn write) are skipped and counted on stderr."""
        return [
            FeedbackEvent.from_json(json.dumps(r))
            for r in FeedbackLog.records(path)
            if r.get("status") == "accepted"
        ]


class FeedbackQueue:
    """multiprocessing queue with validation, overflow accounting and a drain for the learner.

    Picklable: pass it to producer processes (`multiprocessing.Process(args=(q,))`). `clock` is what
    "now" means for the future-timestamp check: the wall clock by default, a `VirtualClock` for
    simulated runs (it is shared across processes).
    """

    def __init__(self, maxsize: int = 256, ctx: mp.context.BaseContext | None = None,
                 clock: Callable[[], float] | None = None, reject_maxsize: int = 256,
                 flush_timeout: float = 1.0):
        if maxsize < 1:
            raise ValueError(f"maxsize must be >= 1, got {maxsize}")
        ctx = ctx or mp.get_context("spawn")
        self.maxsize = maxsize
        self.clock = clock
        self.flush_timeout = flush_timeout
        self._q = ctx.Queue(maxsize)
        self._rejects = ctx.Queue(reject_maxsize)
        self._overflow = ctx.Value("i", 0)
        self._rejected = ctx.Value("i", 0)
        self._accepted = ctx.Value("i", 0)
        self._taken = ctx.Value("i", 0)
        self._rejects_sent = ctx.Value("i", 0)
        self._rejects_taken = ctx.Value("i", 0)
        self._overflow_logged = ctx.Value("i", 0)
        # Rejected events that found the side queue full, by kind; and how many of those drain has logged.
        self._unsent = ctx.Array("i", len(REJECT_KINDS))
        self._unsent_logged = ctx.Array("i", len(REJECT_KINDS))
        self.last_reason: str | None = None  # producer-local: why the last put() returned False

    def _now(self) -> float:
        return time.time() if self.clock is None else self.clock()

    @staticmethod
    def _bump(counter, by: int = 1) -> None:
        with counter.get_lock():
            counter.value += by

    def _reject(self, raw: object, reason: str, kind: str) -> None:
        self._bump(self._rejected)
        self.last_reason = reason
        try:
            self._rejects.put_nowait((raw if isinstance(raw, str) else repr(raw), reason, kind))
            self._bump(self._rejects_sent)
        except queue_lib.Full:  # a burst: counted by kind, logged as a summary on the next drain
            with self._unsent.get_lock():
                self._unsent[REJECT_KINDS.index(kind)] += 1

    def offer(self, event: FeedbackEvent) -> tuple[bool, str | None]:
        """Validate and enqueue without blocking: (True, None), or (False, reason) - counted either way."""
        try:
            validate_event(event, now=self._now())
        except InvalidFeedback as e:
            self._reject(event, str(e), e.kind)
            return False, str(e)
        try:
            self._q.put_nowait(event)
        except queue_lib.Full:
            self._bump(self._overflow)
            self.last_reason = f"queue full ({self.maxsize} events waiting): overflow"
            return False, self.last_reason
        self._bump(self._accepted)
        return True, None

    def put(self, event: FeedbackEvent) -> bool:
        """Validate and enqueue without blocking; False (and counted) when invalid or full."""
        return self.offer(event)[0]

    def _take(self, q, sent, taken, max_items: int | None, timeout: float) -> list:
        """Everything the producers have put so far (waiting up to flush_timeout for items still in a
        producer's feeder thread), then whatever else is there already."""
        out = []
        while max_items is None or len(out) < max_items:
            pending = sent.value - taken.value
            wait = self.flush_timeout if pending > 0 else (timeout if not out else 0.0)
            try:
                item = q.get(timeout=wait) if wait > 0 else q.get_nowait()
            except queue_lib.Empty:
                break
            self._bump(taken)
            out.append(item)
        return out

    def drain(self, log: FeedbackLog | None = None, step: int | None = None, max_items: int | None = None,
              timeout: float = 0.0) -> list[FeedbackEvent]:
        """Take what is queued now (re-validated against the receiver's clock), logging each accepted
        and rejected event and any overflow since the last drain."""
        for raw, reason, kind in self._take(self._rejects, self._rejects_sent, self._rejects_taken, None, 0.0):
            if log is not None:
                log.rejected(raw, reason, kind)
        if log is not None:
            self._log_unsent(log)
        out: list[FeedbackEvent] = []
        for event in self._take(self._q, self._accepted, self._taken, max_items, timeout):
            try:
                validate_event(event, now=self._now())
            except InvalidFeedback as e:
                self._bump(self._rejected)
                if log is not None:
                    log.rejected(event, str(e), e.kind)
                continue
            if log is not None:
                log.accepted(event, step=step)
            out.append(event)
        total = self._overflow.value
        new = total - self._overflow_logged.value
        if new > 0 and log is not None:
            log.overflow(new, total)
            self._overflow_logged.value = total
        return out

    def _log_unsent(self, log: FeedbackLog) -> None:
        """One "rejected_summary" record for the rejected events not logged one by one since the last drain."""
        with self._unsent.get_lock():
            now = list(self._unsent)
        new = {k: now[i] - self._unsent_logged[i] for i, k in enumerate(REJECT_KINDS)
               if now[i] > self._unsent_logged[i]}
        if new:
            log.rejected_summary(new, total=sum(now))
            for i in range(len(REJECT_KINDS)):
                self._unsent_logged[i] = now[i]

    @property
    def overflow(self) -> int:
        return self._overflow.value

    @property
    def rejected(self) -> int:
        return self._rejected.value

    @property
    def accepted(self) -> int:
        return self._accepted.value

    def stats(self) -> dict[str, int]:
        return {"accepted": self.accepted, "rejected": self.rejected, "overflow": self.overflow,
                "waiting": self._accepted.value - self._taken.value}
