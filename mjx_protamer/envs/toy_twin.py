"""The toy point-reach env as a NumPy Gymnasium env (for Stable-Baselines3 comparisons before the
self-touch twin exists). Same dynamics and reward as `mjx_protamer.envs.toy.PointReachEnv`."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from mjx_protamer.envs.toy import ToyEnvConfig


class PointReachGym(gym.Env):
    metadata = {"render_modes": []}

    def __init__(self, config: ToyEnvConfig | None = None, episode_length: int = 25):
        self.config = config or ToyEnvConfig()
        self.episode_length = episode_length
        self.observation_space = gym.spaces.Box(-4.0, 4.0, (6,), np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
        self._weights = np.asarray(self.config.reward_weights, np.float32)

    def _obs(self):
        return np.concatenate([self.pos, self.goal, self.goal - self.pos]).astype(np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.pos = self.np_random.uniform(-1, 1, 2)
        self.goal = self.np_random.uniform(-1, 1, 2)
        self.t = 0
        return self._obs(), {}

    def step(self, action):
        action = np.clip(np.asarray(action, np.float64), -1, 1)
        self.pos = np.clip(self.pos + self.config.max_step * action, -1, 1)
        dist = float(np.linalg.norm(self.goal - self.pos))
        reached = float(dist < self.config.reach_radius)
        terms = np.array([-dist, -float(np.sum(action**2)), reached], np.float32)
        self.t += 1
        return self._obs(), float(terms @ self._weights), False, self.t >= self.episode_length, {"self_contact": reached}
