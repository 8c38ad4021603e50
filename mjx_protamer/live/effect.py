"""`protamer reproduce live`: does a few minutes of a live session steer the infant? Paired sessions per checkpoint.

From each pretrained checkpoint (one per seed of the main job) sessions of the same length run through the real
`protamer finetune` (one process each, live/session.py): one without feedback (DDPG goes on learning from the
intrinsic reward alone), and one per channel with a simulated teacher who holds a hidden rule (a table2 config's,
the built-in lateral rule by default):
- keyboard: `--feedback simulated:keyboard`, unpaced (shown faster than real time, `session.unpaced_updates_per_step`
  updates per shown step, the no-feedback session's too);
- prosody, whisper: `--listen-source speaker`: the simulated person speaks through the real listener (VAD ->
  prosody or Whisper + sentiment), so these sessions run paced at real time, with at most the same updates per
  shown step as the others; in sentences, or in single words (`speaker="words"`: `speaker:words`).
Each final actor then runs the checkpoint's own test episodes (deterministic actor, its test seed), scored by the
hidden rule (`teacher_score`) and the paper's metrics. Per channel: the paired difference teacher - no feedback
over checkpoints (mean, 95% CI, per checkpoint), the drift of the no-feedback sessions from the checkpoint, the
freeze in both arms, and for the voice channels what the pipeline delivered of what the speaker said (latency,
sign accuracy, misses). For DDPG + DeepTAMER each session's reward model is scored too (`r_hat_corr`: r_hat against
the hidden score over the final actor's test steps, as table2's `r_hat_corr_test`; the no-feedback session's
model, which took no event, is the baseline): whether the events taught the model, apart from whether the policy
followed it. With `snapshot_minutes`, every session also saves its policy at each multiple of it
(`finetune --snapshot-every-s`), and each snapshot is scored the same way: the paired difference minute by minute
(`curve` in the JSON, live_curve.png), what a session of each length would have ended with. Finished sessions
are kept, the same command continues, and each kept one must be this plan's (`_check_kept`).
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from mjx_protamer.atomic import write_atomic
from mjx_protamer.live.build import final_actor
from mjx_protamer.live.kinds import LEARNER_KINDS

METRICS = ("teacher_score", "unique_regions", "freeze_ratio", "contact_rate")
CHANNELS = ("keyboard", "prosody", "whisper")
DONE = "DONE"  # written into a session's directory when its process exited 0


@dataclasses.dataclass(frozen=True)
class Plan:
    checkpoints: tuple[Path, ...]
    out: Path
    channels: tuple[str, ...] = ("keyboard",)
    minutes: float = 2.0
    chunk_ms: float = 250.0
    rule_config: Path | None = None
    overrides: tuple[str, ...] = ()  # --set for every session (e.g. a mechanism's setting)
    episodes: int = 10
    parallel: int = 1  # unpaced sessions at once (paced ones always run alone)
    learner: str = "ddpg"  # or "coach": Deep COACH from the checkpoint's actor (its no-feedback arm is the start)
    snapshot_minutes: float = 0.0  # every session's policy also scored at each multiple of this (a curve); 0: none
    speaker: str = "sentences"  # what the simulated speaker of the voice channels says: sentences or words

    @property
    def chunks(self) -> int:
        return int(round(self.minutes * 60_000 / self.chunk_ms))


def rule_override(rule_config) -> str:
    """`feedback.teacher.rule=[...]` carrying a table2 config's hidden rule into a session."""
    from mjx_protamer.experiments.table2 import load_table2_config

    rule = load_table2_config(rule_config).feedback.teacher.rule
    return "feedback.teacher.rule=" + json.dumps([dataclasses.asdict(c) for c in rule])


def _session_argv(plan: Plan, ckpt: Path, arm: str, seed: int, out: Path) -> list[str]:
    from mjx_protamer.live.spec import SPEAKER_SOURCES

    argv = [sys.executable, "-m", "mjx_protamer.cli", "finetune", "--checkpoint", str(ckpt), "--out", str(out),
            "--view", "none", "--chunk-ms", str(plan.chunk_ms), "--max-chunks", str(plan.chunks),
            "--autosave-s", "0", "--set", rule_override(plan.rule_config), "--set", f"feedback.seed={seed}"]
    argv += ["--learner", plan.learner]
    if plan.snapshot_minutes > 0:
        argv += ["--snapshot-every-s", str(plan.snapshot_minutes * 60.0)]
    if arm in ("none", "keyboard"):
        argv += ["--feedback", "none" if arm == "none" else "simulated:keyboard", "--no-pace"]
    else:  # the simulated speaker, at real-time pace, no more updates per shown step than the unpaced sessions
        argv += ["--feedback", arm, "--listen-source", SPEAKER_SOURCES[plan.speaker]]
    for o in plan.overrides:
        argv += ["--set", o]
    if arm in ("prosody", "whisper"):
        argv += ["--set", "session.max_updates_per_step=" + str(_unpaced_ups(plan))]
    return argv


def _unpaced_ups(plan: Plan) -> float:
    from mjx_protamer.human.feedback_config import load_feedback_config
    from mjx_protamer.live.spec import DEFAULT_FEEDBACK_CONFIG

    return load_feedback_config(DEFAULT_FEEDBACK_CONFIG, list(plan.overrides)).session.unpaced_updates_per_step


def session_identity(argv: list[str], arm: str) -> list[str]:
    """What a session's argv says it runs, apart from where: without the interpreter (a venv's path differs by
    machine) and with its own directory as `<session>`. A no-feedback session takes no event, so the teacher's
    rule plays no part in it and is left out: its sessions serve plans that differ only in the rule."""
    args = list(argv[3:])  # after `python -m mjx_protamer.cli`
    args[args.index("--out") + 1] = "<session>"
    if arm == "none":
        k = next(i for i, a in enumerate(args) if a.startswith("feedback.teacher.rule="))
        del args[k - 1:k + 1]
    return args


def _check_kept(argv: list[str], arm: str, out: Path) -> None:
    """Refuse a finished session in `out` that another plan ran (other checkpoint, arm or settings), before any
    session starts: kept sessions are pooled with new ones, so one from another plan would silently mix into the
    result. Sessions finished before DONE recorded their argv are checked by checkpoint and feedback only."""
    from mjx_protamer.config import ConfigError

    if not (out / DONE).is_file():
        return
    want = session_identity(argv, arm)
    try:
        ran = json.loads((out / DONE).read_text(encoding="utf-8"))["argv"]
    except (ValueError, TypeError, KeyError, OSError):
        ran = None
    if ran is None:  # an older session: what its session.json says it ran
        try:
            facts = json.loads((out / "session.json").read_text(encoding="utf-8"))
            ran_pairs = {"--checkpoint": str(facts["checkpoint"]), "--feedback": str(facts["feedback"])}
        except (ValueError, KeyError, OSError):
            raise ConfigError(f"{out} holds a finished session whose session.json cannot be read; remove {out} "
                              "to run it again, or give a new --out") from None
        planned = {"--checkpoint": str(Path(want[want.index("--checkpoint") + 1]).absolute()),  # as recorded
                   "--feedback": want[want.index("--feedback") + 1]}
        diff = next(((f"{flag} {v}", f"{flag} {planned[flag]}") for flag, v in ran_pairs.items()
                     if v != planned[flag]), None)
    else:
        diff = _first_difference(ran, want)
    if diff is not None:
        theirs, ours = diff
        raise ConfigError(f"{out} holds a session another plan ran ({theirs}; this plan: {ours}); give a new --out, "
                          f"or remove {out} to run it with this plan")


def _first_difference(ran: list[str], want: list[str]) -> tuple[str, str] | None:
    """(what `ran` has, what `want` has) at the first place two session argvs differ, the flags that say which
    session it is first (a long rule or setting is named only when those agree); None when they are equal."""
    import difflib

    def value(args, flag):
        return f"{flag} {args[args.index(flag) + 1]}" if flag in args else f"no {flag}"

    for flag in ("--checkpoint", "--feedback", "--learner", "--listen-source"):
        if value(ran, flag) != value(want, flag):
            return value(ran, flag), value(want, flag)
    for tag, i1, i2, j1, j2 in difflib.SequenceMatcher(None, ran, want, autojunk=False).get_opcodes():
        if tag != "equal":
            return " ".join(ran[i1:i2]) or "nothing there", " ".join(want[j1:j2]) or "nothing there"
    return None


def _run_session(argv: list[str], out: Path, arm: str, log=print) -> float:
    """One session into `out` (kept when it finished before); its wall time (s)."""
    if (out / DONE).is_file():
        return float("nan")
    if out.exists():  # an unfinished session of an earlier run: start it again
        import shutil

        shutil.rmtree(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    with open(out.with_suffix(".log"), "w") as fh:
        code = subprocess.run(argv, stdout=fh, stderr=subprocess.STDOUT).returncode
    if code != 0:
        raise RuntimeError(f"the session in {out} failed (exit {code}); see {out.with_suffix('.log')}")
    write_atomic(out / DONE, json.dumps({"argv": session_identity(argv, arm)}))
    wall = time.perf_counter() - t0
    log(f"[live] {out.name}: {wall:.0f} s")
    return wall


def scorer(checkpoint: Path, rule_config, episodes: int):
    """(score, the checkpoint's actor, its env): score(actor_params) -> the rule's teacher_score and the paper's
    metrics on the checkpoint's test episodes (the one evaluator, experiments/evaluate.py)."""
    import jax

    from mjx_protamer.experiments.evaluate import eval_seed, make_evaluator, summarize
    from mjx_protamer.experiments.run_loader import load_run
    from mjx_protamer.experiments.table2 import load_table2_config

    pre, env, state, _ = load_run(checkpoint)
    teacher = load_table2_config(rule_config).feedback.teacher
    keys = jax.random.split(jax.random.PRNGKey(eval_seed(pre)), episodes)
    evaluators = {}  # per reward-model architecture (human.reward_model.reward_fn is one object per architecture)

    def score(actor_params, reward_model=None) -> dict:
        """The metrics of `actor_params`; with `reward_model` (apply, params) also `r_hat_corr`: how closely that
        r_hat follows the hidden rule's score over the same test steps (None where either is constant)."""
        apply, params = reward_model or (None, None)
        if apply not in evaluators:
            evaluators[apply] = jax.jit(make_evaluator(pre, env, teacher, apply))
        models = {"session": params} if apply is not None else None
        ev = summarize(jax.device_get(evaluators[apply](actor_params, keys, models)), pre.train.episode_length)
        out = {k: float(ev[k]) for k in METRICS}
        if apply is not None:
            out["r_hat_corr"] = ev["r_hat_corr_session"]
        return out

    return score, state.actor_params, env


def session_reward_model(session: Path, obs_size: int, action_size: int):
    """(apply, params) of the reward model a DDPG + DeepTAMER session ended with (its newest save in
    `reward_model/`); None for a session without one (Deep COACH). The sizes are the checkpoint env's."""
    import jax

    from mjx_protamer.experiments import checkpoints
    from mjx_protamer.live.record import read_manifest
    from mjx_protamer.live.reward_model import SessionRewardModel
    from mjx_protamer.live.spec import SessionSpec
    from mjx_protamer.live.tamer import REWARD_MODEL_DIR

    if not (session / REWARD_MODEL_DIR).is_dir():
        return None
    spec = SessionSpec.from_manifest(read_manifest(session), session)
    fc, sc = spec.config.feedback, spec.config.session
    model = SessionRewardModel(fc.reward_model, fc.credit, obs_size, action_size, fc.seed,
                               spec.chunk_steps, sc.max_events_per_chunk, sc.rows_per_event)
    steps = checkpoints.available_steps(session / REWARD_MODEL_DIR)
    if not steps:
        return None
    mngr = checkpoints.manager(session / REWARD_MODEL_DIR)
    try:  # the newest save: the one the DDPG state of final_actor comes from
        state = checkpoints.restore(mngr, max(steps), jax.eval_shape(lambda: model.state))
    finally:
        mngr.close()
    return model.apply, state.params


def _session_facts(out: Path) -> dict:
    """What a finished session itself reports: events, updates per shown step, the speaker's delivery."""
    manifest = json.loads((out / "session.json").read_text())
    pace = (manifest.get("measured_pace") or [{}])[-1]
    facts: dict = {"updates_per_step": pace.get("updates_per_step"), "realtime": pace.get("realtime")}
    log = out.with_suffix(".log")
    if log.is_file():
        for line in log.read_text(errors="replace").splitlines():
            if line.startswith("[finetune] saved in"):
                facts["events"] = int(line.split(": ", 1)[1].split(" events")[0])
    speaker = out / "speaker.jsonl"
    if speaker.is_file():
        last = speaker.read_text().strip().splitlines()[-1]
        facts["speaker"] = json.loads(last)["summary"]
    return facts


def run_live_effect(plan: Plan, log=print) -> dict:
    """Every session of the plan (kept where finished), then the scores, the statistics, the figure."""
    plan.out.mkdir(parents=True, exist_ok=True)
    arms = ("none", *plan.channels)
    # Deep COACH learns from corrections alone: without feedback its policy stays the checkpoint's actor, so its
    # no-feedback arm is the start (no session is run for it)
    ran = arms if LEARNER_KINDS[plan.learner].learns_without_feedback else plan.channels
    jobs = {arm: [] for arm in ran}
    for k, ckpt in enumerate(plan.checkpoints):
        for arm in ran:
            d = plan.out / f"{arm}_{k}"
            jobs[arm].append((_session_argv(plan, ckpt, arm, k, d), d))
    for arm in ran:
        for argv, d in jobs[arm]:
            _check_kept(argv, arm, d)
    unpaced = [(arm, *j) for arm in ran if arm in ("none", "keyboard") for j in jobs[arm]]
    t0 = time.perf_counter()
    with ThreadPoolExecutor(max(1, plan.parallel)) as ex:
        list(ex.map(lambda j: _run_session(j[1], j[2], j[0], log), unpaced))
    for arm in ran:
        if arm in ("prosody", "whisper"):
            for argv, d in jobs[arm]:
                _run_session(argv, d, arm, log)
    rows = []
    for k, ckpt in enumerate(plan.checkpoints):
        score, start, env = scorer(ckpt, plan.rule_config, plan.episodes)
        models = {arm: session_reward_model(plan.out / f"{arm}_{k}", env.observation_size, env.action_size)
                  if LEARNER_KINDS[plan.learner].reward_model else None for arm in ran}
        # the start scored with the no-feedback session's reward model, which took no event (the untrained
        # baseline of r_hat_corr; one evaluator compile per checkpoint)
        row = {"checkpoint": str(ckpt), "start": score(start, models.get("none"))}
        for arm in arms:
            d = plan.out / f"{arm}_{k}"
            if arm in ran:
                row[arm] = {**score(final_actor(d, plan.learner), models[arm]), **_session_facts(d)}
            else:
                row[arm] = dict(row["start"])
            if plan.snapshot_minutes > 0:
                row[arm]["snapshots"] = _score_snapshots(d, score, start) if arm in ran else None
        rows.append(row)
        log(f"[live] checkpoint {k}: teacher score start {row['start']['teacher_score']:+.3f}, "
            + ", ".join(f"{a} {row[a]['teacher_score']:+.3f}" for a in arms))
    plan_record = {**{k: (str(v) if isinstance(v, Path) else v) for k, v in dataclasses.asdict(plan).items()},
                   "checkpoints": [str(c) for c in plan.checkpoints], "out": str(plan.out),
                   "rule": rule_override(plan.rule_config)}
    summary = summarize(plan_record, rows, " ".join(sys.argv), time.perf_counter() - t0)
    write_outputs(summary, plan.out)
    return summary


def summarize(plan: dict, rows: list[dict], command: str, wall_s: float) -> dict:
    """The statistics over checkpoints of per-checkpoint rows: a run's (`run_live_effect`), or several runs' of one
    plan pooled (live/merge.py). `plan` is the run's plan as recorded (channels, snapshot_minutes, ...)."""
    from mjx_protamer.experiments.stats import contrast, seed_stats

    channels = tuple(plan["channels"])
    arms = ("none", *channels)
    summary = {"plan": plan, "command": command, "per_checkpoint": rows, "wall_s": wall_s,
               "pooled": {}, "paired": {}, "drift": {}}
    for arm in ("start", *arms):
        summary["pooled"][arm] = {m: seed_stats([r[arm][m] for r in rows]) for m in METRICS}
    for arm in channels:
        summary["paired"][arm] = {m: contrast([r["none"][m] for r in rows], [r[arm][m] for r in rows])
                                  for m in METRICS}
        voice = [r[arm].get("speaker") for r in rows if r[arm].get("speaker")]
        if voice:
            summary["paired"][arm]["speaker"] = _pool_speaker(voice)
    summary["drift"] = {m: seed_stats([r["none"][m] - r["start"][m] for r in rows]) for m in METRICS}
    # whether the reward model learned the rule, apart from whether the policy followed it: r_hat against the
    # hidden score on each arm's final test steps (the no-feedback arm's model never took an event: a baseline;
    # an arm that ran no session, Deep COACH's no-feedback one, has none)
    summary["r_hat_corr"] = {arm: seed_stats([r[arm]["r_hat_corr"] for r in rows])
                             for arm in ("start", *arms) if all(r[arm].get("r_hat_corr") is not None for r in rows)}
    if plan.get("snapshot_minutes", 0) > 0:
        summary["curve"] = curve(rows, arms, channels)
    return summary


def write_outputs(summary: dict, out: Path) -> None:
    """live_effect.json, .md and .png (and live_curve.png with snapshots) into `out`, each written atomically."""
    write_atomic(out / "live_effect.json", json.dumps(summary, indent=1))
    write_atomic(out / "live_effect.md", markdown(summary))
    figure(summary, out / "live_effect.png")
    if "curve" in summary:
        curve_figure(summary, out / "live_curve.png")


def _score_snapshots(session: Path, score, like) -> list[dict]:
    """Each snapshot of a session (`finetune --snapshot-every-s`) scored: [{step, minutes, metrics...}]."""
    from mjx_protamer.experiments.checkpoints import load_model
    from mjx_protamer.live.sinks import SNAPSHOTS, snapshot_steps

    manifest = json.loads((session / "session.json").read_text())
    dt = float(manifest["chunk_ms"]) / 1000.0 / int(manifest["chunk_steps"])
    return [{"step": n, "minutes": round(n * dt / 60.0, 6),
             **score(load_model(session / SNAPSHOTS / f"step_{n:08d}", like))} for n in snapshot_steps(session)]


def curve(rows: list[dict], arms, channels) -> dict:
    """Minute by minute (the snapshots every session has; minute 0 is the checkpoint): each arm pooled, and each
    channel's paired difference to no feedback, with per-checkpoint values. An arm that ran no session (Deep
    COACH's no-feedback arm) stays at the start."""
    from mjx_protamer.experiments.stats import contrast, seed_stats

    ran = [a for a in arms if rows[0][a].get("snapshots") is not None]
    common = set.intersection(*({s["minutes"] for s in r[a]["snapshots"]} for r in rows for a in ran))
    minutes = [0.0, *sorted(common)]

    def at(row, arm, minute, metric):
        if minute == 0.0 or row[arm].get("snapshots") is None:
            return row["start"][metric]
        return next(s[metric] for s in row[arm]["snapshots"] if s["minutes"] == minute)

    out = {"minutes": minutes, "per_checkpoint": {}, "pooled": {}, "paired": {}}
    for arm in arms:
        out["per_checkpoint"][arm] = {m: [[at(r, arm, t, m) for t in minutes] for r in rows] for m in METRICS}
        out["pooled"][arm] = {m: [seed_stats([at(r, arm, t, m) for r in rows]) for t in minutes] for m in METRICS}
    for ch in channels:
        out["paired"][ch] = {m: [contrast([at(r, "none", t, m) for r in rows], [at(r, ch, t, m) for r in rows])
                                 ["paired"] if t > 0 else None for t in minutes] for m in METRICS}
    return out


def _pool_speaker(summaries: list[dict]) -> dict:
    said = sum(s["said"] for s in summaries)
    delivered = sum(s["delivered"] for s in summaries)
    acc = [s["sign_accuracy"] for s in summaries if s["sign_accuracy"] is not None]
    lat = [s["latency_s_median"] for s in summaries if s["latency_s_median"] is not None]
    return {"said": said, "delivered": delivered, "missed": said - delivered,
            "sign_accuracy_mean": float(np.mean(acc)) if acc else None,
            "latency_s_median_of_sessions": float(np.median(lat)) if lat else None,
            "held_back": sum(s["held_back"] for s in summaries), "stray_events": sum(s["stray_events"] for s in summaries)}




def _cell(st: dict, digits: int = 3) -> str:
    if st["mean"] is None:
        return "-"
    ci = "" if st["ci95"] is None else f" ± {st['ci95']:.{digits}f}"
    return f"{st['mean']:+.{digits}f}{ci}"


def markdown(summary: dict) -> str:
    plan = summary["plan"]
    n = len(summary["per_checkpoint"])
    lines = [f"# A live session's effect: {n} checkpoints x {plan['minutes']:g} min shown per session",
             "", f"Rule: {plan['rule_config'] or 'the built-in default (lateral: right hand +1, left -1)'}; "
             f"session settings {plan['overrides'] or 'as shipped'}; mean ± 95% CI over checkpoints.", "",
             "| | " + " | ".join(METRICS) + " |", "|---|" + "---|" * len(METRICS)]
    if summary.get("merged_from"):
        lines[2:2] = ["Pooled from " + ", ".join(f"{m['run']} ({len(m['checkpoints'] or [])} checkpoints)"
                                              for m in summary["merged_from"]) + " (`--merge`).", ""]
    for arm, st in summary["pooled"].items():
        lines.append(f"| {arm} | " + " | ".join(_cell(st[m]) for m in METRICS) + " |")
    for arm, c in summary["paired"].items():
        lines.append(f"| paired {arm} - none | " + " | ".join(
            _cell(c[m]["paired"]) if c[m]["paired"] else "-" for m in METRICS) + " |")
    lines.append("| drift: none - start | " + " | ".join(_cell(summary["drift"][m]) for m in METRICS) + " |")
    if summary.get("r_hat_corr"):
        lines += ["", "The session's reward model against the hidden rule (r_hat_corr on the final test steps): "
                  + ", ".join(f"{arm} {_cell(st)}" for arm, st in summary["r_hat_corr"].items())]
    lines += ["", "Per checkpoint (teacher score): " + "; ".join(
        f"{k}: start {r['start']['teacher_score']:+.2f}, " + ", ".join(
            f"{a} {r[a]['teacher_score']:+.2f}" for a in r if a not in ("checkpoint", "start"))
        for k, r in enumerate(summary["per_checkpoint"]))]
    cv = summary.get("curve")
    if cv:
        lines += ["", "Minute by minute (the sessions' snapshots), teacher score, mean ± 95% CI:", "",
                  "| minutes | " + " | ".join(cv["pooled"]) + " | " + " | ".join(f"paired {c} - none" for c in
                                                                              cv["paired"]) + " |",
                  "|---|" + "---|" * (len(cv["pooled"]) + len(cv["paired"]))]
        for j, t in enumerate(cv["minutes"]):
            cells = [_cell(cv["pooled"][a]["teacher_score"][j]) for a in cv["pooled"]]
            cells += [_cell(cv["paired"][c]["teacher_score"][j]) if cv["paired"][c]["teacher_score"][j] else "-"
                      for c in cv["paired"]]
            lines.append(f"| {t:g} | " + " | ".join(cells) + " |")
        lines.append("")
    for arm, c in summary["paired"].items():
        if "speaker" in c:
            s = c["speaker"]
            says = summary["plan"].get("speaker", "sentences")
            num = lambda v, d: "-" if v is None else f"{v:.{d}f}"
            lines.append(f"- {arm} through the simulated speaker (in {says}): said {s['said']}, delivered "
                         f"{s['delivered']}, missed {s['missed']}, sign accuracy {num(s['sign_accuracy_mean'], 3)}, "
                         f"latency from the end of the words {num(s['latency_s_median_of_sessions'], 2)} s (median "
                         "of sessions)")
    return "\n".join(lines) + "\n"


def figure(summary: dict, path: Path) -> None:
    """Per checkpoint (grey) the teacher score and the freeze ratio at the start, without feedback and with each
    channel; the means with their 95% CI; the paired difference to no feedback written under each channel."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = summary["per_checkpoint"]
    arms = ["start", "none", *summary["paired"]]
    x = np.arange(len(arms))
    fig, axes = plt.subplots(1, 2, figsize=(2.5 + 2.2 * len(arms), 4.2))
    for ax, metric, lim in zip(axes, ("teacher_score", "freeze_ratio"), ((-1.05, 1.05), (-0.02, 1.02))):
        for r in rows:
            ax.plot(x, [r[a][metric] for a in arms], color="0.75", lw=0.8, marker="o", ms=3, zorder=1)
        for i, a in enumerate(arms):
            st = summary["pooled"][a][metric]
            ax.errorbar(i, st["mean"], yerr=st["ci95"] or 0, color="k" if a in ("start", "none") else "C3",
                        marker="s", ms=7, capsize=5, lw=2, zorder=2)
        labels = []
        for a in arms:
            pr = summary["paired"].get(a, {}).get(metric, {}).get("paired")
            labels.append(a if not pr or pr["ci95"] is None else f"{a}\n{pr['mean']:+.2f} ± {pr['ci95']:.2f}")
        ax.set_xticks(x, labels, fontsize=8)
        ax.set_ylim(*lim)
        ax.axhline(0, color="0.6", lw=0.5)
        ax.set_ylabel({"teacher_score": "teacher score (hidden rule, test episodes)",
                       "freeze_ratio": "freeze ratio (test episodes)"}[metric])
    plan = summary["plan"]
    fig.suptitle(f"{len(rows)} checkpoints, {plan['minutes']:g} min sessions: mean ± 95% CI; grey, per checkpoint; "
                 "under a channel: paired difference to no feedback", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def curve_figure(summary: dict, path: Path) -> None:
    """Left: the teacher score by minute of the session, without feedback and with each channel (mean ± 95% CI);
    right: each channel's paired difference to no feedback by minute, per checkpoint in grey."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cv = summary["curve"]
    t = np.asarray(cv["minutes"])
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4.2))
    for i, arm in enumerate(cv["pooled"]):
        st = cv["pooled"][arm]["teacher_score"]
        mean = np.array([s["mean"] for s in st])
        ci = np.array([s["ci95"] or 0.0 for s in st])
        color = "k" if arm == "none" else f"C{3 + i}"
        ax.plot(t, mean, marker="o", color=color, label="no feedback" if arm == "none" else arm)
        ax.fill_between(t, mean - ci, mean + ci, color=color, alpha=0.15)
    ax.set_xlabel("minutes of the session")
    ax.set_ylabel("teacher score (hidden rule, test episodes)")
    ax.legend(fontsize=8)
    for i, ch in enumerate(cv["paired"]):
        color = f"C{3 + i + 1}"
        for a, b in zip(cv["per_checkpoint"][ch]["teacher_score"], cv["per_checkpoint"]["none"]["teacher_score"]):
            bx.plot(t, np.subtract(a, b), color="0.8", lw=0.8, zorder=1)
        st = cv["paired"][ch]["teacher_score"]
        mean = np.array([0.0] + [s["mean"] for s in st[1:]])
        ci = np.array([0.0] + [s["ci95"] or 0.0 for s in st[1:]])
        bx.errorbar(t, mean, yerr=ci, color=color, marker="s", capsize=4, lw=2, label=f"{ch} - no feedback", zorder=2)
    bx.axhline(0, color="0.5", lw=0.6)
    bx.set_xlabel("minutes of the session")
    bx.set_ylabel("paired difference in teacher score")
    bx.legend(fontsize=8)
    n = len(cv["per_checkpoint"]["none"]["teacher_score"])
    fig.suptitle(f"{n} checkpoints: what a session has taught by each minute (its snapshots); mean ± 95% CI, "
                 "grey per checkpoint", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def pretrain_checkpoints(out: Path, seeds: int, config=None, progress: bool = False) -> list[Path]:
    """The main job (the built-in pretrain config, or `config`) for seeds 0..N-1 into OUT/checkpoints/seed_<k>: what
    `protamer pretrain --seeds N --out OUT/checkpoints` trains (experiments/pretrain_seeds.py), each seed bit for bit
    the plain `protamer pretrain --set train.seed=k` run, with seeds.json beside them. Run again, it keeps the
    finished seeds and continues an unfinished one from its last checkpoint."""
    from mjx_protamer.agents.ddpg.config import PretrainConfig
    from mjx_protamer.experiments.pretrain_seeds import SEEDS_KIND, run_pretrain_seeds, seed_dir
    from mjx_protamer.outdir import kind_of

    where = out / "checkpoints"
    run_pretrain_seeds(config or PretrainConfig(), where, seeds, resume=kind_of(where) == SEEDS_KIND,
                       progress=progress)
    return [seed_dir(where, k) for k in range(seeds)]
