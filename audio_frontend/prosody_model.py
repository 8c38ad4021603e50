"""The per-user prosody model: speaker-normalised features -> valence in [-1, 1].

Normalisation: the user's mean neutral feature vector is subtracted (pitch in semitones, energy in dB
and durations in log seconds become "how much higher / louder / faster than my neutral voice"), so a
high voice is not positive merely for being high. A three-class logistic regression (neg / neu / pos,
scikit-learn) is fitted on the user's calibration samples; valence = P(pos) - P(neg), the same form as
the wav2vec2 scorer's P(hap) - P(ang). Prediction needs only numpy (the fitted numbers are stored in the
calibration file), so scoring is cheap and loads nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from audio_frontend.errors import CalibrationError
from audio_frontend.prosody_features import FEATURES, vector

CLASSES = ("neg", "neu", "pos")


@dataclass(frozen=True)
class ProsodyModel:
    features: tuple[str, ...]
    neutral_mean: np.ndarray       # the speaker's neutral voice (raw feature units)
    scale_mean: np.ndarray         # standardisation of the normalised features
    scale_std: np.ndarray
    coef: np.ndarray               # (3, n_features), rows in CLASSES order
    intercept: np.ndarray          # (3,)

    def normalised(self, raw: np.ndarray) -> np.ndarray:
        z = np.asarray(raw, dtype=np.float64) - self.neutral_mean
        z = np.where(np.isfinite(z), z, 0.0)          # unmeasurable: as the neutral voice
        return (z - self.scale_mean) / self.scale_std

    def probabilities(self, raw: np.ndarray) -> dict[str, float]:
        logits = self.coef @ self.normalised(raw) + self.intercept
        p = np.exp(logits - logits.max())
        p /= p.sum()
        return {c: float(v) for c, v in zip(CLASSES, p)}

    def valence(self, raw: np.ndarray) -> tuple[float, dict[str, float]]:
        p = self.probabilities(raw)
        return p["pos"] - p["neg"], p

    def to_dict(self) -> dict:
        return {"features": list(self.features), "classes": list(CLASSES),
                "neutral_mean": [float(v) if np.isfinite(v) else 0.0 for v in self.neutral_mean],
                "scale_mean": self.scale_mean.tolist(), "scale_std": self.scale_std.tolist(),
                "coef": self.coef.tolist(), "intercept": self.intercept.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> "ProsodyModel":
        """Checked: the feature list must be this version's and every number finite."""
        try:
            feats = tuple(d["features"])
            if feats != FEATURES or tuple(d["classes"]) != CLASSES:
                raise ValueError(f"features {list(feats)} / classes {d['classes']} are not this version's "
                                 f"{list(FEATURES)} / {list(CLASSES)}")
            n = len(FEATURES)
            arrays = {k: np.asarray(d[k], dtype=np.float64) for k in
                      ("neutral_mean", "scale_mean", "scale_std", "coef", "intercept")}
            shapes = {"neutral_mean": (n,), "scale_mean": (n,), "scale_std": (n,), "coef": (3, n),
                      "intercept": (3,)}
            for k, shape in shapes.items():
                if arrays[k].shape != shape or not np.all(np.isfinite(arrays[k])):
                    raise ValueError(f"{k} must be {shape} finite numbers")
            if np.any(arrays["scale_std"] <= 0):
                raise ValueError("scale_std must be > 0")
        except (KeyError, TypeError, ValueError) as e:
            raise CalibrationError(f"the calibration's prosody_model is unusable ({e}); run 'protamer calibrate' "
                                   f"again") from None
        return cls(feats, arrays["neutral_mean"], arrays["scale_mean"], arrays["scale_std"], arrays["coef"],
                   arrays["intercept"])


def neutral_reference(neutral: np.ndarray, every: np.ndarray) -> np.ndarray:
    """Mean neutral features; a feature never measured in neutral speech falls back to all samples, then 0."""
    with np.errstate(all="ignore"):
        ref = np.nanmean(neutral, axis=0) if neutral.size else np.full(every.shape[1], np.nan)
        ref = np.where(np.isfinite(ref), ref, np.nanmean(every, axis=0))
    return np.where(np.isfinite(ref), ref, 0.0)


def _fit_arrays(x: np.ndarray, y: np.ndarray, neutral_mean: np.ndarray, c: float) -> ProsodyModel:
    from sklearn.linear_model import LogisticRegression

    z = x - neutral_mean
    z = np.where(np.isfinite(z), z, 0.0)
    mean, std = z.mean(axis=0), z.std(axis=0)
    std = np.where(std > 1e-9, std, 1.0)
    clf = LogisticRegression(C=c, max_iter=2000)
    clf.fit((z - mean) / std, y)
    order = [list(clf.classes_).index(k) for k in CLASSES]
    return ProsodyModel(FEATURES, neutral_mean, mean, std, clf.coef_[order], clf.intercept_[order])


def fit(samples: list[tuple[str, dict]], min_per_class: int = 3, c: float = 1.0
        ) -> tuple[ProsodyModel, list[tuple[str, float]]]:
    """Fit on (label in neg/neu/pos, features) samples. Returns the model and cross-validated (label, valence)
    of the positive and negative samples: what tau and the calibration's sign accuracy are computed from,
    so they describe utterances the model did not see."""
    counts = {k: sum(1 for lab, _ in samples if lab == k) for k in CLASSES}
    if any(counts[k] < min_per_class for k in CLASSES):
        raise CalibrationError(
            f"too few samples: {counts['pos']} positive, {counts['neg']} negative and {counts['neu']} neutral; the "
            f"feature model needs at least {min_per_class} of each (prosody.min_samples_per_sign): record or put "
            f"them in pos/, neg/ and neu/")
    x = np.stack([vector(f) for _, f in samples])
    y = np.array([lab for lab, _ in samples])
    ref = neutral_reference(x[y == "neu"], x)
    model = _fit_arrays(x, y, ref, c)
    from sklearn.model_selection import StratifiedKFold

    folds = min(5, min(counts.values()))
    if folds < 2:   # one sample of a class: nothing to hold out, in-sample valences it is
        held_out = [(lab, float(model.valence(row)[0])) for lab, row in zip(y, x) if lab in ("pos", "neg")]
        return model, held_out
    valences = np.full(len(y), np.nan)
    for train, test in StratifiedKFold(n_splits=folds, shuffle=True, random_state=0).split(x, y):
        m = _fit_arrays(x[train], y[train], ref, c)
        valences[test] = [m.valence(row)[0] for row in x[test]]
    held_out = [(lab, float(v)) for lab, v in zip(y, valences) if lab in ("pos", "neg")]
    return model, held_out
