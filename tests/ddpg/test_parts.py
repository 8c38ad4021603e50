"""The learner's parts: soft target update, TD target, sample-time reward, replay ring buffer, OU noise."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from mjx_protamer.agents.ddpg import losses, noise, replay
from mjx_protamer.agents.ddpg.config import NoiseConfig
from mjx_protamer.agents.ddpg.networks import Actor, Critic


def test_soft_update_is_polyak_average():
    target = {"w": jnp.zeros((3,)), "b": {"c": jnp.full((2,), 10.0)}}
    online = {"w": jnp.ones((3,)), "b": {"c": jnp.zeros((2,))}}
    new = losses.soft_update(target, online, tau=0.001)
    np.testing.assert_allclose(new["w"], 0.001)
    np.testing.assert_allclose(new["b"]["c"], 9.99, rtol=1e-6)
    # Repeated updates converge to the online network: after n steps the gap is (1 - tau)^n.
    t = target
    for _ in range(100):
        t = losses.soft_update(t, online, tau=0.05)
    np.testing.assert_allclose(t["w"], 1 - 0.95**100, rtol=1e-5)
    # tau = 1 copies.
    np.testing.assert_allclose(losses.soft_update(target, online, 1.0)["w"], 1.0)


def test_td_target_bootstraps_through_truncation_not_termination():
    reward = jnp.array([1.0, 1.0])
    next_q = jnp.array([10.0, 10.0])
    y = losses.td_target(reward, next_q, terminal=jnp.array([0.0, 1.0]), gamma=0.9)
    np.testing.assert_allclose(y, [10.0, 1.0])


def _batch(n=5, obs=3, act=2, terms=2):
    k = jax.random.split(jax.random.PRNGKey(0), 4)
    return replay.Transition(
        obs=jax.random.normal(k[0], (n, obs)),
        action=jax.random.uniform(k[1], (n, act), minval=-1, maxval=1),
        reward_terms=jax.random.normal(k[2], (n, terms)),
        next_obs=jax.random.normal(k[3], (n, obs)),
        terminal=jnp.zeros((n,)),
    )


def test_relabel_combines_stored_terms_and_injected_human_reward():
    batch = _batch()
    weights = jnp.array([2.0, -1.0])
    intrinsic = batch.reward_terms @ weights
    np.testing.assert_allclose(losses.relabel(batch, weights, 1.0, 0.1), intrinsic, rtol=1e-6)

    def human(params, obs, action):  # a "model" whose prediction depends on its parameters
        return params["scale"] * jnp.sum(action, axis=-1)

    for scale in (0.0, 3.0):
        r = losses.relabel(batch, weights, 0.5, 0.1, human, {"scale": jnp.float32(scale)})
        np.testing.assert_allclose(r, 0.5 * intrinsic + 0.1 * scale * jnp.sum(batch.action, -1), rtol=1e-5)


def test_replay_wraps_around_and_samples_filled_rows_only():
    buf = replay.init(capacity=5, obs_size=1, action_size=1, num_terms=1)

    def rows(values):
        v = jnp.asarray(values, jnp.float32)
        return replay.Transition(v[:, None], v[:, None], v[:, None], v[:, None], v)

    buf = replay.add(buf, rows([1, 2]))
    assert int(buf.ptr) == 2 and int(buf.size) == 2
    sampled = replay.sample(buf, jax.random.PRNGKey(0), 200)
    assert set(np.asarray(sampled.obs[:, 0]).tolist()) == {1.0, 2.0}

    buf = replay.add(buf, rows([3, 4]))
    buf = replay.add(buf, rows([5, 6]))  # 6 overwrites row 0
    assert int(buf.ptr) == 1 and int(buf.size) == 5
    np.testing.assert_array_equal(buf.data.obs[:, 0], [6, 2, 3, 4, 5])
    buf = replay.add(buf, rows([7, 8, 9]))
    np.testing.assert_array_equal(buf.data.terminal, [6, 7, 8, 9, 5])
    assert int(buf.ptr) == 4 and int(buf.size) == 5
    sampled = replay.sample(buf, jax.random.PRNGKey(1), 500)
    assert set(np.asarray(sampled.action[:, 0]).tolist()) == {5.0, 6.0, 7.0, 8.0, 9.0}


def test_newest_keeps_the_latest_transitions_in_order_for_a_smaller_buffer():
    """A fine-tuning session's replay starts with its pretraining run's latest experience."""
    buf = replay.init(capacity=5, obs_size=1, action_size=1, num_terms=1)
    for v in (jnp.arange(1, 5, dtype=jnp.float32), jnp.arange(5, 8, dtype=jnp.float32)):  # ring: 6, 7, 3, 4, 5
        buf = replay.add(buf, replay.Transition(v[:, None], v[:, None], v[:, None], v[:, None], v))
    small = replay.newest(buf, 3)
    np.testing.assert_array_equal(small.data.obs[:, 0], [5, 6, 7])
    assert int(small.size) == 3 and int(small.ptr) == 0 and small.capacity == 3
    big = replay.newest(buf, 8)  # room for more: all 5, oldest first, the rest empty
    np.testing.assert_array_equal(big.data.terminal, [3, 4, 5, 6, 7, 0, 0, 0])
    assert int(big.size) == 5 and int(big.ptr) == 5
    big = replay.add(big, replay.Transition(*(jnp.full((1, 1), 9.0),) * 4, jnp.full((1,), 9.0)))
    assert float(big.data.obs[5, 0]) == 9.0  # new transitions follow the carried ones


def test_ou_noise_mean_reversion_and_stationary_std():
    config = NoiseConfig(kind="ou", theta=0.15, sigma=0.6)
    steps, procs = 4000, 256

    @jax.jit
    def run(x0, rng):
        def body(x, k):
            x = noise.step(config, x, k)
            return x, x
        return jax.lax.scan(body, x0, jax.random.split(rng, steps))[1]

    xs = np.asarray(run(jnp.full((procs,), 5.0), jax.random.PRNGKey(0)))  # (steps, procs)
    # Mean reversion: the mean decays as (1 - theta)^t from the start value 5.
    for t in (1, 5, 10):
        np.testing.assert_allclose(xs[t - 1].mean(), 5.0 * 0.85**t, atol=0.15)
    # Stationary law of the dt = 1 AR(1): mean 0, std sigma / sqrt(2 theta - theta^2) = 1.139.
    tail = xs[200:]
    expected = noise.stationary_std(config)
    assert abs(expected - 0.6 / np.sqrt(0.3 - 0.0225)) < 1e-9
    assert abs(tail.mean()) < 0.05
    assert abs(tail.std() - expected) / expected < 0.03
    # Successive values are correlated with coefficient 1 - theta.
    lag1 = np.mean(tail[1:] * tail[:-1]) / tail.var()
    assert abs(lag1 - 0.85) < 0.02


def test_noise_resets_per_env_and_gaussian_std():
    config = NoiseConfig(kind="ou")
    state = jnp.ones((3, 2))
    reset = noise.reset_done(config, state, jnp.array([0.0, 1.0, 0.0]))
    np.testing.assert_array_equal(reset, [[1, 1], [0, 0], [1, 1]])
    g = NoiseConfig(kind="gaussian", sigma=0.2)
    x = noise.step(g, jnp.zeros((20000,)), jax.random.PRNGKey(3))
    assert abs(float(jnp.std(x)) - 0.2) < 0.01
    assert float(jnp.abs(noise.step(NoiseConfig(kind="none"), x, jax.random.PRNGKey(0))).max()) == 0.0


def test_networks_shapes_and_action_enters_critic_second_layer():
    actor, critic = Actor(action_size=14), Critic()
    obs, act = jnp.zeros((5, 84)), jnp.zeros((5, 14))
    a_params = actor.init(jax.random.PRNGKey(0), obs)
    c_params = critic.init(jax.random.PRNGKey(1), obs, act)
    assert actor.apply(a_params, obs).shape == (5, 14)
    assert critic.apply(c_params, obs, act).shape == (5,)
    shapes = {k: v["kernel"].shape for k, v in c_params["params"].items()}
    assert shapes == {"Dense_0": (84, 400), "Dense_1": (400 + 14, 300), "Dense_2": (300, 1)}
    a_shapes = {k: v["kernel"].shape for k, v in a_params["params"].items()}
    assert a_shapes == {"Dense_0": (84, 400), "Dense_1": (400, 300), "Dense_2": (300, 14)}
    # Small final layers: initial actions and values are near zero.
    x = jax.random.normal(jax.random.PRNGKey(2), (5, 84))
    assert float(jnp.abs(actor.apply(a_params, x)).max()) < 0.1


def test_preact_penalty_is_a_wall_past_the_free_band_and_moves_a_saturated_actor():
    """The hinge penalty is 0 (and its gradient too) while |pre-tanh| <= free, quadratic beyond; a critic
    that is flat in the action leaves only the penalty, which pulls a saturated output back inside."""
    pre = jnp.array([[0.5, -1.9, 3.0, -4.0]])
    actor_apply = lambda p, obs, pre_tanh=False: p["pre"] if pre_tanh else jnp.tanh(p["pre"])
    flat_critic = lambda cp, obs, a: jnp.zeros((a.shape[0],))
    loss = lambda p, free: losses.actor_loss(p, actor_apply, None, flat_critic, jnp.zeros((1, 3)), 0.5, free)
    assert np.isclose(float(loss({"pre": pre}, 2.0)), 0.5 * (1.0 + 4.0) / 4)
    g = jax.grad(loss)({"pre": pre}, 2.0)["pre"]
    np.testing.assert_allclose(g, [[0.0, 0.0, 0.25, -0.5]], atol=1e-7)  # inside the band: no pull toward 0
    assert np.isclose(float(loss({"pre": pre}, 0.0)), 0.5 * float(jnp.mean(pre**2)))  # free 0: the plain L2


def test_quiet_envs_rotate_so_every_env_spends_the_quiet_share_of_its_time_without_noise():
    from mjx_protamer.agents.ddpg.config import NoiseConfig
    from mjx_protamer.agents.ddpg.train import noisy_envs_at

    ids = np.arange(8)
    fixed = NoiseConfig(quiet_fraction=0.25)
    rotating = NoiseConfig(quiet_fraction=0.25, quiet_rotation_steps=10)
    quiet = lambda noise, it: np.flatnonzero(~np.asarray(noisy_envs_at(ids, it, 8, noise))).tolist()
    assert quiet(fixed, 0) == quiet(fixed, 35) == [6, 7]
    assert quiet(rotating, 0) == quiet(rotating, 9) == [6, 7]
    assert quiet(rotating, 10) == [4, 5] and quiet(rotating, 25) == [2, 3] and quiet(rotating, 39) == [0, 1]
    share = np.mean([~np.asarray(noisy_envs_at(ids, it, 8, rotating)) for it in range(40)], axis=0)
    assert share.tolist() == [0.25] * 8
    assert quiet(NoiseConfig(quiet_rotation_steps=10), 10) == []  # no quiet share: nothing to rotate
