"""The infant rendered offscreen with MuJoCo's renderer, its touched regions highlighted.

A pose is the model's full `qpos`. Live, the learner only hands over observations and actions; the
observation holds the arm joints, wrist flexion and fingers (`EnvConfig.qpos_joints`) but not wrist
rotation and ulnar deviation, which `chunk_poses` takes from the servo targets: the actions through the
env's own low-pass (`model.next_ctrl`), carried from one chunk to the next. A faithful picture, not the
exact state: those two wrist joints lag their targets while moving (up to about 0.5 rad, 30 degrees,
right after a full-range jump of the action; within 0.1 rad a quarter second later), and after an
episode reset the carried targets are off until the low-pass has caught up.
The touched regions of a pose come from native MuJoCo contacts with the env's own sensing rule.
"""

from __future__ import annotations

import mujoco
import numpy as np

from mjx_protamer.envs import body
from mjx_protamer.envs.config import EnvConfig
from mjx_protamer.envs.twin import SelfTouchTwinEnv

TOUCHED_NOW = (1.0, 0.25, 0.1, 1.0)  # orange-red
TOUCHED_BEFORE = (1.0, 0.8, 0.2, 1.0)  # amber


class InfantScene:
    region_names = body.REGIONS

    def __init__(self, config: EnvConfig | None = None, width: int = 480, height: int = 480):
        self.twin = SelfTouchTwinEnv(config or EnvConfig())
        self.model = self.twin.model
        self.m = self.twin.mj_model
        self.data = mujoco.MjData(self.m)
        self.renderer = mujoco.Renderer(self.m, height, width)
        self.camera = mujoco.MjvCamera()
        self.camera.lookat[:] = (0.17, 0.0, 0.05)
        self.camera.distance = 0.9
        self.camera.azimuth = 0.0  # from beyond the feet, head at the top of the picture
        self.camera.elevation = -58.0
        self.geom_region = np.asarray(self.model.sensing.geom_region)
        jnt = mujoco.mjtObj.mjOBJ_JOINT
        in_obs = set(int(i) for i in self.model.qpos_idx)
        self._target_only = [(a, int(self.m.jnt_qposadr[mujoco.mj_name2id(self.m, jnt, name)]))
                             for a, name in enumerate(body.ACTUATED_JOINTS)
                             if int(self.m.jnt_qposadr[mujoco.mj_name2id(self.m, jnt, name)]) not in in_obs]
        k = self.twin.config.k
        self._qpos_at = 4 * (k + 3)
        self._ctrl: np.ndarray | None = None  # servo targets after the last chunk_poses step

    def start_pose(self) -> np.ndarray:
        return np.asarray(self.model.init_qpos, np.float64).copy()

    def pose_from_obs(self, obs: np.ndarray, ctrl: np.ndarray) -> np.ndarray:
        """The pose of one step: the observed joints, and the others at their servo targets `ctrl`."""
        qpos = self.start_pose()
        idx = self.model.qpos_idx
        qpos[idx] = np.asarray(obs, np.float64)[self._qpos_at:self._qpos_at + len(idx)]
        for a, adr in self._target_only:
            qpos[adr] = ctrl[a]
        return qpos

    def chunk_poses(self, obs: np.ndarray, actions: np.ndarray, continues: bool) -> np.ndarray:
        """(n, nq) poses of a chunk's steps; `continues`: the chunk follows the previous one, whose last
        servo targets the low-pass starts from (else from the rest pose's)."""
        ctrl = self._ctrl if continues and self._ctrl is not None else np.asarray(self.model.rest_ctrl, np.float64)
        smoothing = self.twin.config.action_smoothing
        poses = []
        for o, a in zip(obs, actions):
            ctrl = self.model.next_ctrl(np, ctrl, np.asarray(a, np.float64), smoothing)
            poses.append(self.pose_from_obs(o, ctrl))
        self._ctrl = ctrl
        return np.stack(poses) if poses else np.zeros((0, self.m.nq))

    def touched(self, pose: np.ndarray) -> np.ndarray:
        """The main regions (8,) a hand touches in this pose (native contacts, the env's rule)."""
        self.twin.set_state(pose, np.zeros(self.m.nv), self.model.rest_ctrl)
        return np.asarray(self.twin.sense()[1], bool)

    def frame(self, pose: np.ndarray, now=None, before=None) -> np.ndarray:
        """RGB uint8 (H, W, 3): regions touched `now` in red, `before` (so far) in amber."""
        self.data.qpos[:] = pose
        mujoco.mj_kinematics(self.m, self.data)
        self.renderer.update_scene(self.data, camera=self.camera)
        now = np.zeros(len(self.region_names), bool) if now is None else np.asarray(now, bool)
        before = np.zeros_like(now) if before is None else np.asarray(before, bool)
        scene = self.renderer.scene
        for j in range(scene.ngeom):
            g = scene.geoms[j]
            if g.objtype != mujoco.mjtObj.mjOBJ_GEOM:
                continue
            r = self.geom_region[g.objid]
            if 0 <= r < len(now) and now[r]:
                g.rgba[:] = TOUCHED_NOW
            elif 0 <= r < len(before) and before[r]:
                g.rgba[:] = TOUCHED_BEFORE
        return self.renderer.render().copy()

    def colored_frame(self, rgba_by_region: np.ndarray) -> np.ndarray:
        """The rest pose with each main region's geoms in its own colour (rows of (8, 4) RGBA): body maps."""
        self.data.qpos[:] = self.start_pose()
        mujoco.mj_kinematics(self.m, self.data)
        self.renderer.update_scene(self.data, camera=self.camera)
        scene = self.renderer.scene
        for j in range(scene.ngeom):
            g = scene.geoms[j]
            if g.objtype == mujoco.mjtObj.mjOBJ_GEOM and 0 <= self.geom_region[g.objid] < len(rgba_by_region):
                g.rgba[:] = rgba_by_region[self.geom_region[g.objid]]
        return self.renderer.render().copy()

    def close(self) -> None:
        self.renderer.close()
