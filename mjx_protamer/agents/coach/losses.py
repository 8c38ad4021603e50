"""The Deep COACH update as a surrogate loss.

For a window of L steps (oldest first) judged by feedback f, Deep COACH accumulates the eligibility trace

    e <- lambda * e + (pi_theta(a_j | s_j) / pi_old(a_j | s_j)) * grad log pi_theta(a_j | s_j),  j = 0..L-1

and ascends f * e (plus an entropy bonus). The trace equals sum_j lambda^(L-1-j) * ratio_j * grad log pi_j,
so its gradient is that of the surrogate below with the ratio held constant (stop_gradient): the ratio
corrects for windows recorded under an older policy (pi_old is the policy that sampled the action).
The loss is averaged over a minibatch of windows; steps absent from a window (mask 0) contribute nothing.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from mjx_protamer.agents.coach.networks import entropy, log_prob


def trace_coefficients(window: int, decay: float) -> jax.Array:
    """lambda^(L-1-j) for j = 0 (oldest) .. L-1 (newest)."""
    return decay ** jnp.arange(window - 1, -1, -1, dtype=jnp.float32)


def coach_loss(params, apply, obs, action, logp_old, mask, feedback, decay: float, entropy_coef: float,
               min_log_std: float = -3.0, max_ratio: float = 10.0):
    """obs (W, L, O), action (W, L, A), logp_old / mask (W, L), feedback (W,) -> scalar loss, aux."""
    mean, log_std = apply(params, obs)
    logp = log_prob(mean, log_std, action, min_log_std)
    ratio = jax.lax.stop_gradient(jnp.minimum(jnp.exp(logp - logp_old), max_ratio))
    coef = trace_coefficients(obs.shape[1], decay)[None, :]
    trace = jnp.sum(coef * ratio * logp * mask, axis=1)  # (W,)
    pg = -jnp.mean(feedback * trace)
    ent = jnp.mean(entropy(log_std[:, -1], min_log_std))
    return pg - entropy_coef * ent, {"entropy": ent, "ratio": jnp.sum(ratio * mask) / jnp.maximum(jnp.sum(mask), 1)}
