"""The paper's validation protocol (V-A.4), extended into a channel model for simulated teachers.

Per scorer: sign accuracy on signed utterances, the confusion of each true label (pos, neg, neu,
filler) into delivered values +1 / -1 / 0 (a signed utterance that gives 0 is a miss), latency from
the end of speech to the event (the VAD's endpoint wait + scoring) and utterance durations.
"""

from __future__ import annotations

import statistics

import numpy as np

from audio_frontend.labelled import LABELS, Scored

OUTCOMES = ("+1", "-1", "0")
STAGES = ("features_s", "encoder_s", "decoder_s")


def sign(v: float) -> str:
    return "pos" if v > 0 else "neg" if v < 0 else "zero"


def outcome(v: float) -> str:
    return "+1" if v > 0 else "-1" if v < 0 else "0"


def spread(values: list[float]) -> dict | None:
    """Median, 10th / 25th / 75th / 90th percentiles, n."""
    v = [float(x) for x in values if x is not None and np.isfinite(x)]
    if not v:
        return None
    p = np.percentile(v, [10, 25, 75, 90])
    return {"median": statistics.median(v), "p10": float(p[0]), "p25": float(p[1]), "p75": float(p[2]),
            "p90": float(p[3]), "n": len(v)}


def summarize(rows: list[Scored], scorer: str, kinds: dict[str, str] | None = None) -> dict:
    """`kinds`: file -> kind (congruent, against, ...) from a labels.jsonl, for a per-kind accuracy."""
    ok = [r for r in rows if r.error is None]
    labels = [lab for lab in LABELS if any(r.label == lab for r in ok)]
    confusion = {t: {p: 0 for p in ("pos", "neg", "zero")} for t in ("pos", "neg")}
    counts = {t: dict.fromkeys(OUTCOMES, 0) for t in labels}
    for r in ok:
        if r.label in confusion:
            confusion[r.label][sign(r.value)] += 1
        counts[r.label][outcome(r.value)] += 1
    signed = [r for r in ok if r.label in ("pos", "neg")]
    correct = confusion["pos"]["pos"] + confusion["neg"]["neg"]
    rates = {t: {o: c / max(sum(counts[t].values()), 1) for o, c in counts[t].items()} for t in labels}
    by_kind = None
    if kinds:
        by_kind = {}
        for r in signed:
            k = kinds.get(r.path)
            if k:
                by_kind.setdefault(k, []).append(sign(r.value) == r.label)
        by_kind = {k: {"sign_accuracy": sum(v) / len(v), "n": len(v)} for k, v in sorted(by_kind.items())}
    unsigned = [r for r in ok if r.label in ("neu", "filler")]
    lat = [r.latency_s for r in ok if r.latency_s is not None]
    return {
        "scorer": scorer,
        "n_files": len(rows),
        "n_scored": len(ok),
        "n_errors": len(rows) - len(ok),
        "n_signed": len(signed),
        "sign_accuracy": (correct / len(signed)) if signed else None,
        "confusion": confusion,
        "outcome_counts": counts,
        "outcome_rates": rates,
        "miss_rate": (sum(r.value == 0 for r in signed) / len(signed)) if signed else None,
        "zero_rate_unsigned": (sum(r.value == 0 for r in unsigned) / len(unsigned)) if unsigned else None,
        "by_kind": by_kind,
        "mean_latency_s": (sum(lat) / len(lat)) if lat else None,
        "scoring_s": spread(lat),
        "vad_wait_s": spread([r.vad_wait_s for r in ok]),
        "event_latency_s": spread([r.event_latency_s for r in ok]),
        "utterance_s": spread([r.speech_s for r in ok]),
        # where Whisper's scoring time goes (median seconds), for scorers that report it
        "stages_s": {k: spread([r.details[k] for r in ok if k in r.details])["median"]
                     for k in STAGES if any(k in r.details for r in ok)} or None,
        # signed utterances that gave the opposite sign (a 0 is a miss, not a wrong sign)
        "wrong_sign_rate": (sum(sign(r.value) not in (r.label, "zero") for r in signed) / len(signed))
        if signed else None,
        "rows": [{"file": r.path, "label": r.label, "value": r.value, "predicted": sign(r.value)
                  if r.value is not None else None, "latency_s": r.latency_s, "error": r.error,
                  **({"kind": kinds[r.path]} if kinds and r.path in kinds else {}),
                  **({"transcript": r.details.get("transcript")} if "transcript" in r.details else {}),
                  **({"valence": r.details.get("valence")} if "valence" in r.details else {})}
                 for r in rows],
    }


def channel(summary: dict) -> dict:
    """What a simulated teacher needs from one scorer's summary (no per-file rows)."""
    keys = ("scorer", "n_scored", "n_signed", "sign_accuracy", "outcome_counts", "outcome_rates", "miss_rate",
            "zero_rate_unsigned", "wrong_sign_rate", "by_kind", "event_latency_s", "scoring_s", "stages_s",
            "vad_wait_s", "utterance_s")
    return {k: summary.get(k) for k in keys}


def format_table(summary: dict) -> str:
    value_name = "valence" if summary["scorer"].startswith("prosody") else "value"
    lines = [f"{'file':40s} {'label':6s} {value_name:>8s} {'pred':5s} {'latency':>8s}"]
    for r in summary["rows"]:
        name = r["file"][-40:]
        if r["error"]:
            lines.append(f"{name:40s} {r['label']:6s} {'ERROR':>8s}  {r['error']}")
        else:
            extra = f"  {r['transcript']!r}" if "transcript" in r else ""
            lines.append(f"{name:40s} {r['label']:6s} {r['value']:+8.3f} {r['predicted']:5s} "
                         f"{r['latency_s']:7.3f}s{extra}")
    acc = summary["sign_accuracy"]
    lat = summary["event_latency_s"]
    lines += ["", "outcomes (rows: label, columns: delivered value)", f"{'':7s} {'+1':>5s} {'-1':>5s} {'0':>5s}"]
    for lab, c in summary["outcome_counts"].items():
        lines.append(f"{lab:7s} {c['+1']:5d} {c['-1']:5d} {c['0']:5d}")
    miss, zero = summary["miss_rate"], summary["zero_rate_unsigned"]
    lines += [
        "",
        f"sign accuracy: {'n/a' if acc is None else f'{acc:.3f}'} over {summary['n_signed']} signed recordings"
        f" ({summary['n_errors']} unusable)"
        + ("" if miss is None else f"; signed -> 0 (misses): {miss:.3f}")
        + ("" if summary.get("wrong_sign_rate") is None else f"; wrong sign: {summary['wrong_sign_rate']:.3f}")
        + ("" if zero is None else f"; neutral/fillers -> 0: {zero:.3f}"),
        "end of speech -> event: " + ("n/a" if lat is None else
                                      f"median {lat['median']:.3f} s (p90 {lat['p90']:.3f} s)")
        + " = VAD endpoint wait + scoring",
    ]
    return "\n".join(lines)
