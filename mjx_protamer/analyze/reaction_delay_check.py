"""`protamer reaction-delay`'s fit against the truth, on recorded finetune sessions.

    protamer analyze reaction-delay-check SESSION... [--touch head] [--out JSON]
    protamer analyze reaction-delay-check SESSION... --person keyboard --seeds 10 [--out JSON]

- Without --person: the session's own feedback, from a simulated teacher; each simulated event names the step
  it judged (`details.about_step`), so its true delay is known. Per session: the fit (mean, std, CI, reacting
  fraction) or its refusal, the true delays of all the feedback and of the feedback judged at an onset the fit
  can see (a touch beginning after --min-gap-s without it), and whether the CI holds the true mean.
- With --person KIND: a simulated person reacting to the touches the session showed (its recorded onsets,
  as the person perceives them: after --person-gap-s without the touch), with the channel KIND's reaction
  delay max(min, Normal(mean, std)) (channels.PRESETS), missing --miss of the onsets and giving --unrelated
  more feedback at random times; --seeds persons per session, each drawn anew. Per person: the fit against
  the mean of the delays it drew (`ci_holds_true_mean`) and against its population's mean
  (`ci_holds_preset_mean`: what a 95% CI should hold 95% of the time).
The report of docs/experiments.md, "Measuring a reaction delay from a session".
"""

from __future__ import annotations

import bisect
import json
import sys
from pathlib import Path

import numpy as np

from mjx_protamer.human import reaction_delay as rd
from mjx_protamer.live.record import read_session, write_json_atomic
from mjx_protamer.human.touches import shown_touches, touch_onsets


def check(session: Path, touch: str, min_gap_s: float) -> dict:
    manifest, records = read_session(session)
    dt = float(manifest["feedback_config"]["dt"])
    chunks = sorted((r["first_step"], r["t0"]) for r in records if "first_step" in r)
    firsts = [c[0] for c in chunks]

    def shown(step: int) -> float:
        first, t0 = chunks[bisect.bisect_right(firsts, step) - 1]
        return t0 + (step - first) * dt

    events = sorted((e for r in records for e in r.get("events", []) if e.value != 0 and "about_step" in e.details),
                    key=lambda e: e.t_start)
    judged = np.array([shown(e.details["about_step"]) for e in events])
    true = np.array([e.t_start for e in events]) - judged
    intervals, span = shown_touches(records, dt, int(manifest["chunk_steps"]))
    onsets = touch_onsets(intervals.get(touch, []), min_gap_s)
    at_onset = np.array([len(onsets) > 0 and np.min(np.abs(onsets - j)) < dt / 2 for j in judged])
    out = {"session": str(session), "feedback": manifest.get("feedback"), "touch": touch, "n_feedback": len(events),
           "n_onsets": len(onsets), "true_mean_s": float(true.mean()), "true_std_s": float(true.std(ddof=1)),
           "judged_at_an_onset": int(at_onset.sum()),
           "true_mean_at_onsets_s": float(true[at_onset].mean()) if at_onset.any() else None,
           "true_std_at_onsets_s": float(true[at_onset].std(ddof=1)) if at_onset.sum() > 1 else None}
    try:
        fit = rd.fit_reaction_delay(onsets, [e.t_start for e in events], span)
    except rd.NotEnoughReactions as e:
        return {**out, "fit": None, "refused": str(e)}
    out["fit"] = {k: getattr(fit, k) for k in ("mean_s", "std_s", "min_s", "mean_ci95_s", "reacted", "reactions")}
    out["ci_holds_true_mean"] = bool(abs(fit.mean_s - out["true_mean_s"]) <= fit.mean_ci95_s)
    return out


def simulated_person(session: Path, touch: str, min_gap_s: float, kind: str, seed: int, person_gap_s: float,
                     miss: float, unrelated: float) -> dict:
    """One simulated person on a session's touches; `seed` draws its misses, delays and unrelated feedback."""
    from mjx_protamer.human.channels import PRESETS

    manifest, records = read_session(session)
    dt = float(manifest["feedback_config"]["dt"])
    shown, span = shown_touches(records, dt, int(manifest["chunk_steps"]))
    intervals = shown.get(touch, [])
    seen = touch_onsets(intervals, person_gap_s)  # what the person reacts to
    p = PRESETS[kind]
    rng = np.random.default_rng(seed)
    preset_mean = float(np.mean(np.maximum(p["delay_min_s"], np.random.default_rng(12345).normal(
        p["delay_mean_s"], p["delay_std_s"], 1_000_000))))  # the person's population mean (the clamp included)
    react = seen[rng.random(len(seen)) >= miss]
    delays = np.maximum(p["delay_min_s"], rng.normal(p["delay_mean_s"], p["delay_std_s"], len(react)))
    t0 = min(r["t0"] for r in records if "t0" in r)
    other = t0 + rng.uniform(0, span, int(round(unrelated * len(react))))
    out = {"session": str(session), "person": kind, "seed": seed, "person_gap_s": person_gap_s, "n_seen": len(seen),
           "n_reactions": len(react), "n_unrelated": len(other), "true_mean_s": float(delays.mean()),
           "true_std_s": float(delays.std(ddof=1))}
    onsets = touch_onsets(intervals, min_gap_s)
    try:
        fit = rd.fit_reaction_delay(onsets, np.concatenate([react + delays, other]), span)
    except rd.NotEnoughReactions as e:
        return {**out, "n_onsets": len(onsets), "fit": None, "refused": str(e)}
    out.update(n_onsets=len(onsets), fit={k: getattr(fit, k) for k in ("mean_s", "std_s", "min_s", "mean_ci95_s",
                                                                      "reacted", "reactions")},
               ci_holds_true_mean=bool(abs(fit.mean_s - out["true_mean_s"]) <= fit.mean_ci95_s),
               ci_holds_preset_mean=bool(abs(fit.mean_s - preset_mean) <= fit.mean_ci95_s))
    return out


def report(sessions: list[Path], touch: str, min_gap_s: float, out: Path | None, person: str | None, seeds: int,
           person_gap_s: float, miss: float, unrelated: float, command: str) -> int:
    """Prints a line a session (or a simulated person) and writes them to `out` with the `command` that made
    them; 0, or 2 with a one-line reason on stderr for a session that is not there."""
    rows = []
    if person is not None:
        for i, s in enumerate(sessions):
            for seed in range(seeds):  # a new person in every session
                r = simulated_person(s, touch, min_gap_s, person, 1000 * i + seed, person_gap_s, miss, unrelated)
                rows.append(r)
                f = r["fit"]
                print(f"{s} person {seed}: drew {r['true_mean_s']:.3f} +- {r['true_std_s']:.3f} over "
                      f"{r['n_reactions']} reactions; " + (f"fit {f['mean_s']:.3f} +- {f['mean_ci95_s']:.3f} "
                                                           f"(std {f['std_s']:.3f})" if f else r["refused"]))
        summary = _summary(rows)
        print(json.dumps(summary))
        if out is not None:
            write_json_atomic(out, {"command": command, "summary": summary, "persons": rows})
        return 0
    for s in sessions:
        try:
            rows.append(check(s, touch, min_gap_s))
        except FileNotFoundError as e:
            print(f"protamer analyze reaction-delay-check: {e}", file=sys.stderr)
            return 2
        r = rows[-1]
        f = r["fit"]
        fitted = (f"fit {f['mean_s']:.3f} +- {f['mean_ci95_s']:.3f} (std {f['std_s']:.3f}, {100 * f['reacted']:.0f}% "
                  f"reacting)" if f else f"refused: {r['refused']}")
        print(f"{s}: {r['n_feedback']} feedback, {r['n_onsets']} onsets, true {r['true_mean_s']:.3f} +- "
              f"{r['true_std_s']:.3f} ({r['judged_at_an_onset']} judged at an onset); {fitted}")
    if out is not None:
        write_json_atomic(out, {"command": command, "sessions": rows})
    return 0


def _summary(rows: list[dict]) -> dict:
    fitted = [r for r in rows if r["fit"]]
    err = np.array([r["fit"]["mean_s"] - r["true_mean_s"] for r in fitted])
    std_err = np.array([r["fit"]["std_s"] - r["true_std_s"] for r in fitted])
    return {"persons": len(rows), "fitted": len(fitted),
            "ci_holds_true_mean": int(sum(r["ci_holds_true_mean"] for r in fitted)),
            "ci_holds_preset_mean": int(sum(r["ci_holds_preset_mean"] for r in fitted)),
            "mean_error_s": {"mean": float(err.mean()), "max_abs": float(np.abs(err).max())} if len(err) else None,
            "std_error_s": {"mean": float(std_err.mean()), "max_abs": float(np.abs(std_err).max())}
            if len(err) else None}
