"""An output directory a command may write into, checked and locked before anything heavy starts.

A command writes only into a directory that is new, empty, or of its own kind when it continues one
(`--resume`); anything else is refused in one line that says what is there. The directory is claimed with an
exclusive lock (`fcntl.flock` on `.protamer.lock`, held for the life of the run and released by the kernel
when the process dies, kill -9 included), and a probe file is written and removed, so an unwritable path
fails in a second, not after minutes of loading. Each claimed directory holds `.protamer.json`: the kind of
run that owns it. `claimed(...)` holds a claim for a `with` block; a run that fails there before writing anything
leaves the directory as it was found (`Claim.abandon`). Pure Python (no JAX).
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import time
from pathlib import Path

from mjx_protamer.atomic import write_atomic
from mjx_protamer.errors import OutputDirError

MARK = ".protamer.json"
LOCK = ".protamer.lock"


def _what_is_there(path: Path) -> str:
    names = sorted(p.name for p in path.iterdir() if p.name not in (LOCK, MARK))
    shown = ", ".join(names[:4]) + (f" and {len(names) - 4} more" if len(names) > 4 else "")
    theirs = kind_of(path)
    if theirs:
        return f"a {theirs} run ({shown})"
    if (path / "config.yaml").is_file() and (path / "checkpoints").is_dir():
        return f"a pretrain run ({shown})"
    return shown


class Claim:
    """A locked output directory; `release()` (or the process's end) unlocks it."""

    def __init__(self, path: Path, fd: int, created: tuple[str, ...] = ()):
        self.path = path
        self._fd = fd
        self._created = created  # what the claim itself made: "dir", LOCK, MARK
        self._found = _listing(path)  # what was there (names, sizes, times), to tell whether a run wrote anything

    def release(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1

    def abandon(self) -> None:
        """Release after a run that ended before writing anything (a refused config, not enough memory, a
        directory of another kind that a `--resume` looked at): it is left as it was found, without the mark,
        lock or directory the claim made. A directory the run wrote into keeps everything, the mark included."""
        if self._fd >= 0 and _listing(self.path) == self._found:
            for name in (MARK, LOCK):
                if name in self._created:
                    (self.path / name).unlink(missing_ok=True)
            if "dir" in self._created:
                try:
                    self.path.rmdir()
                except OSError:
                    pass
        self.release()


def _listing(path: Path) -> dict | None:
    """The directory's own entries (not the claim's files) with their sizes and modification times."""
    try:
        return {p.name: (p.stat().st_size, p.stat().st_mtime_ns) for p in path.iterdir() if p.name not in (LOCK, MARK)}
    except OSError:
        return None


def kind_of(path: str | Path) -> str | None:
    """The kind of run that claimed `path`, or None."""
    try:
        return json.loads((Path(path) / MARK).read_text(encoding="utf-8")).get("kind")
    except (OSError, ValueError, AttributeError):
        return None


@contextlib.contextmanager
def claimed(path: str | Path, kind: str, resume: bool = False, own: tuple[str, ...] = (), resumable: bool = True):
    """`claim` for the life of a `with` block: released at its end; abandoned (`Claim.abandon`) when the block
    raises, so a run refused before it wrote anything leaves no trace."""
    held = claim(path, kind, resume, own, resumable)
    try:
        yield held
    except BaseException:
        held.abandon()
        raise
    held.release()


def claim(path: str | Path, kind: str, resume: bool = False, own: tuple[str, ...] = (),
          resumable: bool = True) -> Claim:
    """Check, create and lock `path` for a run of `kind`. Without `resume` it must be new or empty; with it, a
    directory claimed by a run of `kind` (or holding one of the files in `own`, for runs recorded before
    claims existed). Raises OutputDirError with what is there and what to do (`resumable`: whether the command
    has a --resume to suggest)."""
    path = Path(path)
    flag = "--out"
    if path.exists() and not path.is_dir():
        raise OutputDirError(f"{flag} {path} is a file, not a directory; give a directory")
    if path.is_dir():
        entries = [p for p in path.iterdir() if p.name != LOCK]
        if resume:
            theirs = kind_of(path)
            if theirs != kind and not (theirs is None and any((path / f).exists() for f in own)):
                what = f"a {theirs} run" if theirs else (_what_is_there(path) or "nothing")
                raise OutputDirError(f"{flag} {path} holds {what}, not a {kind} to continue")
        elif entries and not (len(entries) == 1 and entries[0].name == MARK):  # claimed, nothing written
            ours = kind_of(path) == kind or (kind_of(path) is None and any((path / f).exists() for f in own))
            raise OutputDirError(f"{flag} {path} is not empty (it holds {_what_is_there(path)}); give a new or "
                                 f"empty directory" + (" or --resume to continue it" if ours and resumable else ""))
    created = () if path.is_dir() else ("dir",)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise OutputDirError(f"{flag} {path} cannot be created ({e.strerror or e}); give a writable place") from None
    created += () if (path / LOCK).exists() else (LOCK,)
    try:
        fd = os.open(path / LOCK, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as e:
        raise OutputDirError(f"{flag} {path} is not writable ({e.strerror or e}); give a writable place") from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as e:
        os.close(fd)
        if e.errno in (errno.EAGAIN, errno.EACCES):
            raise OutputDirError(f"{flag} {path} is in use by another protamer run; wait for it to end or give "
                                 "another directory") from None
        raise
    probe = path / f".probe{os.getpid()}"
    try:
        with open(probe, "wb") as fh:
            fh.write(b"x" * 4096)
            fh.flush()
            os.fsync(fh.fileno())
        probe.unlink()
        if kind_of(path) != kind:
            write_atomic(path / MARK, json.dumps({"kind": kind, "claimed": time.time()}))
            created += (MARK,)
    except OSError as e:
        os.close(fd)
        probe.unlink(missing_ok=True)
        raise OutputDirError(f"{flag} {path} is not writable ({e.strerror or e}); free some space or give "
                             "another place") from None
    return Claim(path, fd, created)
