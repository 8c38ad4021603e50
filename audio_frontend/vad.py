"""Voice activity detection and segmentation of a chunk stream into utterances.

`Segmenter` is a streaming state machine fed one chunk at a time (`feed(t_start, chunk)`); it returns
the utterances that end with that chunk. The speech/no-speech decision per chunk is pluggable:

- `RmsDetector` (the paper's): chunk RMS in dBFS above a threshold, absolute or `margin` dB above a noise
  floor measured over the first chunks.
- `WebrtcDetector`: webrtcvad (Google's WebRTC GMM VAD) on the chunk's 30 ms frames; a chunk counts as
  speech when a given fraction of its frames are voiced.
- `SileroDetector`: silero-vad (a small neural VAD; its wheel ships the model, run with torch) on 32 ms
  frames; a chunk counts as speech when a given fraction of its frames have speech probability above a
  threshold. The network is stateful across frames, as in a stream.

Segmentation: an utterance starts after `onset_chunks` speech chunks in a row; `pre_roll_s` of audio from
before the onset is kept (first phonemes). It then either ends after `hangover_s` of non-speech
("endpoint") or is the paper's extended fixed window of `window_s` from the onset ("fixed"). Either way
its length is bounded: shorter than `min_segment_s` is dropped (a click), longer than `max_segment_s` is
cut and emitted.
"""

from __future__ import annotations

import collections
from dataclasses import dataclass, field

import numpy as np

from audio_frontend.sources import dbfs


@dataclass
class Segment:
    audio: np.ndarray      # mono float32, includes the pre-roll
    t_start: float         # wall-clock time of the first sample (pre-roll included)
    t_end: float           # wall-clock time just after the last sample
    t_onset: float         # wall-clock start of the first speech chunk
    sample_rate: int
    reason: str            # "quiet" (endpoint), "window" (fixed), "max_length", "flush"
    levels_dbfs: list[float] = field(default_factory=list)
    t_emit: float = 0.0    # wall-clock end of the chunk that closed the segment (when a live VAD emits it)

    @property
    def duration_s(self) -> float:
        return self.audio.size / self.sample_rate


class RmsDetector:
    def __init__(self, threshold_dbfs: float = -40.0, mode: str = "absolute", margin_db: float = 12.0,
                 noise_floor_chunks: int = 4):
        self.threshold_dbfs = threshold_dbfs
        self.mode = mode
        self.margin_db = margin_db
        self.noise_floor_chunks = noise_floor_chunks
        self._floor_levels: list[float] = []
        self.noise_floor_dbfs: float | None = None

    @property
    def ready(self) -> bool:
        return self.mode == "absolute" or self.noise_floor_dbfs is not None

    def set_noise_floor(self, level_dbfs: float) -> None:
        # digital silence has no floor: keep the threshold meaningful
        self.noise_floor_dbfs = max(level_dbfs, -90.0)
        self.threshold_dbfs = min(self.noise_floor_dbfs + self.margin_db, -1.0)

    def is_speech(self, chunk: np.ndarray, sample_rate: int) -> bool:
        level = dbfs(chunk)
        if not self.ready:
            self._floor_levels.append(level)
            if len(self._floor_levels) >= self.noise_floor_chunks:
                finite = [v for v in self._floor_levels if np.isfinite(v)]
                self.set_noise_floor(float(np.median(finite)) if finite else -90.0)
            return False
        return level >= self.threshold_dbfs


class WebrtcDetector:
    FRAME_S = 0.03

    def __init__(self, aggressiveness: int = 2, speech_fraction: float = 0.5):
        try:
            import webrtcvad
        except ImportError as e:
            raise ImportError(f"vad.kind=webrtc needs the webrtcvad-wheels package ({e}); "
                              f"pip install 'mjx-protamer[audio]' or use vad.kind=rms") from None
        self._vad = webrtcvad.Vad(aggressiveness)
        self.speech_fraction = speech_fraction
        self.ready = True

    def is_speech(self, chunk: np.ndarray, sample_rate: int) -> bool:
        if sample_rate not in (8000, 16000, 32000, 48000):
            raise ValueError(f"webrtcvad supports 8/16/32/48 kHz, not {sample_rate} Hz")
        n = int(sample_rate * self.FRAME_S)
        pcm = (np.clip(chunk, -1, 1) * 32767).astype("<i2")
        frames = [pcm[i:i + n] for i in range(0, pcm.size - n + 1, n)]
        if not frames:
            return False
        voiced = sum(self._vad.is_speech(f.tobytes(), sample_rate) for f in frames)
        return voiced / len(frames) >= self.speech_fraction


class SileroDetector:
    def __init__(self, threshold: float = 0.5, speech_fraction: float = 0.3):
        try:
            import torch
            from silero_vad import load_silero_vad
        except ImportError as e:
            raise ImportError(f"vad.kind=silero needs torch and silero-vad ({e}); pip install 'mjx-protamer[audio]' "
                              f"or use vad.kind=rms") from None
        self._torch = torch
        self._model = load_silero_vad()     # the TorchScript model inside the wheel: no download
        self.threshold = threshold
        self.speech_fraction = speech_fraction
        self._carry = np.zeros(0, np.float32)
        self._rate: int | None = None
        self.ready = True

    def is_speech(self, chunk: np.ndarray, sample_rate: int) -> bool:
        if sample_rate not in (8000, 16000):
            raise ValueError(f"silero-vad supports 8 and 16 kHz, not {sample_rate} Hz")
        if self._rate != sample_rate:
            self._model.reset_states()
            self._rate = sample_rate
        n = 512 if sample_rate == 16000 else 256
        x = np.concatenate([self._carry, np.asarray(chunk, np.float32)])
        m = x.size // n
        self._carry = x[m * n:]
        if m == 0:
            return False
        with self._torch.inference_mode():
            probs = [float(self._model(self._torch.from_numpy(x[i * n:(i + 1) * n].copy()), sample_rate))
                     for i in range(m)]
        return sum(p >= self.threshold for p in probs) / m >= self.speech_fraction


def make_detector(vad_config):
    if vad_config.kind == "silero":
        return SileroDetector(vad_config.silero_threshold, vad_config.silero_speech_fraction)
    if vad_config.kind == "webrtc":
        return WebrtcDetector(vad_config.webrtc_aggressiveness, vad_config.webrtc_speech_fraction)
    return RmsDetector(vad_config.threshold_dbfs, vad_config.threshold_mode, vad_config.noise_floor_margin_db,
                       vad_config.noise_floor_chunks)


class Segmenter:
    def __init__(self, vad_config, sample_rate: int = 16000, chunk_s: float = 0.25, detector=None):
        self.cfg = vad_config
        self.sample_rate = sample_rate
        self.chunk_s = chunk_s
        self.detector = detector if detector is not None else make_detector(vad_config)
        n_pre = int(np.ceil(vad_config.pre_roll_s / chunk_s)) if vad_config.pre_roll_s > 0 else 0
        self._history: collections.deque = collections.deque(maxlen=n_pre + vad_config.onset_chunks)
        self._n_pre = n_pre
        self._loud_run = 0
        self._active = False
        self._chunks: list[tuple] = []  # (t_start, chunk, speech, level_dbfs)
        self._t_onset = 0.0
        self._quiet_s = 0.0
        self.dropped_short = 0

    @property
    def active(self) -> bool:
        return self._active

    def _emit(self, reason: str, t_emit: float) -> Segment | None:
        chunks, self._chunks = self._chunks, []
        self._active = False
        self._loud_run = 0
        self._quiet_s = 0.0
        if reason == "quiet":
            # keep at most one trailing quiet chunk (the decay of the last phoneme)
            while len(chunks) > 1 and not chunks[-1][2] and not chunks[-2][2]:
                chunks.pop()
        audio = np.concatenate([e[1] for e in chunks]).astype(np.float32)
        pre_n = int(round(self.cfg.pre_roll_s * self.sample_rate))
        # trim the pre-roll to exactly pre_roll_s before the onset
        onset_idx = next(i for i, e in enumerate(chunks) if e[0] >= self._t_onset - 1e-9)
        before = sum(e[1].size for e in chunks[:onset_idx])
        cut = max(0, before - pre_n)
        audio = audio[cut:]
        t_start = chunks[0][0] + cut / self.sample_rate
        max_n = int(round(self.cfg.max_segment_s * self.sample_rate))
        audio = audio[:max_n]
        seg = Segment(audio=audio, t_start=t_start, t_end=t_start + audio.size / self.sample_rate,
                      t_onset=self._t_onset, sample_rate=self.sample_rate, reason=reason,
                      levels_dbfs=[e[3] for e in chunks], t_emit=t_emit)
        if seg.duration_s < self.cfg.min_segment_s - 1e-9:
            self.dropped_short += 1
            return None
        return seg

    def feed(self, t_start: float, chunk: np.ndarray) -> list[Segment]:
        chunk = np.asarray(chunk, dtype=np.float32)
        speech = bool(self.detector.is_speech(chunk, self.sample_rate))
        level = dbfs(chunk)
        entry = (t_start, chunk, speech, round(float(level), 1) if np.isfinite(level) else -120.0)
        out: list[Segment] = []
        cfg = self.cfg
        if not self._active:
            self._history.append(entry)
            self._loud_run = self._loud_run + 1 if speech else 0
            if self._loud_run >= cfg.onset_chunks:
                self._active = True
                hist = list(self._history)
                self._t_onset = hist[-cfg.onset_chunks][0]
                self._chunks = hist[-(cfg.onset_chunks + self._n_pre):]
                self._history.clear()
                self._quiet_s = 0.0
        else:
            self._chunks.append(entry)
            self._quiet_s = 0.0 if speech else self._quiet_s + chunk.size / self.sample_rate
        if self._active:
            t_now = t_start + chunk.size / self.sample_rate
            length_from_onset = t_now - self._t_onset
            reason = None
            if cfg.segment_mode == "fixed":
                if length_from_onset >= cfg.window_s - 1e-9:
                    reason = "window"
            elif self._quiet_s >= cfg.hangover_s - 1e-9:
                reason = "quiet"
            if reason is None and length_from_onset + cfg.pre_roll_s >= cfg.max_segment_s - 1e-9:
                reason = "max_length"
            if reason is not None:
                seg = self._emit(reason, t_now)
                if seg is not None:
                    out.append(seg)
        return out

    def flush(self) -> list[Segment]:
        """End of stream: emit the utterance in progress, if any."""
        if not self._active or not self._chunks:
            return []
        last_t, last_chunk = self._chunks[-1][0], self._chunks[-1][1]
        seg = self._emit("flush", last_t + last_chunk.size / self.sample_rate)
        return [seg] if seg is not None else []


def segment_array(audio: np.ndarray, vad_config, sample_rate: int = 16000, chunk_s: float = 0.25,
                  t0: float = 0.0, detector=None) -> list[Segment]:
    """All utterances of an array (offline helper for tests, calibration and validation)."""
    seg = Segmenter(vad_config, sample_rate, chunk_s, detector)
    n = max(1, int(round(sample_rate * chunk_s)))
    out: list[Segment] = []
    for i in range(0, audio.size, n):
        c = audio[i:i + n]
        if c.size < n:
            c = np.pad(c, (0, n - c.size))
        out.extend(seg.feed(t0 + i / sample_rate, c))
    out.extend(seg.flush())
    return out
