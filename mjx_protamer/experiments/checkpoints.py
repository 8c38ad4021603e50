"""Orbax checkpoints of a whole TrainState (learner, env batch, replay, RNG), written atomically.

Orbax writes each step into a temporary directory and renames it when complete, so a run killed while
saving leaves the previous checkpoint intact; `latest_step` only ever sees finished ones. Saving is
synchronous: the train step donates its input buffers, so the next chunk must not start before the save ends.
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import orbax.checkpoint as ocp


def manager(directory: str | Path, max_to_keep: int = 2) -> ocp.CheckpointManager:
    options = ocp.CheckpointManagerOptions(max_to_keep=max_to_keep, enable_async_checkpointing=False)
    return ocp.CheckpointManager(Path(directory).absolute(), options=options)


def _items(leaves) -> dict:
    """The leaves by index, without zero-size arrays (orbax refuses them; mjx.Data has some, e.g. `act`)."""
    return {f"leaf_{i:05d}": leaf for i, leaf in enumerate(leaves) if leaf.size > 0}


def save(mngr: ocp.CheckpointManager, step: int, state) -> None:
    mngr.save(step, args=ocp.args.StandardSave(_items(jax.tree.leaves(state))))
    mngr.wait_until_finished()


def restore(mngr: ocp.CheckpointManager, step: int, like):
    """Restore into the structure, shapes and shardings of `like` (a state or its eval_shape)."""
    leaves, treedef = jax.tree.flatten(like)
    abstract = _items([_abstract(x) for x in leaves])
    restored = mngr.restore(step, args=ocp.args.StandardRestore(abstract))
    out = [restored.get(f"leaf_{i:05d}") for i in range(len(leaves))]
    out = [r if r is not None else _empty(x) for r, x in zip(out, leaves)]
    return jax.tree.unflatten(treedef, out)


def _empty(x):
    array = jnp.zeros(x.shape, x.dtype)
    sharding = getattr(x, "sharding", None)
    return jax.device_put(array, sharding) if sharding is not None else array


def _abstract(x):
    sharding = getattr(x, "sharding", None)
    return jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=sharding)
