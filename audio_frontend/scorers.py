"""Scorers: one audio segment in, one reward in [-1, 1] and JSON-able details out.

- `ProsodyScorer` (DTP): speech-emotion class probabilities (labels from `config.id2label`),
  valence = P(positive_label) - P(negative_label), reward = tanh(valence / tau).
- `WhisperScorer` (DTW): Whisper transcript -> rule layer (keywords, fillers) -> sentiment classifier.
"""

from __future__ import annotations

import math
import time

import numpy as np

from audio_frontend.rules import RuleLayer


def prosody_reward(valence: float, tau: float) -> float:
    return float(math.tanh(valence / tau))


class ProsodyScorer:
    source = "prosody"

    def __init__(self, voice_config, tau: float | None = None, pipe=None, need_tau: bool = True):
        from audio_frontend.calibration import resolve_tau

        self.cfg = voice_config.prosody
        self.sample_rate = voice_config.audio.sample_rate
        if tau is not None:
            self.tau, self.tau_source = float(tau), "argument"
        elif need_tau:
            self.tau, self.tau_source = resolve_tau(self.cfg)   # fails before loading the model
        else:
            self.tau, self.tau_source = 1.0, "uncalibrated (tau=1)"
        if pipe is None:
            from audio_frontend.models import load_audio_classifier
            pipe = load_audio_classifier(self.cfg)
        self.pipe = pipe

    def probabilities(self, audio: np.ndarray) -> dict[str, float]:
        import torch

        with torch.inference_mode():
            out = self.pipe({"raw": np.asarray(audio, dtype=np.float32), "sampling_rate": self.sample_rate},
                            top_k=None)
        return {str(d["label"]): float(d["score"]) for d in out}

    def valence(self, audio: np.ndarray) -> tuple[float, dict[str, float]]:
        probs = self.probabilities(audio)
        return probs.get(self.cfg.positive_label, 0.0) - probs.get(self.cfg.negative_label, 0.0), probs

    def score(self, audio: np.ndarray) -> tuple[float, dict]:
        t0 = time.perf_counter()
        v, probs = self.valence(audio)
        r = prosody_reward(v, self.tau)
        return r, {"valence": v, "tau": self.tau, "probs": probs,
                   "label": max(probs, key=probs.get) if probs else None,
                   "model": self.cfg.model, "score_s": time.perf_counter() - t0}


class WhisperScorer:
    source = "whisper"

    def __init__(self, voice_config, transcriber=None, classifier_pipe=None, load_classifier: bool = True):
        self.cfg = voice_config
        self.sample_rate = voice_config.audio.sample_rate
        self.rules = RuleLayer.from_config(voice_config.sentiment)
        if transcriber is None:
            from audio_frontend.models import load_transcriber
            transcriber = load_transcriber(voice_config.asr, self.sample_rate)
        self.transcriber = transcriber
        if classifier_pipe is None and load_classifier:
            from audio_frontend.models import load_text_classifier
            classifier_pipe = load_text_classifier(voice_config.sentiment)
        self.classifier_pipe = classifier_pipe

    def classify(self, text: str) -> tuple[str, float]:
        if self.classifier_pipe is None:
            raise RuntimeError("no sentiment classifier loaded")
        out = self.classifier_pipe(text)
        top = out[0] if isinstance(out, list) else out
        if isinstance(top, list):
            top = max(top, key=lambda d: d["score"])
        return str(top["label"]), float(top["score"])

    def score(self, audio: np.ndarray) -> tuple[float, dict]:
        t0 = time.perf_counter()
        text = self.transcriber.transcribe(np.asarray(audio, dtype=np.float32))
        t1 = time.perf_counter()
        d = self.rules.decide(text, self.classify if self.classifier_pipe is not None else None)
        return d.value, {"transcript": text, "rule": d.rule, "label": d.label, "label_score": d.score,
                         "asr_model": self.cfg.asr.model, "asr_backend": self.cfg.asr.backend,
                         "asr_s": t1 - t0, "score_s": time.perf_counter() - t0}


def make_scorer(voice_config, scorer: str, **kw):
    if scorer == "prosody":
        return ProsodyScorer(voice_config, **kw)
    if scorer == "whisper":
        return WhisperScorer(voice_config, **kw)
    raise ValueError(f"unknown scorer {scorer!r}; use 'prosody' or 'whisper'")
