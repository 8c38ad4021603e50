"""`protamer bench voice`: latency from the end of an utterance to its event on the feedback queue.

Synthesised utterances (espeak-ng + sox) with silence around them are played through an ArraySource at
real-time speed into the real listener loop (VAD -> scorer -> FeedbackQueue.put). Latency per utterance =
wall-clock time the event was on the queue minus the wall-clock time the speech ended (last sample above
-60 dBFS), so it includes the VAD's end-of-utterance wait and the scoring. Medians are reported, and
beside them (`latency_from_30db_end_s`) the same from a stricter end of speech: the last 10 ms frame within
30 dB of the loudest, which excludes espeak's quiet decay and so counts the VAD's hangover in full.

Scorers: `prosody` (offline features, calibrated first on a few synthesised sentences of the same
voice), `whisper` (packaged faster-whisper tiny.en + rules + VADER), and beside them `prosody_wav2vec2`
and `whisper_distilbert`: the configured weights when on disk, otherwise (offline machines) a randomly
initialised model of the same architecture (wav2vec2-base, distilbert-base), which costs the same
compute; the JSON says which was used.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import statistics
import tempfile
import time

import numpy as np

STAGES = ("features_s", "encoder_s", "decoder_s", "rules_s")
PROSODY_TEXTS = [("good job", "positive"), ("no, stop that", "angry"), ("yes, well done", "positive"),
                 ("bad", "angry"), ("okay", "neutral"), ("that is wrong", "angry")]
# four decided by keywords, one by negation ("not ... right"), one by the sentiment classifier (no keyword),
# so the classifier's cost is in the figures
WHISPER_TEXTS = [("yes", "neutral"), ("good job", "positive"), ("no", "angry"), ("bad", "angry"),
                 ("wonderful, keep going", "positive"), ("you did not do that right", "angry")]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", default=None, help="front-end YAML (default: configs/voice.yaml)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--scorers", default="prosody,whisper,prosody_wav2vec2,whisper_distilbert",
                        help="comma list of prosody, whisper, prosody_wav2vec2, whisper_distilbert")
    parser.add_argument("--repeats", type=int, default=1, help="passes over the utterance list (6 each)")
    parser.add_argument("--require-weights", action="store_true",
                        help="fail instead of using same-architecture random weights when weights are missing")
    parser.add_argument("--threads", type=int, default=None, help="torch / CTranslate2 threads (default: config)")


def speech_end(x: np.ndarray, sample_rate: int, floor_dbfs: float = -60.0) -> float:
    """Seconds from the start of `x` to just after its last sample above `floor_dbfs` (peak)."""
    idx = np.flatnonzero(np.abs(x) > 10 ** (floor_dbfs / 20))
    return (idx[-1] + 1) / sample_rate if idx.size else 0.0


def _fallback_prosody(cfg, tmp: str) -> tuple[str, str]:
    from transformers import Wav2Vec2Config, Wav2Vec2FeatureExtractor, Wav2Vec2ForSequenceClassification

    labels = ["neu", "hap", "ang", "sad"]
    conf = Wav2Vec2Config(id2label=dict(enumerate(labels)), label2id={v: i for i, v in enumerate(labels)},
                          use_weighted_layer_sum=True, classifier_proj_size=256)   # as superb-er
    path = os.path.join(tmp, "prosody-random")
    Wav2Vec2ForSequenceClassification(conf).save_pretrained(path)
    Wav2Vec2FeatureExtractor(feature_size=1, sampling_rate=16000, do_normalize=True,
                             return_attention_mask=True).save_pretrained(path)
    return path, "random-init wav2vec2-base architecture (configured weights not on disk)"


def _fallback_sentiment(tmp: str) -> tuple[str, str]:
    from transformers import DistilBertConfig, DistilBertForSequenceClassification, DistilBertTokenizer

    path = os.path.join(tmp, "sentiment-random")
    os.makedirs(path, exist_ok=True)
    words = ["[PAD]", "[UNK]", "[CLS]", "[SEP]", "[MASK]"] + sorted(
        {w for t, _ in WHISPER_TEXTS + PROSODY_TEXTS for w in t.replace(",", "").split()})
    with open(os.path.join(path, "vocab.txt"), "w") as fh:
        fh.write("\n".join(words) + "\n")
    DistilBertTokenizer(os.path.join(path, "vocab.txt")).save_pretrained(path)
    conf = DistilBertConfig(id2label={0: "NEGATIVE", 1: "POSITIVE"}, label2id={"NEGATIVE": 0, "POSITIVE": 1})
    DistilBertForSequenceClassification(conf).save_pretrained(path)
    return path, "random-init distilbert-base architecture (configured weights not on disk)"


def _bench_calibration(cfg) -> dict:
    """A features calibration for the bench voice from synthesised sentences it does not score."""
    from audio_frontend.calibration import feature_calibration
    from audio_frontend.prosody_features import extract
    from audio_frontend.testset import NEGATIVE, NEUTRAL, POSITIVE, utterance

    rng = np.random.default_rng(0)
    sr = cfg.audio.sample_rate
    samples = []
    for lab, tone, texts in (("pos", "pos", POSITIVE[0]), ("neg", "neg", NEGATIVE[0]), ("neu", "neu", NEUTRAL[0])):
        for text in texts:
            x = utterance(text, tone, "en-us", rng, sr, pad_s=(0.0, 0.0))
            samples.append((lab, extract(x, sr, cfg.prosody.pitch_floor_hz, cfg.prosody.pitch_ceiling_hz)))
    return feature_calibration(samples, cfg.prosody)


def _measure(cfg, scorer, texts, repeats: int) -> dict:
    from audio_frontend.listen import run_listener
    from audio_frontend.sources import ArraySource
    from audio_frontend.synth import synthesize, with_silence
    from mjx_protamer.human.queue import FeedbackQueue

    sr = cfg.audio.sample_rate
    from audio_frontend.labelled import speech_bounds

    pieces, ends, ends30, t = [], [], [], 0.0
    for _ in range(repeats):
        for text, style in texts:
            speech = synthesize(text, style, sr)
            x = with_silence(speech, 0.75, 1.25, sr, noise_dbfs=-70.0)
            ends.append(t + speech_end(x[: -int(1.25 * sr)], sr))
            # the stricter end: the last 10 ms within 30 dB of the loudest (the channel model's criterion)
            ends30.append(t + 0.75 + speech_bounds(speech, sr)[1])
            pieces.append(x)
            t += x.size / sr
    audio = np.concatenate(pieces)
    # warm-up: the first call allocates (reported, not in the medians)
    t_w = time.perf_counter()
    scorer.score(audio[: sr])
    warmup_s = time.perf_counter() - t_w
    q = FeedbackQueue(maxsize=1024)
    arrivals = []
    src = ArraySource(audio, sr, cfg.audio.chunk_s, realtime=True)
    t0 = time.time() + 0.05
    src.t0 = t0
    run_listener(q, cfg, scorer, src, on_event=lambda ev, ok: arrivals.append((time.time(), ev, ok)), log=None)
    lat, lat30, vad_wait, vad_wait30, score_s, values = [], [], [], [], [], []
    parts: dict[str, list[float]] = {k: [] for k in STAGES}
    for t_arr, ev, ok in arrivals:
        # the utterance this event belongs to: the last speech end before the segment end
        mid = (ev.t_start + ev.t_end) / 2 - t0
        i = next((j for j, e in enumerate(ends) if e >= mid - 0.5), None)
        if i is None:
            continue
        end = ends[i]
        lat.append(t_arr - (t0 + end))
        lat30.append(float(t_arr - (t0 + ends30[i])))
        vad_wait.append(ev.t_end - (t0 + end))
        vad_wait30.append(float(ev.t_end - (t0 + ends30[i])))
        score_s.append(ev.details.get("score_s", float("nan")))
        for k in STAGES:
            if isinstance(ev.details.get(k), (int, float)):
                parts[k].append(float(ev.details[k]))
        values.append({"value": ev.value, **{k: ev.details[k] for k in ("transcript", "rule", "valence")
                                            if k in ev.details}})
    lat = [float(v) for v in lat]
    return {"latency_s": statistics.median(lat) if lat else None,
            "latency_p90_s": float(np.percentile(lat, 90)) if lat else None,
            "latency_from_30db_end_s": statistics.median(lat30) if lat30 else None,
            "latency_from_30db_end_p90_s": float(np.percentile(lat30, 90)) if lat30 else None,
            "vad_wait_median_s": statistics.median(vad_wait) if vad_wait else None,
            "vad_wait_from_30db_end_median_s": statistics.median(vad_wait30) if vad_wait30 else None,
            "score_median_s": statistics.median(score_s) if score_s else None,
            # where the scoring time goes (medians): Whisper's features / encoder / decoder, then the rules
            # and sentiment; the prosody scorer has only score_s
            "stages_median_s": {k: statistics.median(v) for k, v in parts.items() if v},
            "warmup_s": warmup_s,
            "n_utterances": len(ends), "n_events": len(arrivals), "latencies_s": lat, "events": values,
            "queue": q.stats()}


def run_voice_benchmark(args) -> dict:
    import torch

    from audio_frontend.config import load_voice_config
    from audio_frontend.errors import MissingWeightsError
    from audio_frontend.models import load_audio_classifier, load_text_classifier
    from audio_frontend.scorers import ProsodyScorer, WhisperScorer
    from audio_frontend.synth import require_tools

    require_tools()
    cfg = load_voice_config(getattr(args, "config", None), list(getattr(args, "overrides", []) or []))
    threads = getattr(args, "threads", None)
    if threads:
        cfg = dataclasses.replace(cfg, prosody=dataclasses.replace(cfg.prosody, threads=threads),
                                  asr=dataclasses.replace(cfg.asr, threads=threads))
    scorers = [s.strip() for s in str(getattr(args, "scorers", "prosody,whisper,prosody_wav2vec2,"
                                                         "whisper_distilbert")).split(",") if s.strip()]
    unknown = sorted(set(scorers) - {"prosody", "whisper", "prosody_wav2vec2", "whisper_distilbert"})
    if unknown:
        from mjx_protamer.config import ConfigError
        raise ConfigError(f"--scorers: unknown {unknown}; use prosody, whisper, prosody_wav2vec2, whisper_distilbert")
    repeats = int(getattr(args, "repeats", 1))
    require = bool(getattr(args, "require_weights", False))
    result: dict = {"device": f"cpu ({os.cpu_count()} cores, {platform.processor() or platform.machine()})",
                    "load_average": list(os.getloadavg()), "torch": torch.__version__, "chunk_s": cfg.audio.chunk_s,
                    "vad": cfg.vad.kind, "segment_mode": cfg.vad.segment_mode, "hangover_s": cfg.vad.hangover_s,
                    "targets_s": {"prosody": 0.1, "whisper": 0.5}}
    for k in scorers:
        result[f"{k}_latency_s"] = None
    with tempfile.TemporaryDirectory() as tmp:
        if "prosody" in scorers:
            from audio_frontend.scorers import FeatureProsodyScorer
            scorer = FeatureProsodyScorer(cfg, calibration=_bench_calibration(cfg))
            r = _measure(cfg, scorer, PROSODY_TEXTS, repeats)
            result["prosody"] = {**r, "weights": "none: Praat features + a model calibrated on other sentences"}
            result["prosody_latency_s"] = r["latency_s"]
        if "prosody_wav2vec2" in scorers:
            wcfg = dataclasses.replace(cfg, prosody=dataclasses.replace(cfg.prosody, kind="wav2vec2"))
            try:
                pipe, weights = load_audio_classifier(wcfg.prosody), wcfg.prosody.model
            except MissingWeightsError:
                if require:
                    raise
                path, weights = _fallback_prosody(wcfg, tmp)
                pipe = load_audio_classifier(dataclasses.replace(wcfg.prosody, model=path))
            scorer = ProsodyScorer(wcfg, tau=wcfg.prosody.tau or 0.5, pipe=pipe)
            r = _measure(wcfg, scorer, PROSODY_TEXTS, repeats)
            result["prosody_wav2vec2"] = {**r, "weights": weights}
            result["prosody_wav2vec2_latency_s"] = r["latency_s"]
        if "whisper" in scorers:
            from audio_frontend.sentiment import load_sentiment
            scorer = WhisperScorer(cfg, classifier=load_sentiment(cfg.sentiment, "vader"))
            r = _measure(cfg, scorer, WHISPER_TEXTS, repeats)
            result["whisper"] = {**r, "asr": f"{cfg.asr.backend}:{cfg.asr.model}", "sentiment_weights": "vader"}
            result["whisper_latency_s"] = r["latency_s"]
        if "whisper_distilbert" in scorers:
            try:
                cls, sweights = load_text_classifier(cfg.sentiment), cfg.sentiment.model
            except MissingWeightsError:
                if require:
                    raise
                path, sweights = _fallback_sentiment(tmp)
                cls = load_text_classifier(dataclasses.replace(cfg.sentiment, model=path))
            scorer = WhisperScorer(cfg, classifier_pipe=cls)
            r = _measure(cfg, scorer, WHISPER_TEXTS, repeats)
            result["whisper_distilbert"] = {**r, "asr": f"{cfg.asr.backend}:{cfg.asr.model}",
                                            "sentiment_weights": sweights}
            result["whisper_distilbert_latency_s"] = r["latency_s"]
    for k in ("prosody", "whisper"):
        if result.get(f"{k}_latency_s") is not None:
            result[f"{k}_meets_target"] = bool(result[f"{k}_latency_s"] < result["targets_s"][k])
    from audio_frontend.listen import _jsonable
    return _jsonable(result)


if __name__ == "__main__":  # python -m audio_frontend.bench  (the same as `protamer bench voice --json`)
    import json

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_arguments(ap)
    print(json.dumps(run_voice_benchmark(ap.parse_args()), indent=2, sort_keys=True))
