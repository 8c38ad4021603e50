"""Model files saved before every model was a checksummed checkpoint: one flax msgpack blob each (a pretrain
run's `reward_model.msgpack`, a COACH session's `coach_policy.msgpack`). Sessions and runs recorded then are
still on users' disks, so they load; a blob has no checksum, so a bit flipped inside an array goes unseen, but a
truncated or garbled file, or one whose arrays do not fit, is refused in one line that names it.
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from mjx_protamer.errors import CheckpointDamaged, CheckpointError
from mjx_protamer.experiments.checkpoints import named_leaves


def load(path: Path, like, what: str, hint: str = ""):
    """The tree in the blob at `path`, shaped and typed as `like` (arrays or their eval_shape). `what` names the
    model in the messages ("reward model"), `hint` says what to give when it does not fit."""
    hint = f"; {hint}" if hint else ""
    from flax import serialization

    try:
        restored = serialization.from_state_dict(like, serialization.msgpack_restore(Path(path).read_bytes()))
    except Exception as e:  # msgpack and flax raise many types for a truncated or garbled file
        why = str(e).strip().splitlines()[0][:160] if str(e).strip() else type(e).__name__
        raise CheckpointDamaged(f"{what} {path} is damaged: it cannot be read ({why}); save it again, or restore "
                                "it from a backup") from None
    leaves, treedef = jax.tree_util.tree_flatten(restored)
    wants = jax.tree_util.tree_leaves(like)
    if len(leaves) != len(wants):
        raise CheckpointError(f"{what} {path} does not fit this config: {len(leaves)} arrays there, "
                              f"{len(wants)} here{hint}")
    out = []
    for name, leaf, want in zip(named_leaves(like), leaves, wants):
        leaf = np.asarray(leaf)
        if leaf.shape != tuple(want.shape):
            raise CheckpointError(f"{what} {path} does not fit this config: {name} is {leaf.shape} there but "
                                  f"{tuple(want.shape)} here{hint}")
        out.append(jnp.asarray(leaf, want.dtype))
    return jax.tree_util.tree_unflatten(treedef, out)
