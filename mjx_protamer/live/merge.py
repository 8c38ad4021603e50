"""`protamer reproduce live --merge RUN RUN ... --out OUT`: finished `reproduce live` runs of one plan over different
checkpoints, pooled into one result over all their checkpoints.

The sessions of a `reproduce live` run are independent per checkpoint, so a plan's checkpoints can be split into
groups run on different machines (or one after another), each its own `--out`; this pools their per-checkpoint
rows into the statistics, table and figure one run over all of them would report (live/effect.py's `summarize`).
Only runs of the same plan pool: the channels, session length, hidden rule (compared as the rule, not the
config's path), session settings, episodes, learner, snapshots and speaker must match, and no checkpoint may
appear twice. What each run was (its command and checkpoints) is kept in `merged_from`. A run's sessions take their feedback seed from the checkpoint's place in
that run (`feedback.seed=k`), so two runs of five checkpoints reuse seeds 0-4 where one run of ten would have used
0-9: the pooled result is exactly the runs', not a bit-for-bit copy of that one run.
"""

from __future__ import annotations

import json
from pathlib import Path

from mjx_protamer.config import ConfigError

# What makes two runs the same experiment (the recorded plan's keys; the default where an older run lacks one)
SAME_PLAN = {"channels": None, "minutes": None, "chunk_ms": None, "overrides": [], "episodes": None,
             "learner": "ddpg", "snapshot_minutes": 0.0, "speaker": "sentences"}
RESULT = "live_effect.json"


def _load(run: Path) -> dict:
    path = Path(run) / RESULT
    try:
        summary = json.loads(path.read_text())
        rows, plan = summary["per_checkpoint"], summary["plan"]
    except FileNotFoundError:
        raise ConfigError(f"--merge {run}: no {RESULT} there (give the --out of a finished `protamer reproduce "
                          "live`)") from None
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise ConfigError(f"--merge {run}: {path} is not a `reproduce live` result ({type(e).__name__}: {e})") from None
    if not isinstance(rows, list) or not isinstance(plan, dict) or not rows:
        raise ConfigError(f"--merge {run}: {path} holds no per-checkpoint rows")
    return summary


def _rule(run: Path, plan: dict) -> str:
    """The hidden rule a run's teacher held (recorded; for a run recorded without it, read from its rule config:
    the same file may be named by another path on another machine)."""
    from mjx_protamer.live.effect import rule_override

    if plan.get("rule"):
        return plan["rule"]
    path = plan.get("rule_config")
    if path is not None and not Path(path).is_file():
        raise ConfigError(f"--merge {run}: it recorded its rule as the file {path}, which is not here; run the merge "
                          "where that path names the same file")
    return rule_override(path)


def check_runs(runs: list[Path], out: Path) -> None:
    """What is wrong with the list of runs before anything is read or written (ConfigError, one line)."""
    if len(runs) < 2:
        raise ConfigError("--merge pools two or more `reproduce live` runs; give their --out directories")
    if any(Path(r).resolve() == Path(out).resolve() for r in runs):
        raise ConfigError(f"--out {out} is one of the runs --merge pools; write the pooled result elsewhere")


def merge_live_effects(runs: list[Path], out: Path, command: str) -> dict:
    """Pool the runs' rows into `out` (live_effect.json, .md, .png): the summary, with `merged_from`."""
    from mjx_protamer.live.effect import summarize, write_outputs

    check_runs(runs, out)
    summaries = [_load(r) for r in runs]
    first = summaries[0]["plan"]
    rule = _rule(runs[0], first)
    for run, s in zip(runs[1:], summaries[1:]):
        for key, default in SAME_PLAN.items():
            a, b = first.get(key, default), s["plan"].get(key, default)
            if a != b:
                raise ConfigError(f"--merge: {run} ran {key}={b!r} but {runs[0]} ran {key}={a!r}; only runs of one "
                                  "plan pool")
        if _rule(run, s["plan"]) != rule:
            raise ConfigError(f"--merge: {run} held another rule than {runs[0]} (rule configs "
                              f"{s['plan'].get('rule_config')} and {first.get('rule_config')}); only runs of one plan "
                              "pool")
    rows, seen = [], {}
    for run, s in zip(runs, summaries):
        for row in s["per_checkpoint"]:
            ckpt = str(Path(row["checkpoint"]).resolve())
            if ckpt in seen:
                raise ConfigError(f"--merge: checkpoint {row['checkpoint']} is in both {seen[ckpt]} and {run}; each "
                                  "checkpoint may be pooled once")
            seen[ckpt] = run
            rows.append(row)
    plan = {**first, "rule": rule, "checkpoints": [r["checkpoint"] for r in rows], "out": str(out)}
    summary = summarize(plan, rows, command, sum(float(s.get("wall_s") or 0.0) for s in summaries))
    summary["merged_from"] = [{"run": str(r), "command": s.get("command"), "checkpoints": s["plan"].get("checkpoints")}
                              for r, s in zip(runs, summaries)]
    Path(out).mkdir(parents=True, exist_ok=True)
    write_outputs(summary, Path(out))
    return summary
