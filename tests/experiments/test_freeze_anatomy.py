"""`protamer analyze freeze-anatomy`: it reads the speed and torque blocks where the env writes them, and counts a
servo pushing at its clip and an action at the wall."""

from types import SimpleNamespace

import numpy as np

from mjx_protamer.analyze import freeze_anatomy
from mjx_protamer.envs.config import EnvConfig
from mjx_protamer.envs.model import observe


def test_layout_finds_the_arm_speeds_and_torques_where_observe_puts_them():
    env = EnvConfig()
    model = SimpleNamespace(qpos_idx=np.arange(len(env.qpos_joints)), qvel_idx=np.arange(len(env.qvel_joints)),
                            torque_idx=np.arange(len(env.torque_actuators)))
    qvel = 100.0 + np.arange(len(env.qvel_joints))
    torque = 200.0 + np.arange(len(env.torque_actuators))
    obs = observe(np, model, np.zeros(4 * (env.k + 3)), np.zeros(len(env.qpos_joints)), qvel, torque,
                  oscillator_hz=env.oscillator_hz, familiarity=np.zeros(8))
    assert obs.shape == (env.observation_size,)
    lay = freeze_anatomy.obs_layout(env)
    assert obs[lay["torque"]].tolist() == torque.tolist()
    speed_in_qvel = [env.qvel_joints.index(n) for n in env.speed_joints]
    assert obs[lay["speed"]].tolist() == qvel[speed_in_qvel].tolist()
    # the same joints the freeze clause of the rules reads ("obs_norm:64:68,70:74")
    assert lay["speed"].tolist() == list(range(64, 68)) + list(range(70, 74))
    assert freeze_anatomy.max_torques(env).tolist() == [1.8, 4.0, 2.5, 3.6] * 2


def test_a_servo_at_its_clip_and_an_action_at_the_wall_are_counted_and_nothing_else():
    env = EnvConfig()
    lay, tmax = freeze_anatomy.obs_layout(env), freeze_anatomy.max_torques(env)
    obs = np.zeros((2, env.observation_size))
    obs[0, lay["torque"]] = -tmax  # every arm servo pushing at its clip
    obs[1, lay["torque"]] = 0.9 * tmax  # below it
    action = np.zeros((2, 14))
    action[0, :7] = 0.97
    action[1, :] = 0.9
    both = freeze_anatomy.part(np.array([True, True]), action, obs, lay, tmax, None)
    assert both["torques_clipped"] == 0.5 and both["actions_at_wall"] == 0.25 and "r_hat" not in both
    assert freeze_anatomy.part(np.array([False, False]), action, obs, lay, tmax, None) is None
    assert freeze_anatomy.runs_of(np.array([1, 1, 0, 1, 0, 0, 1, 1, 1], bool)).tolist() == [2, 1, 3]


def test_the_critic_slope_the_actor_feels_is_damped_by_tanh_and_outward_pushes_are_counted():
    env = EnvConfig()
    lay, tmax = freeze_anatomy.obs_layout(env), freeze_anatomy.max_torques(env)
    obs = np.zeros((2, env.observation_size))
    action = np.zeros((2, 14))
    action[0, 0] = 0.99  # at the wall
    action[1, 0] = -0.99
    grad = np.zeros((2, 14))
    grad[:, 0] = 2.0  # Q rises with a[0]: outward for the first state, inward for the second
    q = np.array([1.0, 3.0])
    best = np.array([5.0, 3.0])  # a far action the critic rates 4 higher for the first state, none for the second
    out = freeze_anatomy.part(np.array([True, True]), action, obs, lay, tmax, None, (q, grad, best))
    assert out["q"] == 2.0 and out["q_slope"] == 2.0 and out["q_gain_random"] == 2.0
    assert out["actor_slope"] == round(2.0 * (1 - 0.99 ** 2), 3)  # tanh passes 2% of the critic's slope
    assert out["outward_at_wall"] == 0.5
