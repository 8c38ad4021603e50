"""The record of a live session, enough to rerun it bit for bit (`protamer finetune --replay DIR`), and checked.

- `session.json` (written atomically at the start, again at each resume): how the session was started (the spec:
  learner, feedback, chunk, configs, seeds), the checkpoint it started from and the SHA-256 of its files.
- `session_chunks.jsonl`, one JSON object per line, each fsynced as written, each carrying its line number `n`
  and `sha`, the SHA-256 of the rest of the line: a line torn by a crash, cut, edited or moved is found and
  named. Kinds of line:
  - a chunk: `segment` (0, then one more per resume), `chunk` (its index within the segment), `first_step`,
    `t0` (the presentation time its steps were stamped with), `events` (the events drained after it, in
    order), `extra` (the DDPG updates made after it, from spare time) and `touches` (the steps at which each
    visible touch began or ended: what `protamer reaction-delay` measures a person against);
  - `final`: the events drained at exit, after the last chunk;
  - `saved`: a save completed (`saved`: its number, the checkpoints' step; `step`: the session's first step after
    it);
  - `resume`: a new segment starts from save `save`: every line between that save's line and this one was
    computed by a process whose state was lost, and is superseded.

Replaying feeds each drain the recorded events (`ScriptedQueue`), stamps the chunks with the recorded times and
makes the recorded extra updates; at a `resume` the replay starts a new segment as the resumed session did
(a fresh learner on the state reached at that save). Pure Python (no JAX).
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

from mjx_protamer.atomic import write_atomic
from mjx_protamer.errors import SessionRecordError
from mjx_protamer.human.events import FeedbackEvent

MANIFEST = "session.json"
CHUNKS = "session_chunks.jsonl"
FORMAT = 2  # 1 (before 6 December): no line numbers or digests, no segments, no extra updates


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
    write_atomic(path, json.dumps(data, indent=2, sort_keys=True))


def _digest(record: dict) -> str:
    body = {k: v for k, v in record.items() if k != "sha"}
    return hashlib.sha256(json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False).encode()).hexdigest()


def _events_json(events: list[FeedbackEvent]) -> list[dict]:
    return [json.loads(e.to_json()) for e in events]


class SessionRecorder:
    """Appends checked lines to session_chunks.jsonl (flushed and fsynced: a kill loses nothing written)."""

    def __init__(self, out_dir: str | Path, segment: int = 0, next_line: int = 0):
        self.dir = Path(out_dir)
        self.segment = segment
        self.n = next_line
        self._fh = open(self.dir / CHUNKS, "a", encoding="utf-8")

    def _write(self, record: dict) -> None:
        record = {"n": self.n, **record}
        record["sha"] = _digest(record)
        self._fh.write(json.dumps(record, allow_nan=False, sort_keys=True) + "\n")
        self._fh.flush()
        os.fsync(self._fh.fileno())
        self.n += 1

    def chunk(self, index: int, first_step: int, t0: float, events: list[FeedbackEvent], extra: int = 0,
              touches: dict | None = None) -> None:
        record = {"segment": self.segment, "chunk": index, "first_step": int(first_step), "t0": float(t0),
                  "events": _events_json(events), "extra": int(extra)}
        if touches:
            record["touches"] = touches
        self._write(record)

    def final(self, events: list[FeedbackEvent]) -> None:
        self._write({"segment": self.segment, "final": True, "events": _events_json(events)})

    def saved(self, save: int, step: int) -> None:
        self._write({"segment": self.segment, "saved": int(save), "step": int(step)})

    def resume(self, save: int, time: float) -> None:
        self._write({"segment": self.segment, "resume": int(save), "time": float(time)})

    def close(self) -> None:
        if not self._fh.closed:
            self._fh.close()


def _read_lines(path: Path, torn_tail_ok: bool) -> tuple[list[dict], int | None]:
    """The checked records of a format-2 file, and the byte offset of a torn last line (None if whole)."""
    data = path.read_bytes()
    records, offset, torn_at = [], 0, None
    lines = data.split(b"\n")
    for i, raw in enumerate(lines):
        last = i == len(lines) - 1
        if last and raw == b"":
            break
        where = f"{path} line {i + 1}"
        try:
            record = json.loads(raw.decode("utf-8"))
            ok = isinstance(record, dict) and record.get("sha") == _digest(record)
        except (ValueError, TypeError):
            record, ok = None, False
        if last and not ok:  # no newline after it: the process died while writing it
            if torn_tail_ok:
                torn_at = offset
                break
            raise SessionRecordError(f"{where} is torn (the session was killed while writing it); `protamer "
                                     f"finetune --resume --out {path.parent}` repairs it, or replay a copy without it")
        if not ok:
            raise SessionRecordError(f"{where} is damaged (its digest does not match: edited, cut or corrupt); the "
                                     "record cannot be replayed or resumed")
        if record.get("n") != len(records):
            raise SessionRecordError(f"{where} is out of place (line number {record.get('n')}, expected "
                                     f"{len(records)}): lines were lost, moved or doubled")
        records.append(record)
        offset += len(raw) + 1
    return records, torn_at


def _superseded(records: list[dict]) -> list[dict]:
    """The records without those a resume superseded (see the module docstring)."""
    out: list[dict] = []
    for r in records:
        if "resume" in r:
            save = r["resume"]
            at = next((i for i in range(len(out) - 1, -1, -1) if out[i].get("saved") == save), None)
            if at is None:
                raise SessionRecordError(f"line {r['n'] + 1} resumes from save {save}, which no line before it "
                                         "records: the record is damaged")
            del out[at + 1:]
        out.append(r)
    return out


def read_session(session_dir: str | Path, torn_tail_ok: bool = False) -> tuple[dict, list[dict]]:
    """(manifest, records in effect) of a recorded session, each record's events as FeedbackEvents. Every line
    is checked (digest, number); a damaged record raises SessionRecordError naming the line. `torn_tail_ok`
    (resume) accepts a torn last line, which is left out."""
    d = Path(session_dir)
    if not (d / MANIFEST).is_file() or not (d / CHUNKS).is_file():
        raise SessionRecordError(f"{d} is not a recorded finetune session (no {MANIFEST} / {CHUNKS}); "
                                f"give the --out directory of a `protamer finetune` session")
    manifest = read_manifest(d)
    if int(manifest.get("record_format", 1)) < FORMAT:
        records = []
        for line in (d / CHUNKS).read_text(encoding="utf-8").splitlines():
            try:
                records.append(json.loads(line))
            except json.JSONDecodeError:
                continue  # format 1 had no digests: a torn last line was skipped
    else:
        records, _ = _read_lines(d / CHUNKS, torn_tail_ok)
        records = _superseded(records)
    for r in records:
        r["events"] = [FeedbackEvent.from_json(json.dumps(e)) for e in r.get("events", [])]
    return manifest, records


def read_manifest(session_dir: str | Path) -> dict:
    path = Path(session_dir) / MANIFEST
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise SessionRecordError(f"{path} cannot be read ({type(e).__name__}: {e}); the session's record is "
                                 "damaged") from None
    if not isinstance(manifest, dict):
        raise SessionRecordError(f"{path} is not a session manifest (a JSON object); the record is damaged")
    return manifest


def repair_torn_tail(session_dir: str | Path) -> bool:
    """Cut a torn last line off session_chunks.jsonl (before a resume appends to it); True if one was cut."""
    path = Path(session_dir) / CHUNKS
    _, torn_at = _read_lines(path, torn_tail_ok=True)
    if torn_at is None:
        return False
    with open(path, "r+b") as fh:
        fh.truncate(torn_at)
        fh.flush()
        os.fsync(fh.fileno())
    return True


def line_count(session_dir: str | Path) -> int:
    """How many whole lines the record holds (the next line's number)."""
    records, _ = _read_lines(Path(session_dir) / CHUNKS, torn_tail_ok=True)
    return len(records)


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
