"""Scorers: one audio segment in, one reward in [-1, 1] and JSON-able details out.

- `FeatureProsodyScorer` (DTP, `prosody.kind: features`, the default): Praat prosodic features through
  the user's calibrated model, valence = P(pos) - P(neg), reward = tanh(valence / tau), 0 inside
  `prosody.neutral_band`.
- `ProsodyScorer` (DTP, `prosody.kind: wav2vec2`): speech-emotion class probabilities (labels from
  `config.id2label`), valence = P(positive_label) - P(negative_label), reward = tanh(valence / tau).
- `WhisperScorer` (DTW): Whisper transcript -> rule layer (keywords, fillers) -> sentiment classifier.
"""

from __future__ import annotations

import math
import time

import numpy as np

from audio_frontend.rules import RuleLayer


def prosody_reward(valence: float, tau: float) -> float:
    return float(math.tanh(valence / tau))


class FeatureProsodyScorer:
    """Offline prosody: needs only the calibration file (the user's model and tau), no weights."""

    source = "prosody"

    def __init__(self, voice_config, calibration: dict | None = None, tau: float | None = None):
        from audio_frontend.calibration import load_calibration
        from audio_frontend.errors import CalibrationError
        from audio_frontend.prosody_model import ProsodyModel

        self.cfg = voice_config.prosody
        self.sample_rate = voice_config.audio.sample_rate
        if calibration is None:
            calibration = load_calibration(self.cfg.calibration_path, self.cfg.min_tau)
        if calibration.get("kind") != "features":
            raise CalibrationError(
                f"prosody.kind=features needs a calibration made with it, but {calibration.get('path', 'the file')} "
                f"is a {calibration.get('kind', 'wav2vec2')} calibration (tau only); run 'protamer calibrate "
                f"--wav-dir DIR' (pos/, neg/, neu/) or set prosody.kind=wav2vec2")
        self.model = ProsodyModel.from_dict(calibration["prosody_model"])
        if tau is not None:
            self.tau, self.tau_source = float(tau), "argument"
        elif self.cfg.tau is not None:
            self.tau, self.tau_source = float(self.cfg.tau), "config prosody.tau"
        else:
            self.tau, self.tau_source = float(calibration["tau"]), calibration.get("path", "calibration")

    def features(self, audio: np.ndarray) -> dict[str, float]:
        from audio_frontend.prosody_features import extract
        return extract(audio, self.sample_rate, self.cfg.pitch_floor_hz, self.cfg.pitch_ceiling_hz)

    def valence(self, audio: np.ndarray) -> tuple[float, dict[str, float]]:
        from audio_frontend.prosody_features import vector
        return self.model.valence(vector(self.features(audio)))

    def score(self, audio: np.ndarray) -> tuple[float, dict]:
        t0 = time.perf_counter()
        v, probs = self.valence(audio)
        r = 0.0 if abs(v) < self.cfg.neutral_band else prosody_reward(v, self.tau)
        return r, {"valence": v, "tau": self.tau, "probs": probs, "label": max(probs, key=probs.get),
                   "model": "features", "score_s": time.perf_counter() - t0}


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

    def __init__(self, voice_config, transcriber=None, classifier_pipe=None, load_classifier: bool = True,
                 classifier=None):
        """`classifier`: a `text -> (label, score)` callable; `classifier_pipe`: a transformers pipeline;
        neither: `sentiment.kind` decides (`audio_frontend.sentiment.load_sentiment`);
        `load_classifier=False`: keyword rules only."""
        from audio_frontend.sentiment import PipelineClassifier, load_sentiment

        self.cfg = voice_config
        self.sample_rate = voice_config.audio.sample_rate
        self.rules = RuleLayer.from_config(voice_config.sentiment, voice_config.asr)
        if transcriber is None:
            from audio_frontend.models import load_transcriber
            transcriber = load_transcriber(voice_config.asr, self.sample_rate)
        self.transcriber = transcriber
        if classifier is None and classifier_pipe is not None:
            classifier = PipelineClassifier(classifier_pipe, voice_config.sentiment.model)
        if classifier is None and load_classifier:
            classifier = load_sentiment(voice_config.sentiment)
        self.classifier = classifier
        self.sentiment_name = getattr(classifier, "name", "custom") if classifier is not None else "rules only"

    def warm_up(self) -> float:
        """Transcribe 0.5 s of silence once (allocations, thread pools); returns the seconds it took."""
        t0 = time.perf_counter()
        self.transcriber.transcribe(np.zeros(self.sample_rate // 2, dtype=np.float32))
        return time.perf_counter() - t0

    def classify(self, text: str) -> tuple[str, float]:
        if self.classifier is None:
            raise RuntimeError("no sentiment classifier loaded")
        return self.classifier(text)

    def score(self, audio: np.ndarray) -> tuple[float, dict]:
        from audio_frontend.models import transcript_of

        t0 = time.perf_counter()
        tr = transcript_of(self.transcriber, np.asarray(audio, dtype=np.float32))
        t1 = time.perf_counter()
        d = self.rules.decide(tr.text, self.classify if self.classifier is not None else None, tr.avg_logprob,
                              tr.alternatives, tr.filler_logprob)
        t2 = time.perf_counter()
        return d.value, {"transcript": tr.text, "rule": d.rule, "alternative": d.alternative,
                         "label": d.label, "label_score": d.score,
                         "filler": d.filler[0] if d.filler else None,
                         "filler_logprob": d.filler[1] if d.filler else None, "gated_value": d.gated_value,
                         "avg_logprob": tr.avg_logprob, "no_speech_prob": tr.no_speech_prob,
                         "sentiment": self.sentiment_name, "asr_model": self.cfg.asr.model,
                         "asr_backend": self.cfg.asr.backend, "asr_s": t1 - t0, **tr.timings,
                         "rules_s": t2 - t1, "score_s": time.perf_counter() - t0}


def make_scorer(voice_config, scorer: str, **kw):
    if scorer == "prosody":
        if voice_config.prosody.kind == "features" and "pipe" not in kw:
            kw.pop("need_tau", None)   # its model *is* the calibration: always needed
            return FeatureProsodyScorer(voice_config, **kw)
        return ProsodyScorer(voice_config, **kw)
    if scorer == "whisper":
        return WhisperScorer(voice_config, **kw)
    raise ValueError(f"unknown scorer {scorer!r}; use 'prosody' or 'whisper'")
