"""Configs shared by the DDPG tests (imported by conftest.py, the tests and the multi-device subprocess)."""

from __future__ import annotations

import dataclasses

from mjx_protamer.agents.ddpg.config import DDPGConfig, NoiseConfig, PretrainConfig, TrainConfig


def tiny_config(**train) -> PretrainConfig:
    """Toy env, small networks: for the learner's plumbing (not its learning)."""
    base = dict(num_envs=4, episode_length=25, total_env_steps=400, warmup_env_steps=40, chunk_steps=50)
    base.update(train)
    return PretrainConfig(
        env_name="toy",
        ddpg=DDPGConfig(actor_hidden=(32, 32), critic_hidden=(32, 32), replay_size=1000, batch_size=16),
        train=TrainConfig(**base),
    )


def learning_config() -> PretrainConfig:
    """Toy env with the reference 400-300 networks; DDPG solves it in ~12k env steps (about 10 s)."""
    return PretrainConfig(
        env_name="toy",
        ddpg=DDPGConfig(tau=0.005, replay_size=20_000, noise=NoiseConfig(kind="gaussian", sigma=0.3)),
        train=TrainConfig(num_envs=8, episode_length=25, total_env_steps=12_000, warmup_env_steps=800,
                          chunk_steps=250, updates_per_step=1, eval_episodes=10),
    )


def replace_train(config: PretrainConfig, **changes) -> PretrainConfig:
    return dataclasses.replace(config, train=dataclasses.replace(config.train, **changes))
