"""DeepTAMER's human-reward model r_hat(s, a): a Flax MLP fitted to credited feedback.

- Network: MLP 256-256 (ReLU) on concat(obs, action), linear scalar output (Warnell et al. 2018; spec,
  "The reference learners"), or with `bounded` its tanh: r_hat within the labels' [-1, 1]. With `ensemble`,
  several such MLPs and r_hat = their mean - `pessimism` x their spread.
- Loss: weighted squared error `sum_i w_i (r_hat(s_i, a_i) - h_i)^2 / sum_i w_i`, with w the credit
  weight of the step (`credit.py`) and h the feedback value.
- Feedback replay (`batched.FeedbackRing`, 1e4 rows in device memory) and updates
  (`batched.reward_model_updates`): minibatch steps on the newly credited rows, plus replay minibatches of
  64 uniformly drawn rows, as in Deep TAMER. The batched runs (experiments/feedback_train.py) and a live
  session (live/reward_model.py, a batch of one) call the same jitted pieces.
- Params enter jitted code as an argument: `reward_fn(hidden)` is a pure `(params, obs, action) -> (B,)`,
  the `human_reward_fn` of `agents.ddpg.make_train`; an update changes values, never shapes or dtypes, so
  the DDPG chunk never recompiles.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Callable, NamedTuple, Sequence

import flax.linen as nn
import jax
import jax.numpy as jnp

from mjx_protamer.config import check


@dataclasses.dataclass(frozen=True)
class RewardModelConfig:
    hidden: tuple[int, ...] = (256, 256)  # hidden layer widths of the reward model's MLP (r_hat(s, a))
    learning_rate: float = 1e-3  # Adam step size
    buffer_size: int = 10_000  # credited rows kept (the oldest are overwritten)
    batch_size: int = 64  # rows per replay minibatch
    updates_per_feedback: int = 1  # gradient steps on the new rows when an event is credited
    replay_every: int = 10  # env steps between replay minibatches (0: never)
    replay_min_rows: int = 64  # no replay before the buffer holds this many rows
    # tanh on the output: r_hat stays in [-1, 1], the labels' range, so the actor cannot find states the model
    # never saw labelled and rates above every label (measured on DTK, docs/experiments.md); False: linear
    bounded: bool = False
    # Praise and reproach weigh the same in the loss, whatever their counts: each row's weight is scaled by
    # (W+ + W-) / (2 W+) or / (2 W-), the stored rows' total weights by sign (at most `balance_max` x; 0 labels,
    # the teacher's silences, keep theirs). A teacher whose learner complies praises far more than it scolds,
    # and a model fitted to that rates the scolded states far above -1 (near 0: measured, docs/experiments.md).
    balance_signs: bool = False
    balance_max: float = 10.0  # the cap on balance_signs' reweighting (see balance_signs)
    # An ensemble of `ensemble` MLPs (own initialisations, the same minibatches, each fitted to the labels), and
    # r_hat = their mean - `pessimism` x their standard deviation: where the members disagree (states far from
    # any label) r_hat is lowered, so the actor is not drawn to states the model over-rates by chance
    # (Lakshminarayanan et al. 2017, deep ensembles; pessimism as in conservative model-based RL).
    ensemble: int = 1
    pessimism: float = 0.0  # r_hat = ensemble mean - pessimism x std (see ensemble); 0: the mean
    # Step-size decay over a batched run (experiments/feedback_train.py; step_size.decay_scale), as DDPG's:
    # 1 until `lr_decay_from` of the run, then linear to `lr_final_fraction`. Screened to shrink r_hat's spread
    # within one score on a compliant learner's states; it did not, that spread is not the optimiser's noise
    # (docs/experiments.md, "a step-size decay for it"), so no config sets it. A live session is open-ended and
    # runs at a constant rate (live/reward_model.py).
    lr_final_fraction: float = 1.0
    lr_decay_from: float = 0.5  # the share of the run before the decay starts (see lr_final_fraction)
    # The observation enters as asinh(obs): about obs near 0, about log(2 |obs|) far out. The touch features are
    # forces in newtons (0 to about 50 N, std up to 9 N); raw, a 20 N press by one hand swamps a 0.5 N
    # touch by the other, and a rule on whether each hand touches sees the two as one state
    # (docs/experiments.md, "Measured: the reward model's input scale"). False: the raw observation.
    asinh_obs: bool = False

    def validate(self) -> None:
        check(self.balance_max >= 1, "balance_max", f"must be >= 1, got {self.balance_max}")
        check(len(self.hidden) >= 1 and min(self.hidden) > 0, "hidden",
              f"needs at least one positive layer width, got {self.hidden}")
        check(self.learning_rate > 0, "learning_rate", f"must be > 0, got {self.learning_rate}")
        check(self.buffer_size >= self.batch_size, "buffer_size",
              f"must be >= batch_size ({self.batch_size}), got {self.buffer_size}")
        check(self.batch_size >= 1, "batch_size", f"must be >= 1, got {self.batch_size}")
        check(self.updates_per_feedback >= 0, "updates_per_feedback", f"must be >= 0, got {self.updates_per_feedback}")
        check(self.replay_every >= 0, "replay_every", f"must be >= 0, got {self.replay_every}")
        check(self.replay_min_rows >= 1, "replay_min_rows", f"must be >= 1, got {self.replay_min_rows}")
        check(self.ensemble >= 1, "ensemble", f"must be >= 1 (members), got {self.ensemble}")
        check(self.pessimism >= 0, "pessimism", f"must be >= 0, got {self.pessimism}")
        check(0.0 < self.lr_final_fraction <= 1.0, "lr_final_fraction",
              f"must be in (0, 1] (1 = a constant step size), got {self.lr_final_fraction}")
        check(0.0 <= self.lr_decay_from < 1.0, "lr_decay_from",
              f"must be in [0, 1) (the share of the run before the decay starts), got {self.lr_decay_from}")
        check(self.pessimism == 0 or self.ensemble >= 2, "pessimism",
              f"needs an ensemble to measure disagreement: set ensemble >= 2 (got {self.ensemble}) or pessimism 0")


def model_input(obs: jax.Array, action: jax.Array, asinh_obs: bool) -> jax.Array:
    return jnp.concatenate([jnp.arcsinh(obs) if asinh_obs else obs, action], axis=-1)


class _Head(nn.Module):
    hidden: Sequence[int]
    bounded: bool

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        for width in self.hidden:
            x = nn.relu(nn.Dense(width)(x))
        out = nn.Dense(1)(x)[..., 0]
        return jnp.tanh(out) if self.bounded else out


class RewardMLP(nn.Module):
    """r_hat (...,) of one MLP, or with `ensemble` > 1 each member's (ensemble, ...)."""
    hidden: Sequence[int] = (256, 256)
    bounded: bool = False
    ensemble: int = 1
    asinh_obs: bool = False

    @nn.compact
    def __call__(self, obs: jax.Array, action: jax.Array) -> jax.Array:
        x = model_input(obs, action, self.asinh_obs)
        if self.ensemble > 1:
            members = nn.vmap(_Head, variable_axes={"params": 0}, split_rngs={"params": True}, in_axes=None,
                              out_axes=0, axis_size=self.ensemble)
            return members(tuple(self.hidden), self.bounded, name="members")(x)
        for width in self.hidden:  # one model: the layers at the top level, as checkpoints before ensembles
            x = nn.relu(nn.Dense(width)(x))
        out = nn.Dense(1)(x)[..., 0]
        return jnp.tanh(out) if self.bounded else out


@functools.lru_cache(maxsize=None)
def reward_fn(hidden: tuple[int, ...] = (256, 256), bounded: bool = False, ensemble: int = 1,
              pessimism: float = 0.0, asinh_obs: bool = False) -> Callable[[dict, jax.Array, jax.Array], jax.Array]:
    """The pure r_hat(params, obs (B, obs), action (B, act)) -> (B,): the model's, or an ensemble's mean less
    `pessimism` x its members' standard deviation. One object per architecture, so jit caches keyed on it stay
    warm."""
    net = RewardMLP(tuple(hidden), bounded, ensemble, asinh_obs)

    def apply(params, obs, action):
        out = net.apply(params, obs, action)
        if ensemble == 1:
            return out
        mean = jnp.mean(out, axis=0)
        # sqrt's gradient is infinite at 0, and members that agree exactly (tanh saturated at +-1 in float32) have
        # a spread of 0: jnp.std made the actor's gradient through r_hat NaN there, and a live session's actor
        # with it. The floor moves r_hat by at most 1e-6.
        spread = jnp.sqrt(jnp.mean(jnp.square(out - mean), axis=0) + 1e-12)
        return mean - pessimism * spread

    return apply


@functools.lru_cache(maxsize=None)
def fit_fn(hidden: tuple[int, ...] = (256, 256), bounded: bool = False, ensemble: int = 1,
           asinh_obs: bool = False) -> Callable[[dict, jax.Array, jax.Array], jax.Array]:
    """What the loss fits: (B,) for one model, (ensemble, B) for an ensemble, each member to the labels
    (`weighted_loss` broadcasts the labels over the members and sums their losses)."""
    net = RewardMLP(tuple(hidden), bounded, ensemble, asinh_obs)
    return lambda params, obs, action: net.apply(params, obs, action)


class RewardNets(NamedTuple):
    net: RewardMLP  # for init
    apply: Callable  # r_hat(params, obs, action) -> (B,)
    fit: Callable  # the fitted outputs (B,) or (ensemble, B)


def reward_nets(config: "RewardModelConfig") -> RewardNets:
    """The one place a reward-model config becomes networks (feedback_train, live.reward_model's
    SessionRewardModel, scripts)."""
    hidden = tuple(config.hidden)
    return RewardNets(RewardMLP(hidden, config.bounded, config.ensemble, config.asinh_obs),
                      reward_fn(hidden, config.bounded, config.ensemble, config.pessimism, config.asinh_obs),
                      fit_fn(hidden, config.bounded, config.ensemble, config.asinh_obs))


def sign_factors(xp, weight, target, max_factor: float):
    """(factor for rows with target < 0, factor for target > 0) from stored rows' weights (see
    RewardModelConfig.balance_signs); 1 for both while either sign is missing."""
    w_neg = xp.sum(xp.where(target < 0, weight, 0.0))
    w_pos = xp.sum(xp.where(target > 0, weight, 0.0))
    both = (w_neg > 0) & (w_pos > 0)
    total = w_neg + w_pos
    f = lambda w: xp.where(both, xp.clip(total / (2 * xp.where(both, w, 1.0)), 1.0 / max_factor, max_factor), 1.0)
    return f(w_neg), f(w_pos)


def balanced_weight(xp, factors, weight, target):
    """`weight` of rows with label `target`, scaled by `sign_factors`' (negative, positive) factors."""
    f_neg, f_pos = factors
    return weight * xp.where(target < 0, f_neg, xp.where(target > 0, f_pos, 1.0))


def weighted_loss(params, apply, obs, action, weight, target):
    """sum_i w_i (pred_i - h_i)^2 / sum_i w_i; an ensemble's (members, B) predictions: the members' sum."""
    pred = apply(params, obs, action)
    return jnp.sum(weight * (pred - target) ** 2) / jnp.maximum(jnp.sum(weight), 1e-8)
