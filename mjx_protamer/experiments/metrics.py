"""The paper's four behaviour metrics, computed from per-step signals of test episodes.

Inputs per episode:
- `self_contact` (T,): 1 where the step had at least one self-contact;
- `region_mask` (T, 8): 1 for each body region touched at that step;
- `arm_speed` (T,): the arm joint-speed norm in rad/s.

Definitions (spec, "Metrics"):
- first_touch_step: steps before the first self-contact (T, the episode length, if none);
- contact_rate: fraction of steps with a self-contact;
- unique_regions: number of distinct regions touched in the episode (of 8);
- freeze_ratio: fraction of steps with arm speed below `freeze_threshold` (1 rad/s).
"""

from __future__ import annotations

import numpy as np

METRIC_NAMES = ("first_touch_step", "contact_rate", "unique_regions", "freeze_ratio")
FREEZE_THRESHOLD = 1.0  # rad/s


def episode_counts(self_contact, region_mask, arm_speed, freeze_threshold: float = FREEZE_THRESHOLD, xp=np) -> dict:
    """Whole-number counts of episodes (leading axes) over their steps (axis -1 of `self_contact`/`arm_speed`,
    -2 of `region_mask`): `first_touch_step`, `contact_steps`, `unique_regions`, `slow_steps`, and
    `region_steps` (..., 8), the steps each region was touched (body maps). Written for any array namespace:
    NumPy here, `jax.numpy` inside the jitted evaluator (experiments/evaluate.py); the metrics are these counts
    over the step count (`from_counts`), so both give the same numbers."""
    contact = self_contact > 0
    touched = region_mask > 0
    steps = contact.shape[-1]
    return {
        "first_touch_step": xp.where(contact.any(axis=-1), xp.argmax(contact, axis=-1), steps),
        "contact_steps": contact.sum(axis=-1),
        "unique_regions": touched.any(axis=-2).sum(axis=-1),
        "slow_steps": (arm_speed < freeze_threshold).sum(axis=-1),
        "region_steps": touched.sum(axis=-2),
    }


def episode_metrics(self_contact, region_mask, arm_speed, freeze_threshold: float = FREEZE_THRESHOLD) -> dict:
    """The four metrics of one episode."""
    contact = np.asarray(self_contact).reshape(-1)
    regions = np.asarray(region_mask)
    speed = np.asarray(arm_speed).reshape(-1)
    steps = contact.shape[0]
    if regions.shape[0] != steps or speed.shape[0] != steps:
        raise ValueError(f"signals differ in length: {steps}, {regions.shape[0]}, {speed.shape[0]}")
    counts = episode_counts(contact[None], regions[None], speed[None], freeze_threshold)
    return _episodes(counts, steps)[0]


def _episodes(counts: dict, steps: int) -> list[dict]:
    return [{"first_touch_step": int(first), "contact_rate": float(contact / steps) if steps else 0.0,
             "unique_regions": int(regions), "freeze_ratio": float(slow / steps) if steps else 0.0}
            for first, contact, regions, slow in zip(*(np.asarray(counts[k]).reshape(-1) for k in (
                "first_touch_step", "contact_steps", "unique_regions", "slow_steps")))]


def from_counts(counts: dict, steps: int) -> dict:
    """Metrics over a batch of episodes from their `episode_counts` (host arrays) and the episode length: each
    metric's mean, the per-region touch frequency, and `per_episode` lists."""
    per = _episodes(counts, steps)
    out: dict = {name: float(np.mean([p[name] for p in per])) for name in METRIC_NAMES}
    out["episodes"] = len(per)
    # where the touches go (body maps): the fraction of all test steps each region was touched
    region_steps = np.asarray(counts["region_steps"]).reshape(-1, np.shape(counts["region_steps"])[-1])
    out["region_touch_frequency"] = [float(v / (len(per) * steps)) for v in region_steps.sum(axis=0)]
    out["per_episode"] = {name: [p[name] for p in per] for name in METRIC_NAMES}
    return out


def summarize(self_contact, region_mask, arm_speed, freeze_threshold: float = FREEZE_THRESHOLD) -> dict:
    """Metrics over a batch of episodes (leading axis): each metric's mean, and `per_episode` lists."""
    contact = np.asarray(self_contact)
    return from_counts(episode_counts(contact, np.asarray(region_mask), np.asarray(arm_speed), freeze_threshold),
                       contact.shape[-1])


def format_table(summary: dict, reference: dict | None = None) -> str:
    """A plain-text table of the metric means (with a reference column, e.g. the paper's DDPG, if given)."""
    lines = [f"{'metric':<18}{'mean':>10}" + (f"{'paper':>10}" if reference else "")]
    for name in METRIC_NAMES:
        row = f"{name:<18}{summary[name]:>10.3f}"
        if reference and name in reference:
            row += f"{reference[name]:>10.3f}"
        lines.append(row)
    return "\n".join(lines)


# Paper Table II, the DDPG baseline (means over 10 test episodes).
PAPER_DDPG = {"first_touch_step": 19.7, "contact_rate": 0.519, "unique_regions": 4.3, "freeze_ratio": 0.180}
