"""The one way to load a saved pretrain run: `eval`, `finetune`, `render` and `reproduce` all call `load_run`.

A run directory holds `config.yaml` and `checkpoints/<step>/`. Whatever is wrong with the path or the
checkpoint (missing, empty, unfinished, truncated, damaged, written by another config, an absent step)
becomes a CheckpointError with a one-line message that says what to give instead.
"""

from __future__ import annotations

from pathlib import Path

from mjx_protamer.errors import CheckpointError

CONFIG_NAME = "config.yaml"
SELECTED_DIR = "checkpoints_selected"  # the snapshot the test episodes ran (train.select_every_chunks > 0)
WHAT = "a pretrain run directory (made by `protamer pretrain --out DIR`), its checkpoints/ or a step in it"


def resolve_checkpoint(path: str | Path) -> tuple[Path, Path, int | None]:
    """(run dir, checkpoints dir, step or None for the latest) from a run dir, its checkpoints dir or a step dir."""
    path = Path(path)
    if not path.exists():
        if path.name.isdigit() and (path.parent.parent / CONFIG_NAME).is_file():
            steps = ", ".join(p.name for p in sorted(path.parent.iterdir(), key=lambda p: p.name.zfill(12))
                              if p.name.isdigit()) if path.parent.is_dir() else ""
            raise CheckpointError(f"checkpoint step {path.name} does not exist in {path.parent}; "
                                  + (f"the steps there: {steps}" if steps else "it holds no checkpoint"))
        raise CheckpointError(f"{path}: no such file or directory; give {WHAT}")
    if (path / CONFIG_NAME).is_file():
        return path, path / "checkpoints", None
    if path.name == "checkpoints" and (path.parent / CONFIG_NAME).is_file():
        return path.parent, path, None
    if path.name.isdigit() and (path.parent.parent / CONFIG_NAME).is_file():
        return path.parent.parent, path.parent, int(path.name)
    raise CheckpointError(f"{path} is not {WHAT} (no {CONFIG_NAME} found)")


def read_run_config(run_dir: Path):
    """The PretrainConfig a run was saved with. A run saved before `env.habituation_s` existed had no
    familiarity trace in its observation, so the missing field reads as 0 there, not as today's default."""
    from mjx_protamer.agents.ddpg.config import PretrainConfig
    from mjx_protamer.config import from_dict, read_raw

    raw = read_raw(run_dir / CONFIG_NAME)
    env = raw.get("env")
    if isinstance(env, dict) and "habituation_s" not in env:
        raw["env"] = dict(env, habituation_s=0.0)
    return from_dict(PretrainConfig, raw)


def load_run(path: str | Path):
    """(config, env, train state, step) of a saved run; the state is restored onto one device.

    A finished run that selected its test snapshot (`train.select_every_chunks`) gives that snapshot as the
    actor (and target actor), with the rest of the state from the last chunk: what its eval.json measured.
    Any earlier step gives that step's own actor."""
    import jax

    from mjx_protamer.agents.ddpg.train import make_train
    from mjx_protamer.experiments import checkpoints
    from mjx_protamer.experiments.env_factory import make_env

    run_dir, ckpt_dir, step = resolve_checkpoint(path)
    config = read_run_config(run_dir)
    steps = checkpoints.available_steps(ckpt_dir)
    if not steps:
        raise CheckpointError(f"no checkpoint in {ckpt_dir}: the run stopped before its first one "
                              f"(one is written every train.checkpoint_every_chunks chunks)")
    step = steps[-1] if step is None else step
    env = make_env(config)
    trainer = make_train(config, env, devices=jax.devices()[:1])
    like = jax.eval_shape(trainer.init, jax.random.PRNGKey(0))
    mngr = checkpoints.manager(ckpt_dir)
    try:
        state = checkpoints.restore(mngr, step, like)
    finally:
        mngr.close()
    if config.train.select_every_chunks > 0 and step == config.train.num_chunks:
        state = _with_selected_actor(run_dir / SELECTED_DIR, step, state)
    return config, env, state, step


def _with_selected_actor(path: Path, step: int, state):
    from mjx_protamer.agents.ddpg import selection
    from mjx_protamer.experiments import checkpoints

    if step not in checkpoints.available_steps(path):
        raise CheckpointError(f"{path} holds no step {step}: this run selected its test actor, and that "
                              f"snapshot is missing; give an earlier step of {path.parent / 'checkpoints'}")
    mngr = checkpoints.manager(path)
    try:
        kept = checkpoints.restore(mngr, step, selection.init(state.actor_params))
    finally:
        mngr.close()
    return state.replace(actor_params=kept.actor_params, target_actor_params=kept.actor_params)
