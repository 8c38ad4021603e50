"""The paper's validation protocol (V-A.4): sign accuracy and confusion matrix on labelled recordings."""

from __future__ import annotations

from audio_frontend.labelled import Scored


def sign(v: float) -> str:
    return "pos" if v > 0 else "neg" if v < 0 else "zero"


def summarize(rows: list[Scored], scorer: str) -> dict:
    ok = [r for r in rows if r.error is None]
    confusion = {t: {p: 0 for p in ("pos", "neg", "zero")} for t in ("pos", "neg")}
    for r in ok:
        confusion[r.label][sign(r.value)] += 1
    correct = confusion["pos"]["pos"] + confusion["neg"]["neg"]
    lat = [r.latency_s for r in ok if r.latency_s is not None]
    return {
        "scorer": scorer,
        "n_files": len(rows),
        "n_scored": len(ok),
        "n_errors": len(rows) - len(ok),
        "sign_accuracy": (correct / len(ok)) if ok else None,
        "confusion": confusion,
        "mean_latency_s": (sum(lat) / len(lat)) if lat else None,
        "rows": [{"file": r.path, "label": r.label, "value": r.value, "predicted": sign(r.value)
                  if r.value is not None else None, "latency_s": r.latency_s, "error": r.error,
                  **({"transcript": r.details.get("transcript")} if "transcript" in r.details else {})}
                 for r in rows],
    }


def format_table(summary: dict) -> str:
    value_name = "valence" if summary["scorer"] == "prosody" else "value"
    lines = [f"{'file':40s} {'label':5s} {value_name:>8s} {'pred':5s} {'latency':>8s}"]
    for r in summary["rows"]:
        name = r["file"][-40:]
        if r["error"]:
            lines.append(f"{name:40s} {r['label']:5s} {'ERROR':>8s}  {r['error']}")
        else:
            extra = f"  {r['transcript']!r}" if "transcript" in r else ""
            lines.append(f"{name:40s} {r['label']:5s} {r['value']:+8.3f} {r['predicted']:5s} "
                         f"{r['latency_s']:7.3f}s{extra}")
    c = summary["confusion"]
    acc = summary["sign_accuracy"]
    lat = summary["mean_latency_s"]
    lines += [
        "",
        "confusion (rows: label, columns: predicted sign)",
        f"{'':6s} {'pos':>5s} {'neg':>5s} {'zero':>5s}",
        f"{'pos':6s} {c['pos']['pos']:5d} {c['pos']['neg']:5d} {c['pos']['zero']:5d}",
        f"{'neg':6s} {c['neg']['pos']:5d} {c['neg']['neg']:5d} {c['neg']['zero']:5d}",
        "",
        f"sign accuracy: {'n/a' if acc is None else f'{acc:.3f}'} over {summary['n_scored']} recordings"
        f" ({summary['n_errors']} unusable)",
        f"mean latency: {'n/a' if lat is None else f'{lat:.3f} s'} (scoring time per recording)",
    ]
    return "\n".join(lines)
