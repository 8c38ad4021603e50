"""The toy point-reach env drawn in 2-D (Pillow): the arena, the goal with its reach radius, the point.

Its observation holds the whole state (position, goal), so a live pose is exact. Its eight "regions"
are the goal's octants (envs/toy.py); the one being reached counts as touched.
"""

from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw

from mjx_protamer.envs.toy import ToyEnvConfig


class PointScene:
    region_names = tuple(f"octant_{i}" for i in range(8))

    def __init__(self, config: ToyEnvConfig | None = None, width: int = 480, height: int = 480):
        self.config = config or ToyEnvConfig()
        self.width, self.height = width, height
        self._trail: list[tuple[float, float]] = []
        self._goal = np.full(2, np.nan)

    def start_pose(self) -> np.ndarray:
        return np.zeros(4)

    def chunk_poses(self, obs: np.ndarray, actions: np.ndarray, continues: bool) -> np.ndarray:
        return np.asarray(obs, np.float64)[:, :4].copy()

    def touched(self, pose: np.ndarray) -> np.ndarray:
        pos, goal = pose[:2], pose[2:4]
        out = np.zeros(8, bool)
        if np.linalg.norm(goal - pos) < self.config.reach_radius:
            octant = int(np.floor((np.arctan2(goal[1], goal[0]) + np.pi) / (2 * np.pi) * 8)) % 8
            out[octant] = True
        return out

    def _px(self, xy) -> tuple[float, float]:
        margin = 20
        s = (min(self.width, self.height) - 2 * margin) / 2.0
        return (self.width / 2 + xy[0] * s, self.height / 2 - xy[1] * s)

    def frame(self, pose: np.ndarray, now=None, before=None) -> np.ndarray:
        img = Image.new("RGB", (self.width, self.height), (236, 240, 245))
        draw = ImageDraw.Draw(img)
        x0, y0 = self._px((-1, 1))
        x1, y1 = self._px((1, -1))
        draw.rectangle((x0, y0, x1, y1), outline=(90, 90, 90), width=2)
        pos, goal = pose[:2], pose[2:4]
        if not np.array_equal(goal, self._goal):  # a new episode: a new trail
            self._trail, self._goal = [], goal.copy()
        self._trail = (self._trail + [tuple(pos)])[-40:]
        if len(self._trail) > 1:
            draw.line([self._px(p) for p in self._trail], fill=(120, 150, 210), width=2)
        r = self.config.reach_radius * (x1 - x0) / 2
        gx, gy = self._px(goal)
        reached = now is not None and bool(np.any(now))
        draw.ellipse((gx - r, gy - r, gx + r, gy + r), outline=(230, 70, 30) if reached else (40, 160, 60), width=3)
        px, py = self._px(pos)
        draw.ellipse((px - 7, py - 7, px + 7, py + 7), fill=(30, 60, 200))
        return np.asarray(img)

    def close(self) -> None:
        pass
