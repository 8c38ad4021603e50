"""`protamer bench vad`: misses and false alarms of the VADs on synthesised sessions with noise.

A session is a sequence of synthesised utterances (several voices; positive, negative, neutral, fillers)
separated by 1-2.5 s pauses, over a background: digital near-silence, white noise at -50 and -35 dBFS,
pink noise at -45 dBFS, or a 220 Hz hum with clicks. Each VAD segments the session as the listener would
(`segment_array`). A miss is an utterance that no segment overlaps; a false alarm is a segment that
overlaps no utterance. Synthesised voices are not real recordings.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

VADS = {  # name -> config overrides of `vad`
    "rms": {"kind": "rms", "threshold_mode": "absolute"},
    "rms_noise_floor": {"kind": "rms", "threshold_mode": "noise_floor"},
    "webrtc": {"kind": "webrtc"},
    "silero": {"kind": "silero"},
}
BACKGROUNDS = ("quiet", "white_-50dBFS", "white_-35dBFS", "pink_-45dBFS", "hum_clicks")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", default=None, help="front-end YAML (default: configs/voice.yaml)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--speakers", default="en-us,en-gb+f2,en-us+m3",
                        help="comma list of espeak-ng voices")
    parser.add_argument("--utterances", type=int, default=8, help="utterances per speaker and background")
    parser.add_argument("--seed", type=int, default=0)


def background(kind: str, n: int, sample_rate: int, rng: np.random.Generator) -> np.ndarray:
    if kind == "quiet":
        return rng.normal(0, 10 ** (-70 / 20), n)
    if kind.startswith("white_"):
        return rng.normal(0, 10 ** (float(kind[6:-4]) / 20), n)
    if kind.startswith("pink_"):
        spec = np.fft.rfft(rng.normal(0, 1, n))
        f = np.fft.rfftfreq(n, 1 / sample_rate)
        spec[1:] /= np.sqrt(f[1:])
        spec[0] = 0
        x = np.fft.irfft(spec, n)
        return x / np.sqrt(np.mean(x ** 2)) * 10 ** (float(kind[5:-4]) / 20)
    if kind == "hum_clicks":
        t = np.arange(n) / sample_rate
        x = 10 ** (-30 / 20) * np.sqrt(2) * np.sin(2 * np.pi * 220 * t)
        for i in range(int(0.3 * sample_rate), n, int(0.7 * sample_rate)):
            x[i:i + 40] += 0.5 * rng.choice([-1, 1])
        return x + rng.normal(0, 10 ** (-70 / 20), n)
    raise ValueError(f"unknown background {kind!r}")


def session(speaker: str, count: int, sample_rate: int, rng) -> tuple[np.ndarray, list[tuple[float, float]]]:
    """Clean speech of one speaker with pauses, and the (start, end) of each utterance's speech."""
    from audio_frontend.labelled import speech_bounds
    from audio_frontend.testset import FILLERS, NEGATIVE, NEUTRAL, POSITIVE, utterance

    pool = [(t, "pos") for t in POSITIVE[1]] + [(t, "neg") for t in NEGATIVE[1]] + \
        [(t, "neu") for t in NEUTRAL[1]] + [(t, "fillers") for t in FILLERS[1]]
    pieces, truth, t = [np.zeros(int(1.5 * sample_rate))], [], 1.5
    for i in rng.choice(len(pool), size=count, replace=False):
        text, tone = pool[i]
        x = utterance(text, tone, speaker, rng, sample_rate, pad_s=(0.0, 0.0))
        s0, s1 = speech_bounds(x, sample_rate)
        truth.append((t + s0, t + s1))
        gap = rng.uniform(1.0, 2.5)
        pieces += [x, np.zeros(int(gap * sample_rate))]
        t += x.size / sample_rate + int(gap * sample_rate) / sample_rate
    return np.concatenate(pieces), truth


def count_errors(segments, truth) -> tuple[int, int]:
    """(misses, false alarms)."""
    def overlaps(a0, a1, b0, b1):
        return a0 < b1 and b0 < a1
    misses = sum(not any(overlaps(s.t_start, s.t_end, u0, u1) for s in segments) for u0, u1 in truth)
    false = sum(not any(overlaps(s.t_start, s.t_end, u0, u1) for u0, u1 in truth) for s in segments)
    return misses, false


def noise_covered(segments, truth, duration_s: float, margin_s: tuple[float, float] = (0.5, 0.75),
                  step_s: float = 0.01) -> tuple[float, float]:
    """(seconds covered, seconds in all) of the time away from speech (more than the pre-roll before an
    utterance and the hangover after it) that segments cover: what an always-on VAD sends to the scorer as if it were speech."""
    t = np.arange(0.0, duration_s, step_s)
    near = np.zeros(t.size, bool)
    for u0, u1 in truth:
        near |= (t >= u0 - margin_s[0]) & (t < u1 + margin_s[1])
    covered = np.zeros(t.size, bool)
    for s in segments:
        covered |= (t >= s.t_start) & (t < s.t_end)
    away = ~near
    return float((covered & away).sum() * step_s), float(away.sum() * step_s)


def run_vad_benchmark(args) -> dict:
    from audio_frontend.config import load_voice_config
    from audio_frontend.synth import require_tools
    from audio_frontend.vad import segment_array

    require_tools()
    cfg = load_voice_config(getattr(args, "config", None), list(getattr(args, "overrides", []) or []))
    sr, chunk = cfg.audio.sample_rate, cfg.audio.chunk_s
    speakers = [s.strip() for s in str(args.speakers).split(",") if s.strip()]
    rng = np.random.default_rng(args.seed)
    sessions = [session(spk, args.utterances, sr, rng) for spk in speakers]
    result = {"what": __doc__.split("\n\n")[1].replace("\n", " "), "speakers": speakers,
              "utterances": len(speakers) * args.utterances, "chunk_s": chunk, "results": {}}
    for bg in BACKGROUNDS:
        row = {}
        noisy = [(np.clip(x + background(bg, x.size, sr, np.random.default_rng([args.seed, i])), -1, 1)
                  .astype(np.float32), truth) for i, (x, truth) in enumerate(sessions)]
        for name, over in VADS.items():
            vcfg = dataclasses.replace(cfg.vad, **over)
            misses = false = n_segs = 0
            noise_s = away_s = 0.0
            t0 = time.perf_counter()
            for x, truth in noisy:
                segs = segment_array(x, vcfg, sr, chunk)
                m, f = count_errors(segs, truth)
                misses, false, n_segs = misses + m, false + f, n_segs + len(segs)
                cov_s, all_s = noise_covered(segs, truth, x.size / sr)
                noise_s, away_s = noise_s + cov_s, away_s + all_s
            audio_s = sum(x.size for x, _ in noisy) / sr
            # segments beyond one per utterance found: noise cut into max-length pieces, split utterances
            row[name] = {"misses": misses, "false_alarms": false, "segments": n_segs,
                         "noise_s_in_segments": round(noise_s, 2), "noise_s_total": round(away_s, 2),
                         "cpu_s_per_audio_s": (time.perf_counter() - t0) / audio_s}
        result["results"][bg] = row
    return result
