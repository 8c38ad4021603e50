"""The native MuJoCo backend (`NativeSelfTouchEnv`): its physics against MJX and its signals against the twin.

What each test pins down:
- the contact sensors give exactly MuJoCo's own contacts (`d.contact` + `mj_contactForce`), deepest first;
- the host senses a batch at once (only the worlds in contact) exactly as `sensing.sense` senses each
  world, including worlds with more contacts than the capacity (the deepest count);
- the jitted native env (callback inside `lax.scan`, resets from the pool) reproduces the NumPy twin's
  trajectory: physics bit for bit (both are `mj_step` in float64), so qpos agrees to float32 rounding and
  the observation, regions and reward (sensing in float32 here, float64 there) to float32 precision;
- native and MJX physics agree on the same state and action within the solver's tolerance (converged
  solver, `conftest.CONVERGED_*`); at the shipping 2 iterations they differ as test_equivalence says;
- NaN isolation, auto-reset and the episode limit behave as in the MJX env (test_env_core);
- `env.backend` resolves to native on a CPU, is validated, and is recorded in the run's config.
"""

from __future__ import annotations

import numpy as np
import pytest

from mjx_protamer.envs.twin import native_contacts

K = 10
BLOCK = K + 3
STEPS = 150


@pytest.fixture(scope="module")
def native_env():
    from mjx_protamer.envs.config import EnvConfig
    from mjx_protamer.envs.native_env import NativeSelfTouchEnv

    # A short action filter (20 ms): the low-pass is exercised on every step, and held random targets are
    # still reached within their 25 steps, so the trajectory makes enough self-contacts to compare.
    # Habituation on a 50 ms / 100 ms scale: the familiarity trace in the observation and the reward moves
    # within the compared steps.
    return NativeSelfTouchEnv(EnvConfig(reset_noise_steps=0, action_filter_s=0.02, habituation_s=0.05,
                                        recovery_s=0.1))


def _held_actions(seed, steps, hold=25):
    rng = np.random.default_rng(seed)
    return np.repeat(rng.uniform(-1, 1, (steps // hold + 1, 14)), hold, axis=0)[:steps].astype(np.float32)


def _random_states(m, model, n, seed):
    rng = np.random.default_rng(seed)
    lo, hi = m.jnt_range[:, 0], m.jnt_range[:, 1]
    for _ in range(n):
        yield (rng.uniform(lo, hi), rng.normal(size=m.nv),
               model.action_to_ctrl(np, rng.uniform(-1, 1, m.nu)), np.zeros(m.nv))


def test_contact_sensors_give_mujocos_contacts(native_env):
    """Random poses (many deep, unusual contacts): the sensor slots hold every active self-contact of
    `d.contact` (same geom pair, penetration, position, normal force), deepest first."""
    import mujoco

    phys = native_env.physics
    m = phys.mj_model
    d = mujoco.MjData(m)
    hand, region = native_env.model.sensing.geom_hand, native_env.model.sensing.geom_region
    states = list(_random_states(m, native_env.model, 300, seed=4))
    geom, pos, dist, force = phys.forward_contacts(phys.state_rows(*(np.array(x) for x in zip(*states))))
    with_contact = 0
    for i, (qpos, qvel, ctrl, ws) in enumerate(states):
        d.qpos[:], d.qvel[:], d.ctrl[:], d.qacc_warmstart[:] = qpos, qvel, ctrl, ws
        mujoco.mj_forward(m, d)
        g, p, x, f = native_contacts(m, d)
        self_contact = [j for j in range(len(x)) if x[j] < 0 and min(region[g[j]]) >= 0 and max(hand[g[j]]) >= 0]
        self_contact = sorted(self_contact, key=lambda j: x[j])[: phys.n_contacts]
        active = dist[i] < 0
        assert active.sum() == len(self_contact), i
        with_contact += bool(self_contact)
        for slot, j in enumerate(self_contact):
            assert sorted(geom[i, slot]) == sorted(g[j])
            np.testing.assert_allclose(dist[i, slot], x[j], rtol=1e-6, atol=1e-9)
            np.testing.assert_allclose(pos[i, slot], p[j], rtol=1e-6, atol=1e-7)
            np.testing.assert_allclose(force[i, slot], f[j], rtol=1e-5, atol=1e-5)
    assert with_contact >= 30, with_contact


@pytest.mark.parametrize("n_contacts", [8, 2])
def test_host_sensing_of_a_batch_equals_sense_per_world(native_env, n_contacts):
    """The callback senses a batch at once, only the worlds in contact, grouped by their number of
    contacts: on 300 random poses (worlds with 0 to 8 self-contacts) its touch features and region masks
    equal `sensing.sense` run world by world on that world's `n_contacts` deepest contacts, bit for bit.
    With capacity 2, worlds with more contacts exist and count only their 2 deepest (MJX's rule)."""
    import mujoco

    from mjx_protamer.envs import sensing
    from mjx_protamer.envs.native_env import unpack
    from mjx_protamer.envs.native_physics import FEW_CONTACTS, NativePhysics

    phys = NativePhysics(native_env.model, native_env.config.physics, n_contacts=n_contacts,
                         touch_k=native_env.config.k)
    m = phys.mj_model
    rows = phys.state_rows(*(np.array(x) for x in zip(*_random_states(m, native_env.model, 300, seed=4))))
    out = unpack(phys, *phys.forward(rows))
    geom, pos, dist, force = phys.forward_contacts(rows)
    counts = np.count_nonzero(dist < 0, axis=1)
    assert ((counts > 0) & (counts <= FEW_CONTACTS)).any()
    if n_contacts > FEW_CONTACTS:
        assert (counts > FEW_CONTACTS).any(), "the group of worlds with many contacts was not exercised"
    else:
        d = mujoco.MjData(m)
        over = 0
        for row in rows:
            mujoco.mj_setState(m, d, row, mujoco.mjtState.mjSTATE_INTEGRATION)
            mujoco.mj_forward(m, d)
            over += np.count_nonzero(d.sensordata.reshape(-1, 8)[:, 4] < 0) > n_contacts
        assert over >= 5, f"only {over} worlds with more than {n_contacts} contacts"
    tables = native_env.model.sensing.as_xp(np)
    for i, row in enumerate(rows):
        d = mujoco.MjData(m)
        mujoco.mj_setState(m, d, row, mujoco.mjtState.mjSTATE_INTEGRATION)
        mujoco.mj_forward(m, d)
        touch, main, extended = sensing.sense(np, tables, native_env.config.k, geom[i], pos[i], dist[i], force[i],
                                              d.geom_xpos, d.geom_xmat.reshape(-1, 3, 3))
        np.testing.assert_array_equal(out.touch[i], touch.astype(np.float32), err_msg=f"world {i}")
        np.testing.assert_array_equal(out.region_mask[i], main, err_msg=f"world {i}")
        np.testing.assert_array_equal(out.extended_region_mask[i], extended, err_msg=f"world {i}")
    assert (np.abs(out.touch).sum(axis=1) > 0).sum() >= 30


@pytest.fixture(scope="module")
def native_roll(native_env, trajectory_fn):
    """Jitted: (reset key, actions (T, 14)) -> per-step obs, qpos, reward, region masks, nan resets."""
    return trajectory_fn(native_env)


@pytest.mark.parametrize("seed", [3, 5])  # held-target sequences that make contact through the 20 ms filter
def test_trajectory_equals_the_twin(native_env, native_roll, seed):
    """150 held-random-action steps from the settled start (shipping solver settings), through the jitted
    env: qpos equal to float32 rounding of the same float64 trajectory; touch features too (sensed in
    float64 on the host, as the twin senses); proprioception to 1e-5 and reward to 1e-3 (float32 in JAX);
    region masks identical on every step."""
    import jax

    from mjx_protamer.envs.twin import SelfTouchTwinEnv

    twin = SelfTouchTwinEnv(native_env.config)
    actions = _held_actions(seed, STEPS)
    obs0_j, (obs_j, qpos_j, rew_j, reg_j, nan_j) = native_roll(jax.random.PRNGKey(seed), actions)
    obs0_t, _ = twin.reset(seed=0)
    np.testing.assert_allclose(obs0_j, obs0_t, atol=1e-5)
    contact_steps, familiar = 0, 0.0
    for t, a in enumerate(actions):
        o, r, _, _, info = twin.step(a)
        np.testing.assert_allclose(qpos_j[t], twin.data.qpos, rtol=1e-6, atol=1e-6, err_msg=f"step {t}")
        b = 4 * BLOCK
        # Touch is sensed on the host in float64 from the same contacts, as the twin does: equal to float32
        # rounding of the result.
        np.testing.assert_allclose(obs_j[t, :b], o[:b], rtol=1e-6, atol=1e-6 * np.abs(o[:b]).max() + 1e-7,
                                   err_msg=f"step {t}")
        np.testing.assert_allclose(obs_j[t, b:], o[b:], atol=1e-5 * max(1.0, np.abs(o[b:]).max()), err_msg=f"step {t}")
        np.testing.assert_allclose(rew_j[t], r, atol=1e-3 * max(1.0, abs(r)), err_msg=f"step {t}")
        np.testing.assert_array_equal(reg_j[t], info["region_mask"], err_msg=f"step {t}")
        contact_steps += bool(info["self_contact"])
        familiar = max(familiar, float(o[-8:].max()))  # the familiarity trace ends the observation
    assert not nan_j.any()
    assert contact_steps >= 5, f"only {contact_steps} steps with a self-contact: the comparison saw too little"
    assert familiar > 0.5, f"familiarity reached only {familiar}: the habituation trace was not compared"


def test_one_step_agrees_with_mjx_at_the_converged_solver(eq_mjx_env, eq_twin):
    """The same state and action stepped by MJX (float32) and natively (float64), solver run to convergence
    (50 Newton / 25 line-search iterations), over 36 held-target states with contacts. On >= 90% of the
    states qpos within 1e-5 rad and qvel within 1e-3 rad/s [measured when written: median 1e-7 rad and
    2e-6 rad/s, 35 of 36 states within 4e-4 rad/s]; on every state qpos within 5e-4 rad and qvel within
    0.1 rad/s [max 9e-5 rad, 0.018 rad/s: a state where a contact at near-zero penetration is active in
    one precision and not the other, or MJX's deepest-8 contact selection drops one]."""
    import jax
    import jax.numpy as jnp
    from mjx_protamer.envs.native_env import unpack
    from mjx_protamer.envs.native_physics import NativePhysics

    env = eq_mjx_env
    phys = NativePhysics(env.model, env.config.physics, n_contacts=env.config.physics.max_contact_points,
                         touch_k=env.config.k)
    rng = np.random.default_rng(5)
    states, actions, touching = [], [], 0
    for ep in range(3):
        eq_twin.reset(seed=ep)
        a = rng.uniform(-1, 1, 14).astype(np.float32)
        for i in range(120):
            d = eq_twin.data
            if i % 10 == 9:
                states.append((d.qpos.copy(), d.qvel.copy(), d.ctrl.copy(), d.qacc_warmstart.copy()))
                actions.append(a.copy())
                touching += d.ncon > 0
            if i % 40 == 39:
                a = rng.uniform(-1, 1, 14).astype(np.float32)
            eq_twin.step(a)
    states = [np.array(x) for x in zip(*states)]
    actions = np.array(actions)
    rows = phys.state_rows(*states)
    bits, packed, bad = phys.step(phys.rows_to_bits(rows), actions)
    stepped = unpack(phys, bits, packed)
    qpos_n, qvel_n = stepped.qpos, stepped.qvel

    @jax.jit
    def mjx_step(qpos, qvel, ctrl, ws, action):
        def one(qpos, qvel, ws, action):
            d = env.init_data.replace(qpos=qpos, qvel=qvel, qacc_warmstart=ws)
            d, _ = env._physics_step(d, action)
            return d.qpos, d.qvel
        return jax.vmap(one)(qpos, qvel, ws, action)

    f32 = lambda x: jnp.asarray(x, jnp.float32)  # noqa: E731
    qpos_m, qvel_m = jax.tree.map(np.asarray, mjx_step(*(f32(x) for x in states), f32(actions)))
    assert not bad.any()
    assert touching >= 5
    dq = np.abs(qpos_n - qpos_m).max(axis=1)
    dv = np.abs(qvel_n - qvel_m).max(axis=1)
    assert ((dq <= 1e-5) & (dv <= 1e-3)).mean() >= 0.9, (np.sort(dq)[-5:], np.sort(dv)[-5:])
    assert dq.max() <= 5e-4 and dv.max() <= 0.1, (dq.max(), dv.max())


@pytest.fixture(scope="module")
def batched_native(native_env):
    import jax

    from mjx_protamer.envs.wrappers import wrap_for_training

    benv = wrap_for_training(native_env, episode_length=3)
    return native_env, jax.jit(benv.reset), jax.jit(benv.step)


def test_nan_state_resets_that_env_only_and_is_counted(batched_native, tmp_path, monkeypatch):
    """A world whose state turns NaN is restored to the settled start and ends its episode; the other
    world steps on exactly as it would have."""
    import jax
    import jax.numpy as jnp

    monkeypatch.chdir(tmp_path)  # MuJoCo writes its bad-state warning to MUJOCO_LOG.TXT in the cwd

    env, reset, step = batched_native
    phys = env.physics
    state = reset(jax.random.split(jax.random.PRNGKey(0), 2))
    clean = step(state, jnp.zeros((2, 14)))
    rows = phys.bits_to_rows(np.asarray(state.data.state)).copy()
    rows[1, phys._qvel_slice] = np.nan
    poisoned = state.replace(data=state.data.replace(state=jnp.asarray(phys.rows_to_bits(rows))))
    nstate = step(poisoned, jnp.zeros((2, 14)))
    assert nstate.metrics["nan_reset"].tolist() == [0.0, 1.0]
    assert nstate.done.tolist() == [0.0, 1.0]
    assert np.isfinite(np.asarray(nstate.obs)).all() and np.isfinite(np.asarray(nstate.info["final_obs"])).all()
    assert np.isfinite(phys.bits_to_rows(np.asarray(nstate.data.state))).all()
    assert int(nstate.info["episodes"][1]) == 1 and int(nstate.info["episodes"][0]) == 0
    np.testing.assert_array_equal(np.asarray(nstate.data.state[0]), np.asarray(clean.data.state[0]))
    np.testing.assert_array_equal(np.asarray(nstate.obs[0]), np.asarray(clean.obs[0]))


def test_episode_limit_truncates_and_auto_resets(batched_native):
    import jax
    import jax.numpy as jnp

    env, reset, step = batched_native
    state = reset(jax.random.split(jax.random.PRNGKey(1), 2))
    assert state.obs.shape == (2, env.observation_size) == (2, 94)  # 84 + the oscillator + 8 familiarities
    for _ in range(3):
        state = step(state, jnp.ones((2, 14)) * 0.3)
    assert state.done.tolist() == [1.0, 1.0] and state.info["truncation"].tolist() == [1.0, 1.0]
    assert state.info["steps"].tolist() == [0, 0]
    assert not np.allclose(np.asarray(state.obs), np.asarray(state.info["final_obs"])), "obs is the reset obs"
    # A reset is a pool start: its physics state is that start's row, bit for bit.
    starts = env._start_states.data.state
    for i in range(2):
        assert (np.asarray(starts) == np.asarray(state.data.state[i])).all(axis=1).any()


def test_backend_choice_resolves_validates_and_is_recorded(capsys):
    import jax

    from mjx_protamer.agents.ddpg.config import PretrainConfig
    from mjx_protamer.config import ConfigError, load_config, to_dict
    from mjx_protamer.experiments.env_factory import resolve_backend, with_resolved_backend

    from mjx_protamer.experiments.env_factory import NATIVE_MIN_ENVS

    expected = "native" if jax.default_backend() == "cpu" else "mjx"
    assert resolve_backend("auto") == expected
    assert resolve_backend("auto", num_envs=NATIVE_MIN_ENVS) == expected
    assert resolve_backend("auto", num_envs=1) == "mjx", "one world steps faster on MJX (callback overhead)"
    assert resolve_backend("native", num_envs=1) == "native"
    assert resolve_backend("mjx") == "mjx" and resolve_backend("native") == "native"
    config = load_config(PretrainConfig, None, [])
    assert config.env.backend == "auto"
    resolved = with_resolved_backend(config)
    assert to_dict(resolved)["env"]["backend"] == expected
    assert f"physics backend: {expected} (auto" in capsys.readouterr().out
    single = with_resolved_backend(load_config(PretrainConfig, None, ["train.num_envs=1"]))
    assert single.env.backend == "mjx"
    forced = with_resolved_backend(load_config(PretrainConfig, None, ["env.backend=mjx"]))
    assert forced.env.backend == "mjx"
    with pytest.raises(ConfigError, match=r"'env.backend': must be one of auto, mjx, native, got 'gpu'"):
        load_config(PretrainConfig, None, ["env.backend=gpu"])
