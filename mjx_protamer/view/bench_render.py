"""Offscreen rendering speed of the infant, per OpenGL backend, as JSON:

    python -m mjx_protamer.view.bench_render [--frames 60] [--repeats 3] [--size 480]

Each backend runs in its own child process (MUJOCO_GL is read once per process). A frame is what the
live view and `protamer render` make: pose, touched regions (native contacts), the rendered image with
regions lit, and a JPEG (what the page receives). Reported: frames/s, median over the repeats.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

_CHILD = """
import json, sys, time
import numpy as np
from mjx_protamer.view.infant_scene import InfantScene
from mjx_protamer.view.playback import _jpeg
frames, repeats, size = map(int, sys.argv[1:4])
scene = InfantScene(width=size, height=size)
poses = scene.model.start_qpos
rates = []
for r in range(repeats + 1):
    t = time.perf_counter()
    for i in range(frames):
        pose = poses[i % len(poses)]
        _jpeg(scene.frame(pose, scene.touched(pose)), 80)
    if r:  # the first round warms up (GL context, shaders)
        rates.append(frames / (time.perf_counter() - t))
scene.close()
print(json.dumps(rates))
"""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--size", type=int, default=480)
    args = ap.parse_args(argv)
    out = {"size": args.size, "frames": args.frames, "repeats": args.repeats, "cpus": os.cpu_count(),
           "load_average": os.getloadavg()[0], "backends": {}}
    for backend in ("egl", "osmesa"):
        env = {**os.environ, "MUJOCO_GL": backend, "PYOPENGL_PLATFORM": backend}
        t = time.time()
        p = subprocess.run([sys.executable, "-c", _CHILD, str(args.frames), str(args.repeats), str(args.size)],
                           env=env, capture_output=True, text=True, timeout=900)
        if p.returncode != 0:
            out["backends"][backend] = {"error": (p.stderr.strip().splitlines() or ["failed"])[-1]}
            continue
        rates = json.loads(p.stdout.strip().splitlines()[-1])
        out["backends"][backend] = {"fps_median": round(statistics.median(rates), 2),
                                    "fps_runs": [round(r, 2) for r in rates], "wall_s": round(time.time() - t, 1)}
    print(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
