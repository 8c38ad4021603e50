"""Pick an offscreen OpenGL backend for MuJoCo's renderer: EGL (Mesa) first, OSMesa as the fallback.

MuJoCo reads MUJOCO_GL once, when `mujoco` is first imported, so the choice is made by probing each
backend in a short child process and then setting MUJOCO_GL (children, e.g. the live view process,
inherit it). In a process that imported mujoco before the choice, the renderer's context class is
rebound to the chosen backend's. A MUJOCO_GL set by the user wins.
"""

from __future__ import annotations

import os
import subprocess
import sys

BACKENDS = ("egl", "osmesa")
INSTALL_HINT = ("install Mesa's EGL or OSMesa (Debian: apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri "
                "libosmesa6)")

_PROBE = """
import mujoco
m = mujoco.MjModel.from_xml_string('<mujoco><worldbody><geom size="1"/></worldbody></mujoco>')
r = mujoco.Renderer(m, 16, 16)
r.update_scene(mujoco.MjData(m))
r.render()
r.close()
"""

_chosen: str | None = None


class GLUnavailable(RuntimeError):
    """No offscreen OpenGL backend works on this machine; the message says what to install."""


def _works(backend: str) -> bool:
    env = {**os.environ, "MUJOCO_GL": backend, "PYOPENGL_PLATFORM": backend}
    try:
        p = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, timeout=60)
    except subprocess.TimeoutExpired:
        return False
    return p.returncode == 0


def choose_backend() -> str:
    """The backend in use from now on ('egl' or 'osmesa', or the user's MUJOCO_GL); raises GLUnavailable."""
    global _chosen
    if _chosen is not None:
        return _chosen
    wanted = os.environ.get("MUJOCO_GL", "").strip().lower()
    candidates = (wanted,) if wanted else BACKENDS
    for backend in candidates:
        if _works(backend):
            os.environ["MUJOCO_GL"] = backend
            os.environ.setdefault("PYOPENGL_PLATFORM", backend)
            _bind(backend)
            _chosen = backend
            return backend
    raise GLUnavailable(f"no offscreen OpenGL for MuJoCo (tried MUJOCO_GL={', '.join(candidates)}); "
                        f"{INSTALL_HINT}")


def _bind(backend: str) -> None:
    """Point an already imported mujoco at the chosen backend (its import read MUJOCO_GL too early)."""
    if "mujoco" not in sys.modules:
        return
    from mujoco.rendering.classic import gl_context

    if backend == "egl":
        from mujoco.egl import GLContext
    elif backend == "osmesa":
        from mujoco.osmesa import GLContext
    else:
        return
    gl_context.GLContext = GLContext
