"""Actor and critic MLPs of the reference DDPG (Lillicrap et al. 2016; spec: 400-300).

The critic takes the action at its second layer, as in the original DDPG paper. Final layers start
uniform in +-3e-3 so initial actions and Q-values are near zero.
"""

from __future__ import annotations

from typing import Sequence

import flax.linen as nn
import jax
import jax.numpy as jnp

_final_init = nn.initializers.uniform(scale=6e-3)  # U[0, 6e-3), shifted below to U[-3e-3, 3e-3)


def _centred(init):
    def wrapped(key, shape, dtype=jnp.float32):
        return init(key, shape, dtype) - 3e-3
    return wrapped


class Actor(nn.Module):
    action_size: int
    hidden: Sequence[int] = (400, 300)

    @nn.compact
    def __call__(self, obs: jax.Array, pre_tanh: bool = False) -> jax.Array:
        x = obs
        for width in self.hidden:
            x = nn.relu(nn.Dense(width)(x))
        x = nn.Dense(self.action_size, kernel_init=_centred(_final_init), bias_init=_centred(_final_init))(x)
        return x if pre_tanh else jnp.tanh(x)  # actions live in [-1, 1]


class Critic(nn.Module):
    hidden: Sequence[int] = (400, 300)

    @nn.compact
    def __call__(self, obs: jax.Array, action: jax.Array) -> jax.Array:
        x = nn.relu(nn.Dense(self.hidden[0])(obs))
        x = jnp.concatenate([x, action], axis=-1)  # the action enters at the second layer
        for width in self.hidden[1:]:
            x = nn.relu(nn.Dense(width)(x))
        q = nn.Dense(1, kernel_init=_centred(_final_init), bias_init=_centred(_final_init))(x)
        return q[..., 0]
