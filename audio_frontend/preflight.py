"""Before a voice session starts: is everything the chosen feedback needs on this machine?

`check_voice_feedback(config, "prosody" | "whisper")` raises the front end's own errors (calibration,
missing weights or packages), each saying how to fix it, so `protamer finetune` can stop before it
spends minutes loading and compiling. Cheap: it reads the calibration file and looks for weight files
and packages, but loads no model.
"""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

from audio_frontend.config import PACKAGED_WHISPER
from audio_frontend.errors import MissingWeightsError


def _need_package(module: str, what: str, pip: str) -> None:
    if importlib.util.find_spec(module) is None:
        raise MissingWeightsError(f"{what} needs the Python package {pip.split('==')[0]} (import {module}), which is "
                                  f"not installed: pip install {pip} (or pip install 'mjx-protamer[audio]')")


def _need_weights(ref: str, allow_download: bool, what: str, key: str, files: str) -> None:
    from audio_frontend.models import _how_to_provide, looks_like_path, weights_on_disk

    if weights_on_disk(ref):
        return
    if looks_like_path(ref):
        raise MissingWeightsError(f"{what} folder {os.path.expanduser(ref)} (from {key}) has no config.json; it must "
                                  f"hold {files} (what save_pretrained writes).")
    if not allow_download:
        raise MissingWeightsError(_how_to_provide(what, ref, key, files))


def check_prosody(cfg) -> str:
    from audio_frontend.calibration import load_calibration
    from audio_frontend.models import PROSODY_FILES

    p = cfg.prosody
    if p.kind == "features":
        from audio_frontend.errors import CalibrationError
        from audio_frontend.prosody_model import ProsodyModel

        _need_package("parselmouth", "prosody.kind=features", "praat-parselmouth==0.4.7")
        rec = load_calibration(p.calibration_path, p.min_tau)
        if rec["kind"] != "features":
            raise CalibrationError(
                f"prosody.kind=features needs a calibration made with it, but {rec['path']} is a {rec['kind']} "
                f"calibration (tau only); run 'protamer calibrate --wav-dir DIR' (pos/, neg/, neu/) or set "
                f"prosody.kind=wav2vec2")
        ProsodyModel.from_dict(rec["prosody_model"])
        tau = p.tau if p.tau is not None else rec["tau"]
        return f"prosody: features model and tau {tau:.3f} from {rec['path']}"
    _need_package("torch", "prosody.kind=wav2vec2", "torch==2.13.0")
    _need_package("transformers", "prosody.kind=wav2vec2", "transformers==5.23.0")
    if p.tau is None:
        rec = load_calibration(p.calibration_path, p.min_tau)
        where = f"tau {rec['tau']:.3f} from {rec['path']}"
    else:
        where = f"tau {p.tau:g} from prosody.tau"
    _need_weights(p.model, p.allow_download, "Prosody (speech emotion)", "prosody.model", PROSODY_FILES)
    return f"prosody: wav2vec2 {p.model}, {where}"


def check_whisper(cfg, keywords_only: bool = False) -> str:
    from audio_frontend.models import SENTIMENT_FILES, WHISPER_FILES, packaged_whisper_path

    a = cfg.asr
    if a.backend == "faster-whisper":
        _need_package("faster_whisper", "asr.backend=faster-whisper", "faster-whisper==1.2.1")
        if a.model == PACKAGED_WHISPER:
            asr = f"faster-whisper tiny.en from {packaged_whisper_path()}"
        elif (Path(os.path.expanduser(a.model)) / "model.bin").is_file():
            asr = f"faster-whisper {a.model}"
        elif Path(os.path.expanduser(a.model)).exists() or a.model.startswith((".", "/", "~")):
            raise MissingWeightsError(f"asr.model={a.model}: no CTranslate2 model.bin there; a faster-whisper folder "
                                      f"holds model.bin, config.json, tokenizer.json, vocabulary.*")
        else:
            asr = f"faster-whisper {a.model} (a size name: the Hugging Face cache or the hub)"
    else:
        _need_package("transformers", "asr.backend=transformers", "transformers==5.23.0")
        ref = a.model if a.model != PACKAGED_WHISPER else "openai/whisper-tiny.en"
        _need_weights(ref, a.allow_download, "Whisper (transformers)", "asr.model", WHISPER_FILES)
        asr = f"transformers {ref}"
    if keywords_only:
        return f"whisper: {asr}, keyword rules only"
    from audio_frontend.sentiment import resolved_kind

    s = cfg.sentiment
    kind = resolved_kind(s)
    if kind == "vader":
        _need_package("vaderSentiment", "sentiment.kind=vader", "vaderSentiment==3.3.2")
        return f"whisper: {asr}, rules + VADER sentiment"
    _need_weights(s.model, s.allow_download, "Sentiment classifier", "sentiment.model", SENTIMENT_FILES)
    return f"whisper: {asr}, rules + {s.model}"


def check_vad(cfg) -> str:
    kind = cfg.vad.kind
    if kind == "webrtc":
        _need_package("webrtcvad", "vad.kind=webrtc", "webrtcvad-wheels==2.0.14.post1")
    elif kind == "silero":
        _need_package("torch", "vad.kind=silero", "torch==2.13.0")
        _need_package("silero_vad", "vad.kind=silero", "silero-vad==6.2.3")
    return f"vad: {kind}"


def check_voice_feedback(cfg, feedback: str, keywords_only: bool = False) -> list[str]:
    """Raise (VoiceError subclasses, with the fix) unless `feedback` ("prosody" or "whisper") can run;
    return one line per part saying what will be used."""
    if feedback == "prosody":
        lines = [check_prosody(cfg)]
    elif feedback == "whisper":
        lines = [check_whisper(cfg, keywords_only)]
    else:
        raise ValueError(f"unknown voice feedback {feedback!r}; use 'prosody' or 'whisper'")
    return lines + [check_vad(cfg)]
