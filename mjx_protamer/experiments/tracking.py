"""How well the position servos track their targets (native MuJoCo, the shipping physics settings).

Random targets over each joint's range are held for `hold_s`; the error |q - target| is read at the
end. Targets that the body or floor blocks cannot be reached by any servo, so errors are reported
twice: over all targets, and over held poses with no contact on that arm (free-space tracking).
"""

from __future__ import annotations

import argparse

import mujoco
import numpy as np

from mjx_protamer.envs import body
from mjx_protamer.envs.config import EnvConfig
from mjx_protamer.envs.model import build_model


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--targets", type=int, default=200, help="random held targets (default 200)")
    parser.add_argument("--hold-s", type=float, default=1.0, help="seconds each target is held (default 1)")
    parser.add_argument("--seed", type=int, default=0)


def run_tracking_benchmark(args: argparse.Namespace) -> dict:
    model = build_model(EnvConfig())
    m = model.mj_model
    d = mujoco.MjData(m)
    rng = np.random.default_rng(args.seed)
    jid = m.actuator_trnid[:, 0]
    qadr = m.jnt_qposadr[jid]
    arm_geoms = {side: {mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"{side}_{p}")
                        for p in ("upper_arm", "lower_arm", "palm", "fingers")} for side in ("left", "right")}
    side_of = np.array(["right"] * 4 + ["left"] * 4 + ["right"] * 3 + ["left"] * 3)
    steps = int(round(args.hold_s / m.opt.timestep))
    all_err, free_err = [], []
    for _ in range(args.targets):
        d.qpos[:] = model.init_qpos
        d.qvel[:] = 0
        target = model.ctrl_lo + rng.random(m.nu) * (model.ctrl_hi - model.ctrl_lo)
        d.ctrl[:] = target
        touched = {"left": False, "right": False}
        for _ in range(steps):
            mujoco.mj_step(m, d)
        for c in d.contact[: d.ncon]:
            for side, geoms in arm_geoms.items():
                if c.geom1 in geoms or c.geom2 in geoms:
                    touched[side] = True
        err = np.abs(d.qpos[qadr] - target)
        all_err.append(err)
        free_err.extend(err[i] for i in range(m.nu) if not touched[side_of[i]])
    all_err = np.concatenate(all_err)
    free_err = np.asarray(free_err)
    stats = lambda e: {"median_rad": float(np.median(e)), "p90_rad": float(np.percentile(e, 90)),  # noqa: E731
                       "max_rad": float(e.max()), "n": int(e.size)}
    return {
        "hold_s": args.hold_s, "targets": args.targets,
        "all_targets": stats(all_err), "free_space": stats(free_err),
        "gains": {name: {"kp": s.kp, "kv": s.kv, "armature": s.armature, "max_torque": s.max_torque}
                  for name, s in body.ARM_JOINTS.items()},
    }
