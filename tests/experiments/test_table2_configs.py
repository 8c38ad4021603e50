"""The shipped Table II configs load and validate, and the variants differ where they say."""

from pathlib import Path

import pytest

from mjx_protamer.agents.ddpg.config import PretrainConfig
from mjx_protamer.config import load_config
from mjx_protamer.experiments.table2 import load_table2_config

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


@pytest.mark.parametrize("name", ["table2.yaml", "table2_paper.yaml", "table2_habituation.yaml",
                                  "table2_attention.yaml"])
def test_shipped_table2_configs_load(name):
    cfg = load_table2_config(CONFIGS / name)
    assert cfg.conditions[0].channel == "none" and [c.name for c in cfg.conditions] == ["DDPG", "DTK", "DTW", "DTP"]
    assert len(cfg.seeds) >= 5 or name == "table2_paper.yaml"  # the paper's single-env setting: one seed


def test_table2_habituation_is_table2_with_the_documented_changes_only():
    """Habituation as in the pretraining default, the lateral rule, the 1.5 rad/s band, the step-size decay and
    the balanced reward model: everything else equals configs/table2.yaml, so the two tables compare."""
    import dataclasses

    base, hab = load_table2_config(CONFIGS / "table2.yaml"), load_table2_config(CONFIGS / "table2_habituation.yaml")
    default_env = load_config(PretrainConfig, CONFIGS / "pretrain.yaml").env
    assert base.pretrain.env.habituation_s == 0.0
    assert (hab.pretrain.env.habituation_s, hab.pretrain.env.recovery_s) == (default_env.habituation_s,
                                                                            default_env.recovery_s)
    assert hab.pretrain.env.reward == dataclasses.replace(base.pretrain.env.reward, speed_low=1.5)
    assert hab.pretrain.ddpg == dataclasses.replace(base.pretrain.ddpg, lr_final_fraction=0.1, lr_decay_from=0.5)
    assert hab.feedback.reward_model == dataclasses.replace(base.feedback.reward_model, balance_signs=True)
    assert hab.pretrain.train == base.pretrain.train and hab.feedback.credit == base.feedback.credit
    assert hab.conditions == base.conditions and hab.seeds == base.seeds and hab.batched == base.batched
    assert [c.signal for c in hab.feedback.teacher.rule] == ["obs_norm:26:52", "obs_norm:0:26"]
    assert [c.value for c in hab.feedback.teacher.rule] == [1.0, -1.0]


def test_table2_attention_is_table2_habituation_with_the_credit_and_model_input_changes_only():
    """Watched silences as full 0 labels, unbalanced signs, the posterior credit and asinh inputs to the reward
    model: everything else equals configs/table2_habituation.yaml, so its baseline is the same baseline and the
    two tables compare."""
    import dataclasses

    hab = load_table2_config(CONFIGS / "table2_habituation.yaml")
    att = load_table2_config(CONFIGS / "table2_attention.yaml")
    assert att.feedback.credit == dataclasses.replace(hab.feedback.credit, silence_weight=1.0,
                                                      silence_needs_attention=True, posterior_temperature=3.0)
    assert att.feedback.reward_model == dataclasses.replace(hab.feedback.reward_model, balance_signs=False,
                                                            asinh_obs=True)
    assert att.pretrain == hab.pretrain and att.feedback.teacher == hab.feedback.teacher
    assert att.conditions == hab.conditions and att.seeds == hab.seeds and att.batched == hab.batched


def test_table_names_the_reward_preset_and_what_a_config_changed_in_it():
    from mjx_protamer.experiments.table2 import reward_preset_name

    names = {n: reward_preset_name(load_table2_config(CONFIGS / n).pretrain)
             for n in ("table2.yaml", "table2_paper.yaml", "table2_habituation.yaml")}
    assert names == {"table2.yaml": "infant", "table2_paper.yaml": "paper",
                     "table2_habituation.yaml": "infant (speed_low 1.5)"}


def test_reproduce_table2_without_config_runs_the_yaml_shipped_in_the_package(tmp_path, monkeypatch, capsys):
    """`reproduce table2` without --config runs configs/table2_attention.yaml (the setting whose table the README
    reports), read from the package, not from the checkout: the file is package data that a wheel ships."""
    import tomllib

    import mjx_protamer
    from mjx_protamer.cli import main
    from mjx_protamer.config import shipped_config
    from mjx_protamer.experiments import table2

    shipped = shipped_config("table2_attention.yaml")
    assert shipped.parent == Path(mjx_protamer.__file__).parent / "configs" and not shipped.is_symlink()
    assert shipped.resolve() == (CONFIGS / "table2_attention.yaml").resolve()  # configs/ links to the package's
    package_data = tomllib.loads((CONFIGS.parent / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    assert "configs/*.yaml" in package_data["mjx_protamer"]
    ran = []

    def run_table2(cfg, out, progress=True, resume=False, at_once=1):
        ran.append(cfg)
        assert at_once == 2  # the default: two conditions at a time
        (out / "table2.md").write_text("table\n")
        return {"table_md": str(out / "table2.md"), "wall_s": 0.0, "out_dir": str(out), "region_frequencies": {},
                **{k: "" for k in ("table_json", "figure1", "figure2", "training_csv")}}

    monkeypatch.setattr(table2, "run_table2", run_table2)
    assert main(["reproduce", "table2", "--out", str(tmp_path / "t2"), "--quiet"]) == 0
    assert ran == [load_table2_config(shipped)]
    assert [(c.signal, c.value) for c in ran[0].feedback.teacher.rule] == [("obs_norm:26:52", 1.0),
                                                                          ("obs_norm:0:26", -1.0)]


def test_overrides_without_a_file_change_only_what_they_name():
    """--set on the built-in default merges into it: the rest of a section keeps the default's values, not the
    section class's (the lateral rule and asinh inputs survive a change of the credit's temperature)."""
    import dataclasses

    base = load_table2_config()
    cfg = load_table2_config(None, ["feedback.credit.posterior_temperature=6.0",
                                    "pretrain.train.total_env_steps=32000"], seeds=10)
    assert cfg.feedback == dataclasses.replace(
        base.feedback, credit=dataclasses.replace(base.feedback.credit, posterior_temperature=6.0))
    assert cfg.pretrain == dataclasses.replace(
        base.pretrain, train=dataclasses.replace(base.pretrain.train, total_env_steps=32000))
    assert cfg.seeds == tuple(range(10)) and cfg.batched == base.batched and cfg.conditions == base.conditions


def test_table2_tour_is_the_default_with_the_tour_rule_selection_and_ten_seeds_only():
    """configs/table2_tour.yaml changes the built-in default's rule, conditions, seeds and test snapshot and
    nothing else, so its DDPG is the default's baseline."""
    import dataclasses

    base, tour = load_table2_config(CONFIGS / "table2_attention.yaml"), load_table2_config(CONFIGS / "table2_tour.yaml")
    assert [(c.signal, c.value, c.sustain) for c in tour.feedback.teacher.rule] == [
        ("habituation", 1.0, 20), ("obs_norm:64:68,70:74", -1.0, 100)]
    assert tour.feedback == dataclasses.replace(base.feedback, teacher=dataclasses.replace(
        base.feedback.teacher, rule=tour.feedback.teacher.rule))
    assert tour.pretrain == dataclasses.replace(base.pretrain, train=dataclasses.replace(
        base.pretrain.train, select_every_chunks=8, select_from=0.5, select_episodes=4))
    assert [c.name for c in tour.conditions] == ["DDPG", "DTK"] and tour.conditions == base.conditions[:2]
    assert tour.seeds == tuple(range(10)) and tour.batched == base.batched


def test_table2_tour_right_is_the_tour_config_with_a_left_hand_reproach_only():
    """configs/table2_tour_right.yaml adds one clause (the left hand touching, -1) to configs/table2_tour.yaml's
    rule and changes nothing else, so its DDPG trains exactly as the tour config's."""
    import dataclasses

    tour = load_table2_config(CONFIGS / "table2_tour.yaml")
    right = load_table2_config(CONFIGS / "table2_tour_right.yaml")
    assert [(c.signal, c.value, c.above, c.below, c.sustain) for c in right.feedback.teacher.rule] == [
        ("habituation", 1.0, 0.5, None, 20), ("obs_norm:0:26", -1.0, 0.05, None, 20),
        ("obs_norm:64:68,70:74", -1.0, None, 1.0, 100)]
    assert right.feedback == dataclasses.replace(tour.feedback, teacher=dataclasses.replace(
        tour.feedback.teacher, rule=right.feedback.teacher.rule))
    assert (right.pretrain, right.batched, right.conditions, right.seeds) == (
        tour.pretrain, tour.batched, tour.conditions, tour.seeds)


@pytest.mark.parametrize("key,value", [("praise_imitation_coef", "50"), ("reproach_avoid_coef", "50"),
                                       ("anchor_praise_hold", "true"), ("noise_follows_hold", "true")])
def test_table2_refuses_a_live_sessions_option_it_cannot_run(key, value):
    """A word as a demonstration reads a live session's feedback ring, and a praise re-anchors the actor on the
    host; the batched runs have neither, so the key would do nothing there (and noise that follows the hold would
    keep their envs from exploring at all): a one-line error naming it instead of a Table II that silently ignored
    it."""
    from mjx_protamer.config import ConfigError

    with pytest.raises(ConfigError, match=f"pretrain.ddpg.{key}.*live session"):
        load_table2_config(None, ["pretrain.ddpg.anchor_coef=50", "pretrain.ddpg.anchor_release_events=10",
                                  f"pretrain.ddpg.{key}={value}"])


@pytest.mark.parametrize("key,value", [("praise_imitation_coef", "50"), ("noise_follows_hold", "true")])
def test_pretrain_refuses_a_live_sessions_option_in_one_line_before_anything_starts(tmp_path, capsys, key, value):
    """The same keys in `protamer pretrain` (one check for both batched commands): noise that follows a hold no
    event moves would train a run that never explores."""
    from mjx_protamer.cli import main

    code = main(["pretrain", "--set", "ddpg.anchor_coef=50", "--set", "ddpg.anchor_release_events=10", "--set",
                 f"ddpg.{key}={value}", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and f"'ddpg.{key}'" in err[0] and "live session's option" in err[0], err
    assert not (tmp_path / "out").exists()
