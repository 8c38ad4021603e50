"""When does the test policy freeze? One seed of a table2 config's DDPG, trained chunk by chunk; every
`--every` chunks it prints the share of slow arm steps (below env.freeze_speed) of the quiet and the noisy envs
in that chunk, and of `--episodes` test episodes of the deterministic actor at that point (docs/experiments.md,
"The baseline's freeze is a snapshot").

    protamer analyze freeze-through-training --config configs/table2.yaml --seed 4 --set pretrain.env.habituation_s=0.25
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np

from mjx_protamer.agents.ddpg.evaluate import make_rollout
from mjx_protamer.agents.ddpg.train import make_train
from mjx_protamer.experiments.env_factory import make_env, with_resolved_backend
from mjx_protamer.experiments.table2 import load_table2_config

# The arm joints' velocities in the self-touch observation: the env's `arm_speed` (the freeze metric) is their
# norm, and the default teacher rule's freeze clause reads the same slice (human/teachers.py).
ARM_VELOCITY_OBS = list(range(64, 68)) + list(range(70, 74))


def freeze_through_training(config, overrides: list[str], seed: int, every: int, episodes: int):
    """Trains the config's DDPG on one seed and yields a line every `every` chunks (and after the last)."""
    cfg = load_table2_config(config, overrides)
    pre = cfg.pretrain
    pre = with_resolved_backend(dataclasses.replace(
        pre, train=dataclasses.replace(pre.train, seed=seed)), announce=False)
    env = make_env(pre)
    trainer = make_train(pre, env, devices=jax.devices()[:1])
    rollout = make_rollout(env, pre.train.episode_length, pre.ddpg.actor_hidden)
    state = trainer.init(jax.random.PRNGKey(seed))
    num_envs = pre.train.num_envs
    first_quiet = num_envs - int(round(pre.ddpg.noise.quiet_fraction * num_envs))
    slow = pre.env.freeze_speed
    for chunk in range(pre.train.num_chunks):
        state, metrics, steps, _ = trainer.collect_chunk(state, None)
        if (chunk + 1) % every and chunk + 1 < pre.train.num_chunks:
            continue
        signals = rollout(state.actor_params, jax.random.split(jax.random.PRNGKey(10_000 + chunk), episodes))
        test_slow = float(np.mean(np.asarray(signals["arm_speed"]) < slow))
        row = {"chunk": chunk + 1, "env_steps": int(metrics["env_steps"]), "test_slow": round(test_slow, 3)}
        row.update(_train_slow(steps, first_quiet, slow))
        yield row


def _train_slow(steps, first_quiet: int, slow: float) -> dict:
    """Slow share of the chunk's steps (T, B) in the quiet and in the noisy envs."""
    speed = np.linalg.norm(np.asarray(steps.obs)[..., ARM_VELOCITY_OBS], axis=-1)
    return {"quiet_slow": round(float(np.mean(speed[:, first_quiet:] < slow)), 3),
            "noisy_slow": round(float(np.mean(speed[:, :first_quiet] < slow)), 3)}
