"""The NumPy twin of the self-touch env: native MuJoCo (`mujoco.MjData`, float64) as a Gymnasium env.

Same model (`build_model(config).mj_model`), same observation, region and reward code as the MJX env
(`sensing.sense`, `reward_terms` and `observe` called with `xp = numpy`); only the physics differs:
native C MuJoCo in float64 instead of MJX in float32. Contacts come from `d.contact[:d.ncon]`, their
normal force from `mujoco.mj_contactForce` (component 0 of the contact-frame force, which for the
pyramidal cone is the sum of the pyramid edge forces, as the MJX env sums them).

Differences from the MJX env that are the simulators', not ours:
- MJX keeps only the deepest `max_contact_points` contacts per condim group; native keeps all.
- Native capsule-capsule collisions may give two contacts for near-parallel capsules; MJX gives one.
- The constraint solver runs few iterations (config), so the two solvers' forces differ a little.

Step semantics follow the MJX env exactly: as `mjx.step`, `mujoco.mj_step` runs forward (kinematics,
contacts, constraint forces, actuator forces) at the current state and then integrates, so the touch
features and torques of a step come from the forward pass at the pre-step positions while qpos and qvel
are the integrated ones; the twin reads `MjData` right after `mj_step`, as the MJX env reads `mjx.Data`.

Episode semantics follow the MJX env: reset loads one of the model's pool of episode starts (the
settled pose after its own `reset_noise_steps` random targets; see model.py), drawn with the NumPy RNG
seeded through `reset(seed=)`; one `step` is one physics step. `terminated` is always False
(the task has no terminal state); `truncated` is True at `episode_length` steps and when a diverged
(NaN) physics state was replaced by the settled start state, which `info["nan_reset"]` reports.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import mujoco
import numpy as np

from mjx_protamer.envs import sensing
from mjx_protamer.envs.config import REWARD_TERMS, EnvConfig
from mjx_protamer.envs.model import arm_speed, build_model, observe
from mjx_protamer.envs.reward import familiarity_signals, reward_terms


def native_contacts(m: mujoco.MjModel, d: mujoco.MjData):
    """Active native contacts as (geom pairs (n, 2), positions (n, 3), penetration (n,), normal force (n,))."""
    n = d.ncon
    if n == 0:
        return np.zeros((0, 2), np.int32), np.zeros((0, 3)), np.zeros(0), np.zeros(0)
    con = d.contact
    geom = np.asarray(con.geom[:n], np.int32).reshape(n, 2)
    pos = np.asarray(con.pos[:n], np.float64).reshape(n, 3)
    dist = np.asarray(con.dist[:n], np.float64).reshape(n)
    force = np.zeros(n)
    f6 = np.zeros(6)
    for i in range(n):
        mujoco.mj_contactForce(m, d, i, f6)
        force[i] = f6[0]
    return geom, pos, dist, force


class SelfTouchTwinEnv(gym.Env):
    """Gymnasium env on native MuJoCo with the MJX env's observation, regions, reward and resets."""

    metadata = {"render_modes": []}

    def __init__(self, config: EnvConfig | None = None):
        self.config = config or EnvConfig()
        self.config.validate()
        self.model = build_model(self.config)
        self.mj_model = self.model.mj_model
        self.data = mujoco.MjData(self.mj_model)
        self._tables = self.model.sensing.as_xp(np)
        self._weights = np.asarray(self.config.reward.weights(), np.float64)
        self.reward_term_names = REWARD_TERMS
        self.action_size = self.mj_model.nu
        self.observation_size = self.config.observation_size
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (self.observation_size,), np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (self.action_size,), np.float32)
        self._steps = 0
        self._prev_touch = np.zeros(4 * (self.config.k + 3))
        self._prev_regions = np.zeros(sensing.N_REGIONS, bool)
        self._familiarity = np.zeros(sensing.N_REGIONS)

    # --- physics state ------------------------------------------------------------------------------
    def _set_start_state(self) -> None:
        """The settled start state every episode begins from (the MJX env's `init_data`)."""
        m, d = self.mj_model, self.data
        mujoco.mj_resetData(m, d)
        d.qpos[:] = self.model.init_qpos
        d.qvel[:] = self.model.init_qvel
        d.ctrl[:] = self.model.rest_ctrl
        d.qacc_warmstart[:] = self.model.init_warmstart
        mujoco.mj_forward(m, d)

    def set_state(self, qpos, qvel, ctrl, qacc_warmstart=None, act=None) -> None:
        """Load a physics state and run `mj_forward` (positions, contacts, constraint forces)."""
        m, d = self.mj_model, self.data
        d.qpos[:] = qpos
        d.qvel[:] = qvel
        d.ctrl[:] = ctrl
        if act is not None and m.na:
            d.act[:] = act
        d.qacc_warmstart[:] = 0.0 if qacc_warmstart is None else qacc_warmstart
        mujoco.mj_forward(m, d)

    # --- observation, regions, reward of the current (forwarded) state --------------------------------
    def sense(self):
        """Touch features, main region mask (8,) and extended region mask (4,) of the current state."""
        geom, pos, dist, normal = native_contacts(self.mj_model, self.data)
        return sensing.sense(np, self._tables, self.config.k, geom, pos, dist, normal,
                             self.data.geom_xpos, self.data.geom_xmat.reshape(-1, 3, 3))

    def signals(self, prev_touch=None, prev_regions=None, action=None, familiarity=None) -> dict[str, Any]:
        """Everything the env derives from the current physics state (float64), as the MJX env does.

        prev_touch / prev_regions default to this state's own (novelty 0, region term stale), the
        action to zeros, the familiarity trace before this step to zeros. Returns obs, reward,
        reward_terms, touch, region_mask, extended_region_mask, self_contact, arm_speed, familiarity (after).
        """
        d = self.data
        touch, regions, extended = self.sense()
        prev_touch = touch if prev_touch is None else np.asarray(prev_touch, np.float64)
        prev_regions = regions if prev_regions is None else np.asarray(prev_regions, bool)
        action = np.zeros(self.action_size) if action is None else np.asarray(action, np.float64)
        familiarity = np.zeros(len(regions)) if familiarity is None else np.asarray(familiarity, np.float64)
        read, after = familiarity_signals(np, self.config, familiarity, regions)
        speed = arm_speed(np, self.model, d.qvel)
        terms = reward_terms(np, self.config.reward, touch, prev_touch, regions, prev_regions, speed,
                             d.actuator_force, action, read)
        obs = observe(np, self.model, touch, d.qpos, d.qvel, d.actuator_force, d.time, self.config.oscillator_hz,
                      after)
        after = familiarity if after is None else after
        return {
            "obs": obs, "reward": float(terms @ self._weights), "reward_terms": terms, "touch": touch,
            "region_mask": regions, "extended_region_mask": extended,
            "self_contact": float(np.any(regions)), "arm_speed": float(speed), "familiarity": after,
        }

    def evaluate_state(self, qpos, qvel, ctrl, qacc_warmstart=None, act=None, prev_touch=None,
                       prev_regions=None, action=None, familiarity=None) -> dict[str, Any]:
        """`set_state` then `signals`: the equivalence tests' entry point (see tests/env)."""
        self.set_state(qpos, qvel, ctrl, qacc_warmstart, act)
        return self.signals(prev_touch, prev_regions, action, familiarity)

    def _bad_state_warnings(self) -> tuple[int, ...]:
        w = self.data.warning
        return tuple(int(w[i].number) for i in (mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL,
                                                mujoco.mjtWarning.mjWARN_BADQACC))

    # --- the Gymnasium API ------------------------------------------------------------------------------
    def _info(self, s: dict[str, Any], nan_reset: bool) -> dict[str, Any]:
        return {
            "reward_terms": s["reward_terms"], "self_contact": s["self_contact"],
            "region_mask": s["region_mask"].astype(np.float32),
            "extended_region_mask": s["extended_region_mask"].astype(np.float32),
            "arm_speed": s["arm_speed"], "nan_reset": float(nan_reset),
        }

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        m, d = self.mj_model, self.data
        # An episode starts from one of the model's pool of settled, randomly perturbed states
        # (model.py), as in the MJX env.
        i = int(self.np_random.integers(self.config.reset_pool_size))
        mujoco.mj_resetData(m, d)
        self.set_state(self.model.start_qpos[i], self.model.start_qvel[i], self.model.start_ctrl[i],
                       self.model.start_warmstart[i])
        s = self.signals()
        s["reward_terms"] = np.zeros_like(s["reward_terms"])
        self._prev_touch, self._prev_regions, self._familiarity = s["touch"], s["region_mask"], s["familiarity"]
        self._steps = 0
        return s["obs"].astype(np.float32), self._info(s, False)

    def step(self, action):
        action = np.asarray(action, np.float64)
        if action.shape != (self.action_size,):
            raise ValueError(f"action must have shape ({self.action_size},), got {action.shape}")
        m, d = self.mj_model, self.data
        d.ctrl[:] = self.model.next_ctrl(np, d.ctrl, action, self.config.action_smoothing)
        warnings = self._bad_state_warnings()
        mujoco.mj_step(m, d)
        # Native MuJoCo catches a diverged state itself (it resets to qpos0 and counts a warning);
        # either way the twin restores the settled start state, as the MJX env does.
        bad = (self._bad_state_warnings() != warnings
               or not (np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel))))
        if bad:
            self._set_start_state()
        s = self.signals(self._prev_touch, self._prev_regions, action, self._familiarity)
        if bad:  # the MJX env zeroes a diverged step's outputs; its episode ends either way
            s["familiarity"] = np.zeros_like(s["familiarity"])
        self._prev_touch, self._prev_regions, self._familiarity = s["touch"], s["region_mask"], s["familiarity"]
        self._steps += 1
        truncated = bad or self._steps >= self.config.episode_length
        return s["obs"].astype(np.float32), s["reward"], False, truncated, self._info(s, bad)
