"""`batch_any`: one branch for a whole vmapped batch, where a branch that is exact for every member exists.

Under `jax.vmap` a `lax.cond` whose predicate is batched becomes a `select`: both branches run for every member
and the results are picked afterwards. Table II vmaps its seeds in one program, and the auto-reset
(`envs/wrappers.py`) branches on "some env of this seed finished": under the seed vmap that predicate is batched,
and every step paid for a reset of every seed's envs. The reset branch is exact for a seed none of whose envs
finished (it keeps their states), so the branch can be taken when any seed needs it.

`batch_any(x)` is `x` outside vmap; under vmap it is `jnp.any` over the mapped axis, one unbatched value
(`jax.custom_batching.custom_vmap`), so a `lax.cond` on it stays a branch.

Not used for DDPG's warm-up branch (`agents/ddpg/train.py`): there a real conditional around the update, on a
value all seeds share, measured slower than the select (5-seed Table II chunk, interleaved in one process,
1.7% slower), and the update branch is not exact for a member still warming up.
"""

from __future__ import annotations

import jax.numpy as jnp
from jax.custom_batching import custom_vmap


@custom_vmap
def batch_any(x):
    return x


@batch_any.def_vmap
def _any_rule(axis_size, in_batched, x):
    (batched,) = in_batched
    return (jnp.any(x, axis=0) if batched else x), False
