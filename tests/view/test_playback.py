"""The live view never makes the learner wait: slow rendering skips steps, a full hand-over queue drops."""

from __future__ import annotations

import time

import numpy as np


class SlowScene:
    """A scene that takes 50 ms a frame (a software renderer on a busy machine)."""

    region_names = ("a", "b")

    def __init__(self):
        self.drawn: list[float] = []

    def chunk_poses(self, obs, actions, continues):
        return np.asarray(obs)

    def touched(self, pose):
        return np.array([pose[0] > 0.5, False])

    def frame(self, pose, now=None, before=None):
        time.sleep(0.05)
        self.drawn.append(float(pose[0]))
        return np.full((32, 32, 3), int(pose[0] * 255), np.uint8)

    def close(self):
        pass


def _snapshot(first_step, n=200, dt=0.005, t0=None, value=0.0):
    obs = np.full((n, 1), value, np.float32)
    obs[:, 0] += np.arange(n) / (10 * n)
    return {"first_step": first_step, "t0": time.time() if t0 is None else t0, "dt": dt, "obs": obs,
            "action": np.zeros((n, 1), np.float32), "r_hat": np.linspace(-1, 1, n), "status": {"events": 3},
            "last_event": None}


def test_a_slow_renderer_skips_steps_in_real_time_instead_of_queueing_them():
    from mjx_protamer.view.playback import Player

    scene = SlowScene()
    player = Player(lambda: scene, max_fps=100).start()
    try:
        player.submit(_snapshot(0))  # 200 steps of 5 ms: one second of real time
        time.sleep(1.2)
        # about 20 frames for 200 due steps: the rest were skipped, none waits in a queue
        assert 3 <= len(scene.drawn) <= 30 and player.skipped >= 150
        seq, jpeg = player.latest()
        assert seq == len(scene.drawn) and jpeg[:2] == b"\xff\xd8"  # a JPEG
        # a newer chunk replaces the old one at once
        player.submit(_snapshot(200, value=0.9))
        end = time.time() + 5
        while scene.drawn[-1] < 0.9 and time.time() < end:
            time.sleep(0.05)
        assert scene.drawn[-1] >= 0.9
        status = player.status_message()
        assert status["events"] == 3 and status["chunk_first_step"] == 200 and status["regions_now"] == ["a"]
        assert 0 < len(status["r_hat"]) <= 250  # the last 5 s of predictions, thinned for the page
    finally:
        player.stop()


def test_offering_chunks_to_a_busy_view_never_blocks_the_learner():
    from mjx_protamer.agents.ddpg.config import PretrainConfig
    from mjx_protamer.human.queue import FeedbackQueue
    from mjx_protamer.view.live import LiveView

    view = LiveView("web", PretrainConfig(env_name="toy"), FeedbackQueue())
    # not started: nobody reads; the learner's hand-over must still return at once
    t = time.perf_counter()
    results = [view.offer(_snapshot(i * 200)) for i in range(50)]
    assert time.perf_counter() - t < 1.0
    assert view.offered == 50 and view.dropped == 50 and not any(results)


def test_window_view_without_a_display_is_a_clear_error(monkeypatch):
    import pytest

    from mjx_protamer.agents.ddpg.config import PretrainConfig
    from mjx_protamer.human.queue import FeedbackQueue
    from mjx_protamer.view.live import LiveView

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(RuntimeError, match="needs a display .* use --view web"):
        LiveView("window", PretrainConfig(), FeedbackQueue())


def test_the_view_process_draws_at_a_lower_priority_than_the_learner():
    """On a small machine the page's renderer must take what the learner leaves, not the spare time the pacer
    turns into updates (docs/human_feedback.md, the pace of a live session)."""
    import os

    from mjx_protamer.agents.ddpg.config import PretrainConfig
    from mjx_protamer.human.queue import FeedbackQueue
    from mjx_protamer.view.live import VIEW_NICE, LiveView

    queue = FeedbackQueue()  # the session keeps it; the child unpickles it after start() returns
    view = LiveView("web", PretrainConfig(env_name="toy"), queue)
    try:
        assert view.start().startswith("http://127.0.0.1:")
        learner = os.getpriority(os.PRIO_PROCESS, 0)
        assert os.getpriority(os.PRIO_PROCESS, view.process.pid) == min(19, learner + VIEW_NICE)
    finally:
        view.close()
