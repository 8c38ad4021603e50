"""A trained table2 run's files: table2.json and table2.md, Figure 1 (training curves), Figure 2 (unique regions
per test episode), training.csv and one body map per condition (drawn by `view.bodymap`: this module is the
only one of `experiments` that imports `view`)."""

from __future__ import annotations

import csv
import json
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from mjx_protamer.experiments.table2.config import Table2Config
from mjx_protamer.experiments.table2.report import format_markdown, summarize

if TYPE_CHECKING:
    from mjx_protamer.experiments.table2.run import Trained


def write_table2(cfg: Table2Config, out_dir, trained: Trained, total_s: float, extra: dict | None = None) -> dict:
    """table2.json / table2.md (with `extra`'s keys added to the summary), the figures and training.csv of a trained
    run into `out_dir`; the paths, the wall time, the summary and each condition's region frequencies (the command
    draws their body maps: a body map renders the infant, which is the view's, above this layer)."""
    from mjx_protamer.atomic import write_atomic

    out = Path(out_dir)
    training, evals = trained.training, trained.evals
    _write_training_csv(training, out / "training.csv")
    summary = {**summarize(cfg, evals, trained.wall, total_s), **(extra or {})}
    write_atomic(out / "table2.json", json.dumps(summary, indent=2))
    write_atomic(out / "table2.md", format_markdown(summary))
    fig1 = plot_training(training, cfg, out / "figure1_training_reward.png")
    fig2 = plot_regions(summary, out / "figure2_unique_regions.png")
    return {"out_dir": str(out), "table_md": str(out / "table2.md"), "table_json": str(out / "table2.json"),
            "figure1": str(fig1), "figure2": str(fig2), "training_csv": str(out / "training.csv"),
            "wall_s": total_s, "summary": summary, "region_frequencies": region_frequencies(evals)}


def _write_training_csv(rows: list[dict], path: Path) -> None:
    keys: list[str] = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)


def _moving(x: np.ndarray, k: int) -> np.ndarray:
    """Moving average that skips NaN (chunks without a finished episode)."""
    out = np.full_like(x, np.nan, dtype=float)
    for i in range(len(x)):
        w = x[max(0, i - k + 1): i + 1]
        w = w[~np.isnan(w)]
        if w.size:
            out[i] = w.mean()
    return out


def plot_training(rows: list[dict], cfg: Table2Config, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4))
    panels = (("episode_return", "training episode return (intrinsic reward)"),
              ("sampled_reward", "reward DDPG trains on per step (α r_env + β r̂)"))
    for ax, (key, label) in zip(axes, panels):
        for c in cfg.conditions:
            curves = []
            for seed in cfg.seeds:
                r = [x for x in rows if x["condition"] == c.name and x["seed"] == seed]
                curves.append(_moving(np.array([x.get(key, np.nan) for x in r], float), cfg.moving_average))
                steps = np.array([x["env_steps"] for x in r])
            curves = np.array(curves)
            with warnings.catch_warnings():  # chunks where no seed finished an episode stay NaN
                warnings.simplefilter("ignore", RuntimeWarning)
                mean = np.nanmean(curves, axis=0)
            line, = ax.plot(steps, mean, label=c.name, lw=2)
            for curve in curves if len(cfg.seeds) > 1 else ():  # every seed, thin: bimodal runs stay visible
                ax.plot(steps, curve, color=line.get_color(), lw=0.6, alpha=0.5)
        ax.set_xlabel("env steps (all envs)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        ax.legend()
    fig.suptitle(f"Figure 1 analogue: moving average ({cfg.moving_average} chunks) over "
                 f"{len(cfg.seeds)} seed(s); thick: mean, thin: each seed")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_regions(summary: dict, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(summary["conditions"])
    data = [summary["conditions"][n]["unique_regions"]["per_episode"] for n in names]
    fig, ax = plt.subplots(figsize=(6, 4.4))
    # the box spans test episodes; its outliers are single episodes, drawn unlike the seed means' circles
    ax.boxplot(data, showmeans=True, flierprops=dict(marker="+", markeredgecolor="grey", markersize=6))
    ax.plot([], [], "^", color="green", label="mean of episodes")
    ax.plot([], [], "+", color="grey", label="single episodes (box outliers)")
    ax.set_xticks(range(1, len(names) + 1), names)
    for i, n in enumerate(names, start=1):
        seed_means = summary["conditions"][n]["unique_regions"]["seed_values"]
        jitter = np.linspace(-0.12, 0.12, len(seed_means)) if len(seed_means) > 1 else np.zeros(1)
        ax.scatter(i + jitter, seed_means, marker="o", facecolors="none", edgecolors="black", zorder=3,
                   label="seed means" if i == 1 else None)
        paper = summary["conditions"][n]["paper"]
        if paper:
            ax.plot(i, paper["unique_regions"], marker="x", color="red", ms=9,
                    label="paper mean" if i == 1 else None)
    ax.set_ylabel("unique regions per test episode")
    ax.set_ylim(-0.3, 8.3)
    ax.grid(alpha=0.3, axis="y")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.08), ncol=4, fontsize=7.5, frameon=False)  # off the data
    ax.set_title(f"Figure 2 analogue ({sum(len(d) for d in data) // len(names)} test episodes per condition)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def region_frequencies(evals: dict) -> dict[str, dict]:
    """Per condition, how often each body region was touched in its test episodes, averaged over its seeds (what
    a body map draws; the command draws them, `view.bodymap.write_condition_body_maps`)."""
    return {name: {"frequency": np.mean([ev["region_touch_frequency"] for ev in per_seed.values()], axis=0).tolist(),
                   "seeds": len(per_seed)} for name, per_seed in evals.items()}
