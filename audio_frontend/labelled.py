"""Labelled recordings (calibration, validation): pos/ and neg/ subfolders or pos_*/neg_* file names."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from audio_frontend.errors import AudioInputError
from audio_frontend.sources import load_wav
from audio_frontend.vad import segment_array

AUDIO_EXT = {".wav", ".flac", ".ogg"}
POS_NAMES = ("pos", "positive")
NEG_NAMES = ("neg", "negative")


def label_of(path: Path, root: Path) -> str | None:
    parts = [p.lower() for p in path.relative_to(root).parts]
    for part in parts[:-1]:
        if part in POS_NAMES:
            return "pos"
        if part in NEG_NAMES:
            return "neg"
    stem = parts[-1]
    for name in sorted(POS_NAMES, key=len, reverse=True):
        if stem.startswith(name) and not stem[len(name):len(name) + 1].isalpha():
            return "pos"
    for name in sorted(NEG_NAMES, key=len, reverse=True):
        if stem.startswith(name) and not stem[len(name):len(name) + 1].isalpha():
            return "neg"
    return None


def find_labelled(root: str | Path) -> tuple[list[tuple[Path, str]], list[Path]]:
    """(labelled files sorted by name, audio files whose label could not be told)."""
    root = Path(root)
    if not root.is_dir():
        raise AudioInputError(f"{root}: not a folder; expected pos/ and neg/ subfolders or pos_*/neg_* files")
    found, unknown = [], []
    for p in sorted(root.rglob("*")):
        if p.is_file() and p.suffix.lower() in AUDIO_EXT:
            lab = label_of(p, root)
            (found.append((p, lab)) if lab else unknown.append(p))
    return found, unknown


def utterance_of(audio: np.ndarray, config) -> np.ndarray:
    """The span from the first to the last VAD segment (whole recording if the VAD finds none)."""
    a = config.audio
    segs = segment_array(audio, config.vad, a.sample_rate, a.chunk_s)
    if not segs:
        return audio
    i0 = int(round(segs[0].t_start * a.sample_rate))
    i1 = int(round(segs[-1].t_end * a.sample_rate))
    return audio[max(0, i0):min(audio.size, i1)]


@dataclass
class Scored:
    path: str
    label: str
    value: float | None = None       # prosody: valence; whisper: rule/classifier value
    latency_s: float | None = None
    details: dict = field(default_factory=dict)
    error: str | None = None


def score_files(files: list[tuple[Path, str]], config, score_fn) -> list[Scored]:
    """`score_fn(audio) -> (value, details)`; bad files give a row with `error`, not an exception."""
    a = config.audio
    out = []
    for path, lab in files:
        try:
            x = load_wav(path, a.sample_rate, a.on_wrong_rate, a.on_multichannel, a.on_clipped, a.clip_fraction,
                         allow_silent=False)
        except AudioInputError as e:
            out.append(Scored(str(path), lab, error=str(e)))
            continue
        utt = utterance_of(x, config)
        t0 = time.perf_counter()
        value, details = score_fn(utt)
        out.append(Scored(str(path), lab, float(value), time.perf_counter() - t0, details))
    return out
