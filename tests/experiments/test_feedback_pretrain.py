"""`protamer pretrain --feedback simulated:KIND` through the CLI function, on the toy env (tiny, one shape).

The simulated teacher wants the point to move up (+1 when action[1] > 0.2, -1 when < -0.2); checks: events
are given and credited, the reward model updates (params change), the CSV/TensorBoard rows carry the
feedback counts and r_hat stats, feedback.jsonl holds every event (append + fsync), eval.json is written,
and resume with feedback is exact.
"""

import json

import numpy as np
import pytest
import yaml

from mjx_protamer.cli import main
from mjx_protamer.human.queue import FeedbackLog

PRETRAIN = {
    "env_name": "toy",
    "ddpg": {"actor_hidden": [16], "critic_hidden": [16, 16], "replay_size": 2000, "batch_size": 16,
             "reward_beta": 1.0},
    "train": {"num_envs": 4, "episode_length": 25, "total_env_steps": 1200, "warmup_env_steps": 100,
              "chunk_steps": 50, "checkpoint_every_chunks": 2, "eval_episodes": 3},
}
FEEDBACK = {
    "dt": 0.05,
    "credit": {"scheme": "step_window", "window_steps": 15, "decay": 0.9, "min_interval_steps": 2},
    "reward_model": {"hidden": [16]},
    "teacher": {"min_gap_steps": 2, "give_rate": 0.5,
                "rule": [{"signal": "action:1", "value": 1.0, "above": 0.2},
                         {"signal": "action:1", "value": -1.0, "below": -0.2}],
                "channel": {"kind": "keyboard"}},
}


def write_configs(tmp_path):
    pre, fb = tmp_path / "toy.yaml", tmp_path / "fb.yaml"
    pre.write_text(yaml.safe_dump(PRETRAIN))
    fb.write_text(yaml.safe_dump({"feedback": FEEDBACK}))
    return pre, fb


def csv_rows(path):
    import csv

    with open(path) as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def keyboard_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("fbpre")
    pre, fb = write_configs(tmp)
    out = tmp / "run"
    rc = main(["pretrain", "--config", str(pre), "--feedback", "simulated:keyboard", "--feedback-config", str(fb),
               "--out", str(out), "--no-progress"])
    assert rc == 0
    return tmp, out


def test_feedback_is_given_credited_and_learned(keyboard_run):
    tmp, out = keyboard_run
    rows = csv_rows(out / "metrics.csv")
    last = rows[-1]
    for key in ("feedback_events", "feedback_total", "credited_rows", "rm_loss", "r_hat_mean", "r_hat_std"):
        assert key in last
    assert float(last["feedback_total"]) > 20
    assert float(last["credited_rows_total"]) > float(last["feedback_total"])
    assert float(last["rm_updates_total"]) > 0
    assert sum(float(r["feedback_dropped"]) for r in rows) == 0
    events = FeedbackLog.read(out / "feedback.jsonl")
    assert len(events) == int(float(last["feedback_total"]))
    assert all(e.source == "simulated" and e.details["channel"] == "keyboard" for e in events)
    # every event judged an earlier step than it arrived at, and the values are the keyboard's +-1
    assert all(e.details["about_step"] < e.details["arrival_step"] for e in events)
    assert {e.value for e in events} <= {-1.0, 1.0}
    # the reward model moved away from its initialisation (same seed, DDPG alone leaves it there)
    import jax
    import jax.numpy as jnp

    from mjx_protamer.experiments import saved_reward_model
    from mjx_protamer.human.reward_model import RewardMLP, RewardModelConfig
    saved = saved_reward_model.load(out, saved_reward_model.like(RewardModelConfig(hidden=(16,)), 6, 2))
    assert int(saved["updates"]) == int(float(last["rm_updates_total"])) > 0
    init = RewardMLP((16,)).init(jax.random.split(jax.random.fold_in(jax.random.PRNGKey(0), 0x7A3E))[0],
                                 jnp.zeros((1, 6)), jnp.zeros((1, 2)))
    k0 = saved["params"]["params"]["Dense_0"]["kernel"]
    assert not np.allclose(np.asarray(k0), np.asarray(init["params"]["Dense_0"]["kernel"]))
    # the model learned the teacher's direction: up is better than down
    from mjx_protamer.human.reward_model import reward_fn
    p = saved["params"]
    obs = np.zeros((1, 6), np.float32)
    up, down = (float(reward_fn((16,))(p, obs, np.array([[0.0, s]], np.float32))[0]) for s in (1.0, -1.0))
    assert up > down
    ev = json.loads((out / "eval.json").read_text())
    assert ev["episodes"] == 3 and "unique_regions" in ev
    assert list((out / "tb").iterdir())


def test_resume_with_feedback_is_exact(keyboard_run):
    tmp, full = keyboard_run
    pre, fb = write_configs(tmp)
    out = tmp / "resumed"
    args = ["pretrain", "--config", str(pre), "--feedback", "simulated:keyboard", "--feedback-config", str(fb),
            "--out", str(out), "--no-progress"]
    from mjx_protamer.commands.train import _feedback_setup
    from mjx_protamer.experiments.pretrain import run_pretrain

    setup, config = _feedback_setup("simulated:keyboard", fb, pre, [], [])
    run_pretrain(config, out, progress=False, max_chunks=3, feedback=setup)  # "killed" after chunk 3 (ckpt 2)
    assert main(args + ["--resume"]) == 0
    a, b = csv_rows(full / "metrics.csv"), csv_rows(out / "metrics.csv")
    assert len(a) == len(b)
    for ra, rb in zip(a, b):
        for k in ("feedback_total", "credited_rows_total", "episode_return", "r_hat_mean"):
            assert ra[k] == rb[k], k
    ea = [(e.t_start, e.value) for e in FeedbackLog.read(full / "feedback.jsonl")]
    eb = [(e.t_start, e.value) for e in FeedbackLog.read(out / "feedback.jsonl")]
    assert ea == eb


@pytest.mark.parametrize("kind", ["keyboard", "prosody", "speech"])
def test_feedback_without_a_feedback_section_runs_the_shipped_feedback_kind_yaml(kind):
    """`pretrain --feedback simulated:KIND` with no feedback section in --config takes configs/feedback_KIND.yaml's
    (the channel's credit, watched silences at 1/32, a bounded reward model), read from the package."""
    from mjx_protamer.commands.train import _feedback_setup
    from mjx_protamer.config import shipped_config
    from mjx_protamer.human.feedback_config import load_feedback_config

    setup, _ = _feedback_setup(f"simulated:{kind}", None, None, [], ["feedback.credit.decay=0.8"])
    shipped = load_feedback_config(shipped_config(f"feedback_{kind}.yaml"), ["feedback.credit.decay=0.8"]).feedback
    assert setup.kind == kind and setup.config == shipped and setup.config.teacher.channel.kind == kind
    assert (setup.config.credit.silence_weight, setup.config.reward_model.bounded) == (0.03, True)


def test_feedback_flag_errors_name_the_problem(tmp_path, capsys):
    pre, fb = write_configs(tmp_path)
    assert main(["pretrain", "--config", str(pre), "--feedback", "keyboard", "--out", str(tmp_path / "x")]) == 2
    assert "simulated:keyboard" in capsys.readouterr().err
    assert main(["pretrain", "--config", str(pre), "--feedback-config", str(fb), "--out", str(tmp_path / "y")]) == 2


def test_teacher_signals_in_jit():
    from mjx_protamer.config import ConfigError
    from mjx_protamer.human.teachers import signal_columns as _signal_columns

    cols = _signal_columns(("reach", "obs:3", "action:1", "obs_norm:0:2,4:5"), ("distance", "effort", "reach"), 6, 2)
    assert cols == (("terms", 2), ("obs", 3), ("action", 1), ("obs_norm", (0, 1, 4)))
    for bad in ("arm_speed", "obs_norm:4:9", "obs:6"):
        with pytest.raises(ConfigError, match="feedback.teacher.rule"):
            _signal_columns((bad,), ("distance",), 6, 2)
