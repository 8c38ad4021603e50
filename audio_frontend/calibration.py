"""Per-user prosody calibration (paper V-A.2): tau = median |valence| of labelled samples.

Two kinds of calibration share one file format:
- `wav2vec2`: tau only (the speech-emotion model is fixed; valence = P(hap) - P(ang)).
- `features`: tau plus the user's own prosody model (`audio_frontend.prosody_model`), fitted from their
  neutral, positive and negative samples.

The file is JSON, written atomically (`mjx_protamer.atomic`: temporary file in the same folder, fsync, os.replace), so a crash
never leaves a half-written calibration. Loading applies the same bounds as writing (`check_tau`).
"""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path
from statistics import median

from audio_frontend.errors import CalibrationError
from mjx_protamer.atomic import write_atomic

FORMAT_VERSION = 2
# Valences lie in [-1, 1], so tau = median |valence| can never exceed 1.
MAX_TAU = 1.0
KINDS = ("features", "wav2vec2")


def tau_problem(tau, min_tau: float = 1e-3) -> str | None:
    """Why `tau` is unusable (None when it is fine): the one rule for writing, loading and config."""
    if isinstance(tau, bool) or not isinstance(tau, (int, float)):
        return f"tau must be a number, not {type(tau).__name__} {tau!r}"
    if not math.isfinite(tau):
        return f"tau={tau} is not finite"
    if not min_tau <= tau <= MAX_TAU:
        return f"tau={tau:g} is outside [{min_tau:g}, {MAX_TAU:g}] (prosody.min_tau .. the largest |valence|)"
    return None


def compute_tau(samples: list[tuple[str, float]], min_per_sign: int = 3, min_tau: float = 1e-3) -> dict:
    """`samples`: (label 'pos'|'neg', valence). Returns the calibration record or raises CalibrationError."""
    bad = [s for s in samples if s[0] not in ("pos", "neg") or not math.isfinite(s[1]) or abs(s[1]) > MAX_TAU]
    if bad:
        raise CalibrationError(f"unusable calibration samples (label must be pos/neg, valence finite in [-1, 1]): "
                               f"{bad[:3]}")
    pos = [v for lab, v in samples if lab == "pos"]
    neg = [v for lab, v in samples if lab == "neg"]
    if len(pos) < min_per_sign or len(neg) < min_per_sign:
        raise CalibrationError(
            f"too few samples: {len(pos)} positive and {len(neg)} negative; at least {min_per_sign} of each "
            f"are needed (prosody.min_samples_per_sign)")
    vals = pos + neg
    tau = float(median(abs(v) for v in vals))
    if tau < min_tau:
        raise CalibrationError(
            f"tau = median |valence| = {tau:.2e} is below {min_tau:g}: the model hears no emotion in these "
            f"samples (valences {[round(v, 4) for v in vals]}); speak with more expression, check the microphone "
            f"level, or check the prosody model")
    if all(v > 0 for v in vals) or all(v < 0 for v in vals):
        sign = "positive" if vals[0] > 0 else "negative"
        raise CalibrationError(
            f"all {len(vals)} samples have {sign} valence, so rewards could never be {'negative' if sign == 'positive' else 'positive'}: "
            f"the model does not separate your positive and negative voice (valences {[round(v, 3) for v in vals]}); "
            f"exaggerate the tone (smile for positive, harsh for negative) and calibrate again")
    pos_ok = sum(v > 0 for v in pos) / len(pos)
    neg_ok = sum(v < 0 for v in neg) / len(neg)
    return {
        "format": FORMAT_VERSION,
        "tau": tau,
        "n_pos": len(pos),
        "n_neg": len(neg),
        "sign_accuracy": (sum(v > 0 for v in pos) + sum(v < 0 for v in neg)) / len(vals),
        "pos_sign_accuracy": pos_ok,
        "neg_sign_accuracy": neg_ok,
        "valences": {"pos": pos, "neg": neg},
        "created": time.time(),
    }


def write_json_atomic(path: str | Path, record: dict) -> Path:
    path = Path(os.path.expanduser(str(path)))
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_atomic(path, json.dumps(record, indent=2, sort_keys=True, allow_nan=False) + "\n")


def write_calibration(path: str | Path, record: dict) -> Path:
    return write_json_atomic(path, record)


def load_calibration(path: str | Path, min_tau: float = 1e-3) -> dict:
    """The calibration record, checked as `compute_tau` checks it; CalibrationError with the fix otherwise."""
    path = Path(os.path.expanduser(str(path)))
    again = "run 'protamer calibrate' again"
    if not path.is_file():
        raise CalibrationError(
            f"no prosody calibration at {path}; run 'protamer calibrate' (records prompts, or --wav-dir DIR with "
            f"pos/, neg/ and neu/ recordings), point prosody.calibration_path at a calibration file, or set "
            f"prosody.tau (prosody.kind=wav2vec2 only)")
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError, OSError) as e:
        raise CalibrationError(f"calibration file {path} is unreadable ({e}); {again}") from None
    if not isinstance(record, dict) or "tau" not in record:
        raise CalibrationError(f"calibration file {path} has no 'tau' field; {again}")
    problem = tau_problem(record["tau"], min_tau)
    if problem:
        raise CalibrationError(f"calibration file {path}: {problem}; {again}")
    kind = record.get("kind", "wav2vec2")   # format 1 files predate the feature model
    if kind not in KINDS:
        raise CalibrationError(f"calibration file {path} has kind={kind!r} (expected one of {KINDS}); {again}")
    if kind == "features" and not isinstance(record.get("prosody_model"), dict):
        raise CalibrationError(f"calibration file {path} (kind features) holds no prosody_model; {again} "
                               f"with --wav-dir holding pos/, neg/ and neu/")
    record["tau"] = float(record["tau"])
    record["kind"] = kind
    record["path"] = str(path)
    return record


def resolve_tau(prosody_cfg) -> tuple[float, str]:
    """(tau, where it came from): prosody.tau when set, else the calibration file."""
    if prosody_cfg.tau is not None:
        return float(prosody_cfg.tau), "config prosody.tau"
    rec = load_calibration(prosody_cfg.calibration_path, prosody_cfg.min_tau)
    return rec["tau"], rec["path"]


def feature_calibration(samples: list[tuple[str, dict]], prosody_cfg) -> dict:
    """Fit the user's prosody model (`prosody.kind: features`) from (label, features) samples, labels
    pos / neg / neu (fillers count as neutral). tau and the sign accuracy come from cross-validated
    valences (each sample scored by a model fitted without it), so they describe unseen utterances."""
    from audio_frontend.prosody_model import fit

    samples = [("neu" if lab == "filler" else lab, f) for lab, f in samples]
    model, held_out = fit(samples, prosody_cfg.min_samples_per_sign)
    record = compute_tau(held_out, prosody_cfg.min_samples_per_sign, prosody_cfg.min_tau)
    record.update(kind="features", prosody_model=model.to_dict(), n_neu=sum(lab == "neu" for lab, _ in samples),
                  valences_are="cross-validated (held-out) valences of the calibration samples")
    return record
