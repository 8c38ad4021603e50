"""A pretrain run's reward model on disk: `reward_model/` in the run directory, in the one checksummed format of
every saved model (experiments/checkpoints.py: leaves by name, SHA-256 verified, a damaged file refused).

The tree is the model's parameters, its Adam state and how many minibatch updates it took. Runs written
before this format kept the same tree in `reward_model.msgpack` (flax msgpack, no checksum); `load` still reads
them (experiments/old_msgpack.py).
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import optax

from mjx_protamer.errors import CheckpointError
from mjx_protamer.experiments import checkpoints, old_msgpack

DIR = "reward_model"
OLD_FILE = "reward_model.msgpack"  # before checksums


def tree(params, opt_state, updates) -> dict:
    """What is saved, on the host (`updates` as an int32 scalar)."""
    return {"params": jax.device_get(params), "opt_state": jax.device_get(opt_state),
            "updates": np.asarray(updates, np.int32)}


def save(run_dir: str | Path, params, opt_state, updates) -> Path:
    """Write the reward model into `run_dir/reward_model/`; an OSError names the path when the write fails."""
    directory = Path(run_dir) / DIR
    checkpoints.save_model(directory, tree(params, opt_state, updates))
    return directory


def like(config, obs_size: int, action_size: int):
    """The saved tree's structure, shapes and dtypes for a reward model of `config` (a RewardModelConfig)."""
    from mjx_protamer.human.reward_model import reward_nets

    net = reward_nets(config).net

    def build():
        params = net.init(jax.random.PRNGKey(0), jnp.zeros((1, obs_size)), jnp.zeros((1, action_size)))
        return {"params": params, "opt_state": optax.adam(config.learning_rate).init(params),
                "updates": jnp.int32(0)}

    return jax.eval_shape(build)


def load(run_dir: str | Path, like_tree) -> dict:
    """The reward model saved in `run_dir`, checked against `like_tree` (from `like`): the checksummed
    directory, else a file of the old format. CheckpointDamaged when it is damaged, CheckpointError when there
    is none or it does not fit."""
    run_dir = Path(run_dir)
    if (run_dir / DIR).is_dir():
        return checkpoints.load_model(run_dir / DIR, like_tree)
    if (run_dir / OLD_FILE).is_file():
        return old_msgpack.load(run_dir / OLD_FILE, like_tree, "reward model",
                                "use the feedback_config.yaml of the run that wrote it")
    raise CheckpointError(f"{run_dir} holds no reward model ({DIR}/ or {OLD_FILE}); give the --out of a "
                          "`protamer pretrain --feedback simulated:KIND` run")

