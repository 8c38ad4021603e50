"""Table II's numbers: per condition and metric the statistics over seeds, the contrasts against the baseline,
and table2.md's layout with the paper's numbers beside ours."""

from __future__ import annotations

import dataclasses
import platform

import jax
import numpy as np

from mjx_protamer.experiments import metrics as M
from mjx_protamer.experiments.machine import cpu_model
from mjx_protamer.experiments.stats import contrast, seed_stats
from mjx_protamer.experiments.table2.config import Table2Config

# Paper Table II (means over 10 test episodes).
PAPER = {
    "DDPG": {"first_touch_step": 19.7, "contact_rate": 0.519, "unique_regions": 4.3, "freeze_ratio": 0.180},
    "DTK": {"first_touch_step": 26.1, "contact_rate": 0.763, "unique_regions": 5.3, "freeze_ratio": 0.047},
    "DTW": {"first_touch_step": 23.7, "contact_rate": 0.536, "unique_regions": 3.1, "freeze_ratio": 0.428},
    "DTP": {"first_touch_step": 15.8, "contact_rate": 0.915, "unique_regions": 4.8, "freeze_ratio": 0.258},
}
LABELS = {"first_touch_step": "First touch step ↓", "contact_rate": "Contact rate ↑",
          "unique_regions": "Unique regions ↑", "freeze_ratio": "Freeze ratio ↓"}


# What `run_table2` also reports of the last actor when it tests a selected snapshot
SELECTION_METRICS = ("unique_regions", "freeze_ratio", "contact_rate", "teacher_score")


def summarize(cfg: Table2Config, evals: dict, wall: dict, total_s: float) -> dict:
    """table2.json's content: per condition and metric the seed statistics, the contrasts against the baseline,
    and the run's setting (`evals[name][seed]`: one seed's test results; `wall[name]`: training seconds)."""
    conds = {}
    for c in cfg.conditions:
        per_seed = evals[c.name]
        entry: dict = {"channel": c.channel, "credit": c.credit if c.channel != "none" else None,
                       "beta": cfg.pretrain.ddpg.reward_beta * c.beta_scale if c.channel != "none" else 0.0,
                       "paper": PAPER.get(c.name)}
        for name in M.METRIC_NAMES + ("teacher_score",):
            entry[name] = seed_stats([per_seed[s][name] for s in cfg.seeds])
            entry[name]["seed_means"] = entry[name]["seed_values"]
            entry[name]["per_episode"] = [v for s in cfg.seeds for v in per_seed[s]["per_episode"][name]]
        for name in ("r_hat_corr_test", "r_hat_corr_untrained", "r_hat_corr_pooled", "r_hat_corr_pooled_untrained",
                     "episode_return"):
            entry[name] = seed_stats([per_seed[s][name] for s in cfg.seeds])
        entry["feedback"] = {k: float(np.mean([per_seed[s]["feedback"][k] for s in cfg.seeds]))
                             for k in per_seed[cfg.seeds[0]]["feedback"]}
        entry["train_wall_s"] = float(np.sum(wall[c.name]))
        if "selection" in per_seed[cfg.seeds[0]]:
            sel = [per_seed[s]["selection"] for s in cfg.seeds]
            entry["selection"] = {
                "tested_chunks": [x["tested_chunk"] for x in sel],
                "last_actor": {k: seed_stats([x["last_actor"][k] for x in sel]) for k in SELECTION_METRICS},
                "tested_minus_last": {k: seed_stats([per_seed[s][k] - x["last_actor"][k]
                                                     for s, x in zip(cfg.seeds, sel)]) for k in SELECTION_METRICS}}
        conds[c.name] = entry
    tc = cfg.pretrain.train
    baseline = next((c.name for c in cfg.conditions if c.channel == "none"), None)
    versus = {c.name: contrast(conds[baseline]["teacher_score"]["seed_values"],
                               conds[c.name]["teacher_score"]["seed_values"])
              for c in cfg.conditions if baseline is not None and c.channel != "none"}
    return {
        "conditions": conds,
        "teacher_score_vs_baseline": {"baseline": baseline, "conditions": versus} if versus else None,
        "seeds": list(cfg.seeds),
        "env": cfg.pretrain.env_name,
        "reward": reward_preset_name(cfg.pretrain),
        "num_envs": tc.num_envs,
        "env_steps_per_run": tc.iterations * tc.num_envs,
        "eval_episodes_per_seed": tc.eval_episodes,
        "wall_s": total_s,
        "machine": f"{platform.machine()}, {jax.local_device_count()} x {jax.local_devices()[0].platform}, "
                   f"{__import__('os').cpu_count()} CPU cores visible" + (f" ({cpu})" if (cpu := cpu_model()) else ""),
    }


def _fmt(stat: dict, digits: int = 3) -> str:
    if stat["mean"] is None:
        return "n/a"
    ci = f" ± {stat['ci95']:.{digits}f}" if stat.get("ci95") is not None else ""
    return f"{stat['mean']:.{digits}f}{ci}"


def reward_preset_name(pre) -> str:
    """The self-touch reward's preset ('infant', 'paper') and any fields changed from it, e.g. 'infant (speed_low
    1.5)', against the preset it differs from least; the env name for another env."""
    if pre.env_name != "self_touch":
        return pre.env_name
    reward = pre.env.reward

    def changed(name):
        base = type(reward).preset(name)
        return [f"{f.name} {getattr(reward, f.name)}" for f in dataclasses.fields(reward)
                if getattr(reward, f.name) != getattr(base, f.name)]

    name = min(type(reward).PRESETS, key=lambda n: len(changed(n)))
    diff = changed(name)
    return f"{name} ({', '.join(diff)})" if diff else name


def _at_once(summary: dict) -> str:
    k = summary.get("conditions_at_once", 1)
    return f" ({k} conditions trained at a time)" if k > 1 else ""


def format_markdown(summary: dict) -> str:
    conds = summary["conditions"]
    names = list(conds)
    n = len(summary["seeds"])
    head = "| Metric | " + " | ".join(f"{c} ours | {c} paper" for c in names) + " |"
    sep = "|---|" + "---|---|" * len(names)
    lines = [f"Table II analogue: mean over {n} seed(s) {summary['seeds']} of each seed's mean over "
             f"{summary['eval_episodes_per_seed']} test episodes (deterministic actor), ± the 95% confidence "
             f"half-width (Student t over seeds); {summary['env']} env, reward preset {summary.get('reward')}, "
             f"{summary['num_envs']} envs x {summary['env_steps_per_run']} env steps per run; wall time "
             f"{summary['wall_s']:.0f} s{_at_once(summary)}.", "", head, sep]
    for metric in M.METRIC_NAMES:
        cells = []
        for c in names:
            paper = conds[c]["paper"]
            cells.append(f"{_fmt(conds[c][metric])} | " + (f"{paper[metric]:.3f}" if paper else "-"))
        lines.append(f"| {LABELS[metric]} | " + " | ".join(cells) + " |")
    lines += ["", "| Teacher and reward model | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for key, label in (("teacher_score", "teacher_score (hidden rule, test episodes) ↑"),
                       ("r_hat_corr_test", "r_hat_corr_test (held-out test states)"),
                       ("r_hat_corr_untrained", "r_hat_corr_untrained (same states)"),
                       ("r_hat_corr_pooled", "r_hat_corr_pooled (every condition's test states)"),
                       ("r_hat_corr_pooled_untrained", "r_hat_corr_pooled_untrained (same states)"),
                       ("episode_return", "test return (intrinsic)")):
        lines.append(f"| {label} | " + " | ".join(_fmt(conds[c][key], 1 if key == "episode_return" else 3)
                                                  for c in names) + " |")
    for key, label in (("feedback_total", "events given (per seed)"), ("credited_rows_total", "credited rows"),
                       ("rm_updates_total", "r_hat updates")):
        lines.append(f"| {label} | " + " | ".join(f"{conds[c]['feedback'][key]:.0f}" for c in names) + " |")
    versus = summary.get("teacher_score_vs_baseline")
    if versus:
        lines += ["", f"| teacher_score against {versus['baseline']} | difference of means | sum of the ci95 | "
                      "beyond it | per-seed differences (paired mean ± ci95) |", "|---|---|---|---|---|"]
        for c, v in versus["conditions"].items():
            if v["difference"] is None:
                lines.append(f"| {c} | n/a | n/a | n/a | n/a |")
                continue
            seeds = ", ".join("n/a" if d is None else f"{d:.2f}" for d in v["paired"]["seed_values"])
            lines.append(f"| {c} | {v['difference']:.3f} | {v['ci95_sum']:.3f} | "
                         f"{'yes' if v['beyond_ci95_sum'] else 'no'} | {_fmt(v['paired'])} ({seeds}) |")
    selected = [c for c in names if "selection" in conds[c]]
    if selected:
        lines += ["", "The tested actor is the best snapshot on validation episodes (train.select_every_chunks); the "
                      "last actor on the same test episodes:", "",
                  "| Condition | tested chunk per seed | " + " | ".join(f"{k}: last actor | tested - last (paired)"
                                                                      for k in SELECTION_METRICS) + " |",
                  "|---|---|" + "---|---|" * len(SELECTION_METRICS)]
        for c in selected:
            sel = conds[c]["selection"]
            lines.append(f"| {c} | {', '.join(str(k) for k in sel['tested_chunks'])} | " + " | ".join(
                f"{_fmt(sel['last_actor'][k])} | {_fmt(sel['tested_minus_last'][k])}" for k in SELECTION_METRICS) + " |")
    lines += ["", "Per-seed means (seeds in order):", ""]
    for metric in M.METRIC_NAMES + ("teacher_score", "r_hat_corr_test", "r_hat_corr_pooled"):
        vals = "; ".join(f"{c} " + ", ".join("n/a" if v is None else f"{v:.3g}" for v in conds[c][metric]["seed_values"])
                         for c in names)
        lines.append(f"- {metric}: {vals}")
    return "\n".join(lines) + "\n"

