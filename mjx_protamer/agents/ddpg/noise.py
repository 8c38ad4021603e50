"""Exploration noise, one independent process per env and action dimension.

Ornstein-Uhlenbeck in the dt = 1 form used by the reference learner:

    x_{t+1} = x_t + theta * (mu - x_t) + sigma * eps_t,   eps_t ~ N(0, 1)

an AR(1) process with coefficient (1 - theta), mean mu and stationary std sigma / sqrt(2 theta - theta^2)
(1.14 for theta 0.15, sigma 0.6; the continuous-time value sigma / sqrt(2 theta) is 1.10). The state restarts
at mu when an episode ends. "gaussian" is independent N(0, sigma^2) per step; "none" adds nothing.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from mjx_protamer.agents.ddpg.config import NoiseConfig


def init(config: NoiseConfig, shape: tuple[int, ...]) -> jax.Array:
    return jnp.full(shape, config.mu, jnp.float32)


def step(config: NoiseConfig, state: jax.Array, rng: jax.Array) -> jax.Array:
    """Advance the noise one step; the returned array is both the new state and the noise to add."""
    eps = jax.random.normal(rng, state.shape, state.dtype)
    if config.kind == "ou":
        return state + config.theta * (config.mu - state) + config.sigma * eps
    if config.kind == "gaussian":
        return config.sigma * eps
    return jnp.zeros_like(state)


def reset_done(config: NoiseConfig, state: jax.Array, done: jax.Array) -> jax.Array:
    """Restart the process of every env whose episode just ended (done has the batch shape)."""
    done = done.reshape(done.shape + (1,) * (state.ndim - done.ndim)) > 0
    return jnp.where(done, config.mu, state)


def stationary_std(config: NoiseConfig) -> float:
    if config.kind == "ou":
        return config.sigma / (2 * config.theta - config.theta**2) ** 0.5
    if config.kind == "gaussian":
        return config.sigma
    return 0.0
