"""The one rollout: what `keep=` names comes back, the start row prepends the reset state, bad names are refused."""

import jax
import numpy as np
import pytest

from mjx_protamer.agents.ddpg.evaluate import make_rollout
from mjx_protamer.agents.ddpg.networks import Actor
from mjx_protamer.envs.toy import PointReachEnv


def _setup():
    env = PointReachEnv()
    params = Actor(action_size=env.action_size, hidden=(8,)).init(jax.random.PRNGKey(0), np.zeros(env.observation_size))
    return env, params, jax.random.split(jax.random.PRNGKey(1), 3)


def test_keep_returns_exactly_the_named_signals_and_start_prepends_the_reset_state():
    env, params, keys = _setup()
    steps = make_rollout(env, 6, (8,), keep=("obs", "action", "reward", "pose", "region_mask"))(params, keys)
    assert set(steps) == {"obs", "action", "reward", "pose", "region_mask"}
    assert steps["obs"].shape == (3, 6, env.observation_size) and steps["region_mask"].shape == (3, 6, 8)
    pictured = make_rollout(env, 6, (8,), keep=("pose", "reward"), start=True)(params, keys)
    assert pictured["pose"].shape == (3, 7, 4)
    reset = jax.vmap(env.reset)(keys)
    np.testing.assert_array_equal(pictured["pose"][:, 0, :2], reset.data["pos"])  # the start, then every step
    np.testing.assert_array_equal(pictured["pose"][:, 1:], steps["pose"])
    np.testing.assert_array_equal(pictured["reward"][:, 1:], steps["reward"])
    # the pose a step reached is where the next observation says the agent is (obs = pos, goal, goal - pos)
    np.testing.assert_array_equal(steps["pose"][:, :-1, :2], steps["obs"][:, 1:, :2])


@pytest.mark.parametrize("keep,start", [(("speed",), False), (("action",), True), ((), False)])
def test_unknown_or_stateless_signals_are_refused(keep, start):
    env, _, _ = _setup()
    with pytest.raises(ValueError, match="rollout keep="):
        make_rollout(env, 6, (8,), keep=keep, start=start)
