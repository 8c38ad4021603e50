"""In-jit DeepTAMER pieces: lag weights match the host credit, window gathering, the device ring."""

import jax
import jax.numpy as jnp
import numpy as np
import optax

from mjx_protamer.human.batched import (draw_credited_steps, draw_silent_steps, reward_model_updates, ring_add,
                                        ring_init)
from mjx_protamer.human.channels import ChannelConfig
from mjx_protamer.human.clock import StepClock
from mjx_protamer.human.credit import CreditAssigner, CreditConfig, lag_weights
from mjx_protamer.human.events import FeedbackEvent
from mjx_protamer.human.reward_model import RewardMLP, reward_fn


def test_lag_weights_match_the_host_credit_on_a_regular_clock():
    """In-jit lag weights from the arrival step = the host credit of an event whose onset is the arrival less
    the channel's utterance and pipeline latency (0 for the other schemes, which take the arrival time)."""
    speech = ChannelConfig("speech")
    for scheme in ("channel", "step_window", "time_window"):
        cfg = CreditConfig(scheme=scheme, min_interval_steps=0)
        clock = StepClock(dt=0.05)
        clock.record_chunk(0, 200, t0=0.0)
        onset = 150 * 0.05 - (speech.arrival_offset_s if scheme == "channel" else 0.0)
        credit, _ = CreditAssigner(cfg, clock, speech).assign(FeedbackEvent(onset, onset, "simulated", 1.0))
        w = lag_weights(cfg, 0.05, speech)
        host = dict(zip(credit.steps, credit.weights))
        jit = {150 - j: float(w[j]) for j in range(len(w)) if w[j] > 0}
        assert host.keys() == jit.keys()
        np.testing.assert_allclose([host[k] for k in sorted(host)], [jit[k] for k in sorted(jit)], rtol=1e-5)


def test_credited_steps_follow_the_lag_weights():
    """The draw the training chunk uses: each event's lags in proportion to their weight, relative to the
    chunk's first step (negative: an earlier chunk), the event's value as target; absent events not ok."""
    T, B = 6, 2
    valid = jnp.zeros((T, B), bool).at[1, 1].set(True).at[4, 0].set(True)
    value = jnp.zeros((T, B)).at[1, 1].set(-1.0).at[4, 0].set(0.5)
    lag_w = jnp.array([0.0, 0.0, 3.0, 1.0])  # lag 2 three times as likely as lag 3; lags 0, 1 never
    rel, env, ok, target, n = jax.jit(lambda k: draw_credited_steps(value, valid, lag_w, k, 3, 4000))(
        jax.random.PRNGKey(0))
    rel, env, ok, target = (np.asarray(x) for x in (rel, env, ok, target))
    assert int(n) == 2 and env[:2].tolist() == [1, 0]  # events in (step, env) order: (1, 1) then (4, 0)
    assert ok[:2].all() and not ok[2].any()
    assert set(np.unique(rel[0])) == {-1, -2} and set(np.unique(rel[1])) == {2, 1}
    assert abs((rel[1] == 2).mean() - 0.75) < 0.03  # step 4 - lag 2
    assert (target[0] == -1).all() and (target[1] == 0.5).all()
    none = draw_credited_steps(value, valid, jnp.zeros(4), jax.random.PRNGKey(0), 3, 4)[2]
    assert not np.asarray(none).any()  # no credit weight (DDPG alone): nothing credited


def test_silent_steps_are_those_no_arrival_could_credit():
    """A step is silent when no feedback arrived at any lag with credit weight after it; each chunk judges the T
    steps whose window closes inside it, and envs without a teacher are never silent."""
    H, T, B = 3, 4, 2
    lag_w = jnp.array([0.0, 0.5, 0.5, 0.0])  # an arrival credits the steps 1 and 2 before it
    arrived = jnp.zeros((H + T, B), bool).at[4, 0].set(True).at[5, 1].set(True)
    active = jnp.array([True, False])
    rel, env, ok, n = jax.jit(lambda k: draw_silent_steps(arrived, active, lag_w, k, H, 2000))(jax.random.PRNGKey(0))
    rel, env, ok = (np.asarray(x) for x in (rel, env, ok))
    assert int(n) == 2
    # judged rows p = 1..4 (their last lag, p + 2, lands in the chunk's rows 3..6); the arrival at row 4 credits
    # rows 2 and 3; rows 1 and 4 (chunk steps -2 and 1) heard nothing; env 1 has no teacher
    assert ok.all() and set(env.tolist()) == {0}
    assert set(rel.tolist()) == {-2, 1} and abs((rel == 1).mean() - 0.5) < 0.05
    everywhere = jnp.zeros((H + T, B), bool).at[2:, 0].set(True)
    assert not np.asarray(draw_silent_steps(everywhere, active, lag_w, jax.random.PRNGKey(0), H, 8)[2]).any()
    none = draw_silent_steps(arrived, active, jnp.zeros(4), jax.random.PRNGKey(0), H, 8)[2]
    assert not np.asarray(none).any()  # no credit weight (DDPG alone): no teacher to be silent

    # with the teacher's attention: a step is silent only if the teacher watched every step whose feedback could
    # have arrived in its window (rows p - 1 .. p + 1 here); looking away at row 5 unmakes row 4's silence
    watching = jnp.ones((H + T, B), bool).at[5, 0].set(False)
    rel, env, ok, n = draw_silent_steps(arrived, active, lag_w, jax.random.PRNGKey(0), H, 200, watching)
    assert int(n) == 1 and set(np.asarray(rel).tolist()) == {-2} and set(np.asarray(env).tolist()) == {0}


def test_ring_keeps_only_weighted_rows_and_wraps():
    ring = ring_init(4, 1, 1)
    x = jnp.arange(6, dtype=jnp.float32)[:, None]
    ring = ring_add(ring, x, x, jnp.array([1.0, 0, 1, 0, 1, 0]), x[:, 0])
    assert int(ring.size) == 3 and int(ring.ptr) == 3
    np.testing.assert_allclose(ring.obs[:3, 0], [0, 2, 4])
    ring = ring_add(ring, x + 10, x, jnp.array([1.0, 1, 0, 0, 0, 0]), x[:, 0])
    assert int(ring.size) == 4 and int(ring.ptr) == 1
    np.testing.assert_allclose(ring.obs[:, 0], [11, 2, 4, 10])


def test_reward_model_updates_fit_the_credited_targets_in_jit():
    """The updates the training chunk uses: fresh rows first, then ring replay; a weightless minibatch
    changes nothing."""
    apply = reward_fn((32,))
    params = RewardMLP((32,)).init(jax.random.PRNGKey(0), jnp.zeros((1, 2)), jnp.zeros((1, 1)))
    opt = optax.adam(1e-2)
    obs = jax.random.normal(jax.random.PRNGKey(1), (64, 2))
    act = jnp.zeros((64, 1))
    target = jnp.sign(obs[:, 0])
    rows = (obs, act, jnp.ones(64), target)
    ring = ring_add(ring_init(256, 2, 1), *rows)
    upd = jax.jit(lambda p, o, k: reward_model_updates(apply, opt, p, o, ring, rows, k, 100, 100, 32, 64))
    new, _, losses, live = upd(params, opt.init(params), jax.random.PRNGKey(2))
    assert bool(np.asarray(live).all()) and float(losses[-20:].mean()) < 0.5
    assert np.corrcoef(np.asarray(apply(new, obs, act)), np.asarray(target))[0, 1] > 0.9
    empty = (obs, act, jnp.zeros(64), target)
    same, _, _, live = reward_model_updates(apply, opt, params, opt.init(params), ring_init(256, 2, 1), empty,
                                            jax.random.PRNGKey(3), 5, 5, 32, 64)
    assert not np.asarray(live).any()
    jax.tree.map(lambda a, b: np.testing.assert_array_equal(a, b), same, params)


def test_fresh_steps_draw_the_new_rows_and_replay_steps_the_ring():
    """The first `n_fresh` steps learn the chunk's new rows only and the next `n_replay` the ring only (separate
    scans, so a replay step never pays for the fresh rows' draw); `fresh_count` leaves the surplus fresh steps
    idle and the replay steps live."""
    apply = reward_fn((32,))
    params = RewardMLP((32,)).init(jax.random.PRNGKey(0), jnp.zeros((1, 2)), jnp.zeros((1, 1)))
    opt = optax.adam(1e-2)
    new_obs = jax.random.normal(jax.random.PRNGKey(1), (64, 2)) + 3.0
    old_obs = jax.random.normal(jax.random.PRNGKey(2), (64, 2)) - 3.0
    act = jnp.zeros((64, 1))
    rows = (new_obs, act, jnp.ones(64), jnp.ones(64))  # the new rows are praised
    ring = ring_add(ring_init(256, 2, 1), old_obs, act, jnp.ones(64), -jnp.ones(64))  # the ring scolds
    run = lambda n_fresh, n_replay, count=None: reward_model_updates(
        apply, opt, params, opt.init(params), ring, rows, jax.random.PRNGKey(3), n_fresh, n_replay, 32, 64,
        fresh_count=count)
    fresh_only, replay_only = run(30, 0)[0], run(0, 30)[0]
    assert float(apply(fresh_only, new_obs, act).mean()) > 0.5
    assert float(apply(replay_only, old_obs, act).mean()) < -0.5
    # replay alone never saw the praised rows, fresh alone never the scolded ones: both stay where they began
    start = lambda o: float(apply(params, o, act).mean())
    assert abs(float(apply(fresh_only, old_obs, act).mean()) - start(old_obs)) < abs(
        float(apply(replay_only, old_obs, act).mean()) - start(old_obs))
    _, _, losses, live = run(5, 3, jnp.int32(2))
    assert losses.shape == (8,)
    np.testing.assert_array_equal(np.asarray(live), [True, True, False, False, False, True, True, True])


def test_balanced_updates_in_jit_weigh_rare_reproach_like_praise():
    """With `balance_max` the in-jit updates scale each row by its sign's factor over the ring: 1 scolded row per
    40 praised ones (overlapping clusters) ends rated lower than without, the praised cluster still high."""
    apply = reward_fn((32,))
    params = RewardMLP((32,)).init(jax.random.PRNGKey(0), jnp.zeros((1, 2)), jnp.zeros((1, 1)))
    opt = optax.adam(1e-3)
    sign = jnp.where(jnp.arange(1640) % 41 == 40, -1.0, 1.0)
    obs = jax.random.normal(jax.random.PRNGKey(1), (1640, 2)) + jnp.stack([2.0 * sign, 0 * sign], -1)
    act = jnp.zeros((1640, 1))
    rows = (obs, act, jnp.ones(1640), sign)
    ring = ring_add(ring_init(2048, 2, 1), *rows)
    probe = jnp.array([[-2.0, 0.0], [2.0, 0.0]])
    rated = {}
    for balance in (None, 10.0):
        new, *_ = jax.jit(lambda p, o, k: reward_model_updates(apply, opt, p, o, ring, rows, k, 0, 100, 64, 64,
                                                               balance))(params, opt.init(params), jax.random.PRNGKey(2))
        rated[balance] = np.asarray(apply(new, probe, jnp.zeros((2, 1))))
    assert rated[10.0][0] < rated[None][0] - 0.25, rated  # measured: -0.35 plain, -0.72 balanced
    assert rated[10.0][1] > 0.5, rated


def test_the_runs_step_size_decay_scales_each_reward_model_update():
    """`scale` (step_size.decay_scale at the chunk's iteration) multiplies Adam's step: one update at scale 0.25
    moves every parameter a quarter as far as at 1; the schedule is 1 before `decay_from`, then linear to the
    final fraction at the run's last iteration."""
    from mjx_protamer.step_size import decay_scale

    apply = reward_fn((32,))
    params = RewardMLP((32,)).init(jax.random.PRNGKey(0), jnp.zeros((1, 2)), jnp.zeros((1, 1)))
    opt = optax.adam(1e-2)
    obs = jax.random.normal(jax.random.PRNGKey(1), (64, 2))
    rows = (obs, jnp.zeros((64, 1)), jnp.ones(64), jnp.sign(obs[:, 0]))
    ring = ring_init(256, 2, 1)
    moved = {s: jax.tree.map(lambda a, b: np.asarray(a) - np.asarray(b),
                             reward_model_updates(apply, opt, params, opt.init(params), ring, rows,
                                                  jax.random.PRNGKey(2), 1, 0, 32, 64, None, s)[0], params)
             for s in (1.0, 0.25)}
    for full, quarter in zip(jax.tree.leaves(moved[1.0]), jax.tree.leaves(moved[0.25])):
        np.testing.assert_allclose(quarter, 0.25 * full, rtol=1e-3, atol=1e-7)  # float32 rounding of p + u
    assert np.abs(jax.tree.leaves(moved[1.0])[0]).max() > 1e-3  # the update moved something
    got = [float(decay_scale(i, 100, 0.5, 0.1)) for i in (0, 50, 75, 100, 200)]
    np.testing.assert_allclose(got, [1.0, 1.0, 0.55, 0.1, 0.1], rtol=1e-6)
    assert float(decay_scale(99, 100, 0.5, 1.0)) == 1.0
