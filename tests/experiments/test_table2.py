"""`protamer reproduce table2` on the toy env with tiny sizes: four conditions, table and figures written."""

import json

import jax
import numpy as np
import pytest
import yaml

from mjx_protamer.config import ConfigError

from mjx_protamer.cli import main

from toy_feedback import toy_feedback_config

CONFIG = {
    **toy_feedback_config(total_env_steps=600, chunk_steps=50, eval_episodes=3),
    "conditions": [{"name": "DDPG", "channel": "none"}, {"name": "DTK", "channel": "keyboard", "credit": "step_window"},
                   {"name": "DTW", "channel": "speech"}, {"name": "DTP", "channel": "prosody"}],
    "moving_average": 2,
}


def test_table2_writes_table_and_figures(tmp_path, capsys):
    cfg = tmp_path / "t2.yaml"
    cfg.write_text(yaml.safe_dump(CONFIG))
    out = tmp_path / "t2"
    assert main(["reproduce", "table2", "--config", str(cfg), "--seeds", "2", "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "Contact rate" in printed and "DTP paper" in printed
    for name in ("table2.md", "table2.json", "figure1_training_reward.png", "figure2_unique_regions.png",
                 "training.csv", "eval_DTK_seed1.json"):
        assert (out / name).stat().st_size > 0, name
    summary = json.loads((out / "table2.json").read_text())
    assert summary["seeds"] == [0, 1] and list(summary["conditions"]) == ["DDPG", "DTK", "DTW", "DTP"]
    c = summary["conditions"]
    assert c["DDPG"]["feedback"]["feedback_total"] == 0
    assert all(c[n]["feedback"]["feedback_total"] > 0 for n in ("DTK", "DTW", "DTP"))
    assert len(c["DTK"]["unique_regions"]["per_episode"]) == 6
    assert c["DTP"]["paper"]["contact_rate"] == 0.915
    versus = summary["teacher_score_vs_baseline"]
    assert versus["baseline"] == "DDPG" and list(versus["conditions"]) == ["DTK", "DTW", "DTP"]
    dtk = versus["conditions"]["DTK"]
    assert dtk["paired"]["seed_values"] == pytest.approx(np.subtract(c["DTK"]["teacher_score"]["seed_values"],
                                                                     c["DDPG"]["teacher_score"]["seed_values"]))
    assert "| teacher_score against DDPG |" in (out / "table2.md").read_text()
    # the pooled reward-model score: every model on the same states; DDPG's model never trains
    pooled = {n: c[n]["r_hat_corr_pooled"]["seed_values"] for n in c}
    assert pooled["DDPG"] == c["DDPG"]["r_hat_corr_pooled_untrained"]["seed_values"]
    assert all(v is None or -1 <= v <= 1 for n in c for v in pooled[n])  # None: the score is constant there
    assert pooled["DTK"][0] is not None and pooled["DTK"] != pooled["DDPG"]
    assert c["DTK"]["r_hat_corr_pooled_untrained"] == c["DTP"]["r_hat_corr_pooled_untrained"]
    # each condition keeps its agents: the saved actors are the ones whose test episodes were scored
    from mjx_protamer.experiments.table2 import load_condition_agents, load_table2_config

    with np.load(out / "test_states_DTK.npz") as f:
        obs, action = f["obs"], f["action"]
    actor, critic, params = load_condition_agents(out, load_table2_config(out / "config.yaml"), "DTK",
                                                  obs.shape[-1], action.shape[-1])
    np.testing.assert_allclose(jax.vmap(actor.apply)(params["actor"], obs), action, atol=1e-5)
    assert np.all(np.isfinite(jax.vmap(critic.apply)(params["critic"], obs, action)))
    with pytest.raises(ConfigError, match="agents/DTX is missing"):
        load_condition_agents(out, load_table2_config(out / "config.yaml"), "DTX", obs.shape[-1], action.shape[-1])
    # `protamer analyze` reads a finished condition's test states, and names what to fix when there are none
    from mjx_protamer.experiments.table2 import load_finished_condition

    _, states = load_finished_condition(out, "DTK")
    np.testing.assert_array_equal(states["obs"], obs)
    with pytest.raises(ConfigError, match="test_states_DTX.npz is missing: give the --out directory"):
        load_finished_condition(out, "DTX")
    # the saved agents scored again without training: the same test episodes (the run's behaviour metrics); the
    # run's own rule gives its teacher scores, the rule with every clause's value negated their negation
    assert main(["reproduce", "rescore", str(out), "--config", str(cfg), "--out", str(tmp_path / "same"),
                 "--quiet"]) == 0
    same = json.loads((tmp_path / "same" / "table2.json").read_text())
    flipped_cfg = tmp_path / "flipped.yaml"
    flipped_rule = [{**clause, "value": -clause["value"]} for clause in CONFIG["feedback"]["teacher"]["rule"]]
    flipped_cfg.write_text(yaml.safe_dump({**CONFIG, "feedback": {**CONFIG["feedback"], "teacher": {
        **CONFIG["feedback"]["teacher"], "rule": flipped_rule}}}))
    assert main(["reproduce", "rescore", str(out), "--config", str(flipped_cfg), "--out", str(tmp_path / "flip"),
                 "--quiet"]) == 0
    flip = json.loads((tmp_path / "flip" / "table2.json").read_text())
    assert flip["rescored"]["run"] == str(out) and flip["rescored"]["rule"][0]["value"] == -1.0
    for n in c:
        for rescored in (same, flip):
            r = rescored["conditions"][n]
            assert r["unique_regions"]["per_episode"] == c[n]["unique_regions"]["per_episode"], n
            assert r["freeze_ratio"]["seed_values"] == pytest.approx(c[n]["freeze_ratio"]["seed_values"]), n
        assert same["conditions"][n]["teacher_score"]["seed_values"] == pytest.approx(
            c[n]["teacher_score"]["seed_values"], abs=1e-6), n
        assert flip["conditions"][n]["teacher_score"]["seed_values"] == pytest.approx(
            [-v for v in c[n]["teacher_score"]["seed_values"]], abs=1e-6), n
    assert flip["teacher_score_vs_baseline"]["conditions"]["DTK"]["paired"]["seed_values"] == pytest.approx(
        [-v for v in dtk["paired"]["seed_values"]], abs=1e-6)
    capsys.readouterr()
    assert main(["reproduce", "rescore", str(out), "--set",
                 "feedback.teacher.rule=[{signal: no_such_signal, value: 1.0, above: 0.5}]", "--quiet"]) == 2
    assert "no_such_signal" in capsys.readouterr().err
    assert main(["reproduce", "rescore", str(tmp_path / "nothing"), "--quiet"]) == 2
    assert "is missing: give the --out directory of a table2 run" in capsys.readouterr().err
    # a run killed after two conditions: --resume keeps what finished and redoes the rest, to the same table
    kept = (out / "condition_DTK.json").read_bytes()
    for name in ("condition_DTW.json", "condition_DTP.json", "table2.json"):
        (out / name).unlink()
    assert main(["reproduce", "table2", "--config", str(cfg), "--seeds", "2", "--out", str(out), "--quiet"]) == 2
    assert "is not empty (it holds a table2 run" in capsys.readouterr().err  # and --resume continues it
    assert main(["reproduce", "table2", "--config", str(cfg), "--seeds", "2", "--out", str(out), "--quiet",
                 "--resume"]) == 0
    resumed = json.loads((out / "table2.json").read_text())["conditions"]
    assert (out / "condition_DTK.json").read_bytes() == kept
    for n in c:
        assert resumed[n]["unique_regions"]["per_episode"] == c[n]["unique_regions"]["per_episode"], n
        assert resumed[n]["freeze_ratio"]["seed_values"] == c[n]["freeze_ratio"]["seed_values"], n
        assert resumed[n]["r_hat_corr_pooled"]["seed_values"] == pooled[n], n  # DTK's models came from disk
    assert main(["reproduce", "table2", "--config", str(cfg), "--seeds", "3", "--out", str(out), "--quiet",
                 "--resume"]) == 2
    assert "the config differs" in capsys.readouterr().err
    # the same seed gives the same DDPG run: seeds fix everything
    out2 = tmp_path / "again"
    assert main(["reproduce", "table2", "--config", str(cfg), "--seeds", "1", "--out", str(out2), "--quiet",
                 "--set", "conditions=[{name: DDPG, channel: none}]"]) == 0
    again = json.loads((out2 / "table2.json").read_text())["conditions"]["DDPG"]
    assert again["contact_rate"]["seed_means"][0] == c["DDPG"]["contact_rate"]["seed_means"][0]
    assert again["freeze_ratio"]["per_episode"] == c["DDPG"]["freeze_ratio"]["per_episode"][:3]


def test_conditions_trained_at_once_compute_what_they_compute_one_after_another(tmp_path):
    """`--conditions-at-once`: the conditions share the machine, not their numbers. Every seed's test results,
    every training row and the saved agents are those of the conditions trained one at a time, bit for bit."""
    cfg = tmp_path / "t2.yaml"
    cfg.write_text(yaml.safe_dump(CONFIG))
    runs = {}
    for k in ("1", "9"):  # 9 asked, 4 conditions: 4 train at once
        out = tmp_path / f"at_once_{k}"
        assert main(["reproduce", "table2", "--config", str(cfg), "--seeds", "2", "--out", str(out), "--quiet",
                     "--conditions-at-once", k]) == 0
        runs[k] = out
    one, four = (json.loads((runs[k] / "table2.json").read_text()) for k in ("1", "9"))
    assert (one["conditions_at_once"], four["conditions_at_once"]) == (1, 4)
    assert "(4 conditions trained at a time)" in (runs["9"] / "table2.md").read_text()
    from mjx_protamer.experiments.machine import cpu_model

    assert cpu_model() is None or one["machine"].endswith(f"({cpu_model()})")  # runs on other CPUs round otherwise
    for name in ("DDPG", "DTK", "DTW", "DTP"):
        for seed in (0, 1):
            a, b = (json.loads((runs[k] / f"eval_{name}_seed{seed}.json").read_text()) for k in ("1", "9"))
            a.pop("train_wall_s"), b.pop("train_wall_s")
            assert a == b, (name, seed)
        with np.load(runs["1"] / f"test_states_{name}.npz") as a, np.load(runs["9"] / f"test_states_{name}.npz") as b:
            for key in a.files:
                np.testing.assert_array_equal(a[key], b[key])
    assert (runs["1"] / "training.csv").read_text() == (runs["9"] / "training.csv").read_text()
