"""Prosodic features of one utterance with Praat (praat-parselmouth): the tone, not the words.

Pitch level, range, slope and final contour (semitones), energy level and range (dB), voicing,
speaking rate (voiced runs per second), duration, harmonics-to-noise ratio and spectral tilt. All are on
log scales (semitones, dB, log seconds), so a speaker's neutral level can be subtracted
(`audio_frontend.prosody_model`). Features that cannot be measured (no voiced frame) are NaN.
One intensity and one pitch analysis per utterance (about 15 ms for 3 s of audio).
"""

from __future__ import annotations

import numpy as np

FEATURES = ("f0_median_st", "f0_range_st", "f0_slope_st_s", "f0_final_st", "intensity_db", "intensity_range_db",
            "voiced_fraction", "log_rate", "log_duration", "hnr_db", "tilt_db")

_TIME_STEP = 0.01


def _active_span(intensity_db: np.ndarray, below_peak_db: float = 30.0) -> np.ndarray:
    """Frames within `below_peak_db` of the loudest: the utterance without its silence or noise floor."""
    if intensity_db.size == 0:
        return np.zeros(0, bool)
    return intensity_db >= np.nanmax(intensity_db) - below_peak_db


def _tilt_db(x: np.ndarray, sample_rate: int) -> float:
    """Energy above 2 kHz relative to 100 Hz - 1 kHz: harsh, pressed or shouted voices have more highs."""
    spec = np.abs(np.fft.rfft(x * np.hanning(x.size))) ** 2
    freqs = np.fft.rfftfreq(x.size, 1.0 / sample_rate)
    low = spec[(freqs >= 100) & (freqs < 1000)].sum()
    high = spec[(freqs >= 2000) & (freqs < min(8000, sample_rate / 2))].sum()
    return float(10 * np.log10((high + 1e-12) / (low + 1e-12)))


def extract(audio: np.ndarray, sample_rate: int, pitch_floor: float = 60.0, pitch_ceiling: float = 600.0
            ) -> dict[str, float]:
    """The FEATURES of a mono float32 utterance (silence around it is ignored)."""
    import parselmouth

    x = np.asarray(audio, dtype=np.float64)
    nan = float("nan")
    out = dict.fromkeys(FEATURES, nan)
    if x.size < int(0.1 * sample_rate) or not np.any(x):
        return out
    snd = parselmouth.Sound(x, sampling_frequency=float(sample_rate))
    inten = snd.to_intensity(minimum_pitch=max(pitch_floor, 50.0), time_step=_TIME_STEP)
    i_db = inten.values[0]
    i_t = inten.xs()
    active = _active_span(i_db)
    if not active.any():
        return out
    t0, t1 = float(i_t[active][0]), float(i_t[active][-1])
    duration = max(t1 - t0, _TIME_STEP)
    pitch = snd.to_pitch_ac(time_step=_TIME_STEP, pitch_floor=pitch_floor, pitch_ceiling=pitch_ceiling)
    f0 = pitch.selected_array["frequency"]
    f_t = pitch.xs()
    in_span = (f_t >= t0) & (f_t <= t1)
    voiced = (f0 > 0) & in_span
    out["intensity_db"] = float(np.mean(i_db[active]))
    out["intensity_range_db"] = float(np.percentile(i_db[active], 90) - np.percentile(i_db[active], 10))
    out["log_duration"] = float(np.log(duration))
    out["voiced_fraction"] = float(voiced.sum() / max(in_span.sum(), 1))
    # voiced runs (roughly syllable nuclei) per second of speech
    v = voiced[in_span].astype(int)
    runs = int(np.sum(np.diff(np.concatenate([[0], v])) == 1))
    out["log_rate"] = float(np.log((runs + 0.5) / duration))
    i0, i1 = int(t0 * sample_rate), int(np.ceil(t1 * sample_rate))
    out["tilt_db"] = _tilt_db(x[i0:i1], sample_rate) if i1 - i0 > 256 else nan
    if voiced.sum() >= 3:
        st = 12.0 * np.log2(f0[voiced] / 100.0)
        tv = f_t[voiced]
        out["f0_median_st"] = float(np.median(st))
        out["f0_range_st"] = float(np.percentile(st, 90) - np.percentile(st, 10))
        out["f0_slope_st_s"] = float(np.polyfit(tv - tv.mean(), st, 1)[0]) if np.ptp(tv) > 0 else 0.0
        tail = st[tv >= tv[0] + 0.7 * np.ptp(tv)]
        out["f0_final_st"] = float(np.mean(tail) - np.median(st)) if tail.size else 0.0
        # harmonics-to-noise ratio from the autocorrelation peak r of voiced frames (Boersma 1993):
        # 10 log10(r / (1 - r)), as Praat's harmonicity, without a second (8x slower) analysis pass
        r = np.clip(pitch.selected_array["strength"][voiced], 1e-4, 1 - 1e-4)
        out["hnr_db"] = float(np.mean(10 * np.log10(r / (1 - r))))
    return out


def vector(features: dict[str, float]) -> np.ndarray:
    return np.array([features[k] for k in FEATURES], dtype=np.float64)
