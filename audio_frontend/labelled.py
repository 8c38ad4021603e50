"""Labelled recordings (calibration, validation).

Labels come from folders (`pos/`, `neg/`, `neu/`, `fillers/`) or file names (`pos_*`, `neg_*`, ...), or,
when the folder holds a `labels.jsonl` (as `protamer synth-voice` writes), from it: by `tone` (what the
prosody scorer should hear) or by `words` (what the Whisper scorer should understand).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from audio_frontend.errors import AudioInputError
from audio_frontend.sources import load_wav
from audio_frontend.vad import segment_array

AUDIO_EXT = {".wav", ".flac", ".ogg"}
LABEL_NAMES = {"pos": ("pos", "positive"), "neg": ("neg", "negative"), "neu": ("neu", "neutral"),
               "filler": ("fillers", "filler")}
LABELS = tuple(LABEL_NAMES)
LABELS_FILE = "labels.jsonl"
_TONE_TO_LABEL = {"pos": "pos", "neg": "neg", "neu": "neu", "fillers": "filler", "filler": "filler"}


def label_of(path: Path, root: Path) -> str | None:
    parts = [p.lower() for p in path.relative_to(root).parts]
    for part in parts[:-1]:
        for lab, names in LABEL_NAMES.items():
            if part in names:
                return lab
    stem = parts[-1]
    for lab, name in sorted(((lab, n) for lab, ns in LABEL_NAMES.items() for n in ns), key=lambda t: -len(t[1])):
        if stem.startswith(name) and not stem[len(name):len(name) + 1].isalpha():
            return lab
    return None


def _from_labels_file(root: Path, label_by: str) -> dict[Path, str]:
    out = {}
    lines = (root / LABELS_FILE).read_text(encoding="utf-8").splitlines()
    for i, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
            out[(root / row["file"]).resolve()] = _TONE_TO_LABEL[row[label_by]]
        except (json.JSONDecodeError, KeyError, TypeError) as e:
            raise AudioInputError(f"{root / LABELS_FILE} line {i}: unusable ({type(e).__name__}: {e}); each line "
                                  f"needs 'file' and '{label_by}' (pos, neg, neu or fillers)") from None
    return out


def find_labelled(root: str | Path, label_by: str = "tone") -> tuple[list[tuple[Path, str]], list[Path]]:
    """(labelled files sorted by name, audio files whose label could not be told). `label_by` (tone or
    words) is used when the folder has a labels.jsonl; otherwise folder and file names decide."""
    root = Path(root)
    if not root.is_dir():
        raise AudioInputError(f"{root}: not a folder; expected pos/, neg/ (and neu/, fillers/) subfolders or "
                              f"pos_*/neg_* files")
    table = _from_labels_file(root, label_by) if (root / LABELS_FILE).is_file() else None
    found, unknown = [], []
    for p in sorted(root.rglob("*")):
        if p.is_file() and p.suffix.lower() in AUDIO_EXT:
            lab = table.get(p.resolve()) if table is not None else label_of(p, root)
            (found.append((p, lab)) if lab else unknown.append(p))
    return found, unknown


def speech_bounds(audio: np.ndarray, sample_rate: int, below_peak_db: float = 30.0, frame_s: float = 0.01
                  ) -> tuple[float, float]:
    """(start, end) in seconds of the frames within `below_peak_db` of the loudest 10 ms frame."""
    n = max(1, int(frame_s * sample_rate))
    m = audio.size // n
    if m == 0:
        return 0.0, audio.size / sample_rate
    e = 10 * np.log10(np.mean(np.square(audio[: m * n].reshape(m, n), dtype=np.float64), axis=1) + 1e-12)
    idx = np.flatnonzero(e >= e.max() - below_peak_db)
    return idx[0] * n / sample_rate, (idx[-1] + 1) * n / sample_rate


@dataclass
class Utterance:
    audio: np.ndarray        # the VAD span (whole recording if the VAD finds nothing)
    speech_s: float          # duration of the speech itself (speech_bounds)
    vad_wait_s: float        # end of speech -> the moment a live VAD would have closed the segment


def utterance_of(audio: np.ndarray, config) -> Utterance:
    """The span from the first to the last VAD segment, and when a live listener would have emitted it."""
    a = config.audio
    t_speech0, t_speech1 = speech_bounds(audio, a.sample_rate)
    segs = segment_array(audio, config.vad, a.sample_rate, a.chunk_s)
    if not segs:
        return Utterance(audio, t_speech1 - t_speech0, audio.size / a.sample_rate - t_speech1)
    i0 = int(round(segs[0].t_start * a.sample_rate))
    i1 = int(round(segs[-1].t_end * a.sample_rate))
    return Utterance(audio[max(0, i0):min(audio.size, i1)], t_speech1 - t_speech0, segs[-1].t_emit - t_speech1)


@dataclass
class Scored:
    path: str
    label: str
    value: float | None = None       # prosody: valence; whisper: rule/classifier value
    latency_s: float | None = None   # scoring time
    details: dict = field(default_factory=dict)
    error: str | None = None
    speech_s: float | None = None
    vad_wait_s: float | None = None

    @property
    def event_latency_s(self) -> float | None:
        """End of speech -> event: the VAD's endpoint wait plus scoring (what a live listener adds)."""
        if self.latency_s is None or self.vad_wait_s is None:
            return None
        return self.vad_wait_s + self.latency_s


def load_labelled(files: list[tuple[Path, str]], config) -> list[tuple[Path, str, Utterance | str]]:
    """(path, label, utterance or the reason the file is unusable)."""
    a = config.audio
    out = []
    for path, lab in files:
        try:
            x = load_wav(path, a.sample_rate, a.on_wrong_rate, a.on_multichannel, a.on_clipped, a.clip_fraction,
                         allow_silent=False)
        except AudioInputError as e:
            out.append((path, lab, str(e)))
            continue
        out.append((path, lab, utterance_of(x, config)))
    return out


def score_loaded(loaded, score_fn) -> list[Scored]:
    """`score_fn(audio) -> (value, details)`; unusable files give a row with `error`, not an exception."""
    out = []
    for path, lab, utt in loaded:
        if isinstance(utt, str):
            out.append(Scored(str(path), lab, error=utt))
            continue
        t0 = time.perf_counter()
        value, details = score_fn(utt.audio)
        out.append(Scored(str(path), lab, float(value), time.perf_counter() - t0, details, speech_s=utt.speech_s,
                          vad_wait_s=utt.vad_wait_s))
    return out


def score_files(files: list[tuple[Path, str]], config, score_fn) -> list[Scored]:
    return score_loaded(load_labelled(files, config), score_fn)
