"""Playback of the learner's chunks at real-time pace, in the view process's render thread.

The learner hands over one snapshot per chunk (its steps' observations and actions, the reward
model's predictions, its status). The player shows the step that is due now: step k of a chunk shown
from wall time t0 is due at t0 + k * dt, so when rendering falls behind, steps are skipped (frames
dropped), never queued; a newer chunk replaces an older one at once.
"""

from __future__ import annotations

import io
import threading
import time
from collections import deque

import numpy as np

from mjx_protamer.view.caption import draw_caption


class Player:
    """Turns snapshots into JPEG frames; `latest()` is what the page shows (overwritten, never queued)."""

    def __init__(self, scene_factory, max_fps: float = 25.0, history_s: float = 5.0, jpeg_quality: int = 80):
        self.scene_factory = scene_factory
        self.min_period = 1.0 / max_fps
        self.history_s = history_s
        self.jpeg_quality = jpeg_quality
        self._lock = threading.Lock()
        self._snapshot: dict | None = None
        self._frame: bytes | None = None
        self.seq = 0  # frames made so far
        self.skipped = 0  # steps that were due but never drawn (rendering behind)
        self.r_hat: deque = deque()  # (step, prediction) over the last history_s seconds
        self.status: dict = {}  # the learner's, from the newest snapshot
        self.shown: dict = {}  # the render thread's: the step on screen and its regions
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.error: str | None = None

    # --- fed by the snapshot reader -------------------------------------------------------------
    def submit(self, snapshot: dict) -> None:
        with self._lock:
            self._snapshot = snapshot
            self.status = dict(snapshot.get("status") or {}, last_event=snapshot.get("last_event"),
                               chunk_first_step=snapshot["first_step"])
            r = snapshot.get("r_hat")
            if r is not None:
                first = snapshot["first_step"]
                self.r_hat.extend((first + i, float(v)) for i, v in enumerate(r))
                keep = int(self.history_s / snapshot["dt"])
                while len(self.r_hat) > keep:
                    self.r_hat.popleft()

    def latest(self) -> tuple[int, bytes | None]:
        with self._lock:
            return self.seq, self._frame

    def status_message(self) -> dict:
        with self._lock:
            r = list(self.r_hat)
            stride = max(1, -(-len(r) // 250))  # at most 250 points for the page
            return {"type": "status", **self.status, **self.shown, "frames": self.seq, "skipped_steps": self.skipped,
                    "r_hat": [[s, round(v, 4)] for s, v in r[::stride]], "error": self.error}

    # --- the render thread ----------------------------------------------------------------------
    def start(self) -> "Player":
        self._thread = threading.Thread(target=self._run, name="view-render", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)

    def _run(self) -> None:
        try:
            scene = self.scene_factory()  # made here: a GL context belongs to the thread that made it
        except Exception as e:  # shown on the page; the learner goes on
            self.error = f"rendering unavailable: {type(e).__name__}: {e}"
            return
        names = scene.region_names
        so_far = np.zeros(len(names), bool)
        drawn: tuple[int, int] | None = None  # (chunk first step, step index) last drawn
        posed: tuple[int, np.ndarray] | None = None  # (chunk first step, its poses)
        next_step = None  # the step after the last posed chunk
        try:
            while not self._stop.is_set():
                t_frame = time.time()
                with self._lock:
                    snap = self._snapshot
                if snap is None:
                    time.sleep(0.02)
                    continue
                n = len(snap["obs"])
                k = int(np.clip((time.time() - snap["t0"]) / snap["dt"], 0, n - 1))
                key = (snap["first_step"], k)
                if key == drawn:
                    time.sleep(0.01)
                    continue
                if drawn is not None and drawn[0] == key[0]:
                    self.skipped += max(0, k - drawn[1] - 1)
                drawn = key
                if posed is None or posed[0] != snap["first_step"]:
                    posed = (snap["first_step"], scene.chunk_poses(snap["obs"], snap["action"],
                                                                   snap["first_step"] == next_step))
                    next_step = snap["first_step"] + n
                pose = posed[1][k]
                now = scene.touched(pose)
                so_far |= now
                step = snap["first_step"] + k
                touched_now = ", ".join(n_ for n_, on in zip(names, now) if on) or "-"
                img = draw_caption(scene.frame(pose, now, so_far), [
                    f"step {step}  t={step * snap['dt']:.2f} s  touching now: {touched_now}",
                    f"touched so far: {int(so_far.sum())} of {len(names)} regions"])
                jpeg = _jpeg(img, self.jpeg_quality)
                with self._lock:
                    self._frame = jpeg
                    self.seq += 1
                    self.shown = {"regions_now": [n_ for n_, on in zip(names, now) if on], "shown_step": step}
                spare = self.min_period - (time.time() - t_frame)
                if spare > 0:
                    time.sleep(spare)
        except Exception as e:
            self.error = f"rendering stopped: {type(e).__name__}: {e}"
        finally:
            scene.close()


def _jpeg(img: np.ndarray, quality: int) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="JPEG", quality=quality)
    return buf.getvalue()
