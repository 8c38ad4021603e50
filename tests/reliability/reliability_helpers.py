"""Helpers shared by the reliability tests (imported by conftest.py and the tests)."""

from __future__ import annotations

import hashlib
from pathlib import Path

from mjx_protamer.agents.ddpg.config import DDPGConfig, PretrainConfig, TrainConfig


def tiny_config() -> PretrainConfig:
    """tests/ddpg's tiny_config shapes (so its compiles are shared), 3 chunks, a checkpoint after each."""
    return PretrainConfig(
        env_name="toy",
        ddpg=DDPGConfig(actor_hidden=(32, 32), critic_hidden=(32, 32), replay_size=1000, batch_size=16),
        train=TrainConfig(num_envs=4, episode_length=25, total_env_steps=600, warmup_env_steps=40, chunk_steps=50,
                          checkpoint_every_chunks=1, eval_episodes=2),
    )


def tree_digest(root: Path) -> str:
    """A digest of every file's path and bytes under root (to show that nothing was changed or lost)."""
    h = hashlib.sha256()
    for p in sorted(Path(root).rglob("*")):
        if p.is_file():
            h.update(str(p.relative_to(root)).encode())
            h.update(p.read_bytes())
    return h.hexdigest()


def run_cli(capsys, *argv) -> tuple[int, list[str]]:
    """`protamer ARGV` in this process: (exit code, the non-empty stderr lines)."""
    from mjx_protamer.cli import main

    code = main([str(a) for a in argv])
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    return code, err
