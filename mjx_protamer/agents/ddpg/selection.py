"""Which snapshot of the actor the test episodes run: the last one, or the best late one on validation episodes.

Why: the deterministic actor's freeze ratio swings within a run (one seed's test policy froze 0.07, then 0.79,
then 0.08 at 32k-env-step intervals: docs/experiments.md, "the test policy's freeze swings"), so the last
snapshot is one draw from that swing. As Stable-Baselines3's `EvalCallback` keeps its `best_model`, every
`train.select_every_chunks` chunks from `train.select_from` of the run the actor is rolled out on
`train.select_episodes` validation episodes and kept when its mean return beats the kept one's. The return is
the learner's own objective, `alpha r_env + beta gain r_hat` (what its critic maximises): never the test
metrics and never the hidden teacher. The validation episodes have their own seed stream (`validation_seed`),
apart from training's and the test episodes', and every candidate meets the same ones.

Pure JAX: `validate` and `keep_better` vmap over seeds; the host decides when (`is_candidate`). Runs wire them
in through one wrapper, `experiments/snapshot_selection.py`.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp

from mjx_protamer.agents.ddpg.evaluate import make_rollout


class Kept(NamedTuple):
    actor_params: Any
    score: jax.Array  # the kept snapshot's validation return (-inf before the first candidate)
    chunk: jax.Array  # the chunk after which it was taken (0: none yet)


def init(actor_params) -> Kept:
    return Kept(actor_params, jnp.float32(-jnp.inf), jnp.int32(0))


def is_candidate(chunk: int, num_chunks: int, every: int, from_fraction: float) -> bool:
    """Whether the actor after `chunk` (1-based) is validated: every `every`-th chunk from `from_fraction`
    of the run, and always the last one (so selection can only add snapshots to the one the paper tests)."""
    if every <= 0:
        return False
    return chunk == num_chunks or (chunk % every == 0 and chunk >= from_fraction * num_chunks)


def make_validate(env, episode_length: int, actor_hidden, alpha: float, beta: float,
                  human_reward_fn: Callable | None = None):
    """validate(actor_params, human_params, keys (E, 2)) -> (mean return under the learner's objective,
    the validation episodes' per-step arm speed (E, T), for diagnostics)."""
    keep = ("reward", "arm_speed") + (("obs", "action") if human_reward_fn is not None else ())
    rollout = make_rollout(env, episode_length, actor_hidden, keep=keep)

    def validate(actor_params, human_params, keys):
        sig = rollout(actor_params, keys)
        reward = alpha * sig["reward"]
        if human_reward_fn is not None:
            human = human_reward_fn(human_params, sig["obs"], sig["action"])
            reward = reward + beta * jnp.reshape(human, reward.shape)
        return jnp.mean(jnp.sum(reward, axis=1)), sig["arm_speed"]

    return validate


def keep_better(kept: Kept, actor_params, score, chunk) -> Kept:
    """The new snapshot where it validates strictly better (a tie keeps the earlier one)."""
    better = score > kept.score
    pick = lambda new, old: jnp.where(better, new, old)  # noqa: E731
    return Kept(jax.tree.map(pick, actor_params, kept.actor_params), pick(score, kept.score),
                pick(jnp.int32(chunk), kept.chunk))
