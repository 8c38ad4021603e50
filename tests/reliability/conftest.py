"""One tiny saved run shared by the reliability tests (toy env, the DDPG tests' compiled shapes: ~5 s).

Tests that damage it work on a copy (`run_copy`); `tree_digest` says whether a directory changed, so each
test can assert that a refusal lost nothing.
"""

from __future__ import annotations

import shutil

import pytest
from reliability_helpers import tiny_config


@pytest.fixture(scope="session")
def tiny_run(tmp_path_factory):
    """(config, run dir, result) of an uninterrupted run; checkpoints 2 and 3 are kept (max_to_keep=2)."""
    from mjx_protamer.experiments.pretrain import run_pretrain

    out = tmp_path_factory.mktemp("reliability") / "run"
    config = tiny_config()
    result = run_pretrain(config, out, progress=False, final_eval=False)
    assert result["finished"] and result["chunks_done"] == 3
    return config, out, result


@pytest.fixture
def run_copy(tiny_run, tmp_path):
    """A copy of the tiny run that a test may damage."""
    dest = tmp_path / "run"
    shutil.copytree(tiny_run[1], dest)
    return dest
