"""Synthesised test speech with Debian's espeak-ng and sox (tests, benchmark, demos).

Styles set pitch, speed and amplitude the way a person marks feedback with their voice:
positive (high, lively), angry (low, fast, loud, slightly overdriven), neutral (flat), filler (soft).
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

STYLES = {
    #            espeak pitch 0..99, speed wpm, amplitude 0..200, sox extra effects
    "positive": dict(pitch=80, speed=150, amplitude=120, effects=[]),
    "angry": dict(pitch=25, speed=170, amplitude=200, effects=["overdrive", "8"]),
    "neutral": dict(pitch=45, speed=120, amplitude=100, effects=[]),
    "filler": dict(pitch=40, speed=110, amplitude=70, effects=[]),
}


def missing_tools() -> list[str]:
    return [t for t in ("espeak-ng", "sox") if shutil.which(t) is None]


def require_tools() -> None:
    missing = missing_tools()
    if missing:
        raise RuntimeError(f"speech synthesis needs {', '.join(missing)}: sudo apt-get install -y espeak-ng sox")


def synthesize(text: str, style: str = "neutral", sample_rate: int = 16000, voice: str = "en-us",
               gain_db: float = 0.0, pitch: int | None = None, speed: int | None = None,
               amplitude: int | None = None) -> np.ndarray:
    """Mono float32 speech at `sample_rate` (trimmed of espeak's leading/trailing silence by nothing)."""
    import soundfile as sf

    require_tools()
    s = dict(STYLES[style])
    pitch = s["pitch"] if pitch is None else pitch
    speed = s["speed"] if speed is None else speed
    amplitude = s["amplitude"] if amplitude is None else amplitude
    with tempfile.TemporaryDirectory() as d:
        raw, out = Path(d) / "raw.wav", Path(d) / "out.wav"
        subprocess.run(["espeak-ng", "-v", voice, "-p", str(pitch), "-s", str(speed), "-a", str(amplitude),
                        "-w", str(raw), text], check=True, capture_output=True)
        cmd = ["sox", str(raw), "-r", str(sample_rate), "-c", "1", "-b", "16", str(out)] + list(s["effects"])
        if gain_db:
            cmd += ["gain", str(gain_db)]
        subprocess.run(cmd, check=True, capture_output=True)
        x, sr = sf.read(str(out), dtype="float32")
    assert sr == sample_rate
    return x.astype(np.float32)


def with_silence(x: np.ndarray, before_s: float, after_s: float, sample_rate: int = 16000,
                 noise_dbfs: float | None = None, seed: int = 0) -> np.ndarray:
    """Pad with silence (or low noise at `noise_dbfs`)."""
    y = np.concatenate([np.zeros(int(before_s * sample_rate), np.float32), x,
                        np.zeros(int(after_s * sample_rate), np.float32)])
    if noise_dbfs is not None:
        rng = np.random.default_rng(seed)
        y = y + rng.normal(0, 10 ** (noise_dbfs / 20), y.size).astype(np.float32)
    return y.astype(np.float32)
