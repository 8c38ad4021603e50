"""Voice front-end commands: `protamer listen`, `calibrate`, `validate-voice`, `synth-voice`.

torch / transformers are imported inside the handlers (through audio_frontend), never at import time,
and nothing here imports JAX.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", default=None, help="front-end YAML (default: configs/voice.yaml)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a config field, e.g. --set prosody.model=/models/ser (repeatable)")


def _load(args):
    from audio_frontend.config import load_voice_config
    return load_voice_config(args.config, args.overrides)


def _fail(e) -> int:
    print(f"protamer: {e}", file=sys.stderr)
    return getattr(e, "exit_code", 1)


class _PrintSink:
    """Stands in for the learner's FeedbackQueue in `protamer listen`: validate, print JSON, log."""

    def __init__(self, log_path: str | None):
        from mjx_protamer.human.queue import FeedbackLog
        self.log = FeedbackLog(log_path) if log_path else None

    def put(self, event) -> bool:
        from mjx_protamer.human.events import InvalidFeedback, validate_event
        try:
            validate_event(event)
        except InvalidFeedback as e:
            if self.log:
                self.log.rejected(event, str(e))
            return False
        print(event.to_json(), flush=True)
        if self.log:
            self.log.accepted(event)
        return True


def cmd_listen(args) -> int:
    from audio_frontend.errors import VoiceError
    from audio_frontend.listen import run_listener
    from audio_frontend.scorers import make_scorer
    from audio_frontend.sources import make_source

    from mjx_protamer.cli_numbers import number

    if args.max_events is not None:
        args.max_events = number("--max-events", args.max_events, 1, 1e9, integer=True)
    cfg = _load(args)
    try:
        source = make_source(cfg, wav=args.wav, realtime=args.realtime)
        if args.wav:
            _ = source.audio  # bad file: fail before loading models
        elif hasattr(source, "open"):
            source.open()     # no PortAudio / no device: fail before loading models
        if args.scorer == "prosody" and args.uncalibrated and cfg.prosody.kind == "features":
            from audio_frontend.errors import CalibrationError
            raise CalibrationError("--uncalibrated works with prosody.kind=wav2vec2 only: the feature scorer's model "
                                   "is fitted by 'protamer calibrate' from your own voice")
        kw = {"need_tau": not args.uncalibrated} if args.scorer == "prosody" else {}
        scorer = make_scorer(cfg, args.scorer, **kw)
        sink = _PrintSink(args.log)
        stats = run_listener(sink, cfg, scorer, source, save_dir=args.save_segments, max_events=args.max_events)
    except VoiceError as e:
        return _fail(e)
    print(f"[voice] {json.dumps(stats)}", file=sys.stderr)
    return 0


def _record_prompts(cfg, n: int) -> list[tuple[str, object]]:
    """Prompt for n positive and n negative utterances on the microphone; one VAD segment each."""
    from audio_frontend.sources import MicSource
    from audio_frontend.vad import Segmenter

    a = cfg.audio
    out = []
    prompts = [("pos", "POSITIVE (smile, warm, e.g. 'good job!')"), ("neg", "NEGATIVE (harsh, e.g. 'no, stop!')")]
    if cfg.prosody.kind == "features":   # the feature model is normalised by the user's neutral voice
        prompts.insert(0, ("neu", "in your NEUTRAL voice (e.g. 'the robot moves its arm')"))
    src = MicSource(a.sample_rate, a.chunk_s, device=a.device)
    src.open()
    try:
        for lab, text in prompts:
            for i in range(n):
                print(f"[{lab} {i + 1}/{n}] say something {text} ...", file=sys.stderr, flush=True)
                seg_maker = Segmenter(cfg.vad, a.sample_rate, a.chunk_s)
                got = None
                for t, chunk in src.chunks():
                    segs = seg_maker.feed(t, chunk)
                    if segs:
                        got = segs[0]
                        break
                print(f"    got {got.duration_s:.2f} s", file=sys.stderr)
                out.append((lab, got.audio))
    finally:
        src.close()
    return out


def cmd_calibrate(args) -> int:
    from audio_frontend.calibration import compute_tau, feature_calibration, write_calibration
    from audio_frontend.errors import CalibrationError, VoiceError
    from audio_frontend.labelled import find_labelled, load_labelled
    from mjx_protamer.cli_numbers import number

    args.n = number("--n", args.n, 1, 1000, integer=True)
    cfg = _load(args)
    out_path = args.out or cfg.prosody.calibration_path
    features = cfg.prosody.kind == "features"
    try:
        if args.wav_dir:
            files, unknown = find_labelled(args.wav_dir, "tone")
            for u in unknown:
                print(f"protamer: skipping {u}: no pos/neg/neu label in its folder or name", file=sys.stderr)
            recorded = []
            for path, lab, utt in load_labelled(files, cfg):
                if isinstance(utt, str):
                    print(f"protamer: skipping {utt}", file=sys.stderr)
                else:
                    recorded.append((lab, utt.audio))
        else:
            recorded = _record_prompts(cfg, args.n)
        if features:
            from audio_frontend.prosody_features import extract
            p = cfg.prosody
            record = feature_calibration(
                [(lab, extract(x, cfg.audio.sample_rate, p.pitch_floor_hz, p.pitch_ceiling_hz)) for lab, x in recorded],
                p)
        else:
            from audio_frontend.scorers import ProsodyScorer
            scorer = ProsodyScorer(cfg, need_tau=False)
            samples = [(lab, scorer.valence(x)[0]) for lab, x in recorded if lab in ("pos", "neg")]
            record = compute_tau(samples, cfg.prosody.min_samples_per_sign, cfg.prosody.min_tau)
            record.update(kind="wav2vec2", model=cfg.prosody.model, positive_label=cfg.prosody.positive_label,
                          negative_label=cfg.prosody.negative_label)
        record.update(user=args.user)
        path = write_calibration(out_path, record)
    except CalibrationError as e:
        print(f"protamer: calibration refused: {e}", file=sys.stderr)
        return e.exit_code
    except VoiceError as e:
        return _fail(e)
    if args.json:
        print(json.dumps({**record, "path": str(path)}, sort_keys=True))
    else:
        print(f"{record['kind']} calibration: tau = {record['tau']:.4f} from {record['n_pos']} positive and "
              f"{record['n_neg']} negative samples" + (f" ({record['n_neu']} neutral)" if features else "")
              + f", held-out sign accuracy {record['sign_accuracy']:.2f}; written to {path}")
    return 0


def cmd_validate(args) -> int:
    from audio_frontend.calibration import write_json_atomic
    from audio_frontend.errors import VoiceError
    from audio_frontend.labelled import find_labelled, score_files
    from audio_frontend.report import channel, format_table, summarize
    from audio_frontend.scorers import make_scorer
    from audio_frontend.validation import kinds_of

    cfg = _load(args)
    if args.per_speaker:
        return _validate_speakers(args, cfg)
    if args.scorer == "both":
        print("protamer: --scorer both needs --per-speaker; give --scorer prosody or whisper", file=sys.stderr)
        return 2
    try:
        files, unknown = find_labelled(args.dir, "tone" if args.scorer == "prosody" else "words")
        if not files:
            print(f"protamer: no labelled recordings in {args.dir}: put them in pos/, neg/ (and neu/, fillers/) "
                  f"subfolders or name them pos_*.wav / neg_*.wav", file=sys.stderr)
            return 3
        scorer = make_scorer(cfg, args.scorer, **({"need_tau": False} if args.scorer == "prosody" else {}))
        rows = score_files(files, cfg, scorer.score)
    except VoiceError as e:
        return _fail(e)
    summary = summarize(rows, args.scorer, kinds_of(Path(args.dir)))
    summary["skipped_unlabelled"] = [str(u) for u in unknown]
    summary["channel"] = channel(summary)
    if args.out:
        write_json_atomic(args.out, summary)
    if args.json:
        print(json.dumps(summary, sort_keys=True))
    else:
        print(format_table(summary))
    return 0 if summary["n_scored"] else 3


def _validate_speakers(args, cfg) -> int:
    import platform
    import time

    from audio_frontend.calibration import write_json_atomic
    from audio_frontend.errors import VoiceError
    from audio_frontend.report import channel, format_table
    from audio_frontend.validation import validate_speakers

    scorers = ("prosody", "whisper") if args.scorer == "both" else (args.scorer,)
    try:
        res = validate_speakers(args.dir, cfg, scorers, log=sys.stderr)
    except VoiceError as e:
        return _fail(e)
    out = {
        "what": "channel model of the voice scorers: per scorer, delivered value (+1/-1/0) for each true label, "
                "sign accuracy on signed utterances, misses (signed -> 0), latency from end of speech to event "
                "(VAD endpoint wait + scoring time on this machine) and utterance durations",
        "source": {"command": " ".join(["protamer validate-voice", str(args.dir), "--per-speaker", "--scorer",
                                        args.scorer] + [f"--set {o}" for o in args.overrides]),
                   "data": str(args.dir), "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                   "machine": f"{platform.machine()}, {__import__('os').cpu_count()} cores",
                   "vad": cfg.vad.kind, "hangover_s": cfg.vad.hangover_s, "chunk_s": cfg.audio.chunk_s,
                   "prosody": {"kind": "features", "neutral_band": cfg.prosody.neutral_band,
                               "calibration": "per speaker, from that speaker's calib/ sentences"},
                   "asr": f"{cfg.asr.backend}:{cfg.asr.model}",
                   "asr_decoding": {"window_s": cfg.asr.window_s, "pad": cfg.asr.pad, "beam_size": cfg.asr.beam_size,
                                    "num_hypotheses": cfg.asr.num_hypotheses, "compute_type": cfg.asr.compute_type,
                                    "alternative_margin": cfg.sentiment.alternative_margin,
                                    "filler_gate": dataclasses.asdict(cfg.sentiment.filler_gate)},
                   "labels": "prosody by tone, whisper by words (labels.jsonl)",
                   "note": "synthesised espeak-ng voices are not real recordings"},
        "speakers": res["speakers"],
        "per_speaker": res["per_speaker"],
        "channels": {name: channel(s) for name, s in res["scorers"].items()},
    }
    if args.out:
        write_json_atomic(args.out, out)
    if args.json:
        print(json.dumps(out, sort_keys=True))
    else:
        for name, s in res["scorers"].items():
            print(f"== {name}")
            print(format_table({**s, "rows": []}))
    return 0


def cmd_synth(args) -> int:
    from audio_frontend.testset import SPEAKERS, make_test_set
    from mjx_protamer.cli_numbers import number, seed

    args.seed = seed("--seed", args.seed)
    if args.noise_dbfs is not None:
        args.noise_dbfs = number("--noise-dbfs", args.noise_dbfs, -120, 0)
    if args.max_per_group is not None:
        args.max_per_group = number("--max-per-group", args.max_per_group, 1, 1e6, integer=True)
    speakers = tuple(v.strip() for v in args.speakers.split(",") if v.strip()) if args.speakers else SPEAKERS
    try:
        counts = make_test_set(args.dir, speakers, noise_dbfs=args.noise_dbfs, seed=args.seed,
                               max_per_group=args.max_per_group, probe=args.probe)
    except (RuntimeError, OSError) as e:
        return _fail(e)
    print(f"wrote {sum(counts.values())} utterances ({counts}) for {len(speakers)} speakers into {args.dir}; "
          f"synthesised voices, not real recordings")
    return 0


def register(subparsers) -> None:
    p = subparsers.add_parser("listen", help="voice feedback: microphone (or WAV) -> VAD -> scorer -> events",
                              description="Print one JSON feedback event per utterance (stdout).")
    _common(p)
    p.add_argument("--scorer", choices=("prosody", "whisper"), default="prosody")
    p.add_argument("--wav", default=None, help="read this file instead of the microphone")
    p.add_argument("--realtime", action="store_true", help="with --wav: play the file at real-time speed")
    p.add_argument("--save-segments", default=None, metavar="DIR", help="save each scored segment as WAV here")
    p.add_argument("--log", default=None, metavar="FILE", help="also append events to this JSONL feedback log")
    p.add_argument("--max-events", default=None, help="stop after this many utterances")
    p.add_argument("--uncalibrated", action="store_true",
                   help="prosody.kind=wav2vec2 without calibration (tau = 1); the feature scorer always needs one")
    p.set_defaults(handler=cmd_listen)

    p = subparsers.add_parser("calibrate", help="per-user prosody calibration: the user's model and tau",
                              description="Record prompted positive/negative samples (or read --wav-dir) "
                                          "and write the calibration file.")
    _common(p)
    p.add_argument("--wav-dir", default=None, help="labelled recordings: pos/, neg/ and neu/ (or fillers/) subfolders "
                                                   "or pos_*/neg_*/neu_* files")
    p.add_argument("--n", default=5, help="samples per sign when recording (default 5)")
    p.add_argument("--out", default=None, help="calibration file (default: prosody.calibration_path)")
    p.add_argument("--user", default="", help="a name stored in the calibration file")
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=cmd_calibrate)

    p = subparsers.add_parser("validate-voice", help="sign accuracy / confusion / latency on labelled recordings",
                              description="The paper's protocol: e.g. 10 positive and 10 negative recordings.")
    _common(p)
    p.add_argument("dir", help="folder with pos/, neg/ (and neu/, fillers/) subfolders or pos_*/neg_* files, or "
                                "with --per-speaker a folder of speakers (made by synth-voice)")
    p.add_argument("--scorer", choices=("prosody", "whisper", "both"), default="prosody",
                   help="both: only with --per-speaker")
    p.add_argument("--per-speaker", action="store_true",
                   help="DIR/<speaker>/calib and test: calibrate prosody per speaker on calib, score test, pool")
    p.add_argument("--out", default=None, help="also write the JSON result to this file (atomically)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=cmd_validate)

    p = subparsers.add_parser("synth-voice", help="write a labelled synthesised voice test set (espeak-ng + sox)",
                              description="Several espeak-ng voices, positive / negative / neutral tone, the same "
                                          "words said both ways, fillers; DIR/<speaker>/{calib,test}/{pos,neg,neu,"
                                          "fillers}/*.wav with labels.jsonl. Not real recordings.")
    p.add_argument("dir")
    p.add_argument("--speakers", default=None, help="comma list of espeak-ng voices (default: six en voices)")
    p.add_argument("--noise-dbfs", default=None, help="add white noise at this level (dBFS, -120..0)")
    p.add_argument("--seed", default=0, help="the noise's seed, 0..2^32-1 (default 0)")
    p.add_argument("--max-per-group", default=None, help="keep at most N sentences per tone and kind")
    p.add_argument("--probe", action="store_true", help="also a probe/ split per speaker: one-word keywords in both "
                                                         "tones and 12 fillers in two styles (the filler gate's test)")
    p.set_defaults(handler=cmd_synth)
