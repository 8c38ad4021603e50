"""The step-size decay over a run, shared by DDPG's actor and critic and the batched reward model.

1 until `decay_from` of the run's iterations, then linear to `final_fraction` at its last one. Adam's step is
linear in its learning rate, so multiplying an update by this scale is the scheduled rate, and the optimiser
state keeps its shape (no schedule inside the optimiser, whose count would also advance on skipped steps).
"""

from __future__ import annotations

import jax.numpy as jnp


def decay_scale(iteration, iterations: int, decay_from: float, final_fraction: float):
    """The multiplier at `iteration` of a run of `iterations` (float32 scalar; 1.0 when `final_fraction` is 1)."""
    if final_fraction >= 1.0:
        return jnp.float32(1.0)
    start = decay_from * iterations
    progress = jnp.clip((iteration - start) / max(iterations - start, 1.0), 0.0, 1.0)
    return (1.0 - progress * (1.0 - final_fraction)).astype(jnp.float32)
