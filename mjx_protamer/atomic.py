"""Files replaced atomically: a kill or a power cut at any moment leaves the old content or the new, never a
torn file under the name.

The new content goes to a hidden temporary file in the same folder (a rename is atomic only within one file
system), which is flushed to disk before it is renamed over the target; then the folder is synced, so the
rename itself is durable. A write that fails removes its temporary file and raises the OSError unchanged,
so each caller reports a full disk or a missing permission as it always has. `replacing` yields the temporary
path to writers that want a path of their own (matplotlib's savefig, a video encoder, a CSV writer); its
name keeps the target's suffix, from which they pick the format.

Pure Python (no JAX): every writer of the package, whatever its layer, goes through it.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Iterator


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextlib.contextmanager
def replacing(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside `path`; when the block ends normally, what was written there replaces
    `path` (durably); when it raises, the temporary file is removed and `path` is left as it was."""
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.tmp{os.getpid()}{path.suffix}")
    try:
        yield tmp
        _fsync(tmp)  # the writer closed it: its bytes reach the disk before the name points at them
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync(path.parent)


def write_atomic(path: str | Path, data: str | bytes) -> Path:
    """Replace `path` with `data` (text as UTF-8)."""
    with replacing(path) as tmp:
        tmp.write_bytes(data.encode() if isinstance(data, str) else data)
    return Path(path)
