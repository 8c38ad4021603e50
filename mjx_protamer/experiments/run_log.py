"""Per-chunk training logs: a CSV, TensorBoard event files (tensorboardX) and a training-curve plot."""

from __future__ import annotations

import csv
import math
import sys
from pathlib import Path

import numpy as np

from mjx_protamer.atomic import replacing

CSV_NAME = "metrics.csv"
PLOT_NAME = "training_curve.png"


def flatten(metrics: dict, term_names: tuple[str, ...]) -> dict[str, float]:
    """Host scalars from a chunk's metrics; the reward-term vector becomes one column per term."""
    row: dict[str, float] = {}
    for key, value in metrics.items():
        value = np.asarray(value)
        if key == "reward_terms":
            for name, v in zip(term_names, value.reshape(-1)):
                row[f"reward_term/{name}"] = float(v)
        else:
            row[key] = float(value)
    return row


def read_rows(path: str | Path) -> tuple[list[dict[str, float]], int]:
    """(rows, skipped) of a metrics CSV: rows that parse completely, and the count of those that do not (a
    row torn by a kill in the middle of a write, or damage)."""
    rows, skipped = [], 0
    with Path(path).open(newline="") as f:
        for r in csv.DictReader(f):
            try:
                if None in r or any(v is None for v in r.values()):
                    raise ValueError("short or long row")
                rows.append({k: float(v) for k, v in r.items()})
            except ValueError:
                skipped += 1
    return rows, skipped


class RunLog:
    """Appends one row per chunk. On resume, rows past the restored chunk (written after the last
    checkpoint of a killed run) and a row torn by the kill are dropped (and counted on stderr), so the
    log matches an uninterrupted run."""

    def __init__(self, out_dir: str | Path, resume_chunk: int = 0, tensorboard: bool = True):
        self.out_dir = Path(out_dir)
        self.csv_path = self.out_dir / CSV_NAME
        self.rows: list[dict] = []
        if resume_chunk > 0 and self.csv_path.exists():
            rows, skipped = read_rows(self.csv_path)
            if skipped:
                print(f"note: {self.csv_path}: skipped {skipped} unreadable row(s) (a write torn by the kill)",
                      file=sys.stderr)
            self.rows = [r for r in rows if r["chunk"] <= resume_chunk]
        self._rewrite()
        self.writer = None
        if tensorboard:
            from tensorboardX import SummaryWriter

            purge = int(self.rows[-1]["env_steps"]) + 1 if self.rows else None
            self.writer = SummaryWriter(str(self.out_dir / "tb"), purge_step=purge)

    def _rewrite(self) -> None:
        """The CSV from `self.rows`, replaced atomically (a kill leaves the old file or the new one)."""
        with replacing(self.csv_path) as tmp, tmp.open("w", newline="") as f:
            if self.rows:
                w = csv.DictWriter(f, fieldnames=list(self.rows[0]))
                w.writeheader()
                w.writerows(self.rows)

    def write(self, row: dict[str, float]) -> None:
        new_file = not self.rows
        self.rows.append(row)
        with self.csv_path.open("a", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(self.rows[0]))
            if new_file:
                w.writeheader()
            w.writerow(row)
        if self.writer is not None:
            step = int(row["env_steps"])
            for key, value in row.items():
                if key not in ("chunk", "env_steps") and not math.isnan(value):
                    self.writer.add_scalar(key if "/" in key else f"train/{key}", value, step)
            self.writer.flush()

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()


def plot_curve(rows: list[dict], path: str | Path) -> Path:
    """Reward per step, episode return and contact rate against env steps, as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps = [r["env_steps"] for r in rows]
    panels = [("step_reward", "reward per env step", "tab:blue"),
              ("episode_return", "episode return (finished episodes)", "tab:green"),
              ("contact_rate", "self-contact rate", "tab:orange")]
    fig, axes = plt.subplots(1, len(panels), figsize=(14, 3.5))
    for ax, (key, label, color) in zip(axes, panels):
        ax.plot(steps, [r.get(key, float("nan")) for r in rows], marker=".", color=color)
        ax.set_ylabel(label)
        ax.set_xlabel("env steps")
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)
