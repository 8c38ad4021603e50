"""The compiled self-touch model: MjModel, sensing tables, index sets and the settled start state.

Shared by the MJX env and the native-MuJoCo twin so both read the same joints, actuators and tables.
Built once per configuration (cached): the touch tables take about two seconds.

Episode starts: the spec's reset is "settle, then a few small random actions so starts differ". Doing
that inside every reset would put `reset_noise_steps` physics steps into each reset, and with batched
envs whose episodes end at different times a reset happens almost every step. So the starts are made
once, natively: a pool of `reset_pool_size` states, each the settled pose followed by its own
`reset_noise_steps` random targets (seeded by `reset_pool_seed`); a reset draws one of them.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import mujoco
import numpy as np

from mjx_protamer.envs import body
from mjx_protamer.envs.config import EnvConfig
from mjx_protamer.envs.sensing import SensingTables, build_sensing_tables
from mjx_protamer.envs.touch import build_touch_tables

SETTLE_STEPS = 400  # 2 s at rest targets before the first episode


@dataclasses.dataclass(frozen=True)
class SelfTouchModel:
    mj_model: mujoco.MjModel
    sensing: SensingTables
    qpos_idx: np.ndarray
    qvel_idx: np.ndarray
    torque_idx: np.ndarray
    speed_idx: np.ndarray
    ctrl_lo: np.ndarray
    ctrl_hi: np.ndarray
    rest_ctrl: np.ndarray
    init_qpos: np.ndarray
    init_qvel: np.ndarray
    init_warmstart: np.ndarray
    start_qpos: np.ndarray  # (P, nq) the pool of episode starts
    start_qvel: np.ndarray  # (P, nv)
    start_ctrl: np.ndarray  # (P, nu)
    start_warmstart: np.ndarray  # (P, nv)

    def action_to_ctrl(self, xp, action):
        """Policy action in [-1, 1] -> position targets, affinely onto each joint's range."""
        a = xp.clip(action, -1.0, 1.0)
        return self.ctrl_lo + 0.5 * (a + 1.0) * (self.ctrl_hi - self.ctrl_lo)

    def next_ctrl(self, xp, prev_ctrl, action, smoothing: float):
        """The servo targets of the next step: the action's targets through a first-order low-pass.

        `smoothing` is exp(-dt / tau) (0: the targets jump to the action, the paper's servos). Stiff position
        servos at 200 Hz turn any jump of the target into a fast jerk, so a policy (or exploration noise)
        that changes its action every 5 ms moves the arm at 10-20 rad/s; the low-pass makes the commanded
        motion human-scale while the servos still track what is commanded.
        """
        return smoothing * prev_ctrl + (1.0 - smoothing) * self.action_to_ctrl(xp, action)


def _name_ids(m: mujoco.MjModel, obj: mujoco.mjtObj, names) -> np.ndarray:
    ids = [mujoco.mj_name2id(m, obj, n) for n in names]
    missing = [n for n, i in zip(names, ids) if i < 0]
    if missing:
        raise ValueError(f"model has no {obj.name} named {missing}")
    return np.array(ids)


@functools.lru_cache(maxsize=8)
def build_model(config: EnvConfig) -> SelfTouchModel:
    m = mujoco.MjModel.from_xml_string(body.infant_xml(config.physics))
    geom_names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, i) for i in range(m.ngeom)]
    touch = build_touch_tables(k=config.k, spacing_hand=config.touch.spacing_hand,
                               spacing_fingers=config.touch.spacing_fingers,
                               spread_factor=config.touch.spread_factor)
    sensing = build_sensing_tables(geom_names, touch)

    jnt = mujoco.mjtObj.mjOBJ_JOINT
    qpos_idx = m.jnt_qposadr[_name_ids(m, jnt, config.qpos_joints)]
    qvel_idx = m.jnt_dofadr[_name_ids(m, jnt, config.qvel_joints)]
    speed_idx = m.jnt_dofadr[_name_ids(m, jnt, config.speed_joints)]
    torque_idx = _name_ids(m, mujoco.mjtObj.mjOBJ_ACTUATOR, config.torque_actuators)
    act_ids = _name_ids(m, mujoco.mjtObj.mjOBJ_ACTUATOR, body.ACTUATED_JOINTS)
    assert (act_ids == np.arange(m.nu)).all(), "actuators must be declared in action order"

    # Settle at the rest pose with natively simulated physics; every episode starts from here.
    d = mujoco.MjData(m)
    rest = np.array([math.radians(body.REST_POSE_DEG[n.split("_", 1)[1]]) for n in body.ACTUATED_JOINTS])
    for name in ("left_fingers", "right_fingers"):
        d.qpos[m.jnt_qposadr[mujoco.mj_name2id(m, jnt, name)]] = math.radians(body.FINGER_REST_DEG)
    for i, name in enumerate(body.ACTUATED_JOINTS):
        d.qpos[m.jnt_qposadr[mujoco.mj_name2id(m, jnt, name)]] = rest[i]
    d.ctrl[:] = rest
    for _ in range(SETTLE_STEPS):
        mujoco.mj_step(m, d)
    settled = (d.qpos.copy(), d.qvel.copy(), d.qacc_warmstart.copy())
    pool = _start_pool(m, d, rest, config)
    mujoco.mj_resetData(m, d)
    d.qpos[:], d.qvel[:], d.qacc_warmstart[:] = settled
    return SelfTouchModel(
        mj_model=m, sensing=sensing, qpos_idx=qpos_idx, qvel_idx=qvel_idx, torque_idx=torque_idx,
        speed_idx=speed_idx, ctrl_lo=m.actuator_ctrlrange[:, 0].copy(), ctrl_hi=m.actuator_ctrlrange[:, 1].copy(),
        rest_ctrl=rest, init_qpos=settled[0], init_qvel=settled[1], init_warmstart=settled[2],
        start_qpos=pool[0], start_qvel=pool[1], start_ctrl=pool[2], start_warmstart=pool[3],
    )


def _start_pool(m: mujoco.MjModel, settled: mujoco.MjData, rest: np.ndarray, config: EnvConfig):
    rng = np.random.default_rng(config.reset_pool_seed)
    half_range = 0.5 * (m.actuator_ctrlrange[:, 1] - m.actuator_ctrlrange[:, 0])
    out = [[], [], [], []]
    d = mujoco.MjData(m)
    for _ in range(config.reset_pool_size):
        mujoco.mj_copyData(d, m, settled)
        d.ctrl[:] = rest
        noise = rng.standard_normal((config.reset_noise_steps, m.nu))
        targets = np.clip(rest + config.reset_noise_scale * half_range * noise,
                          m.actuator_ctrlrange[:, 0], m.actuator_ctrlrange[:, 1])
        for ctrl in targets:
            d.ctrl[:] = ctrl
            mujoco.mj_step(m, d)
        for store, value in zip(out, (d.qpos, d.qvel, d.ctrl, d.qacc_warmstart)):
            store.append(value.copy())
    return tuple(np.stack(x) for x in out)


def observe(xp, model: SelfTouchModel, touch, qpos, qvel, actuator_force, time=0.0, oscillator_hz: float = 0.0,
            familiarity=None):
    """The observation: [s_left(k), s_right(k), s_qpos, s_qvel, s_torque] (the paper's 84 dims), then, with
    an oscillator, [sin, cos] of its phase 2 pi f t (t the episode time): a rhythm generator the policy can
    drive movement from (see EnvConfig.oscillator_hz); then, with habituation, the 8 regions' familiarity
    (EnvConfig.habituation_s)."""
    parts = [touch, qpos[model.qpos_idx], qvel[model.qvel_idx], actuator_force[model.torque_idx]]
    if oscillator_hz > 0:
        phase = 2.0 * math.pi * oscillator_hz * time
        parts.append(xp.stack([xp.sin(phase), xp.cos(phase)]).astype(touch.dtype))
    if familiarity is not None:
        parts.append(xp.asarray(familiarity, dtype=touch.dtype))
    return xp.concatenate(parts)


def arm_speed(xp, model: SelfTouchModel, qvel):
    """Norm of the arm joints' speeds (rad/s): the freeze metric and the movement-band reward."""
    return xp.sqrt(xp.sum(qvel[model.speed_idx] ** 2))
