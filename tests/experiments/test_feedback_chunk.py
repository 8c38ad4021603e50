"""The in-jit feedback chunk's data path: DDPG alone is plain DDPG bit for bit, the credit history holds what
the replay holds, the trace shows what the chunk did without changing it, and the chunk runs sharded over two
devices like plain DDPG."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import jax
import numpy as np
import pytest

from mjx_protamer.config import from_dict

from toy_feedback import toy_feedback_config

RAW = toy_feedback_config(num_devices=0)


def build(raw=RAW):
    from mjx_protamer.experiments.env_factory import make_env
    from mjx_protamer.experiments.feedback_train import make_feedback_train
    from mjx_protamer.experiments.table2 import Table2Config

    cfg = from_dict(Table2Config, raw)
    return cfg, make_feedback_train(cfg.pretrain, make_env(cfg.pretrain), cfg.feedback, cfg.batched)


@pytest.fixture(scope="module")
def setup():
    return build()


def _equal(a, b):
    return all(np.array_equal(np.asarray(x), np.asarray(y), equal_nan=True)
               for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)))


def test_gain_zero_is_plain_ddpg_bit_for_bit(setup):
    """DDPG alone through the feedback chunk (silent teacher, gain 0) = `train_chunk` of a trainer without
    any human reward: the same learner, env batch and replay, and the same DDPG metrics, chunk by chunk."""
    from mjx_protamer.agents.ddpg.train import make_train
    from mjx_protamer.experiments.env_factory import make_env

    cfg, ft = setup
    plain = make_train(cfg.pretrain, make_env(cfg.pretrain))
    ts, fs = ft.trainer.init(jax.random.PRNGKey(3)), ft.init(3)
    ref = plain.init(jax.random.PRNGKey(3))
    fp = ft.params(None, cfg.feedback.credit)
    for _ in range(cfg.pretrain.train.num_chunks):
        ts, fs, m, _ = ft.chunk(ts, fs, fp)
        ref, mr = plain.train_chunk(ref, None)
        assert _equal({k: m[k] for k in mr}, mr)
    assert _equal(ts, ref)
    assert float(m["feedback_total"]) == 0 and float(m["credited_rows_total"]) == 0
    # the reward model's work is skipped: it stays as `init` made it, and its ring empty
    fresh = ft.init(3)
    assert _equal((fs.rm_params, fs.rm_opt_state, fs.ring), (fresh.rm_params, fresh.rm_opt_state, fresh.ring))
    assert float(m["rm_updates_total"]) == 0 and np.isnan(float(m["rm_loss"]))


def test_credit_history_is_what_the_replay_holds(setup):
    """The credited (obs, action) of steps before a chunk come from the carried history, not the replay: after
    every chunk, history row h of env b is the replay row the pointer arithmetic of the old path read
    (step H - h back: row ptr - (H - h) B + b). The events arrive, are credited and train the model."""
    cfg, ft = setup
    B, H, cap = cfg.pretrain.train.num_envs, ft.history_len, cfg.pretrain.ddpg.replay_size
    assert H == ft.lag_len - 1 and H > cfg.pretrain.train.chunk_steps  # windows reach several chunks back
    ts, fs = ft.trainer.init(jax.random.PRNGKey(0)), ft.init(0)
    fp = ft.params("prosody", dataclasses.replace(cfg.feedback.credit, scheme="time_window"))
    for chunk in range(1, cfg.pretrain.train.num_chunks + 1):
        ts, fs, m, ev = ft.chunk(ts, fs, fp)
        filled = min(H, chunk * cfg.pretrain.train.chunk_steps)
        rows = (int(ts.replay.ptr) + (np.arange(H - filled, H)[:, None] - H) * B + np.arange(B)) % cap
        np.testing.assert_array_equal(np.asarray(fs.history.obs)[H - filled:], np.asarray(ts.replay.data.obs)[rows])
        np.testing.assert_array_equal(np.asarray(fs.history.action)[H - filled:],
                                      np.asarray(ts.replay.data.action)[rows])
    assert float(m["feedback_total"]) > 20 and float(m["credited_rows_total"]) > float(m["feedback_total"])
    assert float(m["rm_updates_total"]) > 0 and float(m["feedback_dropped"]) == 0


def test_the_trace_is_what_the_chunk_did_and_asking_for_it_changes_nothing(setup):
    """`collect_chunk`'s trace: the credited rows of weight > 0 are the rows the feedback ring received, in order;
    the teacher's output is nonzero exactly at the (step, env) of the chunk's events, with their values; the
    steps it holds are those the credit history carries. Training with the trace (`collect_chunk`) and without
    (`chunk`, which drops it) gives the same params, ring, metrics and events bit for bit."""
    cfg, ft = setup
    T, H = cfg.pretrain.train.chunk_steps, ft.history_len
    credit = dataclasses.replace(cfg.feedback.credit, scheme="step_window", silence_weight=0.03)
    fp = ft.params("keyboard", credit)  # a short window: steps with no feedback in theirs are silent rows
    plain = (ft.trainer.init(jax.random.PRNGKey(5)), ft.init(5))
    traced = (ft.trainer.init(jax.random.PRNGKey(5)), ft.init(5))
    silent_rows = event_rows = 0
    for _ in range(cfg.pretrain.train.num_chunks):
        ring0 = jax.device_get(traced[1].ring)
        it0 = int(traced[0].iteration)  # the chunk donates its inputs
        *plain, m, ev = ft.chunk(*plain, fp)
        *traced, mt, evt, trace = ft.collect_chunk(*traced, fp)
        assert _equal((m, ev), (mt, evt))
        trace, ring, evt = jax.device_get((trace, traced[1].ring, evt))
        rows = trace.credited
        kept = rows.weight > 0
        cap = ring.obs.shape[0]
        n = int(kept.sum())
        assert n < cap and int(ring.ptr) == (int(ring0.ptr) + n) % cap
        assert int(ring.size) == min(int(ring0.size) + n, cap)
        at = (int(ring0.ptr) + np.arange(n)) % cap
        for field in ("obs", "action", "weight", "target"):
            np.testing.assert_array_equal(getattr(ring, field)[at], getattr(rows, field)[kept])
        silent_rows += int(np.sum(kept & (rows.target == 0)))
        event_rows += int(np.sum(kept & (rows.target != 0)))
        teacher = trace.teacher
        spoke = set(zip(*np.nonzero(teacher["value"])))
        assert spoke == set(zip(*np.nonzero(teacher["valid"])))
        present = evt["present"]
        assert spoke == {(int(a) - it0, int(e)) for a, e in zip(evt["arrival"][present], evt["env"][present])}
        np.testing.assert_array_equal(teacher["value"][evt["arrival"][present] - it0, evt["env"][present]],
                                      evt["value"][present])
        np.testing.assert_array_equal(np.asarray(traced[1].history.obs)[H - T:], trace.obs)
        np.testing.assert_array_equal(np.asarray(traced[1].history.action)[H - T:], trace.action)
        assert trace.signals.shape[:2] == trace.obs.shape[:2]
    assert float(mt["feedback_total"]) > 20 and event_rows > 0 and silent_rows > 0
    assert _equal(plain, traced)


SCRIPT = textwrap.dedent(
    """
    import dataclasses, json, sys
    import jax, jax.numpy as jnp, numpy as np
    sys.path.insert(0, sys.argv[1] + "/tests/experiments")
    from test_feedback_chunk import build

    cfg, ft = build()
    fp = ft.params("keyboard", dataclasses.replace(cfg.feedback.credit, scheme="step_window"))
    ts, fs = ft.trainer.init(jax.random.PRNGKey(0)), ft.init(0)
    envs = set()
    for _ in range(cfg.pretrain.train.num_chunks):
        ts, fs, m, ev = ft.chunk(ts, fs, fp)
        ev = jax.device_get(ev)
        envs |= {int(e) for p, e in zip(ev["present"], ev["env"]) if p}
    shards = lambda x: [np.asarray(s.data) for s in x.addressable_shards]
    rm, actor = shards(jax.tree.leaves(fs.rm_params)[0]), shards(jax.tree.leaves(ts.actor_params)[0])
    m = jax.device_get(m)
    # seeds vmapped over the sharded program, as `reproduce table2` runs it
    vts = jax.jit(jax.vmap(ft.trainer.init))(jax.vmap(jax.random.PRNGKey)(jnp.arange(2)))
    vfs = jax.jit(jax.vmap(ft.init))(jnp.arange(2))
    vchunk = jax.jit(jax.vmap(ft.chunk_fn, in_axes=(0, 0, None)))
    for _ in range(cfg.pretrain.train.num_chunks):
        vts, vfs, vm, _ = vchunk(vts, vfs, fp)
    # the trace of a sharded chunk: every env's steps, the credited rows of both devices once
    ts, fs, _, ev, trace = ft.collect_chunk(ts, fs, fp)
    trace, ev = jax.device_get((trace, ev))
    print(json.dumps({
        "trace_obs": list(trace.obs.shape), "trace_spoke": int(trace.teacher["valid"].sum()),
        "trace_events": int(ev["present"].sum()), "trace_rows": int(trace.credited.weight.shape[0]),
        "devices": ft.trainer.num_devices, "replicas": len(rm),
        "rm_replicas_equal": all(np.array_equal(rm[0], r) for r in rm),
        "actor_replicas_equal": all(np.array_equal(actor[0], r) for r in actor),
        "history_local": [list(s.shape) for s in shards(fs.history.obs)], "history_len": ft.history_len,
        "event_envs": sorted(envs), "feedback_total": float(m["feedback_total"]),
        "rm_updates_total": float(m["rm_updates_total"]), "credited": float(m["credited_rows_total"]),
        "max_events": ft.max_events, "rows_per_event": cfg.batched.rows_per_event,
        "silence_rows": cfg.batched.silence_rows_per_chunk,
        "corr": float(m["r_hat_score_corr"]),
        "vmapped_seed0": float(vm["feedback_total"][0]), "vmapped_seed1": float(vm["feedback_total"][1]),
    }))
    """
)


def test_feedback_chunk_runs_on_two_devices():
    """Over 2 forced host devices: envs, teachers and credit history split; the reward model replicated and
    updated identically on each (replicas equal); events come from the envs of both devices; seeds vmap over
    the sharded program (seed 0 vmapped = seed 0 alone)."""
    root = Path(__file__).resolve().parents[2]
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", JAX_PLATFORMS="cpu")
    proc = subprocess.run([sys.executable, "-c", SCRIPT, str(root)], env=env, capture_output=True, text=True,
                          timeout=600, cwd=root)
    assert proc.returncode == 0, proc.stderr[-3000:]
    r = json.loads(proc.stdout.strip().splitlines()[-1])
    assert r["devices"] == 2 and r["replicas"] == 2
    assert r["rm_replicas_equal"] and r["actor_replicas_equal"]
    assert r["history_local"] == [[r["history_len"], 2, 6]] * 2
    assert r["event_envs"] == [0, 1, 2, 3]
    assert r["feedback_total"] > 20 and r["credited"] > r["feedback_total"] and r["rm_updates_total"] > 0
    assert np.isfinite(r["corr"])
    assert r["vmapped_seed0"] == r["feedback_total"] and r["vmapped_seed1"] > 0
    assert r["trace_obs"] == [20, 4, 6] and r["trace_spoke"] == r["trace_events"]
    assert r["trace_rows"] == 2 * (r["max_events"] * r["rows_per_event"] + r["silence_rows"])


def test_teach_quiet_puts_the_teachers_on_the_envs_without_noise_only():
    """`batched.teach_quiet`: feedback comes only from the envs acting with the deterministic actor (the last
    `quiet_fraction` of them), which are the behaviour the test episodes measure; without such envs the config
    is refused with the field to change."""
    from mjx_protamer.config import ConfigError

    raw = toy_feedback_config(num_devices=0)
    raw["pretrain"]["ddpg"]["noise"] = {"quiet_fraction": 0.5}
    raw["batched"] = {"teach_quiet": True}
    cfg, ft = build(raw)
    ts, fs = ft.trainer.init(jax.random.PRNGKey(0)), ft.init(0)
    fp = ft.params("keyboard", cfg.feedback.credit)
    envs = []
    for _ in range(cfg.pretrain.train.num_chunks):
        ts, fs, m, ev = ft.chunk(ts, fs, fp)
        envs += np.asarray(ev["env"])[np.asarray(ev["present"])].tolist()
    assert len(envs) > 10 and set(envs) <= {2, 3}, envs
    raw["pretrain"]["ddpg"]["noise"] = {"quiet_fraction": 0.0}
    with pytest.raises(ConfigError, match="quiet_fraction"):
        build(raw)
    raw["batched"] = {"teach_quiet": True, "teach_envs": 2}
    with pytest.raises(ConfigError, match="teach_envs"):
        build(raw)


def test_posterior_credit_moves_each_events_weight_by_the_models_agreement(setup):
    """`credit.posterior_temperature` T: the same rows are credited as without it, each event keeps its total
    weight, and within an event a row's weight is proportional to exp(T v r_hat) under the model the chunk
    started with (credit.posterior_weights)."""
    import jax.numpy as jnp

    from mjx_protamer.human.credit import posterior_weights

    cfg0, ft0 = setup
    raw = toy_feedback_config(num_devices=0)
    raw["feedback"]["credit"] = {"posterior_temperature": 4.0}
    cfg, ft = build(raw)
    fresh = lambda: (ft.trainer.init(jax.random.PRNGKey(0)), ft.init(0))  # a chunk donates its inputs
    rm_before = jax.device_get(fresh()[1].rm_params)
    _, post_fs, m, ev = ft.chunk(*fresh(), ft.params("keyboard", cfg.feedback.credit))
    _, prior_fs, _, _ = ft0.chunk(*fresh(), ft0.params("keyboard", cfg0.feedback.credit))
    post, prior = jax.device_get(post_fs.ring), jax.device_get(prior_fs.ring)
    n = int(post.size)
    assert n == int(prior.size) > 50
    for field in ("obs", "action", "target"):
        np.testing.assert_array_equal(getattr(post, field)[:n], getattr(prior, field)[:n])
    w, w0, h = post.weight[:n], prior.weight[:n], post.target[:n]
    np.testing.assert_allclose(w.sum(), w0.sum(), rtol=1e-5)
    assert np.abs(w - w0).max() > 0.05
    # log w - T v r_hat is the event's normaliser: one value per event
    r = np.asarray(ft.apply(rm_before, jnp.asarray(post.obs[:n]), jnp.asarray(post.action[:n])))
    per_event = np.unique(np.round(np.log(w / w0) - 4.0 * h * r, 4))
    assert len(per_event) <= int(np.sum(ev["present"])) < n / 4
    # the rule itself: numpy and JAX agree, temperature 0 is the prior, zero weights stay zero
    wt, v, rh = np.array([[0.2, 0.5, 0.3, 0.0]]), np.ones((1, 4)), np.array([[0.9, -0.2, 0.4, 1.0]])
    got = posterior_weights(np, wt, v, rh, 2.0)
    np.testing.assert_allclose(got, np.asarray(posterior_weights(jnp, jnp.asarray(wt), v, rh, 2.0)), rtol=1e-6)
    np.testing.assert_allclose(got.sum(), 1.0) and np.testing.assert_array_equal(posterior_weights(np, wt, v, rh, 0.0), wt)
    assert got[0, 3] == 0 and got[0, 0] > wt[0, 0] and got[0, 1] < wt[0, 1]
