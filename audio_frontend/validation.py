"""Per-speaker validation: calibrate on each speaker's calib/ set, score their test/ set, pool the results.

For a folder made by `protamer synth-voice` (DIR/<speaker>/calib and DIR/<speaker>/test, labels.jsonl)
or recordings laid out the same way. Prosody (features) is labelled by tone, Whisper by words. The
result is one summary per scorer (`audio_frontend.report.summarize`) plus per-speaker accuracies.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from audio_frontend.errors import AudioInputError
from audio_frontend.labelled import LABELS_FILE, Scored, find_labelled, load_labelled, score_loaded
from audio_frontend.models import transcript_of
from audio_frontend.report import summarize


def speakers_of(root: str | Path) -> list[Path]:
    root = Path(root)
    found = sorted(p for p in root.iterdir() if (p / "calib").is_dir() and (p / "test").is_dir()) \
        if root.is_dir() else []
    if not found:
        raise AudioInputError(f"{root}: no speaker folders with calib/ and test/ inside (make one with "
                              f"'protamer synth-voice {root}', or drop --per-speaker for a single folder)")
    return found


def kinds_of(folder: Path) -> dict[str, str]:
    """file path -> kind (congruent, against, neutral, filler) from the folder's labels.jsonl."""
    f = folder / LABELS_FILE
    if not f.is_file():
        return {}
    rows = [json.loads(line) for line in f.read_text(encoding="utf-8").splitlines() if line.strip()]
    return {str(folder / r["file"]): r["kind"] for r in rows if "kind" in r and "file" in r}


def calibrate_speaker(cfg, calib_dir: Path) -> dict:
    """The feature calibration record fitted from one speaker's calib/ folder (by tone)."""
    from audio_frontend.calibration import feature_calibration
    from audio_frontend.prosody_features import extract

    files, _ = find_labelled(calib_dir, "tone")
    samples = []
    for _path, lab, utt in load_labelled(files, cfg):
        if not isinstance(utt, str):
            samples.append((lab, extract(utt.audio, cfg.audio.sample_rate, cfg.prosody.pitch_floor_hz,
                                         cfg.prosody.pitch_ceiling_hz)))
    return feature_calibration(samples, cfg.prosody)


def _whisper_rows(loaded, transcriber, rules, classifiers: dict) -> dict[str, list[Scored]]:
    """Transcribe each file once, decide with every sentiment classifier."""
    out: dict[str, list[Scored]] = {name: [] for name in classifiers}
    for path, lab, utt in loaded:
        if isinstance(utt, str):
            for name in classifiers:
                out[name].append(Scored(str(path), lab, error=utt))
            continue
        t0 = time.perf_counter()
        tr = transcript_of(transcriber, utt.audio)
        asr_s = time.perf_counter() - t0
        for name, clf in classifiers.items():
            t1 = time.perf_counter()
            d = rules.decide(tr.text, clf, tr.avg_logprob, tr.alternatives, tr.filler_logprob)
            out[name].append(Scored(str(path), lab, d.value, asr_s + time.perf_counter() - t1,
                                    {"transcript": tr.text, "rule": d.rule, "alternative": d.alternative,
                                     "avg_logprob": tr.avg_logprob, "filler": d.filler,
                                     "gated_value": d.gated_value, **tr.timings},
                                    speech_s=utt.speech_s, vad_wait_s=utt.vad_wait_s))
    return out


def validate_speakers(root: str | Path, cfg, scorers=("prosody", "whisper"), log=None) -> dict:
    from audio_frontend.scorers import FeatureProsodyScorer

    speakers = speakers_of(root)
    pooled: dict[str, list[Scored]] = {}
    kinds: dict[str, str] = {}
    per_speaker: dict[str, dict] = {}
    whisper = None
    if "whisper" in scorers:
        from audio_frontend.models import load_transcriber, weights_on_disk
        from audio_frontend.rules import RuleLayer
        from audio_frontend.sentiment import PipelineClassifier, load_sentiment

        classifiers = {"whisper+vader": load_sentiment(cfg.sentiment, "vader")}
        if weights_on_disk(cfg.sentiment.model):
            from audio_frontend.models import load_text_classifier
            classifiers["whisper+distilbert"] = PipelineClassifier(load_text_classifier(cfg.sentiment),
                                                                   cfg.sentiment.model)
        whisper = (load_transcriber(cfg.asr, cfg.audio.sample_rate), RuleLayer.from_config(cfg.sentiment, cfg.asr),
                   classifiers)
    for spk in speakers:
        test = spk / "test"
        kinds.update(kinds_of(test))
        mine: dict[str, list[Scored]] = {}
        if "prosody" in scorers:
            record = calibrate_speaker(cfg, spk / "calib")
            scorer = FeatureProsodyScorer(cfg, calibration=record)
            files, _ = find_labelled(test, "tone")
            mine["prosody"] = score_loaded(load_labelled(files, cfg), scorer.score)
        if whisper is not None:
            files, _ = find_labelled(test, "words")
            mine.update(_whisper_rows(load_labelled(files, cfg), *whisper))
        per_speaker[spk.name] = {}
        for name, rows in mine.items():
            pooled.setdefault(name, []).extend(rows)
            s = summarize(rows, name)
            per_speaker[spk.name][name] = {"sign_accuracy": s["sign_accuracy"], "miss_rate": s["miss_rate"],
                                           "zero_rate_unsigned": s["zero_rate_unsigned"]}
        if log is not None:
            print(f"[validate] {spk.name}: " + ", ".join(
                f"{n} {v['sign_accuracy']:.3f}" for n, v in per_speaker[spk.name].items()), file=log, flush=True)
    return {"speakers": [s.name for s in speakers], "per_speaker": per_speaker,
            "scorers": {name: summarize(rows, name, kinds) for name, rows in pooled.items()}}
