"""Evaluate a policy on test episodes (deterministic actor) and load a trained run from its checkpoint."""

from __future__ import annotations

from pathlib import Path

import jax
import numpy as np

from mjx_protamer.experiments import metrics

CONFIG_NAME = "config.yaml"


def evaluate(config, env, actor_params, episodes: int, seed: int) -> dict:
    """The four metrics (means and per-episode lists) and the mean return over `episodes` test episodes."""
    from mjx_protamer.agents.ddpg.evaluate import make_rollout

    rollout = make_rollout(env, config.train.episode_length, config.ddpg.actor_hidden)
    keys = jax.random.split(jax.random.PRNGKey(seed), episodes)
    signals = jax.device_get(rollout(actor_params, keys))
    summary = metrics.summarize(signals["self_contact"], signals["region_mask"], signals["arm_speed"])
    returns = np.sum(signals["reward"], axis=1)
    summary["episode_return"] = float(returns.mean())
    summary["per_episode"]["episode_return"] = [float(r) for r in returns]
    return summary


def eval_seed(config) -> int:
    """Test episodes use their own seed stream, apart from training's."""
    return config.train.seed + 10_000


def resolve_checkpoint(path: str | Path) -> tuple[Path, Path, int | None]:
    """(run dir, checkpoints dir, step or None for the latest) from a run dir, its checkpoints dir or a step dir."""
    path = Path(path)
    if (path / CONFIG_NAME).is_file():
        return path, path / "checkpoints", None
    if path.name == "checkpoints" and (path.parent / CONFIG_NAME).is_file():
        return path.parent, path, None
    if path.name.isdigit() and (path.parent.parent / CONFIG_NAME).is_file():
        return path.parent.parent, path.parent, int(path.name)
    raise FileNotFoundError(f"{path} is not a pretrain run directory, its checkpoints/ or a checkpoint step in it")


def load_run(path: str | Path):
    """(config, env, train state, step) of a saved run; the state is restored onto one device."""
    from mjx_protamer.agents.ddpg.config import PretrainConfig
    from mjx_protamer.agents.ddpg.train import make_train
    from mjx_protamer.config import load_config
    from mjx_protamer.experiments import checkpoints
    from mjx_protamer.experiments.env_factory import make_env

    run_dir, ckpt_dir, step = resolve_checkpoint(path)
    import yaml

    saved = yaml.safe_load((run_dir / CONFIG_NAME).read_text()) or {}
    # Runs saved before the backend choice existed ran (and checkpointed their env state) on MJX.
    legacy = [] if "backend" in (saved.get("env") or {}) else ["env.backend=mjx"]
    config = load_config(PretrainConfig, run_dir / CONFIG_NAME, legacy)
    env = make_env(config)
    trainer = make_train(config, env, devices=jax.devices()[:1])
    mngr = checkpoints.manager(ckpt_dir)
    step = mngr.latest_step() if step is None else step
    if step is None:
        raise FileNotFoundError(f"no checkpoint in {ckpt_dir}")
    like = jax.eval_shape(trainer.init, jax.random.PRNGKey(0))
    state = checkpoints.restore(mngr, step, like)
    return config, env, state, step
