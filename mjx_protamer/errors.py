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
