"""Audio sources: one interface, three implementations (microphone, WAV file, in-memory array).

Every source yields `(t_start, chunk)` pairs: `chunk` is mono float32 in [-1, 1] at the configured rate,
`t_start` the wall-clock time (`time.time()`) of the chunk's first sample. Sources are picklable before
they are opened, so a listener process can be started with one.
"""

from __future__ import annotations

import abc

import queue as queue_lib
import threading
import time
import warnings
from dataclasses import dataclass
from math import gcd
from pathlib import Path
from typing import Iterator

import numpy as np

from audio_frontend.errors import AudioDeviceError, AudioInputError


@dataclass(frozen=True)
class AudioCheck:
    """What `inspect_audio` found: levels and flags the caller may act on."""

    duration_s: float
    peak: float
    rms_dbfs: float
    clipped_fraction: float
    silent: bool
    clipped: bool


def dbfs(x: np.ndarray) -> float:
    """RMS level in dB relative to full scale (a full-scale sine is -3 dBFS); -inf for digital silence."""
    if x.size == 0:
        return float("-inf")
    rms = float(np.sqrt(np.mean(np.square(x, dtype=np.float64))))
    return 20.0 * np.log10(rms) if rms > 0 else float("-inf")


def inspect_audio(x: np.ndarray, sample_rate: int, silent_dbfs: float = -60.0,
                  clip_fraction: float = 0.01) -> AudioCheck:
    x = np.asarray(x, dtype=np.float32)
    peak = float(np.max(np.abs(x))) if x.size else 0.0
    frac = float(np.mean(np.abs(x) >= 0.999)) if x.size else 0.0
    level = dbfs(x)
    return AudioCheck(duration_s=x.size / sample_rate, peak=peak, rms_dbfs=level, clipped_fraction=frac,
                      silent=level < silent_dbfs, clipped=frac > clip_fraction)


def resample(x: np.ndarray, sr_in: int, sr_out: int) -> np.ndarray:
    """Polyphase resampling (scipy when present, else linear interpolation)."""
    if sr_in == sr_out:
        return x.astype(np.float32, copy=False)
    try:
        from scipy.signal import resample_poly
    except ImportError:  # pragma: no cover - scipy is a dependency of the audio stack in practice
        n_out = int(round(x.size * sr_out / sr_in))
        t_out = np.arange(n_out) * (sr_in / sr_out)
        return np.interp(t_out, np.arange(x.size), x).astype(np.float32)
    g = gcd(sr_in, sr_out)
    return resample_poly(x, sr_out // g, sr_in // g).astype(np.float32)


def wav_truncation(path: str | Path) -> tuple[float, float] | None:
    """(seconds the RIFF/WAVE header declares, seconds the file holds) when the data chunk is cut short;
    None for a complete file, a streamed header (size 0 or 0xFFFFFFFF), or a file that is not RIFF/WAVE."""
    import struct

    with open(path, "rb") as fh:
        head = fh.read(12)
        if len(head) < 12 or head[:4] != b"RIFF" or head[8:12] != b"WAVE":
            return None
        size_total = Path(path).stat().st_size
        block_align, rate = 0, 0
        while True:
            hdr = fh.read(8)
            if len(hdr) < 8:
                return None
            cid, size = hdr[:4], struct.unpack("<I", hdr[4:])[0]
            if cid == b"fmt ":
                fmt = fh.read(min(size, 16))
                if len(fmt) >= 14:
                    _tag, _ch, rate, _bps, block_align = struct.unpack("<HHIIH", fmt[:14])
                fh.seek(size - len(fmt) + (size & 1), 1)
                continue
            if cid == b"data":
                present = size_total - fh.tell()
                if size in (0, 0xFFFFFFFF) or size <= present or not (block_align and rate):
                    return None
                return size / block_align / rate, present / block_align / rate
            fh.seek(size + (size & 1), 1)


def load_wav(path: str | Path, sample_rate: int = 16000, on_wrong_rate: str = "convert",
             on_multichannel: str = "convert", on_clipped: str = "warn", clip_fraction: float = 0.01,
             allow_silent: bool = True) -> np.ndarray:
    """Read a sound file as mono float32 at `sample_rate`, or raise AudioInputError saying why.

    Wrong rate / several channels are converted (resampled / averaged) or refused per policy; an empty,
    unreadable or corrupt file is refused; a clipped one warns or is refused; a silent one is refused
    unless `allow_silent`.
    """
    import soundfile as sf

    path = Path(path)
    if not path.is_file():
        raise AudioInputError(f"{path}: no such file")
    if path.stat().st_size == 0:
        raise AudioInputError(f"{path}: the file is empty (0 bytes)")
    cut = wav_truncation(path)
    if cut is not None:
        raise AudioInputError(f"{path}: truncated: its header declares {cut[0]:.2f} s of audio but the file holds "
                              f"{cut[1]:.2f} s (an interrupted recording or copy); copy it again, or keep what is "
                              f"there with: sox {path.name} fixed.wav")
    try:
        data, sr = sf.read(str(path), dtype="float32", always_2d=True)
    except (sf.LibsndfileError, RuntimeError, ValueError) as e:
        raise AudioInputError(f"{path}: not a readable sound file (corrupt or unsupported format): {e}") from None
    if data.shape[0] == 0:
        raise AudioInputError(f"{path}: the file holds no samples")
    if data.shape[1] > 1:
        if on_multichannel == "refuse":
            raise AudioInputError(f"{path}: {data.shape[1]} channels; mono is required "
                                  f"(set audio.on_multichannel=convert to average the channels)")
        data = data.mean(axis=1, keepdims=True)
    x = data[:, 0]
    if not np.all(np.isfinite(x)):
        raise AudioInputError(f"{path}: the file holds NaN or infinite samples")
    if sr != sample_rate:
        if on_wrong_rate == "refuse":
            raise AudioInputError(f"{path}: sample rate {sr} Hz; {sample_rate} Hz is required "
                                  f"(set audio.on_wrong_rate=convert to resample)")
        x = resample(x, sr, sample_rate)
    x = np.clip(x, -1.0, 1.0).astype(np.float32)
    check = inspect_audio(x, sample_rate, clip_fraction=clip_fraction)
    if check.clipped:
        msg = (f"{path}: {100 * check.clipped_fraction:.1f}% of samples are at full scale (clipped); "
               f"record with lower input gain")
        if on_clipped == "refuse":
            raise AudioInputError(msg)
        warnings.warn(msg, stacklevel=2)
    if check.silent and not allow_silent:
        raise AudioInputError(f"{path}: silent (RMS {check.rms_dbfs:.1f} dBFS); nothing to score")
    return x


class AudioSource(abc.ABC):
    """Yields `(t_start_wallclock, chunk)`; `close()` releases the device. Use as a context manager."""

    sample_rate: int = 16000
    chunk_s: float = 0.25

    @property
    def chunk_samples(self) -> int:
        return max(1, int(round(self.sample_rate * self.chunk_s)))

    @abc.abstractmethod
    def chunks(self) -> Iterator[tuple[float, np.ndarray]]:
        """Chunks of `chunk_samples` mono float32 samples with their wall-clock start times."""

    def close(self) -> None:
        pass

    def __enter__(self) -> "AudioSource":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class ArraySource(AudioSource):
    """An in-memory mono float32 array. `realtime=True` paces chunks at the speed of sound playback,
    so wall-clock times and latencies mean what they would with a microphone; otherwise chunks come as
    fast as they are consumed, stamped from `t0` (default: as if the recording ended just now)."""

    def __init__(self, audio: np.ndarray, sample_rate: int = 16000, chunk_s: float = 0.25,
                 realtime: bool = False, t0: float | None = None):
        a = np.asarray(audio, dtype=np.float32)
        if a.ndim != 1:
            raise AudioInputError(f"ArraySource needs a 1-D mono array, got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            raise AudioInputError("ArraySource: the array holds NaN or infinite samples")
        self.audio = a
        self.sample_rate = sample_rate
        self.chunk_s = chunk_s
        self.realtime = realtime
        self.t0 = t0

    def chunks(self) -> Iterator[tuple[float, np.ndarray]]:
        n = self.chunk_samples
        t0 = self.t0
        if t0 is None:
            # real time: the audio starts now; faster than real time: stamped as if it had just been
            # recorded (ending now), so no event carries a time in the future
            t0 = time.time() if self.realtime else time.time() - self.audio.size / self.sample_rate
        for i in range(0, self.audio.size, n):
            t_chunk = t0 + i / self.sample_rate
            if self.realtime:
                # a microphone delivers a chunk once its last sample has been captured
                delay = t_chunk + n / self.sample_rate - time.time()
                if delay > 0:
                    time.sleep(delay)
            chunk = self.audio[i:i + n]
            if chunk.size < n:
                chunk = np.pad(chunk, (0, n - chunk.size))
            yield t_chunk, chunk


class WavSource(ArraySource):
    """A sound file, converted (or refused) by `load_wav`; opened lazily so it pickles as a path."""

    def __init__(self, path: str | Path, sample_rate: int = 16000, chunk_s: float = 0.25,
                 realtime: bool = False, **load_kwargs):
        self.path = Path(path)
        self.sample_rate = sample_rate
        self.chunk_s = chunk_s
        self.realtime = realtime
        self.t0 = None
        self.load_kwargs = load_kwargs
        self._audio: np.ndarray | None = None

    @property
    def audio(self) -> np.ndarray:  # type: ignore[override]
        if self._audio is None:
            self._audio = load_wav(self.path, self.sample_rate, **self.load_kwargs)
        return self._audio

    @audio.setter
    def audio(self, value: np.ndarray) -> None:
        self._audio = value


PORTAUDIO_FIX = ("install the PortAudio library: 'sudo apt-get install libportaudio2' (Debian/Ubuntu), "
                 "'brew install portaudio' (macOS); or feed a WAV file instead (--wav FILE)")


def import_sounddevice():
    """sounddevice, or AudioDeviceError naming the fix when PortAudio is missing."""
    try:
        import sounddevice as sd
    except OSError as e:  # sounddevice raises OSError('PortAudio library not found')
        raise AudioDeviceError(f"cannot use the microphone: {e}; {PORTAUDIO_FIX}") from None
    except ImportError as e:
        raise AudioDeviceError(f"cannot use the microphone: the 'sounddevice' package is missing ({e}); "
                               f"install the audio extra: pip install 'mjx-protamer[audio]'") from None
    return sd


def check_input_device(device: str | int | None = None) -> dict:
    """The input device's info, or AudioDeviceError when there is none (e.g. a headless server)."""
    sd = import_sounddevice()
    try:
        info = sd.query_devices(device if device not in ("", None) else None, kind="input")
    except Exception as e:  # sounddevice raises ValueError / PortAudioError for no device
        try:
            n_inputs = sum(1 for d in sd.query_devices() if d.get("max_input_channels", 0) > 0)
        except Exception:
            n_inputs = 0
        raise AudioDeviceError(
            f"no usable audio input device ({e}); found {n_inputs} input device(s). Plug in / enable a "
            f"microphone (check 'python -m sounddevice' lists one), choose one with audio.device=NAME_OR_INDEX, "
            f"or feed a WAV file instead (--wav FILE)") from None
    if int(info.get("max_input_channels", 0)) < 1:
        raise AudioDeviceError(f"device {info.get('name')!r} has no input channels; choose another with "
                               f"audio.device=NAME_OR_INDEX (see 'python -m sounddevice')")
    return dict(info)


class MicSource(AudioSource):
    """The microphone through sounddevice at `sample_rate` mono. The PortAudio callback only enqueues a
    copy of each block with its capture time; all processing happens in the consumer."""

    def __init__(self, sample_rate: int = 16000, chunk_s: float = 0.25, device: str | int | None = None,
                 max_queued_chunks: int = 400):
        self.sample_rate = sample_rate
        self.chunk_s = chunk_s
        self.device = device if device not in ("", None) else None
        self.max_queued_chunks = max_queued_chunks
        self._stream = None
        self._q: queue_lib.Queue | None = None
        self._stop = threading.Event()
        self.dropped = 0

    def __getstate__(self):
        state = dict(self.__dict__)
        state.update(_stream=None, _q=None, _stop=None)
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._stop = threading.Event()

    def open(self) -> None:
        sd = import_sounddevice()
        dev = self.device
        if isinstance(dev, str) and dev.isdigit():
            dev = int(dev)
        check_input_device(dev)
        self._q = queue_lib.Queue(self.max_queued_chunks)
        q = self._q

        def callback(indata, frames, time_info, status):  # runs on PortAudio's thread: enqueue only
            t_end = time.time()
            try:
                q.put_nowait((t_end - frames / self.sample_rate, indata[:, 0].copy()))
            except queue_lib.Full:
                self.dropped += 1

        try:
            self._stream = sd.InputStream(samplerate=self.sample_rate, channels=1, dtype="float32",
                                          blocksize=self.chunk_samples, device=dev, callback=callback)
            self._stream.start()
        except Exception as e:
            raise AudioDeviceError(f"could not open the microphone at {self.sample_rate} Hz mono: {e}; "
                                   f"choose another device with audio.device=NAME_OR_INDEX") from None

    def chunks(self) -> Iterator[tuple[float, np.ndarray]]:
        if self._stream is None:
            self.open()
        assert self._q is not None
        while not self._stop.is_set():
            try:
                yield self._q.get(timeout=0.5)
            except queue_lib.Empty:
                continue

    def stop(self) -> None:
        self._stop.set()

    def close(self) -> None:
        self._stop.set()
        if self._stream is not None:
            try:
                self._stream.stop()
                self._stream.close()
            finally:
                self._stream = None


def make_source(config, wav: str | None = None, realtime: bool = False) -> AudioSource:
    """The microphone, or the WAV file `wav`, per the front-end config's audio section."""
    a = config.audio
    if wav:
        return WavSource(wav, a.sample_rate, a.chunk_s, realtime=realtime, on_wrong_rate=a.on_wrong_rate,
                         on_multichannel=a.on_multichannel, on_clipped=a.on_clipped,
                         clip_fraction=a.clip_fraction)
    return MicSource(a.sample_rate, a.chunk_s, device=a.device)
