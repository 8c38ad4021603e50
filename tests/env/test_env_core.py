"""The self-touch env's parts: touch tables, sensing rules, reward terms, config errors, wrappers.

NumPy tests first (no compile); the JAX part shares one compiled batched step (B = 2).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mjx_protamer.config import ConfigError, load_config
from mjx_protamer.envs import body
from mjx_protamer.envs.config import EnvConfig, RewardConfig
from mjx_protamer.envs.model import build_model
from mjx_protamer.envs.reward import habituate, reward_terms
from mjx_protamer.envs.sensing import sense
from mjx_protamer.envs.touch import build_touch_tables


@pytest.fixture(scope="module")
def model():
    return build_model(EnvConfig())


@pytest.fixture(scope="module")
def np_tables(model):
    return model.sensing.as_xp(np)


def _gid(model, name):
    import mujoco

    return mujoco.mj_name2id(model.mj_model, mujoco.mjtObj.mjOBJ_GEOM, name)


def _identity_frames(model):
    ngeom = model.mj_model.ngeom
    return np.zeros((ngeom, 3)), np.tile(np.eye(3), (ngeom, 1, 1))


@pytest.mark.parametrize("k", [10, 4])
def test_candidate_tables_hold_exact_nearest_and_spread_sensors(k):
    tables = build_touch_tables(k=k)
    tables.check_candidates(np.random.default_rng(k), n_points=400)


def test_sensor_counts_follow_the_spec_spacing():
    t = build_touch_tables()
    palm = (t.sensor_geom == 0).sum()
    fingers = (t.sensor_geom == 1).sum()
    palm_area = 4 * math.pi * body.PALM_R**2
    finger_area = 2 * math.pi * body.FINGER_R * 2 * body.FINGER_HALF + 4 * math.pi * body.FINGER_R**2
    assert palm == pytest.approx(palm_area / 0.007**2, rel=0.1)
    assert fingers == pytest.approx(finger_area / 0.002**2, rel=0.15)


def _one_contact(model, hand, other, local_point, force, depth=-1e-3):
    geom = np.array([[_gid(model, hand), _gid(model, other)]])
    xpos, xmat = _identity_frames(model)
    return geom, np.array([local_point]), np.array([depth]), np.array([force]), xpos, xmat


def test_single_contact_conserves_normal_force_and_reports_position(model, np_tables):
    rng = np.random.default_rng(0)
    for _ in range(50):
        direction = rng.normal(size=3)
        point = body.PALM_R * direction / np.linalg.norm(direction)
        touch, regions, extended = sense(np, np_tables, 10, *_one_contact(model, "left_palm", "head", point, 2.5))
        palm = touch[0:13]
        np.testing.assert_allclose(palm[:3], point, atol=1e-12)
        # The spread ball (1.5 spacings) holds fewer sensors than the k = 10 nearest: all force is read.
        assert palm[3:].sum() == pytest.approx(2.5, rel=1e-9)
        assert np.all(np.diff(palm[3:]) <= 1e-12) or palm[3] > 0  # nearest sensor first and loaded
        assert np.all(touch[13:] == 0), "only the left palm touched"
        assert regions.tolist() == [r == "head" for r in body.REGIONS]
        assert not extended.any()


def test_multiple_contacts_are_averaged_and_floor_is_ignored(model, np_tables):
    a = np.array([0.0, 0.0, body.FINGER_HALF + body.FINGER_R])  # tip of the finger capsule
    b = np.array([body.FINGER_R, 0.0, 0.0])  # its side
    geom = np.array([[_gid(model, "right_fingers"), _gid(model, "upper_body")],
                     [_gid(model, "hip"), _gid(model, "right_fingers")],
                     [_gid(model, "floor"), _gid(model, "right_fingers")]])
    xpos, xmat = _identity_frames(model)
    touch, regions, _ = sense(np, np_tables, 10, geom, np.stack([a, b, a]), np.array([-1e-3, -1e-3, -1e-3]),
                              np.array([1.0, 3.0, 50.0]), xpos, xmat)
    fingers = touch[39:52]
    np.testing.assert_allclose(fingers[:3], (a + b) / 2, atol=1e-12)
    # The two contacts are far apart: each one's k readings hold its own force; the mean is (1+3)/2.
    assert fingers[3:].sum() == pytest.approx(2.0, rel=1e-9)
    assert set(np.array(body.REGIONS)[regions]) == {"upper_body", "hip"}


def test_inactive_contacts_and_no_contact_give_zeros(model, np_tables):
    touch, regions, extended = sense(np, np_tables, 10, *_one_contact(model, "left_palm", "head",
                                                                          [body.PALM_R, 0, 0], 1.0, depth=+1e-3))
    assert not touch.any() and not regions.any() and not extended.any()


def test_own_lower_arm_is_not_a_self_contact_but_other_arm_is(model, np_tables):
    _, regions, _ = sense(np, np_tables, 10, *_one_contact(model, "left_fingers", "left_lower_arm",
                                                            [body.FINGER_R, 0, 0], 1.0))
    assert not regions.any()
    _, regions, _ = sense(np, np_tables, 10, *_one_contact(model, "left_fingers", "right_lower_arm",
                                                            [body.FINGER_R, 0, 0], 1.0))
    assert np.array(body.REGIONS)[regions].tolist() == ["right_lower_arm"]


def test_hand_to_hand_contact_touches_both_hands(model, np_tables):
    touch, regions, extended = sense(np, np_tables, 10, *_one_contact(model, "left_palm", "right_palm",
                                                                          [body.PALM_R, 0, 0], 1.0))
    assert not regions.any(), "the other hand is an extended region, not one of the 8"
    assert extended.tolist() == [True, True, False, False]
    assert touch[0:13].any() and touch[26:39].any()


def test_reward_terms_match_hand_computed_values():
    cfg = RewardConfig.preset("paper")
    touch = np.array([0.5, -1.5, 2.0])
    prev = np.array([0.5, 0.5, 0.0])
    regions = np.array([True, False, True])
    torque = np.array([1.0, -2.0])
    action = np.array([0.9, -1.0, 0.5])
    terms = reward_terms(np, cfg, touch, prev, regions, np.array([True, False, False]), 2.0, torque, action)
    expected = [4 * math.tanh(0.05 * 4.0), math.sqrt(0 + 4 + 4), 0.3, 0.0, -0.001 * 5, -0.8 * (0.1 + 0.2), 0.0]
    np.testing.assert_allclose(terms, expected, rtol=1e-12)
    # Same regions as before (a subset): -1; too slow and too fast: -0.5 each.
    stale = reward_terms(np, cfg, touch, prev, regions, regions, 0.5, torque, action)
    assert stale[2] == -1.0 and stale[3] == -0.5
    assert reward_terms(np, cfg, touch, prev, regions, regions, 3.5, torque, action)[3] == -0.5


def test_infant_reward_pays_for_touching_not_pressing_hand_computed():
    """The infant preset: contact tanh(2 sum|touch|) (a 1 N touch earns 0.96 of a 20 N press, where the paper's
    4 tanh(0.05 sum) pays 0.2 against 2.5); novelty on tanh(touch / 1 N), at most 1."""
    cfg = RewardConfig()
    assert cfg == RewardConfig.preset("infant") and RewardConfig.preset("paper").contact_scale == 4.0
    z = np.zeros(3)
    light, hard = np.array([1.0, 0, 0]), np.array([20.0, 0, 0])
    c_light = reward_terms(np, cfg, light, light, z > 0, z > 0, 2.0, z, z)[0]
    c_hard = reward_terms(np, cfg, hard, hard, z > 0, z > 0, 2.0, z, z)[0]
    assert c_light == pytest.approx(math.tanh(2.0)) and c_hard == pytest.approx(1.0)
    paper = RewardConfig.preset("paper")
    assert reward_terms(np, paper, light, light, z > 0, z > 0, 2.0, z, z)[0] == pytest.approx(4 * math.tanh(0.05))
    touch, prev = np.array([0.5, -1.5, 2.0]), np.array([0.5, 0.5, 0.0])
    novelty = reward_terms(np, cfg, touch, prev, z > 0, z > 0, 2.0, z, z)[1]
    by_hand = math.sqrt((math.tanh(-1.5) - math.tanh(0.5)) ** 2 + math.tanh(2.0) ** 2)  # 1.57 before the clip
    assert by_hand > 1.0 and novelty == 1.0
    small = reward_terms(np, cfg, np.array([0.1, 0, 0]), z, z > 0, z > 0, 2.0, z, z)[1]
    assert small == pytest.approx(math.tanh(0.1))


def test_habituation_pays_for_unfamiliar_regions_and_familiarity_recovers_hand_computed():
    """A region touched for 1 s at habituation_s 0.5 s is 1 - e^-2 familiar; the term pays 1 - familiarity
    per touched region; 5 s untouched at recovery_s 5 s leaves e^-1 of it."""
    env = EnvConfig(habituation_s=0.5, recovery_s=5.0)
    on, off = env.familiarity_rates()
    assert on == pytest.approx(math.exp(-0.005 / 0.5)) and off == pytest.approx(math.exp(-0.005 / 5.0))
    head = np.zeros(8, bool)
    head[3] = True
    f = np.zeros(8)
    for _ in range(200):  # 1 s on the head
        f = habituate(np, f, head, (on, off))
    np.testing.assert_allclose(f, np.where(head, 1 - math.exp(-2.0), 0.0), rtol=1e-9)
    both = head.copy()
    both[0] = True  # the head again, and the hip for the first time
    z = np.zeros(3)
    term = reward_terms(np, RewardConfig(), z, z, both, both, 2.0, z, np.zeros(14), f)[6]
    assert term == pytest.approx(math.exp(-2.0) + 1.0)
    for _ in range(1000):  # 5 s touching nothing
        f = habituate(np, f, np.zeros(8, bool), (on, off))
    assert f[3] == pytest.approx((1 - math.exp(-2.0)) * math.exp(-1.0), rel=1e-9)
    # Without a trace the term is 0, and the paper's preset does not weigh it.
    assert reward_terms(np, RewardConfig(), z, z, both, both, 2.0, z, np.zeros(14))[6] == 0.0
    assert RewardConfig.preset("paper").habituation == 0.0
    assert EnvConfig(habituation_s=0.5).observation_size == EnvConfig(habituation_s=0.0).observation_size + 8
    with pytest.raises(ConfigError, match="habituation_s"):
        load_config(EnvConfig, None, ["habituation_s=-1"])


def test_reward_preset_by_name_in_a_config(tmp_path):
    assert load_config(EnvConfig, None, ["reward=paper"]).reward == RewardConfig.preset("paper")
    with pytest.raises(ConfigError, match="unknown preset 'babyish'"):
        load_config(EnvConfig, None, ["reward=babyish"])


def test_config_errors_name_the_field(tmp_path):
    with pytest.raises(ConfigError, match="k"):
        load_config(EnvConfig, None, ["k=0"])
    with pytest.raises(ConfigError, match="unknown config key.*physics.iteratons"):
        load_config(EnvConfig, None, ["physics.iteratons=3"])
    with pytest.raises(ConfigError, match="qpos_joints.*left_knee"):
        load_config(EnvConfig, None, ["qpos_joints=[left_knee]"])
    with pytest.raises(ConfigError, match="reward.speed_low"):
        load_config(EnvConfig, None, ["reward.speed_low=5"])
    with pytest.raises(ConfigError, match="physics.self_condim.*1 or 3"):
        load_config(EnvConfig, None, ["physics.self_condim=2"])
    path = tmp_path / "env.yaml"
    path.write_text("k: 6\nreward:\n  energy: 0.0\n")
    cfg = load_config(EnvConfig, path)
    assert cfg.k == 6 and cfg.observation_size == 4 * 9 + 32 + 2 + 8 and cfg.reward.weights()[4] == 0.0  # + oscillator, familiarities


def test_body_model_facts(model):
    m = model.mj_model
    assert m.nu == 14 and m.npair == 48
    assert all(m.geom_contype == 0) and all(m.geom_conaffinity == 0), "only explicit pairs collide"
    # Primitives MJX collides cheaply only: plane, sphere, capsule.
    import mujoco

    allowed = {mujoco.mjtGeom.mjGEOM_PLANE, mujoco.mjtGeom.mjGEOM_SPHERE, mujoco.mjtGeom.mjGEOM_CAPSULE}
    assert set(m.geom_type.tolist()) <= {int(t) for t in allowed}
    names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, i) for i in range(m.nu)]
    assert tuple(names) == body.ACTUATED_JOINTS
    # The settled start is at rest.
    assert np.abs(model.init_qvel).max() < 0.05


# --- JAX: one compiled batched step shared by the tests below ----------------------------------------

@pytest.fixture(scope="module")
def batched():
    import jax

    from mjx_protamer.envs.self_touch import SelfTouchEnv
    from mjx_protamer.envs.wrappers import wrap_for_training

    env = SelfTouchEnv()
    benv = wrap_for_training(env, episode_length=3)
    return env, benv, jax.jit(benv.reset), jax.jit(benv.step)


def test_nan_state_resets_that_env_only_and_is_counted(batched):
    import jax
    import jax.numpy as jnp

    env, _, reset, step = batched
    state = reset(jax.random.split(jax.random.PRNGKey(0), 2))
    poisoned = state.data.replace(qvel=state.data.qvel.at[1].set(jnp.nan))
    state = state.replace(data=poisoned)
    actions = jnp.zeros((2, 14))
    nstate = step(state, actions)
    assert nstate.metrics["nan_reset"].tolist() == [0.0, 1.0]
    assert nstate.done.tolist() == [0.0, 1.0]
    assert np.isfinite(np.asarray(nstate.obs)).all() and np.isfinite(np.asarray(nstate.info["final_obs"])).all()
    assert np.isfinite(np.asarray(nstate.data.qpos)).all()
    assert int(nstate.info["episodes"][1]) == 1 and int(nstate.info["episodes"][0]) == 0
    assert bool(jnp.isfinite(nstate.reward).all())


def test_episode_limit_truncates_and_auto_resets(batched):
    import jax
    import jax.numpy as jnp

    env, _, reset, step = batched
    state = reset(jax.random.split(jax.random.PRNGKey(1), 2))
    assert state.obs.shape == (2, env.observation_size) == (2, 84 + 2 + 8)  # + the oscillator, the familiarities
    actions = jnp.ones((2, 14)) * 0.3
    for t in range(3):
        state = step(state, actions)
    assert state.done.tolist() == [1.0, 1.0] and state.info["truncation"].tolist() == [1.0, 1.0]
    assert state.info["steps"].tolist() == [0, 0], "steps restart after the reset"
    assert not np.allclose(np.asarray(state.obs), np.asarray(state.info["final_obs"])), "obs is the reset obs"
    # Different reset keys per env: the two fresh starts differ.
    assert not np.allclose(np.asarray(state.data.qpos[0]), np.asarray(state.data.qpos[1]))


def test_wrong_action_shape_is_refused(batched):
    import jax
    import jax.numpy as jnp

    env, _, reset, _ = batched
    single = jax.tree.map(lambda x: x[0], reset(jax.random.split(jax.random.PRNGKey(0), 2)))
    with pytest.raises(ValueError, match=r"action must have shape \(14,\)"):
        env.step(single, jnp.zeros(13))


def test_fixed_length_tuple_fields_load(tmp_path):
    import dataclasses

    from mjx_protamer.config import from_dict

    @dataclasses.dataclass(frozen=True)
    class Point:
        xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
        names: tuple[str, ...] = ()

    assert from_dict(Point, {"xyz": [1, 2, 3.5], "names": ["a"]}) == Point((1.0, 2.0, 3.5), ("a",))
    with pytest.raises(ConfigError, match=r"xyz\[1\]"):
        from_dict(Point, {"xyz": [1, "b", 3]})
    with pytest.raises(ConfigError, match="expected 3 items"):
        from_dict(Point, {"xyz": [1, 2]})


def test_a_run_saved_before_habituation_loads_without_it(tmp_path):
    """Saved runs list every field; one written before `habituation_s` existed had an 86-dim observation,
    so its checkpoint needs the trace off, while a run saved today keeps its own value."""
    import yaml

    from mjx_protamer.agents.ddpg.config import PretrainConfig
    from mjx_protamer.config import to_dict
    from mjx_protamer.experiments.run_loader import read_run_config

    saved = to_dict(PretrainConfig())
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(saved))
    assert read_run_config(tmp_path).env.habituation_s == 0.25
    del saved["env"]["habituation_s"]
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(saved))
    old = read_run_config(tmp_path)
    assert old.env.habituation_s == 0.0 and old.env.observation_size == 84 + 2
