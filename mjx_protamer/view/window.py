"""`--view window`: MuJoCo's passive viewer on a display, showing the newest chunk at real-time pace;
+ / - / 0 typed in the window feed the FeedbackQueue like terminal keys. Runs in the view process."""

from __future__ import annotations

import queue as queue_lib
import time

import numpy as np

from mjx_protamer.human.events import FeedbackEvent

# GLFW key codes: '=' (the + key without shift), keypad +, '-', keypad -, '0', keypad 0
KEYS = {61: 1.0, 334: 1.0, 45: -1.0, 333: -1.0, 48: 0.0, 320: 0.0}


def run_window(run_config, feedback_queue, snapshots, ready) -> None:
    import mujoco
    import mujoco.viewer

    from mjx_protamer.view.scenes import make_scene

    if run_config.env_name == "toy":
        raise RuntimeError("--view window shows the self-touch infant; the toy env has --view web")
    scene = make_scene(run_config, 64, 64)

    def on_key(code: int) -> None:
        if code in KEYS:
            t = time.time()
            ok, reason = feedback_queue.offer(FeedbackEvent(t, t, "keyboard", KEYS[code], {"via": "window"}))
            print(f"[view] {KEYS[code]:+.0f} " + ("accepted" if ok else f"refused: {reason}"), flush=True)

    data = mujoco.MjData(scene.m)
    data.qpos[:] = scene.start_pose()
    mujoco.mj_forward(scene.m, data)
    snap = poses = None
    next_step = None
    with mujoco.viewer.launch_passive(scene.m, data, key_callback=on_key) as viewer:
        ready.put((True, None))
        while viewer.is_running():
            try:
                while True:
                    got = snapshots.get_nowait()
                    if got is None:
                        return
                    poses = scene.chunk_poses(got["obs"], got["action"], got["first_step"] == next_step)
                    snap, next_step = got, got["first_step"] + len(got["obs"])
            except queue_lib.Empty:
                pass
            if snap is not None:
                k = int(np.clip((time.time() - snap["t0"]) / snap["dt"], 0, len(snap["obs"]) - 1))
                data.qpos[:] = poses[k]
                mujoco.mj_forward(scene.m, data)
                viewer.sync()
            time.sleep(1 / 60)
