"""The intrinsic reward: contact, novelty, region, movement band, energy, joint limits and habituation.

Written once for NumPy and JAX (`xp`). The terms are returned unweighted, in
`config.REWARD_TERMS` order; the reward is their dot product with `RewardConfig.weights()`, which a
learner can redo at sample time (relabelling) from the stored terms.
"""

from __future__ import annotations

from mjx_protamer.envs.config import EnvConfig, RewardConfig


def habituate(xp, familiarity, regions, rates):
    """The familiarity trace one step on: touched regions approach 1, the others decay towards 0.

    rates = (retention of unfamiliarity while touched, retention of familiarity while not), from
    EnvConfig.familiarity_rates().
    """
    touched_keep, untouched_keep = rates
    return xp.where(regions, 1.0 - (1.0 - familiarity) * touched_keep, familiarity * untouched_keep)


def familiarity_signals(xp, env: EnvConfig, familiarity, regions):
    """(the trace the habituation term reads, the trace after this step, which the observation shows);
    (None, None) with habituation off. The one place both envs decide it."""
    if env.habituation_s <= 0:
        return None, None
    return familiarity, habituate(xp, familiarity, regions, env.familiarity_rates())


def reward_terms(xp, cfg: RewardConfig, touch, prev_touch, regions, prev_regions, arm_speed, torque, action,
                 familiarity=None):
    """The terms at one step; `familiarity` is the trace before this step (None: no habituation, term 0)."""
    contact = cfg.contact_scale * xp.tanh(cfg.contact_gain * xp.sum(xp.abs(touch)))
    if cfg.novelty_force_scale > 0:
        now, before = xp.tanh(touch / cfg.novelty_force_scale), xp.tanh(prev_touch / cfg.novelty_force_scale)
    else:
        now, before = touch, prev_touch
    novelty = xp.sqrt(xp.sum((now - before) ** 2))
    if cfg.novelty_clip > 0:
        novelty = xp.minimum(novelty, cfg.novelty_clip)
    # New regions: the touched set is not a subset of the previous step's set.
    new_region = xp.any(regions & ~prev_regions)
    region = xp.where(new_region, cfg.region_new, cfg.region_stale)
    arm_speed = xp.asarray(arm_speed)
    movement = cfg.movement_penalty * (xp.asarray(arm_speed < cfg.speed_low, dtype=touch.dtype)
                                       + xp.asarray(arm_speed > cfg.speed_high, dtype=touch.dtype))
    energy = -cfg.energy_coef * xp.sum(torque**2)
    joint_limit = -cfg.limit_coef * xp.sum(xp.clip(xp.abs(action) - cfg.limit_threshold, 0.0, 1.0))
    habituation = 0.0 if familiarity is None else xp.sum(xp.where(regions, 1.0 - familiarity, 0.0))
    return xp.stack([xp.asarray(t, dtype=touch.dtype) for t in
                     (contact, novelty, region, movement, energy, joint_limit, habituation)])
