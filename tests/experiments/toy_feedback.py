"""The toy point-reach problem with a simulated teacher, as a table2-shaped config (shared by the tests here)."""

from __future__ import annotations

import copy


def toy_feedback_config(**train) -> dict:
    """A raw (YAML-shaped) config: tiny DDPG on the toy env, a teacher that approves reaching and disapproves a
    negative second action; `train` overrides the run settings."""
    raw = {
        "pretrain": {
            "env_name": "toy",
            "ddpg": {"actor_hidden": [16], "critic_hidden": [16, 16], "replay_size": 2000, "batch_size": 16,
                     "reward_beta": 1.0},
            "train": {"num_envs": 4, "episode_length": 25, "total_env_steps": 800, "warmup_env_steps": 100,
                      "chunk_steps": 20},
        },
        "feedback": {
            "dt": 0.05,
            "reward_model": {"hidden": [16]},
            "teacher": {"min_gap_steps": 2, "rule": [{"signal": "reach", "value": 1.0, "above": 0.5},
                                                     {"signal": "action:1", "value": -1.0, "below": -0.5}]},
        },
    }
    raw["pretrain"]["train"].update(train)
    return copy.deepcopy(raw)
