"""Statistics over seeds (or checkpoints): means with Student-t 95% intervals, per-seed values, paired contrasts;
and the correlation every r_hat score reports.

One place for what every table of the project reports (Table II, the live sessions, the screens).
"""

from __future__ import annotations

import numpy as np


def seed_stats(values) -> dict:
    """Mean over seeds, the per-seed values and the 95% confidence half-width of the mean (Student t)."""
    from scipy import stats

    v = np.asarray([np.nan if x is None else x for x in values], float)
    v = v[np.isfinite(v)]
    n = len(v)
    mean = float(v.mean()) if n else None
    ci = float(stats.t.ppf(0.975, n - 1) * v.std(ddof=1) / np.sqrt(n)) if n > 1 else None
    return {"mean": mean, "ci95": ci, "seed_values": [None if x is None else float(x) for x in values],
            "seed_std": float(v.std(ddof=1)) if n > 1 else None}


def contrast(baseline, values) -> dict:
    """A feedback condition's metric against the baseline's on the same seeds.

    `beyond_ci95_sum`: the difference of the means exceeds the sum of the two 95% half-widths (issue 8's
    criterion; it ignores that both runs of a seed start from the same networks, envs and noise).
    `paired`: the per-seed differences with their own mean and 95% half-width (a paired t interval over the
    seeds, valid because the seeds are independent of each other); `paired_beyond_zero` when that interval
    excludes 0."""
    base, cond = seed_stats(baseline), seed_stats(values)
    if base["mean"] is None or cond["mean"] is None or base["ci95"] is None or cond["ci95"] is None:
        return {"difference": None, "ci95_sum": None, "beyond_ci95_sum": None, "paired": None,
                "paired_beyond_zero": None}
    diffs = [None if a is None or b is None else b - a for a, b in zip(baseline, values)]
    paired = seed_stats(diffs)
    return {"difference": cond["mean"] - base["mean"], "ci95_sum": base["ci95"] + cond["ci95"],
            "beyond_ci95_sum": bool(cond["mean"] - base["mean"] > base["ci95"] + cond["ci95"]),
            "paired": paired,
            "paired_beyond_zero": None if paired["ci95"] is None else bool(paired["mean"] - paired["ci95"] > 0)}


def pearson(x, y) -> float | None:
    """Pearson correlation of two equally long arrays; None where either side is constant (no variation to track,
    where NumPy would give NaN and a warning)."""
    x, y = np.asarray(x), np.asarray(y)
    x, y = x - x.mean(), y - y.mean()
    den = float(np.sqrt(np.sum(x * x) * np.sum(y * y)))
    return float(np.sum(x * y) / den) if den > 1e-12 else None
