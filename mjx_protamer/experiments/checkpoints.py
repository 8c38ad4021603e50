"""Orbax checkpoints of a whole TrainState (learner, env batch, replay, RNG), written atomically.

Orbax writes each step into a temporary directory and renames it when complete, so a run killed while
saving leaves the previous checkpoint intact; `latest_step` only ever sees finished ones. Saving is
synchronous: the train step donates its input buffers, so the next chunk must not start before the save ends.
"""

from __future__ import annotations

from pathlib import Path

import jax
import orbax.checkpoint as ocp


def manager(directory: str | Path, max_to_keep: int = 2) -> ocp.CheckpointManager:
    options = ocp.CheckpointManagerOptions(max_to_keep=max_to_keep, enable_async_checkpointing=False)
    return ocp.CheckpointManager(Path(directory).absolute(), options=options)


def save(mngr: ocp.CheckpointManager, step: int, state) -> None:
    mngr.save(step, args=ocp.args.StandardSave(state))
    mngr.wait_until_finished()


def restore(mngr: ocp.CheckpointManager, step: int, like):
    """Restore into the structure, shapes and shardings of `like` (a state or its eval_shape)."""
    abstract = jax.tree.map(_abstract, like)
    return mngr.restore(step, args=ocp.args.StandardRestore(abstract))


def _abstract(x):
    sharding = getattr(x, "sharding", None)
    return jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=sharding)
