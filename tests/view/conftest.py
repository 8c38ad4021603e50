"""View tests: offscreen OpenGL is chosen once, before any test renders (EGL, else OSMesa)."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def gl_backend():
    from mjx_protamer.view.gl import GLUnavailable, choose_backend

    try:
        return choose_backend()
    except GLUnavailable as e:
        pytest.skip(f"{e} (scripts/test.sh installs them as root)")


@pytest.fixture(scope="session")
def infant(gl_backend):
    from mjx_protamer.view.infant_scene import InfantScene

    scene = InfantScene()
    yield scene
    scene.close()
