"""Append-only JSON-lines files that survive a kill at any moment.

A process killed in the middle of a write leaves a torn last line (no newline at its end). Appending
after it would glue the next record onto it and both would be lost to readers, so `open_append` first
ends such a line (readers then skip that one line, and only it). `read` returns the records and how many
lines it could not parse, so callers can say so instead of skipping silently.

Pure Python (no JAX): the audio front end and the learner both use it.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import IO


def open_append(path: str | Path) -> IO[str]:
    """Open `path` for appending, ending a torn last line first so the next record starts on a line of its own."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.exists() and path.stat().st_size > 0:
        with open(path, "rb") as fh:
            fh.seek(-1, os.SEEK_END)
            torn = fh.read(1) != b"\n"
        if torn:
            with open(path, "ab") as fh:
                fh.write(b"\n")
                fh.flush()
                os.fsync(fh.fileno())
    return open(path, "a", encoding="utf-8")


def append(fh: IO[str], record: dict) -> None:
    """Write one record as a line and make it durable (flushed and fsynced) before returning."""
    fh.write(json.dumps(record, sort_keys=True) + "\n")
    fh.flush()
    os.fsync(fh.fileno())


def read(path: str | Path) -> tuple[list[dict], int]:
    """(records, skipped): every line that parses as a JSON object, and the count of lines that do not
    (torn writes, or damage); blank lines are neither."""
    records, skipped = [], 0
    with open(path, "rb") as fh:
        for raw in fh:
            line = raw.decode("utf-8", errors="replace").strip()
            if not line:
                continue
            try:
                record = json.loads(line)
            except json.JSONDecodeError:
                skipped += 1
                continue
            if isinstance(record, dict):
                records.append(record)
            else:
                skipped += 1
    return records, skipped


def read_reporting(path: str | Path) -> list[dict]:
    """The records of `path`; when lines had to be skipped, one note on stderr says how many."""
    records, skipped = read(path)
    if skipped:
        print(f"note: {path}: skipped {skipped} unreadable line(s) (a write torn by a crash, or damage); "
              f"read {len(records)} record(s)", file=sys.stderr)
    return records
