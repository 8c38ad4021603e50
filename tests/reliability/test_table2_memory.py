"""`reproduce table2` estimates the memory of all its seeds side by side (and what it keeps of every condition)
from abstract shapes before allocating anything, as `pretrain` does: `--seeds 1000` is refused at once in one line
(what it needs, what is free, how many seeds would fit) instead of an XLA out-of-memory error after 37 s."""

from __future__ import annotations

import re
import time

import yaml
from reliability_helpers import run_cli

from mjx_protamer.experiments import memory

GiB = 2 ** 30


def _toy(tmp_path, replay_size: int = 20_000):
    path = tmp_path / "t2.yaml"
    path.write_text(yaml.safe_dump({
        "pretrain": {"env_name": "toy", "ddpg": {"replay_size": replay_size},
                     "train": {"num_envs": 4, "episode_length": 25, "total_env_steps": 600, "warmup_env_steps": 100,
                               "chunk_steps": 50}},
        "feedback": {"teacher": {"rule": [{"signal": "reach", "value": 1.0, "above": 0.5}]}},
        "conditions": [{"name": "DDPG", "channel": "none"}, {"name": "DTK", "channel": "keyboard"}]}))
    return path


def test_seeds_that_cannot_fit_are_refused_before_allocating(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(memory, "available_bytes", lambda devices: 1 * GiB)
    t0 = time.perf_counter()
    code, err = run_cli(capsys, "reproduce", "table2", "--config", _toy(tmp_path), "--seeds", "1000",
                        "--out", tmp_path / "out", "--quiet")
    assert code == 2 and len(err) == 1, err
    line = err[0]
    assert line.startswith("protamer: not enough memory: reproduce table2 (2 conditions, 2 at a time) for 1,000 "
                           "seeds needs about "), line
    assert "learner state and replay" in line and "feedback state" in line and "but 1.00 GiB is available" in line
    assert "lower --seeds (about " in line
    assert "or lower ddpg.replay_size, train.num_envs or train.eval_episodes, or train fewer conditions at once " \
           "(--conditions-at-once 1)" in line
    # the seeds said to fit do fit with the headroom, one more does not
    fit = int(re.search(r"about ([\d,]+) would fit", line).group(1).replace(",", ""))
    assert time.perf_counter() - t0 < 30  # no compile, nothing allocated
    assert not (tmp_path / "out").exists()  # the directory claimed for it is gone again
    code, err = run_cli(capsys, "reproduce", "table2", "--config", _toy(tmp_path), "--seeds", str(fit + 1),
                        "--out", tmp_path / "out", "--quiet")
    assert code == 2 and "not enough memory" in err[0], err
    from mjx_protamer.experiments.env_factory import make_env
    from mjx_protamer.experiments.feedback_train import make_feedback_train
    from mjx_protamer.experiments.table2 import load_table2_config, memory_per_seed

    cfg = load_table2_config(_toy(tmp_path))
    env = make_env(cfg.pretrain)
    parts = memory_per_seed(cfg, env, make_feedback_train(cfg.pretrain, env, cfg.feedback, cfg.batched), at_once=2)
    assert memory.check_seeds_fit(parts, fit, [], "t", "h") == fit * sum(parts.values())


def test_the_estimate_counts_every_seed_and_the_replay(tmp_path):
    from mjx_protamer.experiments.env_factory import make_env
    from mjx_protamer.experiments.feedback_train import make_feedback_train
    from mjx_protamer.experiments.table2 import load_table2_config, memory_per_seed

    small, big = (load_table2_config(_toy(tmp_path, n)) for n in (20_000, 200_000))
    parts = {}
    for name, cfg in (("small", small), ("big", big)):
        env = make_env(cfg.pretrain)
        ft = make_feedback_train(cfg.pretrain, env, cfg.feedback, cfg.batched)
        parts[name] = memory_per_seed(cfg, env, ft)
    # two conditions trained at once hold two learners, feedback states and test episodes; what is kept of every
    # condition until the end does not grow
    two = memory_per_seed(big, env, ft, at_once=2)
    assert all(two[k] == 2 * parts["big"][k] for k in ("learner state and replay", "feedback state", "test episodes"))
    assert two["kept per condition"] == parts["big"]["kept per condition"]
    row = (parts["big"]["learner state and replay"] - parts["small"]["learner state and replay"]) / 180_000
    assert row >= 4 * (2 * env.observation_size + env.action_size + 2)  # obs, next obs, action, reward, done
    assert parts["big"]["feedback state"] == parts["small"]["feedback state"]
    assert all(v >= 0 for v in parts["small"].values()) and parts["small"]["test episodes"] > 0


def test_the_built_in_default_with_1000_seeds_is_refused_at_once(tmp_path, capsys, monkeypatch):
    """The issue's case: the built-in default (self-touch) and --seeds 1000 on a machine with 20 GiB free."""
    monkeypatch.setattr(memory, "available_bytes", lambda devices: 20 * GiB)
    code, err = run_cli(capsys, "reproduce", "table2", "--seeds", "1000", "--out", tmp_path / "out", "--quiet")
    assert code == 2 and len(err) == 1 and "not enough memory" in err[0] and "lower --seeds (about" in err[0], err
    assert not (tmp_path / "out").exists()
