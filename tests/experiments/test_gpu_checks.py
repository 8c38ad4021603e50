"""scripts/gpu_checks.sh refuses, in one line and before anything heavy, to file CPU figures as GPU ones."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "gpu_checks.sh"


def _run(*args, tmp_path):
    env = dict(os.environ, PYTHON=sys.executable, JAX_PLATFORMS="cpu")
    return subprocess.run(["bash", str(SCRIPT), *args], capture_output=True, text=True, env=env, timeout=120,
                          cwd=tmp_path)


def test_gpu_checks_refuse_a_cpu_without_allow_cpu(tmp_path):
    out = tmp_path / "out"
    r = _run(str(out), tmp_path=tmp_path)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "JAX sees no GPU" in lines[0] and "--allow-cpu" in lines[0]
    assert not out.exists()  # nothing started


@pytest.mark.parametrize("args, says", [((), "give an output folder"), (("--fast", "x"), "unknown option --fast")])
def test_gpu_checks_explain_bad_arguments(tmp_path, args, says):
    r = _run(*args, tmp_path=tmp_path)
    assert r.returncode == 2 and says in r.stderr and len(r.stderr.strip().splitlines()) == 1
