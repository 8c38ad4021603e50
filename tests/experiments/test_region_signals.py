"""Region signals on the self-touch env: a `region:head` / `region:hip` rule fires exactly on the steps the
env's region mask says, in the in-jit feedback chunk and in the simulated teacher of a live session
(`finetune`), and the mask rides beside the chunk's transitions without entering the replay.

One tiny self-touch setup: a live session's learner (one env, one 100-step chunk) seen by its simulated
teacher, and 4 envs for the in-jit path (a reference chunk that says what they touched, and a feedback chunk
of the same worlds). Random actions never reach the head in so few steps, so the actor holds one pose that does:
its last layer's kernel is zeroed and its bias is the pose (found by holding 512 random poses for 1 s: with this
one the hip is touched from ~0.1 s and the head from ~0.2 s, mostly at separate times), without noise and with
a learning rate too small to move it (0 is refused). The two 4-env chunks then step the same worlds.
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
import pytest

from mjx_protamer.config import ConfigError, from_dict

RULE = [{"signal": "region:head", "value": 1.0, "above": 0.5}, {"signal": "region:hip", "value": -1.0, "above": 0.5}]
# A teacher that speaks on every step it scores (no gap, no silence, no mistakes): its events list the rule's hits.
TEACHER = {"rule": RULE, "threshold": 0.5, "give_rate": 1.0, "min_gap_steps": 0, "flip_prob": 0.0,
           "silence_fraction": 0.0}
RAW = {
    "pretrain": {
        "env_name": "self_touch",
        "env": {"backend": "native"},
        "ddpg": {"actor_hidden": [16], "critic_hidden": [16, 16], "replay_size": 1000, "batch_size": 16,
                 "actor_lr": 1e-30, "noise": {"kind": "none"}},
        "train": {"num_envs": 4, "episode_length": 1000, "total_env_steps": 800, "warmup_env_steps": 0,
                  "chunk_steps": 100, "seed": 0},
    },
    "feedback": {"reward_model": {"hidden": [16]}, "teacher": TEACHER},
}
HEAD, HIP = 3, 0  # body.REGIONS order
POSE = (-0.899, -0.953, -0.389, 0.883, -0.282, 0.914, -0.421, -0.915, -0.155, -0.846, -0.794, -0.116, 0.729, 0.709)


def holding_pose(ts):
    """The train state with an actor that outputs POSE whatever it observes."""
    last = ts.actor_params["params"]["Dense_1"]
    held = {"kernel": np.zeros_like(last["kernel"]), "bias": np.arctanh(np.asarray(POSE, np.float32))}
    params = {"params": {**ts.actor_params["params"], "Dense_1": held}}
    fresh = lambda: jax.tree.map(jax.numpy.array, params)  # noqa: E731  (own buffers: chunks donate them)
    return ts.replace(actor_params=fresh(), target_actor_params=fresh())


@pytest.fixture(scope="module")
def runs():
    from mjx_protamer.agents.ddpg.train import make_train
    from mjx_protamer.envs.body import REGIONS
    from mjx_protamer.experiments.env_factory import make_env
    from mjx_protamer.experiments.feedback_train import make_feedback_train
    from mjx_protamer.experiments.table2 import Table2Config
    from mjx_protamer.human.clock import VirtualClock
    from mjx_protamer.human.feedback_config import SessionConfig
    from mjx_protamer.live.sources import SimulatedTeacher
    from mjx_protamer.live.tamer import TamerLearner, session_pretrain

    assert (REGIONS[HEAD], REGIONS[HIP]) == ("head", "hip")
    cfg = from_dict(Table2Config, RAW)
    env = make_env(cfg.pretrain)
    key = jax.random.PRNGKey(cfg.pretrain.train.seed)
    fc, T = cfg.feedback, cfg.pretrain.train.chunk_steps

    # the host path (`protamer finetune --feedback simulated:keyboard`): one chunk of the session's learner (one
    # env), seen by its simulated teacher, then drained (as live/loop.py)
    session = SessionConfig()
    clock = VirtualClock(start=1000.0)
    learner = TamerLearner(session_pretrain(cfg.pretrain, T, session, {}, cfg.pretrain.ddpg.replay_size), env, fc,
                           session, use_model=True, clock=clock)
    teacher = SimulatedTeacher(learner.queue, fc.teacher, fc.dt, fc.seed, env, clock)
    learner.state = holding_pose(learner.state)
    learner.commit()
    chunk = learner.step_chunk(clock())
    clock.set(chunk.t0 + T * fc.dt)
    teacher.observe(chunk)
    outcomes = learner.take_events(chunk.first_step + T - 1)
    host_events = [o.event for o in outcomes] + teacher.teacher.take_scheduled()  # drained, and not yet due

    # what the 4 worlds of the in-jit path touch: a reference chunk of the same worlds (same seed, held pose)
    ref = make_train(cfg.pretrain, env)
    _, _, ref_steps, ref_extras = ref.collect_chunk(holding_pose(ref.init(key)), None)

    # the in-jit path (table2, pretrain --feedback simulated:...): one feedback chunk
    ft = make_feedback_train(cfg.pretrain, env, cfg.feedback, cfg.batched)
    ts, fs = holding_pose(ft.trainer.init(key)), ft.init(cfg.pretrain.train.seed)
    ts, fs, metrics, events = ft.chunk(ts, fs, ft.params("keyboard", cfg.feedback.credit))
    mask = np.asarray(ref_extras["region_mask"])  # (T, B, 8): what the env said each step touched
    return dict(cfg=cfg, env=env, mask=mask, ref_obs=np.asarray(ref_steps.obs),
                ref_terms=np.asarray(ref_steps.reward_terms), chunk=chunk, host_events=host_events,
                ts=ts, metrics=jax.device_get(metrics), events=jax.device_get(events), ft=ft)


def test_region_clauses_fire_exactly_where_the_mask_says_in_jit_and_on_the_host(runs):
    mask = runs["mask"]
    T, B = mask.shape[:2]
    assert mask.shape[2] == 8 and set(np.unique(mask)) <= {0.0, 1.0}
    expected = mask[..., HEAD] - mask[..., HIP]  # the rule by hand: +1 head, -1 hip, 0 both or neither
    # the worlds must touch the head on some steps and not on others, or the test proves nothing
    assert 0 < (mask[..., HEAD] > 0).sum() < T * B and (expected != 0).any()

    # host: the session's simulated teacher gave feedback on exactly the steps the rule scores on the region
    # mask of the learner's chunk, with that score
    chunk = runs["chunk"]
    assert chunk.first_step == 0 and chunk.region_mask.shape == (T, 8)
    on_host = chunk.region_mask[:, HEAD] - chunk.region_mask[:, HIP]
    assert 0 < (chunk.region_mask[:, HEAD] > 0).sum() < T and (on_host != 0).any()  # or it proves nothing
    host = {e.details["about_step"]: e.details["score"] for e in runs["host_events"]}
    assert sorted(host) == np.flatnonzero(on_host).tolist()
    assert all(host[t] == on_host[t] for t in host)

    # in jit: the chunk's mean hidden score over every env and step is the hand-computed one, and every event
    # delivered is about a step the rule scored, with its sign
    m, ev = runs["metrics"], runs["events"]
    assert m["score_mean"] == pytest.approx(expected.mean(), abs=1e-6)
    present = ev["present"]
    assert present.sum() > 0
    about, env_i, value = ev["about"][present], ev["env"][present], ev["value"][present]
    assert (value > 0).any() and (value < 0).any()
    assert np.array_equal(np.sign(value), expected[about, env_i])
    # every step the in-jit teacher of an env judged is one the rule scores in that env (some of its deliveries
    # can be dropped by the pending ring when two land on one arrival step, none invented)
    for b in range(B):
        assert set(about[env_i == b].tolist()) <= set(np.flatnonzero(expected[:, b]).tolist())


def test_the_region_mask_rides_beside_the_transitions_not_in_the_replay(runs):
    from mjx_protamer.agents.ddpg.replay import Transition

    # the mask is of the step each transition reached: the reward's `region` term pays a new region exactly
    # where the mask gains one over the step before
    reward = runs["cfg"].pretrain.env.reward
    assert reward.region_new != reward.region_stale
    mask = runs["mask"] > 0
    new = (mask[1:] & ~mask[:-1]).any(-1)
    region_term = runs["ref_terms"][1:, :, runs["env"].reward_term_names.index("region")]
    assert new.any() and np.array_equal(region_term == reward.region_new, new)

    replay = runs["ts"].replay.data
    assert type(replay) is Transition and replay._fields == ("obs", "action", "reward_terms", "next_obs", "terminal")
    assert all(x.shape[0] == runs["cfg"].pretrain.ddpg.replay_size for x in replay)


def test_region_signals_are_a_config_error_where_there_are_no_regions_or_no_such_region(runs):
    from mjx_protamer.experiments.env_factory import make_env
    from mjx_protamer.experiments.feedback_train import make_feedback_train
    from mjx_protamer.experiments.table2 import Table2Config
    from mjx_protamer.human.clock import VirtualClock
    from mjx_protamer.human.queue import FeedbackQueue
    from mjx_protamer.human.teachers import env_signal_columns
    from mjx_protamer.live.sources import SimulatedTeacher

    from toy_feedback import toy_feedback_config

    toy_raw = toy_feedback_config()
    toy_raw["feedback"]["teacher"]["rule"] = [{"signal": "region:head", "value": 1.0, "above": 0.5}]
    toy = from_dict(Table2Config, toy_raw)
    toy_env = make_env(toy.pretrain)
    with pytest.raises(ConfigError, match="'region:head' reads body regions, and this env has none"):
        make_feedback_train(toy.pretrain, toy_env, toy.feedback)
    # a live session's simulated teacher (the one source of either learner, DDPG + DeepTAMER or COACH) checks
    # its rule against the env before the session runs
    with pytest.raises(ConfigError, match="'region:head' reads body regions, and this env has none"):
        env_signal_columns(toy.feedback.teacher.signals, toy_env)
    with pytest.raises(ConfigError, match="this env has none"):
        SimulatedTeacher(FeedbackQueue(8), toy.feedback.teacher, toy.feedback.dt, 0, toy_env, VirtualClock())
    cfg = runs["cfg"]
    bad = dataclasses.replace(cfg.feedback, teacher=from_dict(type(cfg.feedback.teacher), {
        **TEACHER, "rule": [{"signal": "region:foot", "value": 1.0, "above": 0.5}]}))
    with pytest.raises(ConfigError, match="'region:foot' names no body region; allowed: region:hip, "
                                          "region:lower_body, region:upper_body, region:head"):
        make_feedback_train(cfg.pretrain, runs["env"], bad)
