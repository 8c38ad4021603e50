"""Conditions of several table2 runs side by side: pooled by name over seeds, paired against a reference.

An ablation often runs as several programs: a condition's seeds 0-9 in one run and 10-19 in another, or a
variant (a channel with another delay, `--set feedback.teacher.channel...`) in its own run beside the run it
varies. This pools every condition by name over the runs' `table2.json` (`seed_values` with the run's `seeds`;
a seed given twice for one name is an error) and prints JSON: per condition and metric the mean, the 95%
half-width and the per-seed values (`table2.seed_stats`), and with `--reference NAME` each condition's
difference to it, unpaired and paired over the seeds both ran (`table2.contrast`). `--plot PNG` draws each
metric's per-seed values, the mean and its 95% interval, one panel a metric.

    protamer analyze compare-conditions RUN[@TAG]... [--names DTK,DTW,...] [--reference DTK]
        [--metric teacher_score --metric r_hat_corr_test] [--plot compare.png]
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from mjx_protamer.experiments.table2 import contrast, seed_stats

DEFAULT_METRICS = ("teacher_score", "r_hat_corr_test", "unique_regions", "freeze_ratio")


def pool(runs: list[str], metrics) -> dict[str, dict[str, dict[int, float]]]:
    """{condition: {metric: {seed: value}}} over the runs; a seed twice for one condition raises ValueError.
    A run given as DIR@TAG names its conditions NAME@TAG (the same condition trained or scored two ways)."""
    pooled: dict[str, dict[str, dict[int, float]]] = {}
    for arg in runs:
        run, _, tag = str(arg).partition("@")
        run = Path(run)
        path = run if run.suffix == ".json" else run / "table2.json"
        if not path.is_file():
            raise ValueError(f"{path} is missing: give the --out directory of a finished table2 run")
        summary = json.loads(path.read_text())
        for name, cond in summary["conditions"].items():
            name = f"{name}@{tag}" if tag else name
            for m in metrics:
                if m not in cond:
                    continue
                per_seed = pooled.setdefault(name, {}).setdefault(m, {})
                for seed, v in zip(summary["seeds"], cond[m]["seed_values"]):
                    if seed in per_seed:
                        raise ValueError(f"condition {name} has seed {seed} in two runs (the second: {run}); "
                                         f"give each seed of a condition once")
                    per_seed[seed] = v
    return pooled


def compare(pooled: dict, names: list[str], metrics, reference: str | None) -> dict:
    out: dict = {"conditions": {}, "reference": reference}
    for name in names:
        entry = {}
        for m in metrics:
            sv = pooled[name].get(m, {})
            seeds = sorted(sv)
            entry[m] = {"seeds": seeds, **seed_stats([sv[s] for s in seeds])}
            if reference is not None and name != reference and m in pooled[reference]:
                ref = pooled[reference][m]
                common = [s for s in seeds if s in ref]
                entry[m]["vs_reference"] = {"seeds": common, **contrast([ref[s] for s in common],
                                                                        [sv[s] for s in common])}
        out["conditions"][name] = entry
    return out


def plot(result: dict, metrics, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(result["conditions"])
    fig, axes = plt.subplots(1, len(metrics), figsize=(1.2 + 0.75 * len(names) * len(metrics), 4.2), squeeze=False)
    for ax, m in zip(axes[0], metrics):
        for i, n in enumerate(names):
            st = result["conditions"][n][m]
            v = np.asarray([np.nan if x is None else x for x in st["seed_values"]], float)
            jitter = np.linspace(-0.18, 0.18, len(v)) if len(v) > 1 else np.zeros(len(v))
            ax.scatter(i + jitter, v, marker="o", facecolors="none", edgecolors="grey", s=18, zorder=2,
                       label="seeds" if i == 0 else None)
            if st["mean"] is not None:
                ax.errorbar(i, st["mean"], yerr=st["ci95"] or 0.0, fmt="s", color="black", capsize=4, zorder=3,
                            label="mean ± 95% CI" if i == 0 else None)
        ax.set_xticks(range(len(names)), names, rotation=35, ha="right", fontsize=8)
        ax.set_title(m, fontsize=9)
        ax.grid(alpha=0.3, axis="y")
    axes[0][0].legend(fontsize=7, loc="best")
    n_seeds = sorted({len(result["conditions"][n][metrics[0]]["seed_values"]) for n in names})
    fig.suptitle(f"per-seed values, seeds per condition: {', '.join(map(str, n_seeds))}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def compare_runs(runs: list[str], names: list[str] | None, metrics, reference: str | None) -> dict:
    """`compare` of the pooled runs' conditions `names` (None: all, in the runs' order); a condition no run has
    raises ValueError, as `pool` does for a seed given twice."""
    pooled = pool(runs, metrics)
    names = list(names) if names else list(pooled)
    for n in names + ([reference] if reference else []):
        if n not in pooled:
            raise ValueError(f"no run has a condition named {n!r}; they have: {', '.join(pooled)}")
    return compare(pooled, names, metrics, reference)
