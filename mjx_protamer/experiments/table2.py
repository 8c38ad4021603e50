"""Reproduce the paper's Table II and Figures 1-2 with simulated teachers.

Four conditions with the same seeds and the same hidden teacher rule: DDPG (no feedback), DTK (simulated
keyboard), DTW (simulated speech: the Whisper + sentiment channel, +1/0/-1 through a confusion matrix, long
latency) and DTP (simulated prosody: continuous, noisy). Every condition runs the same compiled program
(`feedback_train.make_feedback_train`): the channel, credit weights and human-reward gain are values, and
DDPG alone is the gain-0, silent-teacher case (its reward is bit for bit DDPG's). DDPG's random stream does
not depend on the feedback path, so for a seed the four conditions start from the same networks, envs and
exploration noise. Each trained policy is evaluated on `eval_episodes` test episodes with the deterministic
actor (the same test seed for every condition).

Outputs in `out`: table2.md and table2.json (the paper's layout, the paper's numbers beside ours),
figure1_training_reward.png (moving average of the training episode return per condition),
figure2_unique_regions.png (box plot of unique regions per test episode), training.csv (every chunk of
every run) and eval_<condition>_seed<k>.json.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import platform
import time
from pathlib import Path
from typing import Literal

import jax
import numpy as np

from mjx_protamer.config import ConfigError, check, to_dict
from mjx_protamer.experiments import metrics as M
from mjx_protamer.experiments.feedback_train import BatchedFeedbackConfig, make_feedback_train
from mjx_protamer.experiments.run_log import flatten

# Paper Table II (means over 10 test episodes).
PAPER = {
    "DDPG": {"first_touch_step": 19.7, "contact_rate": 0.519, "unique_regions": 4.3, "freeze_ratio": 0.180},
    "DTK": {"first_touch_step": 26.1, "contact_rate": 0.763, "unique_regions": 5.3, "freeze_ratio": 0.047},
    "DTW": {"first_touch_step": 23.7, "contact_rate": 0.536, "unique_regions": 3.1, "freeze_ratio": 0.428},
    "DTP": {"first_touch_step": 15.8, "contact_rate": 0.915, "unique_regions": 4.8, "freeze_ratio": 0.258},
}
LABELS = {"first_touch_step": "First touch step ↓", "contact_rate": "Contact rate ↑",
          "unique_regions": "Unique regions ↑", "freeze_ratio": "Freeze ratio ↓"}


def _pretrain_default():
    from mjx_protamer.agents.ddpg.config import PretrainConfig
    return PretrainConfig()


def _feedback_default():
    from mjx_protamer.human.tamer_loop import FeedbackConfig
    return FeedbackConfig()


@dataclasses.dataclass(frozen=True)
class Condition:
    name: str
    channel: Literal["none", "keyboard", "prosody", "speech"] = "none"
    credit: Literal["step_window", "time_window"] = "time_window"
    beta_scale: float = 1.0  # multiplies ddpg.reward_beta for this condition (a value: no recompile)

    def validate(self) -> None:
        check(bool(self.name), "name", "must not be empty")
        check(self.beta_scale >= 0, "beta_scale", f"must be >= 0, got {self.beta_scale}")


DEFAULT_CONDITIONS = (Condition("DDPG", "none"), Condition("DTK", "keyboard"), Condition("DTW", "speech"),
                      Condition("DTP", "prosody"))


@dataclasses.dataclass(frozen=True)
class Table2Config:
    pretrain: object = dataclasses.field(default_factory=_pretrain_default)  # PretrainConfig
    feedback: object = dataclasses.field(default_factory=_feedback_default)  # FeedbackConfig (rule, model, dt)
    batched: BatchedFeedbackConfig = dataclasses.field(default_factory=BatchedFeedbackConfig)
    conditions: tuple[Condition, ...] = DEFAULT_CONDITIONS
    seeds: tuple[int, ...] = (0,)
    moving_average: int = 10  # chunks in Figure 1's moving average

    def validate(self) -> None:
        check(len(self.conditions) >= 1, "conditions", "needs at least one condition")
        names = [c.name for c in self.conditions]
        check(len(set(names)) == len(names), "conditions", f"names must be unique, got {names}")
        check(len(self.seeds) >= 1, "seeds", "needs at least one seed")
        check(self.moving_average >= 1, "moving_average", f"must be >= 1, got {self.moving_average}")


def load_table2_config(path=None, overrides=None, seeds: int | None = None) -> Table2Config:
    from mjx_protamer.agents.ddpg.config import PretrainConfig
    from mjx_protamer.config import from_dict, read_raw
    from mjx_protamer.human.tamer_loop import FeedbackConfig

    raw = read_raw(path, overrides)
    allowed = {"pretrain", "feedback", "batched", "conditions", "seeds", "moving_average"}
    unknown = sorted(set(raw) - allowed)
    if unknown:
        raise ConfigError(f"unknown config key(s) {', '.join(unknown)}; allowed keys: {', '.join(sorted(allowed))}")
    if seeds is not None:
        if seeds < 1:
            raise ConfigError(f"--seeds must be >= 1, got {seeds}")
        raw["seeds"] = list(range(seeds))
    top = {k: v for k, v in raw.items() if k in ("batched", "conditions", "seeds", "moving_average")}
    from mjx_protamer.config import _build  # nested dataclasses with the usual validation

    cfg = _build(_Top, top)
    out = Table2Config(pretrain=from_dict(PretrainConfig, raw.get("pretrain")),
                       feedback=from_dict(FeedbackConfig, raw.get("feedback")),
                       batched=cfg.batched, conditions=cfg.conditions, seeds=cfg.seeds,
                       moving_average=cfg.moving_average)
    out.validate()
    return out


@dataclasses.dataclass(frozen=True)
class _Top:
    batched: BatchedFeedbackConfig = dataclasses.field(default_factory=BatchedFeedbackConfig)
    conditions: tuple[Condition, ...] = DEFAULT_CONDITIONS
    seeds: tuple[int, ...] = (0,)
    moving_average: int = 10

    def validate(self) -> None:
        Table2Config.validate(self)  # type: ignore[arg-type]


def run_table2(cfg: Table2Config, out_dir, progress: bool = True) -> dict:
    from mjx_protamer.experiments.env_factory import make_env, with_resolved_backend
    from mjx_protamer.experiments.evaluate import eval_seed, evaluate

    cfg = dataclasses.replace(cfg, pretrain=with_resolved_backend(cfg.pretrain, announce=progress))
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    import yaml

    (out / "config.yaml").write_text(yaml.safe_dump(to_dict(cfg), sort_keys=False))
    pre = cfg.pretrain
    tc = pre.train
    env = make_env(pre)
    t_all = time.perf_counter()
    ft = make_feedback_train(pre, env, cfg.feedback, cfg.batched)
    training: list[dict] = []
    evals: dict[str, dict[int, dict]] = {c.name: {} for c in cfg.conditions}
    wall: dict[str, list[float]] = {c.name: [] for c in cfg.conditions}
    for seed in cfg.seeds:
        seeded = dataclasses.replace(pre, train=dataclasses.replace(tc, seed=seed))
        for cond in cfg.conditions:
            kind = None if cond.channel == "none" else cond.channel
            credit = dataclasses.replace(cfg.feedback.credit, scheme=cond.credit)
            t0 = time.perf_counter()
            ts = ft.trainer.init(jax.random.PRNGKey(seed))
            fs = ft.init(seed)
            fp = ft.params(kind, credit)
            fp = fp._replace(gain=fp.gain * cond.beta_scale)
            for chunk in range(1, tc.num_chunks + 1):
                ts, fs, m, _ = ft.chunk(ts, fs, fp)
                row = flatten(jax.device_get(m), env.reward_term_names)
                training.append({"condition": cond.name, "seed": seed, "chunk": chunk, **row})
                if progress and (chunk % max(1, tc.num_chunks // 5) == 0 or chunk == tc.num_chunks):
                    print(f"[{cond.name} seed {seed}] chunk {chunk}/{tc.num_chunks} return "
                          f"{row['episode_return']:.1f} contact {row['contact_rate']:.2f} feedback "
                          f"{row['feedback_total']:.0f} r_hat corr {row['r_hat_score_corr']:+.2f} "
                          f"({time.perf_counter() - t0:.0f} s)", flush=True)
            ev = evaluate(seeded, env, ts.actor_params, tc.eval_episodes, eval_seed(seeded))
            ev["feedback"] = {k: training[-1][k] for k in ("feedback_total", "feedback_pos_total",
                                                           "feedback_neg_total", "credited_rows_total",
                                                           "rm_updates_total", "r_hat_score_corr")}
            ev["train_wall_s"] = time.perf_counter() - t0
            wall[cond.name].append(ev["train_wall_s"])
            evals[cond.name][seed] = ev
            (out / f"eval_{cond.name}_seed{seed}.json").write_text(json.dumps(ev, indent=2))
    total_s = time.perf_counter() - t_all
    _write_training_csv(training, out / "training.csv")
    summary = _summarize(cfg, evals, wall, total_s)
    (out / "table2.json").write_text(json.dumps(summary, indent=2))
    (out / "table2.md").write_text(format_markdown(summary))
    fig1 = plot_training(training, cfg, out / "figure1_training_reward.png")
    fig2 = plot_regions(summary, out / "figure2_unique_regions.png")
    return {"out_dir": str(out), "table_md": str(out / "table2.md"), "table_json": str(out / "table2.json"),
            "figure1": str(fig1), "figure2": str(fig2), "training_csv": str(out / "training.csv"),
            "wall_s": total_s, "summary": summary}


def _write_training_csv(rows: list[dict], path: Path) -> None:
    keys: list[str] = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)


def _summarize(cfg: Table2Config, evals: dict, wall: dict, total_s: float) -> dict:
    conds = {}
    for c in cfg.conditions:
        per_seed = evals[c.name]
        entry: dict = {"channel": c.channel, "credit": c.credit if c.channel != "none" else None,
                       "beta": cfg.pretrain.ddpg.reward_beta * c.beta_scale if c.channel != "none" else 0.0,
                       "paper": PAPER.get(c.name)}
        for name in M.METRIC_NAMES:
            episodes = [v for s in cfg.seeds for v in per_seed[s]["per_episode"][name]]
            seed_means = [per_seed[s][name] for s in cfg.seeds]
            entry[name] = {"mean": float(np.mean(episodes)), "seed_means": seed_means,
                           "seed_std": float(np.std(seed_means)), "per_episode": episodes}
        entry["feedback"] = {k: float(np.mean([per_seed[s]["feedback"][k] for s in cfg.seeds]))
                             for k in per_seed[cfg.seeds[0]]["feedback"]}
        entry["episode_return"] = float(np.mean([per_seed[s]["episode_return"] for s in cfg.seeds]))
        entry["train_wall_s"] = float(np.sum(wall[c.name]))
        conds[c.name] = entry
    tc = cfg.pretrain.train
    return {
        "conditions": conds,
        "seeds": list(cfg.seeds),
        "env": cfg.pretrain.env_name,
        "num_envs": tc.num_envs,
        "env_steps_per_run": tc.iterations * tc.num_envs,
        "eval_episodes_per_seed": tc.eval_episodes,
        "wall_s": total_s,
        "machine": f"{platform.machine()}, {jax.device_count()} x {jax.devices()[0].platform}, "
                   f"{__import__('os').cpu_count()} CPU cores visible",
    }


def format_markdown(summary: dict) -> str:
    conds = summary["conditions"]
    names = list(conds)
    multi = len(summary["seeds"]) > 1
    head = "| Metric | " + " | ".join(f"{n} ours | {n} paper" for n in names) + " |"
    sep = "|---|" + "---|---|" * len(names)
    lines = [f"Table II analogue: means over {summary['eval_episodes_per_seed']} test episodes x "
             f"{len(summary['seeds'])} seed(s) {summary['seeds']} (deterministic actor); {summary['env']} env, "
             f"{summary['num_envs']} envs x {summary['env_steps_per_run']} env steps per run; "
             f"wall time {summary['wall_s']:.0f} s.", "", head, sep]
    for metric in M.METRIC_NAMES:
        cells = []
        for n in names:
            e = conds[n][metric]
            ours = f"{e['mean']:.3f}" + (f" ± {e['seed_std']:.3f}" if multi else "")
            paper = conds[n]["paper"]
            cells.append(f"{ours} | {paper[metric]:.3f}" if paper else f"{ours} | -")
        lines.append(f"| {LABELS[metric]} | " + " | ".join(cells) + " |")
    lines += ["", "| Feedback | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for key, label in (("feedback_total", "events given"), ("credited_rows_total", "credited rows"),
                       ("rm_updates_total", "r_hat updates"), ("r_hat_score_corr", "corr(r_hat, hidden score)")):
        lines.append(f"| {label} | " + " | ".join(f"{conds[n]['feedback'][key]:.2f}" if key == "r_hat_score_corr"
                                                   else f"{conds[n]['feedback'][key]:.0f}" for n in names) + " |")
    lines.append(f"| test return (intrinsic) | " + " | ".join(f"{conds[n]['episode_return']:.1f}" for n in names)
                 + " |")
    if multi:
        lines += ["", "± : std over seeds of the per-seed means."]
    return "\n".join(lines) + "\n"


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
            with np.errstate(all="ignore"):
                mean = np.nanmean(curves, axis=0)
            line, = ax.plot(steps, mean, label=c.name)
            if len(cfg.seeds) > 1:
                ax.fill_between(steps, np.nanmin(curves, axis=0), np.nanmax(curves, axis=0), alpha=0.15,
                                color=line.get_color())
        ax.set_xlabel("env steps (all envs)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        ax.legend()
    fig.suptitle(f"Figure 1 analogue: moving average ({cfg.moving_average} chunks) over "
                 f"{len(cfg.seeds)} seed(s); shaded: min-max over seeds")
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
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.boxplot(data, showmeans=True)
    ax.set_xticks(range(1, len(names) + 1), names)
    for i, n in enumerate(names, start=1):
        paper = summary["conditions"][n]["paper"]
        if paper:
            ax.plot(i, paper["unique_regions"], marker="x", color="red", ms=9,
                    label="paper mean" if i == 1 else None)
    ax.set_ylabel("unique regions per test episode")
    ax.set_ylim(-0.3, 8.3)
    ax.grid(alpha=0.3, axis="y")
    ax.legend(loc="upper right")
    ax.set_title(f"Figure 2 analogue ({sum(len(d) for d in data) // len(names)} test episodes per condition)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
