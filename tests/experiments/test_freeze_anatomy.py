"""scripts/freeze_anatomy.py: it reads the speed and torque blocks where the env writes them, and counts a servo
pushing at its clip and an action at the wall."""

import importlib.util
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from mjx_protamer.envs.config import EnvConfig
from mjx_protamer.envs.model import observe

_spec = importlib.util.spec_from_file_location(
    "freeze_anatomy", Path(__file__).resolve().parents[2] / "scripts" / "freeze_anatomy.py")
script = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(script)


def test_layout_finds_the_arm_speeds_and_torques_where_observe_puts_them():
    env = EnvConfig()
    model = SimpleNamespace(qpos_idx=np.arange(len(env.qpos_joints)), qvel_idx=np.arange(len(env.qvel_joints)),
                            torque_idx=np.arange(len(env.torque_actuators)))
    qvel = 100.0 + np.arange(len(env.qvel_joints))
    torque = 200.0 + np.arange(len(env.torque_actuators))
    obs = observe(np, model, np.zeros(4 * (env.k + 3)), np.zeros(len(env.qpos_joints)), qvel, torque,
                  oscillator_hz=env.oscillator_hz, familiarity=np.zeros(8))
    assert obs.shape == (env.observation_size,)
    lay = script.obs_layout(env)
    assert obs[lay["torque"]].tolist() == torque.tolist()
    speed_in_qvel = [env.qvel_joints.index(n) for n in env.speed_joints]
    assert obs[lay["speed"]].tolist() == qvel[speed_in_qvel].tolist()
    # the same joints the freeze clause of the rules reads ("obs_norm:64:68,70:74")
    assert lay["speed"].tolist() == list(range(64, 68)) + list(range(70, 74))
    assert script.max_torques(env).tolist() == [1.8, 4.0, 2.5, 3.6] * 2


def test_a_servo_at_its_clip_and_an_action_at_the_wall_are_counted_and_nothing_else():
    env = EnvConfig()
    lay, tmax = script.obs_layout(env), script.max_torques(env)
    obs = np.zeros((2, env.observation_size))
    obs[0, lay["torque"]] = -tmax  # every arm servo pushing at its clip
    obs[1, lay["torque"]] = 0.9 * tmax  # below it
    action = np.zeros((2, 14))
    action[0, :7] = 0.97
    action[1, :] = 0.9
    both = script.part(np.array([True, True]), action, obs, lay, tmax, None)
    assert both["torques_clipped"] == 0.5 and both["actions_at_wall"] == 0.25 and "r_hat" not in both
    assert script.part(np.array([False, False]), action, obs, lay, tmax, None) is None
    assert script.runs_of(np.array([1, 1, 0, 1, 0, 0, 1, 1, 1], bool)).tolist() == [2, 1, 3]
