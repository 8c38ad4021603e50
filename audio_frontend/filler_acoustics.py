"""Is an utterance one open vowel with no consonant? The filler gate's acoustic evidence (Praat).

A hesitation filler ("er", "uh", "ah") is a single vowel: one rise and fall of loudness, voiced, the jaw
open throughout. Every keyword the rules sign has a consonant ("yeah" [j], "no" [n], "bad" [b d],
"yes" [s], "okay" [k]), and a consonant shows in one of two ways: a closure or fricative makes a dip in
loudness between two louder stretches, or a constriction (nasal, glide, stop transition) pulls the first
formant low in the voiced frames next to it. So the two numbers measured here are
- `dip_db`: the deepest dip in loudness inside the utterance (frames within 30 dB of the loudest),
  relative to the lower of the loudest points before and after it; ~0 for one syllable with no closure;
- `f1_min_hz`: the lowest first formant over the voiced frames of that span; a vowel without a
  consonant keeps F1 at its own height (mid and open vowels: above ~400 Hz), a consonant pulls it down.

This is not a test of steadiness: espeak's Scottish "er" glides from [e] to [ɐ] (F2 falls ~900 Hz)
and Whisper hears it as "Yeah.", yet it has no consonant. Thresholds live in the filler gate's config
(`sentiment.filler_gate.vowel_max_dip_db`, `vowel_min_f1_hz`); docs/voice.md says how they were chosen.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

_STEP_S = 0.01            # one frame of the tracks
_EDGE_S = 0.02            # frames nearer the ends than this are left out (the analyses' windows overhang)
_SPAN_DB = 30.0           # the utterance: frames within this of the loudest (as prosody_features)
# Burg formant tracker ceiling between Praat's advice for men (5000 Hz) and women (5500 Hz): one
# setting for every voice, as the thresholds were chosen with it
_MAX_FORMANT_HZ = 5250.0


@dataclass(frozen=True)
class VowelShape:
    dip_db: float       # deepest loudness dip inside the utterance
    f1_min_hz: float    # lowest F1 over its voiced frames (NaN: no voiced frame)
    seconds: float      # time the analysis took

    def is_open_vowel(self, max_dip_db: float, min_f1_hz: float) -> bool:
        """One syllable with no closure (dip below `max_dip_db`) whose F1 never falls to `min_f1_hz`."""
        return bool(self.dip_db < max_dip_db and self.f1_min_hz > min_f1_hz)   # NaN F1: False


def loudness_dip_db(intensity_db: np.ndarray) -> float:
    """The deepest dip of a loudness track below the lower of its maxima on either side (0 for a
    track that only rises then falls)."""
    d = np.asarray(intensity_db, dtype=np.float64)
    if d.size < 3:
        return 0.0
    left = np.maximum.accumulate(d)
    right = np.maximum.accumulate(d[::-1])[::-1]
    return float(np.max(np.minimum(left, right) - d))


def vowel_shape(audio: np.ndarray, sample_rate: int) -> VowelShape:
    """`VowelShape` of a mono utterance (silence around it is ignored). About 10-30 ms for 1 s."""
    import time

    import parselmouth

    t0 = time.perf_counter()
    x = np.asarray(audio, dtype=np.float64).reshape(-1)
    if x.size < 2 * _EDGE_S * sample_rate + 3 * _STEP_S * sample_rate or not np.any(x) or not np.all(np.isfinite(x)):
        return VowelShape(0.0, float("nan"), time.perf_counter() - t0)     # nothing to measure: not a vowel
    snd = parselmouth.Sound(x, sampling_frequency=float(sample_rate))
    ts = np.arange(_EDGE_S, snd.xmax - _EDGE_S, _STEP_S)
    intensity = snd.to_intensity(time_step=_STEP_S)
    pitch = snd.to_pitch(time_step=_STEP_S)
    formant = snd.to_formant_burg(max_number_of_formants=5, maximum_formant=_MAX_FORMANT_HZ)
    db = np.array([intensity.get_value(t) for t in ts], dtype=np.float64)
    if not np.any(np.isfinite(db)):
        return VowelShape(0.0, float("nan"), time.perf_counter() - t0)
    db = np.where(np.isfinite(db), db, np.nanmin(db))
    idx = np.flatnonzero(db >= db.max() - _SPAN_DB)
    a, b = int(idx[0]), int(idx[-1]) + 1
    span = ts[a:b]
    voiced = [t for t in span if np.isfinite(pitch.get_value_at_time(t))]
    f1 = np.array([formant.get_value_at_time(1, t) for t in voiced], dtype=np.float64)
    f1 = f1[np.isfinite(f1)]
    return VowelShape(loudness_dip_db(db[a:b]), float(f1.min()) if f1.size else float("nan"),
                      time.perf_counter() - t0)


def lazy_vowel_shape(audio: np.ndarray, sample_rate: int, timings: dict | None = None):
    """A callable for the rule layer: measures `vowel_shape(audio)` when first asked (only short signed
    transcripts are), once; its time goes to `timings["vowel_s"]`."""
    done: list[VowelShape] = []

    def shape() -> VowelShape:
        if not done:
            done.append(vowel_shape(audio, sample_rate))
            if timings is not None:
                timings["vowel_s"] = done[0].seconds
        return done[0]

    return shape
