"""Shared, session-scoped fixtures: few distinct compiled shapes, tiny sizes (compiles dominate on 2 cores)."""

from __future__ import annotations

import pytest
from ddpg_helpers import learning_config


@pytest.fixture(scope="session")
def learned_run(tmp_path_factory):
    """One uninterrupted pretrain run on the toy env (shared by the learning, resume and CLI tests)."""
    from mjx_protamer.experiments.pretrain import run_pretrain

    out = tmp_path_factory.mktemp("learned")
    config = learning_config()
    result = run_pretrain(config, out, progress=False)
    return config, out, result
