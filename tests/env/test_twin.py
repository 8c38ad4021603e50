"""The NumPy twin as a Gymnasium env: the checker passes, a seed fixes the trajectory, bad input fails."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from mjx_protamer.envs.twin import SelfTouchTwinEnv


@pytest.fixture(scope="module")
def twin():
    return SelfTouchTwinEnv()


def test_check_env_passes(twin):
    from gymnasium.utils.env_checker import check_env

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*infinity.*")  # unbounded observation Box: intended
        check_env(twin, skip_render_check=True)
    assert twin.observation_space.shape == (84 + 2 + 8,) and twin.observation_space.dtype == np.float32
    assert twin.action_space.shape == (14,) and twin.action_space.dtype == np.float32
    assert (twin.action_space.low == -1).all() and (twin.action_space.high == 1).all()


def _rollout(env, seed, steps=120):
    obs, info = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    out = [obs]
    for i in range(steps):
        if i % 40 == 0:
            a = rng.uniform(-1, 1, 14).astype(np.float32)
        obs, reward, terminated, truncated, info = env.step(a)
        assert terminated is False and not truncated
        out.append(np.append(obs, reward))
    return out, info


def test_seed_fixes_trajectory(twin):
    a, info = _rollout(twin, 7)
    b, _ = _rollout(twin, 7)
    c, _ = _rollout(twin, 8)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert not np.array_equal(a[0], c[0]), "different seeds should start from different states"
    assert set(info) >= {"reward_terms", "self_contact", "region_mask", "extended_region_mask", "arm_speed",
                         "nan_reset"}
    assert info["reward_terms"].shape == (7,) and info["region_mask"].shape == (8,)
    assert info["extended_region_mask"].shape == (4,)


def test_truncates_at_episode_length():
    from mjx_protamer.envs.config import EnvConfig

    env = SelfTouchTwinEnv(EnvConfig(episode_length=5))
    env.reset(seed=0)
    flags = [env.step(np.zeros(14, np.float32))[3] for _ in range(5)]
    assert flags == [False] * 4 + [True]


def test_nan_state_resets_and_is_reported(twin, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MuJoCo logs the bad-state warning to ./MUJOCO_LOG.TXT
    twin.reset(seed=0)
    twin.data.qvel[:] = np.nan
    obs, reward, terminated, truncated, info = twin.step(np.zeros(14, np.float32))
    assert info["nan_reset"] == 1.0 and truncated and not terminated
    assert np.all(np.isfinite(obs)) and np.isfinite(reward)
    np.testing.assert_allclose(twin.data.qpos, twin.model.init_qpos)


def test_wrong_action_shape_names_the_shape(twin):
    twin.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(14,\)"):
        twin.step(np.zeros(13, np.float32))
