"""The reaction delay of a recorded session, fitted and reported (`protamer reaction-delay SESSION`, and the end of
`protamer finetune --calibrate`): the onsets of one touch on the shown infant against the person's feedback
(human/reaction_delay.py fits them), printed, with its JSON and a histogram written atomically."""

from __future__ import annotations

import sys
from pathlib import Path

from mjx_protamer.atomic import replacing


def _fail(msg: str, who: str = "protamer reaction-delay") -> int:
    print(f"{who}: {msg}", file=sys.stderr)
    return 2


def measure(session: Path, touch: str | None, sign: str = "any", window_s=None, min_gap_s: float | None = None,
            json_path: Path | None = None, plot_path: Path | None = None,
            who: str = "protamer reaction-delay", rerun: str = "") -> int:
    """Fit and print the reaction delay of a recorded session (also the end of `finetune --calibrate`);
    0, or 2 with a one-line reason on stderr. `touch` None: the session's --calibrate touch, else head.
    `rerun`: the command that refits with other options (named in the advice when it is not this one)."""
    import math

    from mjx_protamer.human import reaction_delay as rd
    from mjx_protamer.live.record import read_session, write_json_atomic
    from mjx_protamer.human.touches import shown_touches, touch_onsets

    def fail(msg: str) -> int:
        return _fail(msg, who)

    window = tuple(window_s) if window_s else rd.WINDOW_S
    min_gap = rd.MIN_GAP_S if min_gap_s is None else min_gap_s
    if not (0 <= window[0] < window[1] and math.isfinite(window[1])):
        return fail(f"--window-s needs 0 <= LO < HI < inf, got {window[0]:g} {window[1]:g}")
    if not (math.isfinite(min_gap) and min_gap >= 0):
        return fail(f"--min-gap-s must be a number >= 0, got {min_gap:g}")
    try:
        manifest, records = read_session(session)
        dt, chunk_steps = float(manifest["feedback_config"]["dt"]), int(manifest["chunk_steps"])
        touch = touch or manifest.get("calibrate") or "head"
        intervals, span = shown_touches(records, dt, chunk_steps)
        responses = rd.feedback_onsets(records, sign)
    except FileNotFoundError as e:
        return fail(str(e))
    except (ValueError, KeyError, TypeError, AttributeError) as e:  # a damaged or foreign session record
        return fail(f"{session}: cannot read the session record ({type(e).__name__}: {e})")
    if not any("first_step" in r for r in records):
        return fail(f"{session} showed no chunk (stopped while loading)")
    if not intervals:
        return fail(f"{session} recorded no touches: a session of an env without body regions (the toy), "
                     "or one recorded before sessions logged touches; record a self-touch session")
    from mjx_protamer.envs.body import REGIONS
    from mjx_protamer.human.touches import HANDS

    if touch not in (*REGIONS, *HANDS):
        return fail(f"--touch {touch!r}: not a touch; use one of " + ", ".join((*REGIONS, *HANDS)))
    if touch not in intervals:
        return fail(f"--touch {touch!r} never happened in {session}; it recorded: "
                     + ", ".join(sorted(intervals)))
    onsets = touch_onsets(intervals[touch], min_gap)
    try:
        fit = rd.fit_reaction_delay(onsets, responses, span, window)
    except rd.NotEnoughReactions as e:
        simulated = str(manifest.get("feedback", "")).startswith("simulated:")
        why = (f"a simulated teacher reacts to its own rule, not to {touch}'s onsets (docs/experiments.md, "
               f"'Measuring a reaction delay from a session', shows a rule that does)" if simulated else
               f"give feedback each time {touch} starts touching, for 2-3 minutes")
        return fail(f"{e}. {why[0].upper() + why[1:]}; or count a touch's beginning differently with "
                    f"{rerun + ' ' if rerun else ''}--min-gap-s (now {min_gap:g}), --sign (now {sign}) or "
                    f"--window-s (now {window[0]:g} {window[1]:g})")
    channel = manifest.get("feedback_config", {}).get("teacher", {}).get("channel", {})
    result = {"session": str(session), "feedback": manifest.get("feedback"), "touch": touch,
              "sign": sign, "min_gap_s": min_gap, "session_s": span, **fit.to_dict(),
              "overrides": fit.channel_overrides(), "credited_with": channel}
    print(f"reaction delay to {touch} onsets ({manifest.get('feedback')} feedback, {span:.0f} s shown): "
          f"{fit.n_onsets} onsets (one every {span / max(fit.n_onsets, 1):.1f} s), {fit.n_feedback} feedback "
          f"events, {fit.reactions:.0f} reactions ({100 * fit.reacted:.0f}% of the feedback)")
    print(f"  mean {fit.mean_s:.3f} s +- {fit.mean_ci95_s:.3f} (95% CI), std {fit.std_s:.3f} s, "
          f"fastest (2.5th percentile) {fit.min_s:.3f} s")
    if fit.outside_window > 0.025:
        print(f"  note: {100 * fit.outside_window:.0f}% of the fitted delays fall outside --window-s "
              f"{window[0]:g} {window[1]:g}: the std and the reacting fraction are underestimated; widen it")
    from mjx_protamer.human.channels import KINDS, ChannelConfig

    if channel.get("kind") in KINDS:
        ch = ChannelConfig(kind=channel["kind"], **{k: channel.get(k) for k in
                                                     ("delay_mean_s", "delay_std_s", "delay_min_s")})
        print(f"  the session credited with {ch.kind}'s delay {ch.get('delay_mean_s'):.3f} +- "
              f"{ch.get('delay_std_s'):.3f} s (fastest {ch.get('delay_min_s'):.3f} s)")
    print("  credit with: " + " ".join(f"--set {o}" for o in fit.channel_overrides()))
    try:
        if json_path is not None:
            write_json_atomic(json_path, result)
            print(f"  wrote {json_path}")
        if plot_path is not None:
            _plot(fit, touch, plot_path)
            print(f"  wrote {plot_path}")
    except OSError as e:
        return fail(f"cannot write the output: {e}")
    return 0


def _plot(fit, touch: str, path: Path) -> None:
    """Histogram of each feedback's delay to its likeliest onset, reactions and the rest apart, with the fitted
    Normal scaled to the reactions; written atomically."""
    import math

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    d = np.asarray(fit.delays_s)
    r = np.asarray(fit.responsibility)
    lo, hi = fit.window_s
    bins = np.arange(lo, hi + 0.05, 0.05)
    fig, ax = plt.subplots(figsize=(6.4, 3.6), dpi=120)
    ok = np.isfinite(d)
    ax.hist([d[ok & (r >= 0.5)], d[ok & (r < 0.5)]], bins=bins, stacked=True, color=["#3b75af", "#bbbbbb"],
            label=["reactions (P >= 0.5)", "other feedback"])
    x = np.linspace(lo, hi, 400)
    pdf = np.exp(-0.5 * ((x - fit.mean_s) / fit.std_s) ** 2) / (fit.std_s * math.sqrt(2 * math.pi))
    ax.plot(x, pdf * fit.reactions * 0.05, color="#c44e52",
            label=f"Normal({fit.mean_s:.2f}, {fit.std_s:.2f}) x {fit.reactions:.0f}")
    ax.axvline(fit.min_s, color="#555555", ls=":", label=f"fastest (2.5%) {fit.min_s:.2f} s")
    ax.set_xlabel(f"feedback onset - {touch} onset (s)")
    ax.set_ylabel("feedback events")
    ax.set_title(f"reaction delay: {fit.mean_s:.3f} +- {fit.mean_ci95_s:.3f} s (95% CI), {fit.n_feedback} events")
    ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        with replacing(path) as tmp:
            fig.savefig(tmp, format="png")
    finally:
        plt.close(fig)
