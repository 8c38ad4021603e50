"""A bounded feedback queue between host processes (keyboard, voice, teachers) and the learner.

Producers call `put(event)` from any process: the event is validated, and a full queue counts an
overflow instead of blocking or dropping silently. The learner calls `drain()` between jitted chunks;
every accepted event goes to an append-only JSONL log (flushed and fsynced per line, so a crash
loses at most the line being written), rejected ones to the log with their reason.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import queue as queue_lib
import time
from pathlib import Path

from mjx_protamer.human.events import FeedbackEvent, InvalidFeedback, validate_event


class FeedbackLog:
    """Append-only JSONL log of accepted and rejected feedback; each line is durable once written."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fh = open(self.path, "a", encoding="utf-8")

    def _write(self, record: dict) -> None:
        self._fh.write(json.dumps(record, sort_keys=True) + "\n")
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def accepted(self, event: FeedbackEvent, step: int | None = None) -> None:
        record = json.loads(event.to_json())
        record.update(status="accepted", received=time.time(), step=step)
        self._write(record)

    def rejected(self, raw: object, reason: str) -> None:
        self._write({"status": "rejected", "reason": reason, "received": time.time(), "raw": repr(raw)})

    def close(self) -> None:
        self._fh.close()

    @staticmethod
    def read(path: str | Path) -> list[FeedbackEvent]:
        """The accepted events of a log; a torn last line (a crash mid-write) is skipped."""
        events = []
        for line in Path(path).read_text(encoding="utf-8").splitlines():
            try:
                record = json.loads(line)
            except json.JSONDecodeError:
                continue
            if record.get("status") == "accepted":
                events.append(FeedbackEvent.from_json(line))
        return events


class FeedbackQueue:
    """multiprocessing queue with validation, overflow accounting and a drain for the learner.

    Picklable: pass it to producer processes (`multiprocessing.Process(args=(q,))`).
    """

    def __init__(self, maxsize: int = 256, ctx: mp.context.BaseContext | None = None):
        if maxsize < 1:
            raise ValueError(f"maxsize must be >= 1, got {maxsize}")
        ctx = ctx or mp.get_context("spawn")
        self.maxsize = maxsize
        self._q = ctx.Queue(maxsize)
        self._overflow = ctx.Value("i", 0)
        self._rejected = ctx.Value("i", 0)
        self._accepted = ctx.Value("i", 0)

    def put(self, event: FeedbackEvent) -> bool:
        """Validate and enqueue without blocking; False (and counted) when invalid or full."""
        try:
            validate_event(event)
        except InvalidFeedback:
            with self._rejected.get_lock():
                self._rejected.value += 1
            return False
        try:
            self._q.put_nowait(event)
        except queue_lib.Full:
            with self._overflow.get_lock():
                self._overflow.value += 1
            return False
        with self._accepted.get_lock():
            self._accepted.value += 1
        return True

    def drain(self, log: FeedbackLog | None = None, step: int | None = None, max_items: int | None = None,
              timeout: float = 0.0) -> list[FeedbackEvent]:
        """Take what is queued now (re-validated against the receiver's clock), logging each."""
        out: list[FeedbackEvent] = []
        while max_items is None or len(out) < max_items:
            try:
                event = self._q.get(timeout=timeout) if timeout > 0 and not out else self._q.get_nowait()
            except queue_lib.Empty:
                break
            try:
                validate_event(event)
            except InvalidFeedback as e:
                with self._rejected.get_lock():
                    self._rejected.value += 1
                if log is not None:
                    log.rejected(event, str(e))
                continue
            if log is not None:
                log.accepted(event, step=step)
            out.append(event)
        return out

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
        return {"accepted": self.accepted, "rejected": self.rejected, "overflow": self.overflow}
