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
