"""Does a live fine-tuning session steer the infant? Paired sessions from each pretrained checkpoint.

From each checkpoint two `protamer finetune` sessions of the same length run unpaced (the computations of a
live session, shown faster than real time): one with a simulated teacher (`--feedback simulated:keyboard` by
default, its hidden rule from a table2 config, the built-in default's lateral rule unless `--rule-config`),
one without feedback (DDPG goes on learning from the intrinsic reward alone). The starting actor and both
sessions' final actors then run the same test episodes (the checkpoint's test seed), scored by the rule:
`teacher_score`, and the paper's metrics. Per checkpoint (seed) and pooled: mean ± 95% CI over checkpoints
and the paired difference of the teacher's session against the session without feedback.

    .venv/bin/python scripts/finetune_effect.py --checkpoints RUN0 RUN1 ... --minutes 5 --out DIR

Sessions already in DIR (their session.json and checkpoint) are kept, so an interrupted run continues.
Writes DIR/finetune_effect.json and prints a table.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
METRICS = ("teacher_score", "unique_regions", "freeze_ratio", "contact_rate")
CHUNK_MS = 250.0  # finetune's default chunk, passed explicitly so the session length does not hang on it


def _rule_override(rule_config) -> str:
    """`--set feedback.teacher.rule=[...]` carrying a table2 config's hidden rule into a session."""
    import dataclasses

    from mjx_protamer.experiments.table2 import load_table2_config

    rule = load_table2_config(rule_config).feedback.teacher.rule
    return "feedback.teacher.rule=" + json.dumps([dataclasses.asdict(c) for c in rule])


def _session(checkpoint: Path, feedback: str, seed: int, chunks: int, out: Path, rule: str, extra) -> float:
    """One unpaced finetune session into `out` (kept when it finished before); its wall time (s)."""
    if (out / "session.json").is_file() and (out / "checkpoints").is_dir():
        return float("nan")
    cmd = [str(ROOT / ".venv/bin/protamer"), "finetune", "--checkpoint", str(checkpoint), "--feedback", feedback,
           "--view", "none", "--no-pace", "--chunk-ms", str(CHUNK_MS), "--max-chunks", str(chunks), "--autosave-s", "0", "--out", str(out),
           "--set", rule, "--set", f"feedback.seed={seed}", *extra]
    t0 = time.perf_counter()
    with open(out.with_suffix(".log"), "w") as log:
        code = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT).returncode
    if code != 0:
        sys.exit(f"finetune_effect: the session in {out} failed (exit {code}); see {out.with_suffix('.log')}")
    return time.perf_counter() - t0


def _scorer(checkpoint: Path, rule_config, episodes: int):
    """score(actor_params) -> metrics on the checkpoint's test episodes, the rule's teacher_score among them."""
    import jax

    from mjx_protamer.agents.ddpg.evaluate import make_rollout
    from mjx_protamer.experiments import metrics as M
    from mjx_protamer.experiments.evaluate import eval_seed
    from mjx_protamer.experiments.run_loader import load_run
    from mjx_protamer.experiments.table2 import load_table2_config
    from mjx_protamer.human.teachers import env_signal_columns, rule_scores, rule_signals

    pre, env, state, _ = load_run(checkpoint)
    teacher = load_table2_config(rule_config).feedback.teacher
    cols = env_signal_columns(teacher.signals, env)
    rollout = make_rollout(env, pre.train.episode_length, pre.ddpg.actor_hidden)
    keys = jax.random.split(jax.random.PRNGKey(eval_seed(pre)), episodes)

    def score(actor_params) -> dict:
        sig = jax.device_get(rollout(actor_params, keys))
        s = np.asarray(rule_scores(teacher, rule_signals(cols, sig["obs"], sig["action"], sig["reward_terms"],
                                                         sig["region_mask"])))
        ev = M.summarize(sig["self_contact"], sig["region_mask"], sig["arm_speed"],
                         freeze_threshold=pre.env.freeze_speed)
        return {"teacher_score": float(s.mean()), **{k: float(ev[k]) for k in METRICS[1:]}}

    return score, state.actor_params


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--checkpoints", type=Path, nargs="+", required=True, help="pretrain runs, one per seed")
    p.add_argument("--minutes", type=float, default=5.0, help="shown time per session (default 5)")
    p.add_argument("--feedback", default="simulated:keyboard", help="the teacher's channel (simulated:KIND)")
    p.add_argument("--rule-config", type=Path, default=None, help="a table2 YAML whose teacher rule is hidden "
                   "(default: the built-in default's, the lateral rule)")
    p.add_argument("--episodes", type=int, default=10)
    p.add_argument("--fresh-replay", action="store_true", help="sessions start with an empty replay (finetune's "
                   "--fresh-replay, the design before 5 December)")
    p.add_argument("--out", type=Path, required=True)
    args = p.parse_args(argv)
    if not args.feedback.startswith("simulated:"):
        sys.exit("finetune_effect: --feedback must be simulated:keyboard|prosody|speech")
    from mjx_protamer.experiments.run_loader import load_run
    from mjx_protamer.experiments.table2 import contrast, seed_stats

    args.out.mkdir(parents=True, exist_ok=True)
    rule = _rule_override(args.rule_config)
    chunks = int(round(args.minutes * 60 * 1000 / CHUNK_MS))
    rows = []
    for seed, ckpt in enumerate(args.checkpoints):
        extra = ["--fresh-replay"] if args.fresh_replay else []
        walls = {fb: _session(ckpt, fb, seed, chunks, args.out / f"{fb.replace(':', '_')}_{seed}", rule, extra)
                 for fb in ("none", args.feedback)}
        score, start_actor = _scorer(ckpt, args.rule_config, args.episodes)
        session = json.loads((args.out / f"{args.feedback.replace(':', '_')}_{seed}" / "session.json").read_text())
        steps = chunks * session["chunk_steps"]
        row = {"seed": seed, "checkpoint": str(ckpt), "steps": steps,
               "shown_s": steps * session["feedback_config"]["dt"],
               "wall_s": walls, "start": score(start_actor)}
        for fb in ("none", args.feedback):
            row[fb] = score(load_run(args.out / f"{fb.replace(':', '_')}_{seed}")[2].actor_params)
        rows.append(row)
        print(f"seed {seed}: teacher score start {row['start']['teacher_score']:+.3f}, without feedback "
              f"{row['none']['teacher_score']:+.3f}, with {row[args.feedback]['teacher_score']:+.3f}", flush=True)
    summary = {"command": " ".join(sys.argv), "minutes": args.minutes, "feedback": args.feedback,
               "fresh_replay": args.fresh_replay,
               "rule": rule, "per_seed": rows, "pooled": {}}
    for cond in ("start", "none", args.feedback):
        summary["pooled"][cond] = {m: seed_stats([r[cond][m] for r in rows]) for m in METRICS}
    summary["paired"] = {m: contrast([r["none"][m] for r in rows], [r[args.feedback][m] for r in rows])
                         for m in METRICS}
    tmp = args.out / "finetune_effect.json.tmp"
    tmp.write_text(json.dumps(summary, indent=1))
    tmp.replace(args.out / "finetune_effect.json")
    print(f"\n{len(rows)} checkpoints, {args.minutes:g} min shown per session; mean ± 95% CI (per seed)")
    for m in METRICS:
        cells = []
        for cond in ("start", "none", args.feedback):
            st = summary["pooled"][cond][m]
            ci = "" if st["ci95"] is None else f" ± {st['ci95']:.3f}"
            cells.append(f"{cond} {st['mean']:+.3f}{ci} ({', '.join(f'{v:.2f}' for v in st['seed_values'])})")
        pr = summary["paired"][m]["paired"]
        paired = "" if not pr or pr["ci95"] is None else f"; paired (feedback - none) {pr['mean']:+.3f} ± {pr['ci95']:.3f}"
        print(f"{m}: " + "; ".join(cells) + paired)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
