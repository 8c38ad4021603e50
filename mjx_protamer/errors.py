"""Errors the command line reports as one line with exit code 2 (besides ConfigError in `config`).

Pure Python, no JAX: `cli.main` catches them without importing the learner.
"""

from __future__ import annotations


class CheckpointError(ValueError):
    """A checkpoint cannot be used; the one-line message says which and what to do."""


class CheckpointDamaged(CheckpointError):
    """The checkpoint's files are missing, unfinished or corrupt (an earlier one may still be intact)."""


class OutOfMemoryEstimate(ValueError):
    """A run would need more memory than the machine has; the message gives both and what to lower."""


class SessionRecordError(ValueError):
    """A live session's record (session.json, session_chunks.jsonl) cannot be used as it is; the message names
    the file and line."""


class OutputDirError(ValueError):
    """An output directory cannot be used (not empty, another kind of run's, locked, not writable); the message
    says what is there and what to give instead."""


class DistributedError(RuntimeError):
    """A run on several processes cannot go on: a process did not join, died, or the hand-off of the results
    failed; the message names the process and what is kept. Exit code 1."""


class WriteFailed(RuntimeError):
    """A run could not write its files (a full disk, no permission); the message names the path and the last good
    checkpoint, which `--resume` continues from. Exit code 1."""


def write_failed(e: OSError, out, last_good: str, again: str) -> WriteFailed:
    """The one line of a run stopped by a failed write: the path and why, what is kept, how to go on."""
    path = e.filename or out
    why = e.strerror or str(e) or type(e).__name__
    return WriteFailed(f"{path}: {why}; {last_good}; free some space (or fix the permissions), then {again}")
