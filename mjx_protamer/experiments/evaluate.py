"""Evaluate a policy on test episodes (deterministic actor). Loading a saved run is `run_loader.load_run`."""

from __future__ import annotations

import jax
import numpy as np

from mjx_protamer.experiments import metrics
# Re-exported: callers that load a run for evaluation import these from here.
from mjx_protamer.experiments.run_loader import CONFIG_NAME, load_run, resolve_checkpoint  # noqa: F401


def evaluate(config, env, actor_params, episodes: int, seed: int) -> dict:
    """The four metrics (means and per-episode lists) and the mean return over `episodes` test episodes."""
    from mjx_protamer.agents.ddpg.evaluate import make_rollout

    rollout = make_rollout(env, config.train.episode_length, config.ddpg.actor_hidden)
    keys = jax.random.split(jax.random.PRNGKey(seed), episodes)
    signals = jax.device_get(rollout(actor_params, keys))
    # env.freeze_speed (rad/s; the toy env scales its speed so that 1 "rad/s" means 0.1 per step) is the
    # freeze metric's threshold for every env.
    summary = metrics.summarize(signals["self_contact"], signals["region_mask"], signals["arm_speed"],
                                freeze_threshold=config.env.freeze_speed)
    returns = np.sum(signals["reward"], axis=1)
    summary["episode_return"] = float(returns.mean())
    summary["per_episode"]["episode_return"] = [float(r) for r in returns]
    return summary


def eval_seed(config) -> int:
    """Test episodes use their own seed stream, apart from training's."""
    return config.train.seed + 10_000


def validation_seed(config) -> int:
    """Validation episodes (choosing the test snapshot, agents/ddpg/selection.py) use a third stream."""
    return config.train.seed + 20_000
