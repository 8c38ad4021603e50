"""Shared test setup: a persistent JAX compilation cache so repeated runs skip most compiles.

JAX compiles are 10-50 s per shape on a 2-core CPU: tests share fixtures (see each folder's conftest)
and keep the number of distinct compiled shapes small.
"""

import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")
os.environ.setdefault(
    "JAX_COMPILATION_CACHE_DIR", os.path.join(os.path.expanduser("~"), ".cache", "mjx_protamer", "jax")
)
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "1")


import subprocess  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import pytest  # noqa: E402


@pytest.fixture(scope="session")
def toy_run(tmp_path_factory):
    """A tiny toy-env pretrain run (about 25 s), shared by the finetune and view tests."""
    out = tmp_path_factory.mktemp("toy") / "pt"
    env = {**os.environ, "JAX_PLATFORMS": "cpu", "PYTHONUNBUFFERED": "1"}
    subprocess.run([sys.executable, "-m", "mjx_protamer.cli", "pretrain", "--out", str(out), "--no-progress",
                    "--set", "env_name=toy", "--set", "ddpg.actor_hidden=[16]", "--set", "ddpg.critic_hidden=[16,16]",
                    "--set", "train.num_envs=4", "--set", "train.episode_length=50",
                    "--set", "train.total_env_steps=1200", "--set", "train.warmup_env_steps=400",
                    "--set", "train.chunk_steps=100"],
                   check=True, capture_output=True, env=env, cwd=Path(__file__).resolve().parents[1], timeout=300)
    return out
