"""When does the test policy freeze? One seed of a table2 config's DDPG, trained chunk by chunk (the one runner,
`experiments/runner.py`); every `--every` chunks it prints the share of slow arm steps (below env.freeze_speed)
of the quiet and the noisy envs in that chunk, and of `--episodes` test episodes of the deterministic actor at
that point (docs/experiments.md, "The baseline's freeze is a snapshot").

    protamer analyze freeze-through-training --config configs/table2.yaml --seed 4 --set pretrain.env.habituation_s=0.25
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import jax
import numpy as np

from mjx_protamer.agents.ddpg.evaluate import make_rollout
from mjx_protamer.agents.ddpg.train import make_train
from mjx_protamer.experiments.env_factory import make_env, with_resolved_backend
from mjx_protamer.experiments.runner import run_chunks
from mjx_protamer.experiments.table2 import load_table2_config

# The arm joints' velocities in the self-touch observation: the env's `arm_speed` (the freeze metric) is their
# norm, and the default teacher rule's freeze clause reads the same slice (human/teachers.py).
ARM_VELOCITY_OBS = list(range(64, 68)) + list(range(70, 74))


def freeze_through_training(config, overrides: list[str], seed: int, every: int, episodes: int,
                            report: Callable[[dict], None]) -> None:
    """Trains the config's DDPG on one seed through the one runner (`run_chunks`) and reports a row every
    `every` chunks (and after the last)."""
    cfg = load_table2_config(config, overrides)
    pre = cfg.pretrain
    pre = with_resolved_backend(dataclasses.replace(
        pre, train=dataclasses.replace(pre.train, seed=seed)), announce=False)
    env = make_env(pre)
    trainer = make_train(pre, env, devices=jax.devices()[:1])
    rollout = make_rollout(env, pre.train.episode_length, pre.ddpg.actor_hidden, keep=("arm_speed",))
    num_chunks = pre.train.num_chunks
    num_envs = pre.train.num_envs
    first_quiet = num_envs - int(round(pre.ddpg.noise.quiet_fraction * num_envs))
    slow = pre.env.freeze_speed
    chunks_run = [0]

    def step(state):
        """A chunk; on a reported one also the chunk's arm velocities and the test episodes' arm speed."""
        state, metrics, steps, _ = trainer.collect_chunk(state, None)
        chunks_run[0] += 1
        chunk = chunks_run[0]
        if chunk % every and chunk < num_chunks:
            return state, metrics, None
        test = rollout(state.actor_params, jax.random.split(jax.random.PRNGKey(10_000 + chunk - 1), episodes))
        return state, metrics, (steps.obs[..., ARM_VELOCITY_OBS], test["arm_speed"])

    def progress_fn(info):
        if info.extra is None:
            return
        arm_velocity, test_speed = info.extra
        row = {"chunk": info.chunk, "env_steps": int(info.metrics["env_steps"]),
               "test_slow": round(float(np.mean(np.asarray(test_speed) < slow)), 3)}
        row.update(_train_slow(arm_velocity, first_quiet, slow))
        report(row)

    run_chunks(step, trainer.init(jax.random.PRNGKey(seed)), num_chunks, pre.train.chunk_steps * num_envs,
               progress_fn=progress_fn)


def _train_slow(arm_velocity, first_quiet: int, slow: float) -> dict:
    """Slow share of the chunk's steps (T, B) in the quiet and in the noisy envs, from their arm velocities."""
    speed = np.linalg.norm(np.asarray(arm_velocity), axis=-1)
    return {"quiet_slow": round(float(np.mean(speed[:, first_quiet:] < slow)), 3),
            "noisy_slow": round(float(np.mean(speed[:, :first_quiet] < slow)), 3)}
