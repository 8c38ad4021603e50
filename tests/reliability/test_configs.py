"""Every probed config failure: a one-line error and exit code 2 before anything is written or allocated;
YAML 1.2 numbers accepted."""

from __future__ import annotations

import pytest
from reliability_helpers import run_cli

from mjx_protamer.agents.ddpg.config import PretrainConfig
from mjx_protamer.config import load_config

BAD_FILES = {
    "empty": ("", "is empty"),
    "only a comment": ("# nothing here\n", "is empty"),
    "a list": ("- pretrain\n- feedback\n", "must hold a mapping"),
    "invalid YAML": ("pretrain: [1,\n", "is not valid YAML (line 2"),
    "a section that is a list": ("{section}: [1, 2]\n", "mapping"),
}

# (command line with {f} for the file and {out} for the output, a section of that file)
COMMANDS = {
    "pretrain --config": (["pretrain", "--config", "{f}", "--out", "{out}"], "ddpg"),
    "pretrain --feedback-config": (["pretrain", "--feedback", "simulated:keyboard", "--feedback-config", "{f}",
                                    "--out", "{out}"], "feedback"),
    "reproduce table2 --config": (["reproduce", "table2", "--config", "{f}", "--out", "{out}"], "feedback"),
    "calibrate --config (voice)": (["calibrate", "--config", "{f}", "--out", "{out}"], "prosody"),
}


@pytest.mark.parametrize("command", list(COMMANDS))
@pytest.mark.parametrize("bad", list(BAD_FILES))
def test_a_bad_config_file_is_refused_in_one_line(tmp_path, capsys, command, bad):
    argv, section = COMMANDS[command]
    text, says = BAD_FILES[bad]
    text = text.format(section=section)
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    out = tmp_path / "out"
    code, err = run_cli(capsys, *[a.format(f=path, out=out) for a in argv])
    assert code == 2
    assert len(err) == 1 and says in err[0], err
    assert not out.exists()
    assert path.read_text() == text


NON_FINITE_OR_OUT_OF_RANGE = [
    ("ddpg.reward_alpha=.nan", "'ddpg.reward_alpha': must be a finite number"),
    ("ddpg.reward_beta=.inf", "'ddpg.reward_beta': must be a finite number"),
    ("ddpg.noise.mu=-.inf", "'ddpg.noise.mu': must be a finite number"),
    ("env.reward.contact_gain=.nan", "'env.reward.contact_gain': must be a finite number"),
    ("env.freeze_speed=.inf", "'env.freeze_speed': must be a finite number"),
    ("train.updates_per_step=0", "'train.updates_per_step': must be >= 1"),
    ("ddpg.reward_beta=-1", "'ddpg.reward_beta': must be >= 0"),
]


@pytest.mark.parametrize("override, says", NON_FINITE_OR_OUT_OF_RANGE, ids=[o for o, _ in NON_FINITE_OR_OUT_OF_RANGE])
def test_non_finite_and_out_of_range_numbers_are_refused(tmp_path, capsys, override, says):
    code, err = run_cli(capsys, "pretrain", "--set", override, "--out", tmp_path / "out")
    assert code == 2 and len(err) == 1 and says in err[0], err
    assert not (tmp_path / "out").exists()


def test_non_finite_numbers_are_refused_in_a_feedback_section(tmp_path, capsys):
    code, err = run_cli(capsys, "pretrain", "--feedback", "simulated:prosody", "--set", "feedback.dt=.nan",
                        "--out", tmp_path / "out")
    assert code == 2 and len(err) == 1 and "'feedback.dt': must be a finite number" in err[0], err


@pytest.mark.parametrize("text", ["1e-4", "1E-4", "1.0e-4", "0.0001"])
def test_yaml_1_2_numbers_are_numbers(text):
    assert load_config(PretrainConfig, None, [f"ddpg.actor_lr={text}"]).ddpg.actor_lr == pytest.approx(1e-4)


def test_yaml_1_2_numbers_in_a_file(tmp_path):
    (tmp_path / "c.yaml").write_text("ddpg:\n  critic_lr: 3e-4\n  actor_lr: 5E-5\n")
    cfg = load_config(PretrainConfig, tmp_path / "c.yaml")
    assert (cfg.ddpg.critic_lr, cfg.ddpg.actor_lr) == (3e-4, 5e-5)


def test_resume_into_a_directory_without_a_checkpoint_is_refused(tmp_path, capsys):
    code, err = run_cli(capsys, "pretrain", "--resume", "--out", tmp_path / "new", "--set", "env_name=toy",
                        "--set", "train.episode_length=25")
    assert code == 2 and len(err) == 1
    assert "--resume: " in err[0] and "holds no checkpoint to continue from" in err[0], err
    assert not (tmp_path / "new").exists()


def test_resume_of_a_run_killed_before_its_first_checkpoint_is_refused(tiny_run, tmp_path, capsys):
    import shutil

    run = tmp_path / "run"
    shutil.copytree(tiny_run[1], run)
    for step in (run / "checkpoints").iterdir():
        shutil.rmtree(step)
    code, err = run_cli(capsys, "pretrain", "--resume", "--out", run, "--config", run / "config.yaml")
    assert code == 2 and "holds no checkpoint to continue from" in err[0]
    assert (run / "metrics.csv").is_file()  # what the killed run logged is still there


def test_a_replay_that_cannot_fit_is_refused_before_allocating(tmp_path, capsys):
    """10^11 transitions (terabytes): refused up front with the estimate, not an XLA out-of-memory later."""
    code, err = run_cli(capsys, "pretrain", "--set", "env_name=toy", "--set", "train.episode_length=25",
                        "--set", "ddpg.replay_size=100000000000", "--out", tmp_path / "out")
    assert code == 2 and len(err) == 1, err
    assert err[0].startswith("protamer: not enough memory: the run's state needs about ")
    assert "100,000,000,000 transitions" in err[0] and "lower ddpg.replay_size (about " in err[0]
    assert not (tmp_path / "out").exists()


def test_the_memory_estimate_is_the_state_size():
    """The estimate is the bytes of the state's arrays, from their shapes alone."""
    import jax
    import jax.numpy as jnp

    from mjx_protamer.experiments import memory

    like = jax.eval_shape(lambda: {"replay": jnp.zeros((1000, 6)), "n": jnp.zeros((), jnp.int32)})
    assert memory.tree_bytes(like) == 1000 * 6 * 4 + 4
    assert 0 < memory.host_available_bytes() < 2**50


def test_env_freeze_speed_is_the_freeze_metric_threshold(tiny_run):
    """It was validated but unread (the metric used a hard-coded 1 rad/s)."""
    import dataclasses

    from mjx_protamer.envs.toy import PointReachEnv
    from mjx_protamer.experiments.evaluate import evaluate

    config, _, result = tiny_run
    actor = result["state"].actor_params
    never = dataclasses.replace(config, env=dataclasses.replace(config.env, freeze_speed=1e-9))
    always = dataclasses.replace(config, env=dataclasses.replace(config.env, freeze_speed=1e9))
    env = PointReachEnv(config.toy)
    assert evaluate(never, env, actor, 2, 0)["freeze_ratio"] < 0.5
    assert evaluate(always, env, actor, 2, 0)["freeze_ratio"] == 1.0


# --- one run schema (FeedbackRunConfig) and the typed resume check ---------------------------------------------


def test_every_command_reads_a_run_s_sections_alike(tmp_path):
    """A feedback file's sections (batched among them) load in `finetune`'s loader and as table2's run sections to
    the same values; a table2 file may hold a live session's sections too."""
    from mjx_protamer.config import shipped_config
    from mjx_protamer.experiments.table2 import load_table2_config
    from mjx_protamer.human.feedback_config import load_feedback_config

    path = tmp_path / "run.yaml"
    path.write_text(shipped_config("feedback_keyboard.yaml").read_text()
                    + "batched:\n  rows_per_event: 8\ncoach:\n  window: 5\n")
    run, table2 = load_feedback_config(path), load_table2_config(path)
    assert (run.batched.rows_per_event, run.coach.window) == (8, 5)
    for section in ("pretrain", "feedback", "batched", "session", "coach"):
        assert getattr(table2, section) == getattr(run, section), section


@pytest.mark.parametrize("argv, says", [
    (["pretrain", "--feedback", "simulated:keyboard", "--set", "coach.window=abc"],
     "config field 'coach.window': expected an integer"),
    (["pretrain", "--feedback", "simulated:keyboard", "--set", "session.no_such_knob=1"],
     "unknown config key(s) session.no_such_knob"),
    (["pretrain", "--feedback", "simulated:keyboard", "--set", "batched.rows_per_event=0"],
     "config field 'batched.rows_per_event': must be >= 1"),
    (["pretrain", "--feedback", "simulated:keyboard", "--set", "pretrain.train.num_envs=x"],
     "config field 'pretrain.train.num_envs': expected an integer"),
    (["pretrain", "--set", "coach.window=3"], "need --feedback simulated:KIND"),
    (["reproduce", "table2", "--set", "coach.window=0"], "config field 'coach.window': must be >= 1"),
    (["reproduce", "table2", "--set", "session.spare_fraction=2"], "config field 'session.spare_fraction'"),
], ids=lambda v: " ".join(v) if isinstance(v, list) else None)
def test_every_section_is_settable_and_a_bad_value_is_named(tmp_path, capsys, argv, says):
    code, err = run_cli(capsys, *argv, "--out", tmp_path / "out")
    assert code == 2 and len(err) == 1 and says in err[0], err
    assert not (tmp_path / "out").exists()


def test_resume_compares_the_typed_config_and_names_what_differs(tmp_path):
    import dataclasses

    import yaml

    from mjx_protamer.config import ConfigError, check_resume_config, to_dict
    from mjx_protamer.experiments.table2 import Table2Config

    cfg = Table2Config()
    old = to_dict(cfg)
    del old["session"], old["coach"], old["batched"]["rows_per_event"]  # written before they joined the schema
    saved = tmp_path / "config.yaml"
    saved.write_text(yaml.safe_dump(old, default_flow_style=True))  # and formatted otherwise
    check_resume_config(saved, cfg)
    with pytest.raises(ConfigError, match=r"the config differs from the one saved in .* in feedback\.dt, seeds$"):
        check_resume_config(saved, dataclasses.replace(cfg, seeds=(0, 1), feedback=dataclasses.replace(
            cfg.feedback, dt=0.01)))
    saved.write_text(yaml.safe_dump(dict(old, no_such_section=1)))
    with pytest.raises(ConfigError, match="no longer loads: unknown config key"):
        check_resume_config(saved, cfg)


def test_pretrain_resume_reads_the_saved_config_as_eval_does(tmp_path):
    """A run saved before env.habituation_s existed ran without a familiarity trace: it continues with 0, not
    with today's default."""
    import dataclasses

    import yaml

    from mjx_protamer.config import ConfigError, check_resume_config, to_dict
    from mjx_protamer.experiments.run_loader import read_run_config

    old = to_dict(PretrainConfig())
    del old["env"]["habituation_s"]
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(old))
    read = lambda path: read_run_config(path.parent)  # noqa: E731
    then = dataclasses.replace(PretrainConfig(), env=dataclasses.replace(PretrainConfig().env, habituation_s=0.0))
    check_resume_config(tmp_path / "config.yaml", then, read)
    with pytest.raises(ConfigError, match="in env.habituation_s$"):
        check_resume_config(tmp_path / "config.yaml", PretrainConfig(), read)
