"""The paper's four behaviour metrics, computed from per-step signals of test episodes.

Pure NumPy on host arrays; inputs per episode:
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


def episode_metrics(self_contact, region_mask, arm_speed, freeze_threshold: float = FREEZE_THRESHOLD) -> dict:
    """The four metrics of one episode."""
    contact = np.asarray(self_contact).reshape(-1) > 0
    regions = np.asarray(region_mask) > 0
    speed = np.asarray(arm_speed).reshape(-1)
    steps = contact.shape[0]
    if regions.shape[0] != steps or speed.shape[0] != steps:
        raise ValueError(f"signals differ in length: {steps}, {regions.shape[0]}, {speed.shape[0]}")
    touched = np.flatnonzero(contact)
    return {
        "first_touch_step": int(touched[0]) if touched.size else steps,
        "contact_rate": float(contact.mean()) if steps else 0.0,
        "unique_regions": int(regions.any(axis=0).sum()),
        "freeze_ratio": float((speed < freeze_threshold).mean()) if steps else 0.0,
    }


def summarize(self_contact, region_mask, arm_speed, freeze_threshold: float = FREEZE_THRESHOLD) -> dict:
    """Metrics over a batch of episodes (leading axis): each metric's mean, and `per_episode` lists."""
    per = [
        episode_metrics(c, r, s, freeze_threshold)
        for c, r, s in zip(np.asarray(self_contact), np.asarray(region_mask), np.asarray(arm_speed))
    ]
    out: dict = {name: float(np.mean([p[name] for p in per])) for name in METRIC_NAMES}
    out["episodes"] = len(per)
    # where the touches go (body maps): the fraction of all test steps each region was touched
    out["region_touch_frequency"] = [float(v) for v in (np.asarray(region_mask) > 0).reshape(
        -1, np.asarray(region_mask).shape[-1]).mean(axis=0)]
    out["per_episode"] = {name: [p[name] for p in per] for name in METRIC_NAMES}
    return out


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
