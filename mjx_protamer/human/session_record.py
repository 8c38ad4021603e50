"""The record of a finetune session, enough to rerun it bit for bit (`protamer finetune --replay DIR`).

- `session.json` (written atomically at the start): how the session was started (learner, feedback,
  chunk size, config overrides, seeds), the checkpoint it started from and the SHA-256 of its files,
  and where the voice segments went.
- `session_chunks.jsonl` (one line per drain of the feedback queue, fsynced): the chunk's first step,
  the presentation time its steps were stamped with, every event the learner drained, in order, and the
  steps at which each visible touch began or ended (`touches.py`; what `protamer reaction-delay` measures
  a person's reaction delay against).
  A last line `{"final": true, ...}` holds the events drained at exit.

Replaying feeds those events to the same learner at the same drains (`ScriptedQueue`) with the same
step times, so the credit, the reward-model updates and the DDPG/COACH updates are the same
computations on the same inputs. Pure Python (no JAX).
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

from mjx_protamer.human.events import FeedbackEvent

MANIFEST = "session.json"
CHUNKS = "session_chunks.jsonl"


def tree_sha256(path: str | Path) -> str:
    """SHA-256 over the relative names and bytes of every file under `path` (or of one file)."""
    path = Path(path)
    h = hashlib.sha256()
    files = [path] if path.is_file() else sorted(p for p in path.rglob("*") if p.is_file())
    for f in files:
        h.update(str(f.relative_to(path) if f != path else f.name).encode())
        with f.open("rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
    return h.hexdigest()


def write_json_atomic(path: str | Path, data: dict) -> None:
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    with tmp.open("w", encoding="utf-8") as fh:
        json.dump(data, fh, indent=2, sort_keys=True)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


class SessionRecorder:
    """Appends one line per drain to session_chunks.jsonl (flushed and fsynced: a kill loses nothing
    that was drained)."""

    def __init__(self, out_dir: str | Path, manifest: dict | None = None):
        self.dir = Path(out_dir)
        if manifest is not None:
            write_json_atomic(self.dir / MANIFEST, manifest)
        self._fh = open(self.dir / CHUNKS, "a", encoding="utf-8")

    def _write(self, record: dict) -> None:
        self._fh.write(json.dumps(record, allow_nan=False) + "\n")
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def chunk(self, index: int, first_step: int, t0: float, events: list[FeedbackEvent],
              touches: dict | None = None) -> None:
        record = {"chunk": index, "first_step": int(first_step), "t0": float(t0),
                  "events": [json.loads(e.to_json()) for e in events]}
        if touches:
            record["touches"] = touches
        self._write(record)

    def final(self, events: list[FeedbackEvent]) -> None:
        self._write({"final": True, "events": [json.loads(e.to_json()) for e in events]})

    def close(self) -> None:
        if not self._fh.closed:
            self._fh.close()


def read_session(session_dir: str | Path) -> tuple[dict, list[dict]]:
    """(manifest, chunk records with their events as FeedbackEvent) of a recorded session.
    A torn last line (a crash mid-write) is skipped."""
    d = Path(session_dir)
    if not (d / MANIFEST).is_file() or not (d / CHUNKS).is_file():
        raise FileNotFoundError(f"{d} is not a recorded finetune session (no {MANIFEST} / {CHUNKS}); "
                                f"give the --out directory of a `protamer finetune` session")
    manifest = json.loads((d / MANIFEST).read_text(encoding="utf-8"))
    records = []
    for line in (d / CHUNKS).read_text(encoding="utf-8").splitlines():
        try:
            r = json.loads(line)
        except json.JSONDecodeError:
            continue
        r["events"] = [FeedbackEvent.from_json(json.dumps(e)) for e in r.get("events", [])]
        records.append(r)
    return manifest, records


class ScriptedQueue:
    """Stands in for the FeedbackQueue in a replay: each drain returns the next recorded drain's events
    (logged as accepted, as the live queue logs them)."""

    def __init__(self, drains: list[list[FeedbackEvent]]):
        self._drains = list(drains)
        self._next = 0
        self.accepted = sum(len(d) for d in drains)

    def drain(self, log=None, step: int | None = None, **_) -> list[FeedbackEvent]:
        if self._next >= len(self._drains):
            return []
        events = self._drains[self._next]
        self._next += 1
        if log is not None:
            for e in events:
                log.accepted(e, step=step)
        return list(events)

    def offer(self, event):
        return False, "a replayed session takes no new feedback"

    def put(self, event) -> bool:
        return False

    def stats(self) -> dict[str, int]:
        return {"accepted": self.accepted, "rejected": 0, "overflow": 0, "waiting": 0}
