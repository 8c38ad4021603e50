"""The Gaussian policy of Deep COACH: mean = tanh(MLP(s)), a learned state-independent log std.

With relu hidden layers the mean network has the DDPG actor's shape and names (Dense_0, ..., Dense_n), so a
fine-tuning session can start from a pretrained actor (`CoachRun.start_from_actor`).

Actions are sampled from N(mean, std^2) and clipped to [-1, 1] by the env; the log-probability is of the
unclipped sample, the quantity the eligibility trace differentiates.
"""

from __future__ import annotations

from typing import Sequence

import flax.linen as nn
import jax
import jax.numpy as jnp


class GaussianPolicy(nn.Module):
    action_size: int
    hidden: Sequence[int] = (64, 64)
    init_log_std: float = -0.5
    activation: str = "tanh"  # or "relu", the DDPG actor's

    @nn.compact
    def __call__(self, obs: jax.Array) -> tuple[jax.Array, jax.Array]:
        act = nn.relu if self.activation == "relu" else nn.tanh
        x = obs
        for width in self.hidden:
            x = act(nn.Dense(width)(x))
        mean = jnp.tanh(nn.Dense(self.action_size, kernel_init=nn.initializers.uniform(1e-2))(x))
        log_std = self.param("log_std", nn.initializers.constant(self.init_log_std), (self.action_size,))
        return mean, jnp.broadcast_to(log_std, mean.shape)


def log_prob(mean, log_std, action, min_log_std: float = -3.0):
    log_std = jnp.maximum(log_std, min_log_std)
    z = (action - mean) / jnp.exp(log_std)
    return jnp.sum(-0.5 * z**2 - log_std - 0.5 * jnp.log(2 * jnp.pi), axis=-1)


def entropy(log_std, min_log_std: float = -3.0):
    log_std = jnp.maximum(log_std, min_log_std)
    return jnp.sum(log_std + 0.5 * jnp.log(2 * jnp.pi * jnp.e), axis=-1)
