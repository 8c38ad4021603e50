"""Window replay for Deep COACH: each row is one window of L steps and the feedback that judged it."""

from __future__ import annotations

import numpy as np


class WindowReplay:
    def __init__(self, capacity: int, window: int, obs_size: int, action_size: int):
        self.capacity = capacity
        self.obs = np.zeros((capacity, window, obs_size), np.float32)
        self.action = np.zeros((capacity, window, action_size), np.float32)
        self.logp = np.zeros((capacity, window), np.float32)
        self.mask = np.zeros((capacity, window), np.float32)
        self.feedback = np.zeros((capacity,), np.float32)
        self.ptr = 0
        self.size = 0

    def add(self, obs, action, logp, mask, feedback) -> int:
        i = self.ptr
        self.obs[i], self.action[i], self.logp[i], self.mask[i], self.feedback[i] = obs, action, logp, mask, feedback
        self.ptr = (self.ptr + 1) % self.capacity
        self.size = min(self.size + 1, self.capacity)
        return i

    def batch(self, rng: np.random.Generator, n: int, newest: int):
        """n windows: the newest one and n - 1 drawn uniformly (with replacement) from the replay."""
        rows = np.concatenate([[newest], rng.integers(0, self.size, n - 1)])
        return self.obs[rows], self.action[rows], self.logp[rows], self.mask[rows], self.feedback[rows]
