"""DDPG's pure pieces: the sample-time reward, the critic and actor losses, the soft target update."""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp

from mjx_protamer.agents.ddpg.replay import Transition

# human_reward_fn(human_params, obs (B, obs), action (B, act)) -> (B,) predicted human reward.
HumanRewardFn = Callable[[Any, jax.Array, jax.Array], jax.Array]


class HumanTerm(NamedTuple):
    """What the actor climbs of the person's reward besides the critic's Q: `reward_coef * r_hat(s, mu(s))`
    (action biasing) and `critic_coef * Q_h(s, mu(s))`, a critic of r_hat alone (`ddpg.human_critic_coef`)."""
    reward_fn: HumanRewardFn
    reward_params: Any
    reward_coef: float
    critic_apply: Callable | None = None
    critic_params: Any = None
    critic_coef: float = 0.0


def relabel(
    batch: Transition,
    weights: jax.Array,
    alpha: float,
    beta: float,
    human_reward_fn: HumanRewardFn | None = None,
    human_params: Any = None,
) -> jax.Array:
    """The reward of sampled transitions: alpha * terms @ weights + beta * human_reward_fn(params, s, a).

    Computed at sample time so that stored transitions always see the current human-reward model.
    """
    reward = alpha * (batch.reward_terms @ weights)
    if human_reward_fn is not None:
        human = human_reward_fn(human_params, batch.obs, batch.action)
        reward = reward + beta * jnp.reshape(human, reward.shape)
    return reward


def critic_loss(critic_params, critic_apply, batch: Transition, target_q: jax.Array):
    """Mean squared TD error against a fixed target; returns (loss, mean Q)."""
    q = critic_apply(critic_params, batch.obs, batch.action)
    return jnp.mean((q - target_q) ** 2), jnp.mean(q)


def td_target(reward, next_q, terminal, gamma: float) -> jax.Array:
    """y = r + gamma * (1 - terminal) * Q'(s', mu'(s')); a time-limit truncation is not terminal."""
    return jax.lax.stop_gradient(reward + gamma * (1.0 - terminal) * next_q)


def actor_loss(actor_params, actor_apply, critic_params, critic_apply, obs: jax.Array, preact_coef: float = 0.0,
               preact_free: float = 0.0, human: tuple | None = None, anchor: tuple | None = None,
               imitate: tuple | None = None, avoid: tuple | None = None):
    """Deterministic policy gradient: maximise Q(s, mu(s)), less `preact_coef * mean(max(|pre| - free, 0)^2)`
    over the pre-tanh activations.

    Once the actor's pre-activations grow past ~3, tanh is flat and the critic's gradient no longer moves
    the action: the policy sticks in a corner of the action box. The penalty keeps it where it can learn.
    With `preact_free` > 0 it is a wall, not a pull: actions inside |a| < tanh(free) are not biased toward 0.

    `human` (a HumanTerm): action biasing (Knox & Stone 2011; CREW's continuous Deep
    TAMER): the actor also climbs `coef * r_hat(s, mu(s))` directly. Through the critic alone, r_hat reaches the
    policy only after the critic has bootstrapped it into Q, which a few minutes of feedback do not allow.
    `anchor` = (anchor_params, coef): `coef * mean |mu(s) - mu_anchor(s)|^2`, a pull toward the actor a session
    started from: what the intrinsic reward alone would change drifts no further than the pull allows.
    `imitate` = (obs, action, weight, coef): `coef * sum w |mu(s) - a|^2 / sum w` over rows the person praised
    (`ddpg.praise_imitation_coef`; no rows, weight 0: no pull). `avoid` = (obs, action, weight, coef):
    `coef * sum w max(0, 1 - |mu(s) - a|^2) / sum w` over rows the person reproached (`ddpg.reproach_avoid_coef`).
    """
    pre = actor_apply(actor_params, obs, True)
    action = jnp.tanh(pre)
    loss = -jnp.mean(critic_apply(critic_params, obs, action))
    loss = loss + preact_coef * jnp.mean(jnp.maximum(jnp.abs(pre) - preact_free, 0.0) ** 2)
    if human is not None:
        loss = loss + human_bias_loss(action, obs, human)
    if anchor is not None:
        params, coef = anchor
        ref = jax.lax.stop_gradient(actor_apply(params, obs))
        loss = loss + coef * jnp.mean(jnp.sum((action - ref) ** 2, axis=-1))
    if imitate is not None:
        loss = loss + imitation_loss(actor_params, actor_apply, *imitate)
    if avoid is not None:
        loss = loss + avoidance_loss(actor_params, actor_apply, *avoid)
    return loss


def _weighted_mean(actor_params, actor_apply, obs, action, weight, of_distance) -> jax.Array:
    """`sum_i w_i f(|mu(s_i) - a_i|^2) / sum_i w_i` (0 where every weight is 0)."""
    d2 = jnp.sum((actor_apply(actor_params, obs) - action) ** 2, axis=-1)
    return jnp.sum(weight * of_distance(d2)) / jnp.maximum(jnp.sum(weight), 1e-6)


def imitation_loss(actor_params, actor_apply, obs, action, weight, coef: float) -> jax.Array:
    """`coef * sum_i w_i |mu(s_i) - a_i|^2 / sum_i w_i`: the actor pulled toward demonstrated actions."""
    return coef * _weighted_mean(actor_params, actor_apply, obs, action, weight, lambda d2: d2)


def avoidance_loss(actor_params, actor_apply, obs, action, weight, coef: float) -> jax.Array:
    """`coef * sum_i w_i max(0, 1 - |mu(s_i) - a_i|^2) / sum_i w_i`: the actor pushed away from what was
    reproached, until its action differs by 1 (a hinge: a push that stops, not a flight to the action box's edge)."""
    return coef * _weighted_mean(actor_params, actor_apply, obs, action, weight, lambda d2: jnp.maximum(0.0, 1.0 - d2))


def human_bias_loss(action, obs, human: HumanTerm) -> jax.Array:
    """The person's terms of the actor loss: `-reward_coef * mean r_hat(s, a) - critic_coef * mean Q_h(s, a)`.

    r_hat's action gradient only says which nearby action the person likes at this very step; Q_h, trained on
    r_hat with its own bootstrap, also says which action leads to what the person likes a moment later (a hand
    that must travel to where the praise is)."""
    loss = jnp.zeros(())
    if human.reward_coef > 0:
        loss = loss - human.reward_coef * jnp.mean(human.reward_fn(human.reward_params, obs, action))
    if human.critic_coef > 0:
        loss = loss - human.critic_coef * jnp.mean(human.critic_apply(human.critic_params, obs, action))
    return loss


def human_actor_loss(actor_params, actor_apply, obs: jax.Array, human: tuple) -> jax.Array:
    """Action biasing's term alone, as a function of the actor (for its own optimiser: `ddpg.human_actor_lr`)."""
    return human_bias_loss(jnp.tanh(actor_apply(actor_params, obs, True)), obs, human)


def soft_update(target, online, tau: float):
    """Polyak averaging: target <- tau * online + (1 - tau) * target."""
    return jax.tree.map(lambda t, o: (1.0 - tau) * t + tau * o, target, online)
