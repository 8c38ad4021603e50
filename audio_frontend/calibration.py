"""Per-user prosody calibration (paper V-A.2): tau = median |valence| of labelled samples.

The file is JSON, written atomically (temporary file in the same folder, fsync, os.replace), so a crash
never leaves a half-written calibration.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
import time
from pathlib import Path
from statistics import median

from audio_frontend.errors import CalibrationError

FORMAT_VERSION = 1


def compute_tau(samples: list[tuple[str, float]], min_per_sign: int = 3, min_tau: float = 1e-3) -> dict:
    """`samples`: (label 'pos'|'neg', valence). Returns the calibration record or raises CalibrationError."""
    bad = [s for s in samples if s[0] not in ("pos", "neg") or not math.isfinite(s[1])]
    if bad:
        raise CalibrationError(f"unusable calibration samples (label must be pos/neg, valence finite): {bad[:3]}")
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


def write_calibration(path: str | Path, record: dict) -> Path:
    path = Path(os.path.expanduser(str(path)))
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump(record, fh, indent=2, sort_keys=True, allow_nan=False)
            fh.write("\n")
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def load_calibration(path: str | Path) -> dict:
    path = Path(os.path.expanduser(str(path)))
    if not path.is_file():
        raise CalibrationError(
            f"no prosody calibration at {path}; run 'protamer calibrate' (records prompts, or --wav-dir DIR with "
            f"pos/ and neg/ recordings), point prosody.calibration_path at a calibration file, or set prosody.tau")
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
        tau = float(record["tau"])
    except (json.JSONDecodeError, KeyError, TypeError, ValueError) as e:
        raise CalibrationError(f"calibration file {path} is unreadable ({e}); run 'protamer calibrate' again") from None
    if not math.isfinite(tau) or tau <= 0:
        raise CalibrationError(f"calibration file {path} has tau={tau}; run 'protamer calibrate' again")
    record["tau"] = tau
    record["path"] = str(path)
    return record


def resolve_tau(prosody_cfg) -> tuple[float, str]:
    """(tau, where it came from): prosody.tau when set, else the calibration file."""
    if prosody_cfg.tau is not None:
        return float(prosody_cfg.tau), "config prosody.tau"
    rec = load_calibration(prosody_cfg.calibration_path)
    return rec["tau"], rec["path"]
