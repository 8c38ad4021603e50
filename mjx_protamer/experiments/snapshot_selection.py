"""Snapshot selection (agents/ddpg/selection.py) wired into a runner step: the one wrapper that `protamer
pretrain` and every table2 condition use.

The wrapped step carries the kept snapshot as the state's last part (None until the first candidate, or a
`selection.init` that a checkpoint can hold) and validates the actor after every candidate chunk on the run's
validation episodes (`validation_seed`). With `seeds` every part is vmapped over seeds, each seed on its own
validation stream. Each candidate's row (chunk, validation return, freeze ratio of the validation episodes;
per seed lists with `seeds`) goes to `candidates` and to `on_candidate`.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

from mjx_protamer.agents.ddpg import selection
from mjx_protamer.experiments.evaluate import validation_seed


class SnapshotSelection:
    """Built once per run (its jitted validation is traced once); `wrap` a step per training run."""

    def __init__(self, config, env, human_reward_fn: Callable | None = None, seeds=None, human_params_axes=0):
        tc, dc = config.train, config.ddpg
        self.config = config
        validate = selection.make_validate(env, tc.episode_length, dc.actor_hidden, dc.reward_alpha,
                                           dc.reward_beta, human_reward_fn)
        init, keep = selection.init, selection.keep_better
        if seeds is None:
            self.keys = jax.random.split(jax.random.PRNGKey(validation_seed(config)), tc.select_episodes)
        else:
            validate = jax.vmap(validate, in_axes=(0, human_params_axes, 0))
            keep = jax.vmap(keep, in_axes=(0, 0, 0, None))
            init = jax.vmap(init)
            self.keys = jnp.stack([jax.random.split(jax.random.PRNGKey(validation_seed(dataclasses.replace(
                config, train=dataclasses.replace(tc, seed=int(s))))), tc.select_episodes) for s in seeds])
        self.per_seed = seeds is not None
        self.validate, self.keep, self.init = jax.jit(validate), jax.jit(keep), init

    def wrap(self, step, actor_of: Callable, human_params_of: Callable, start: int = 0,
             candidates: list | None = None, on_candidate: Callable[[list], None] | None = None):
        """(`step'`, candidates): `step'(state + (kept,))` runs `step(state) -> (state, metrics, extra)` (state a
        tuple), then on a candidate chunk validates `actor_of(new state)` under `human_params_of(new state)` and
        keeps it where it validates better. Chunks count from `start` (a resumed run); `candidates` are the
        rows so far (a resumed run's), kept up to date, and passed to `on_candidate` after each new one."""
        tc = self.config.train
        threshold = self.config.env.freeze_speed
        candidates = [] if candidates is None else candidates
        chunk = [start]

        def selecting_step(state):
            new, metrics, extra = step(state[:-1])
            kept = state[-1]
            chunk[0] += 1
            if selection.is_candidate(chunk[0], tc.num_chunks, tc.select_every_chunks, tc.select_from):
                actor = actor_of(new)
                score, speed = self.validate(actor, human_params_of(new), self.keys)
                kept = self.keep(self.init(actor) if kept is None else kept, actor, score, chunk[0])
                slow = np.asarray(speed) < threshold
                if self.per_seed:
                    row = {"chunk": chunk[0], "score": np.asarray(score).tolist(),
                           "freeze_ratio": np.mean(slow, axis=(1, 2)).tolist()}
                else:
                    row = {"chunk": chunk[0], "score": float(score), "freeze_ratio": float(np.mean(slow))}
                candidates.append(row)
                if on_candidate is not None:
                    on_candidate(candidates)
            return tuple(new) + (kept,), metrics, extra

        return selecting_step, candidates

