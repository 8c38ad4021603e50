"""Config loading and validation: bad values and unknown keys are errors that name the field."""

from __future__ import annotations

from pathlib import Path

import pytest

from mjx_protamer.agents.ddpg.config import DDPGConfig, PretrainConfig
from mjx_protamer.config import ConfigError, load_config

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


@pytest.mark.parametrize(
    "override, field",
    [
        ("ddpg.tau=0", "ddpg.tau"),
        ("ddpg.gamma=1.0", "ddpg.gamma"),
        ("ddpg.lr_final_fraction=0", "ddpg.lr_final_fraction"),
        ("ddpg.lr_decay_from=1.0", "ddpg.lr_decay_from"),
        ("ddpg.batch_size=0", "ddpg.batch_size"),
        ("ddpg.replay_size=10", "ddpg.replay_size"),
        ("ddpg.critic_hidden=[400]", "ddpg.critic_hidden"),
        ("ddpg.noise.kind=pink", "ddpg.noise.kind"),
        ("ddpg.noise.theta=-1", "ddpg.noise.theta"),
        ("train.num_envs=0", "train.num_envs"),
        ("train.updates_per_step=-1", "train.updates_per_step"),
        ("train.chunk_steps=abc", "train.chunk_steps"),
        ("train.warmup_env_steps=10000000", "train.warmup_env_steps"),
        ("env_name=cartpole", "env_name"),
        ("env.k=0", "env.k"),
        ("train.episode_length=500", "train.episode_length"),  # must match env.episode_length
    ],
)
def test_bad_values_name_the_field(override, field):
    with pytest.raises(ConfigError, match=f"'{field}"):
        load_config(PretrainConfig, None, [override])


def test_unknown_key_is_named():
    with pytest.raises(ConfigError, match="ddpg.learning_rate"):
        load_config(PretrainConfig, None, ["ddpg.learning_rate=0.1"])


def test_defaults_are_the_paper_reference():
    d = DDPGConfig()
    assert (d.actor_hidden, d.critic_hidden) == ((400, 300), (400, 300))
    assert (d.actor_lr, d.critic_lr, d.gamma, d.tau, d.batch_size, d.replay_size) == (1e-3, 1e-3, 0.99, 0.001, 64, 100_000)
    assert (d.noise.kind, d.noise.theta, d.noise.sigma) == ("ou", 0.15, 0.6)


@pytest.mark.parametrize("name", ["pretrain.yaml", "paper_single_env.yaml"])
def test_shipped_configs_load(name):
    c = load_config(PretrainConfig, CONFIGS / name)
    assert c.train.iterations * c.train.num_envs >= c.train.total_env_steps


def test_paper_single_env_is_the_paper_setting():
    c = load_config(PretrainConfig, CONFIGS / "paper_single_env.yaml")
    t = c.train
    assert (t.num_envs, t.episode_length, t.updates_per_step) == (1, 1000, 1)
    assert t.total_env_steps == 20 * 1000
    assert c.env_name == "self_touch"
    assert c.ddpg == DDPGConfig()


def test_chunk_rounding():
    c = load_config(PretrainConfig, None, ["train.num_envs=3", "train.total_env_steps=1000", "train.chunk_steps=100",
                                           "train.warmup_env_steps=100"])
    assert c.train.iterations == 400 and c.train.num_chunks == 4


def test_builtin_default_is_configs_pretrain_yaml():
    """`protamer pretrain` without --config (a fresh install has no configs/) runs the batched default."""
    assert load_config(PretrainConfig) == load_config(PretrainConfig, CONFIGS / "pretrain.yaml")
