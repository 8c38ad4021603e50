"""`from mjx_protamer.quiet_mjx import mjx`: mujoco.mjx without its "Failed to import warp" lines.

MuJoCo-MJX 3.17 prints `Failed to import warp: ...` and `Failed to import mujoco_warp: ...` on stdout on
every import when the optional NVIDIA Warp backend is not installed. We never use that backend, and the
lines cluttered every command (and `--json` output). Only those two lines are dropped; anything else the
import prints passes through. Import mujoco.mjx through here (the first import is the one that prints).
"""

from __future__ import annotations

import contextlib
import io
import sys

_NOISE = ("Failed to import warp:", "Failed to import mujoco_warp:")


def _import_quietly():
    captured = io.StringIO()
    with contextlib.redirect_stdout(captured):
        from mujoco import mjx
    for line in captured.getvalue().splitlines(keepends=True):
        if not line.startswith(_NOISE):
            sys.stdout.write(line)
    return mjx


mjx = _import_quietly()
