"""The tested snapshot (`train.select_every_chunks`): which chunks are validated, that the best one is kept, and
that `reproduce table2` tests exactly the snapshot that validated best under the learner's objective."""

import dataclasses
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import yaml

from mjx_protamer.agents.ddpg import selection
from mjx_protamer.cli import main
from mjx_protamer.config import ConfigError

from toy_feedback import toy_feedback_config


def test_candidates_are_late_chunks_and_always_the_last():
    picked = [c for c in range(1, 81) if selection.is_candidate(c, 80, 8, 0.5)]
    assert picked == [40, 48, 56, 64, 72, 80]
    assert [c for c in range(1, 11) if selection.is_candidate(c, 10, 4, 0.0)] == [4, 8, 10]
    assert not any(selection.is_candidate(c, 80, 0, 0.5) for c in range(1, 81))  # 0: the last actor, unvalidated


def test_keep_better_keeps_the_strictly_best_snapshot():
    kept = selection.init({"w": jnp.zeros(3)})
    kept = selection.keep_better(kept, {"w": jnp.ones(3)}, jnp.float32(-5.0), 4)
    assert int(kept.chunk) == 4 and float(kept.score) == -5.0  # anything beats -inf
    kept = selection.keep_better(kept, {"w": 2 * jnp.ones(3)}, jnp.float32(-7.0), 8)
    assert int(kept.chunk) == 4 and np.all(np.asarray(kept.actor_params["w"]) == 1)
    kept = selection.keep_better(kept, {"w": 3 * jnp.ones(3)}, jnp.float32(-5.0), 12)  # a tie keeps the earlier
    assert int(kept.chunk) == 4
    kept = selection.keep_better(kept, {"w": 4 * jnp.ones(3)}, jnp.float32(1.0), 16)
    assert int(kept.chunk) == 16 and np.all(np.asarray(kept.actor_params["w"]) == 4)


def test_table2_tests_the_snapshot_that_validated_best(tmp_path):
    raw = {**toy_feedback_config(total_env_steps=960, chunk_steps=20, eval_episodes=3, select_every_chunks=2,
                                 select_from=0.0, select_episodes=2),
           "conditions": [{"name": "DDPG", "channel": "none"},
                          {"name": "DTK", "channel": "keyboard", "credit": "step_window"}]}
    cfg_path = tmp_path / "t2.yaml"
    cfg_path.write_text(yaml.safe_dump(raw))
    out = tmp_path / "t2"
    assert main(["reproduce", "table2", "--config", str(cfg_path), "--seeds", "2", "--out", str(out), "--quiet"]) == 0
    from mjx_protamer.experiments.env_factory import make_env
    from mjx_protamer.experiments.evaluate import validation_seed
    from mjx_protamer.experiments.table2 import load_condition_agents, load_table2_config

    cfg = load_table2_config(out / "config.yaml")
    tc = cfg.pretrain.train
    best, tested = {}, set()
    for name in ("DDPG", "DTK"):
        for seed in (0, 1):
            sel = json.loads((out / f"eval_{name}_seed{seed}.json").read_text())["selection"]
            chunks = [c["chunk"] for c in sel["candidates"]]
            assert chunks == list(range(2, tc.num_chunks + 1, 2))
            scores = [c["score"] for c in sel["candidates"]]
            assert sel["tested_chunk"] == chunks[int(np.argmax(scores))]
            assert all(0.0 <= c["freeze_ratio"] <= 1.0 for c in sel["candidates"])
            best[name, seed] = max(scores)
            tested.add(sel["tested_chunk"])
            ev = json.loads((out / f"eval_{name}_seed{seed}.json").read_text())
            if sel["tested_chunk"] == tc.num_chunks:  # the last actor tested twice on the same episodes
                assert all(ev[k] == sel["last_actor"][k] for k in sel["last_actor"])
    summary = json.loads((out / "table2.json").read_text())["conditions"]
    for name in ("DDPG", "DTK"):
        diff = summary[name]["selection"]["tested_minus_last"]["freeze_ratio"]["seed_values"]
        evs = [json.loads((out / f"eval_{name}_seed{s}.json").read_text()) for s in (0, 1)]
        assert diff == pytest.approx([e["freeze_ratio"] - e["selection"]["last_actor"]["freeze_ratio"] for e in evs])
    assert "tested - last (paired)" in (out / "table2.md").read_text()
    assert tested - {tc.num_chunks}, "this run must test an earlier snapshot somewhere, or nothing is checked"
    # DDPG's objective is r_env alone, so its saved (tested) actor validates again at the kept score, whichever
    # chunk it came from
    with np.load(out / "test_states_DDPG.npz") as f:
        obs, action = f["obs"], f["action"]
    _, _, params = load_condition_agents(out, cfg, "DDPG", obs.shape[-1], action.shape[-1])
    env = make_env(cfg.pretrain)
    validate = selection.make_validate(env, tc.episode_length, cfg.pretrain.ddpg.actor_hidden,
                                       cfg.pretrain.ddpg.reward_alpha, cfg.pretrain.ddpg.reward_beta)
    for i, seed in enumerate((0, 1)):
        seeded = dataclasses.replace(cfg.pretrain, train=dataclasses.replace(tc, seed=seed))
        keys = jax.random.split(jax.random.PRNGKey(validation_seed(seeded)), tc.select_episodes)
        score, _ = validate(jax.tree.map(lambda x, i=i: x[i], params["actor"]), None, keys)
        assert float(score) == pytest.approx(best["DDPG", seed], rel=1e-5, abs=1e-4)


def test_selection_settings_are_validated(tmp_path):
    raw = {**toy_feedback_config(select_from=1.0), "conditions": [{"name": "DDPG", "channel": "none"}]}
    cfg_path = tmp_path / "bad.yaml"
    cfg_path.write_text(yaml.safe_dump(raw))
    from mjx_protamer.experiments.table2 import load_table2_config

    with pytest.raises(ConfigError, match="select_from"):
        load_table2_config(cfg_path)


def test_pretrain_keeps_its_selected_snapshot_across_a_resume(tmp_path):
    """`protamer pretrain` with selection: eval.json measures the best-validating snapshot, a run killed and
    resumed selects and measures exactly what an uninterrupted one does, and `load_run` gives that actor."""
    from mjx_protamer.agents.ddpg.config import PretrainConfig
    from mjx_protamer.config import from_dict
    from mjx_protamer.experiments.evaluate import eval_seed, evaluate
    from mjx_protamer.experiments.pretrain import run_pretrain
    from mjx_protamer.experiments.run_loader import load_run

    raw = {"env_name": "toy",
           "ddpg": {"actor_hidden": [16], "critic_hidden": [16, 16], "replay_size": 2000, "batch_size": 16},
           "train": {"num_envs": 4, "episode_length": 25, "total_env_steps": 1200, "warmup_env_steps": 100,
                     "chunk_steps": 50, "checkpoint_every_chunks": 2, "eval_episodes": 3,
                     "select_every_chunks": 2, "select_from": 0.0, "select_episodes": 2}}
    cfg_path = tmp_path / "toy.yaml"
    cfg_path.write_text(yaml.safe_dump(raw))
    whole, resumed = tmp_path / "whole", tmp_path / "resumed"
    assert main(["pretrain", "--config", str(cfg_path), "--out", str(whole), "--no-progress"]) == 0
    config = from_dict(PretrainConfig, raw)
    run_pretrain(config, resumed, progress=False, max_chunks=3)  # "killed" after chunk 3 (checkpoint 2)
    assert main(["pretrain", "--config", str(cfg_path), "--out", str(resumed), "--no-progress", "--resume"]) == 0

    ev = json.loads((whole / "eval.json").read_text())
    sel = ev["selection"]
    assert [c["chunk"] for c in sel["candidates"]] == [2, 4, 6]
    assert sel["tested_chunk"] == [2, 4, 6][int(np.argmax([c["score"] for c in sel["candidates"]]))]
    assert sel["tested_chunk"] != 6, "this seed's run must test an earlier snapshot, or load_run is not checked"
    assert json.loads((resumed / "eval.json").read_text()) == ev
    assert json.loads((resumed / "selection.json").read_text())["candidates"] == sel["candidates"]
    config, env, state, _ = load_run(whole)
    again = evaluate(config, env, state.actor_params, 3, eval_seed(config))
    assert again["freeze_ratio"] == ev["freeze_ratio"] and again["episode_return"] == pytest.approx(ev["episode_return"])
