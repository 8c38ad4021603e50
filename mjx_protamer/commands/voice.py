"""Voice front-end commands: `protamer listen`, `protamer calibrate`, `protamer validate-voice`.

torch / transformers are imported inside the handlers (through audio_frontend), never at import time,
and nothing here imports JAX.
"""

from __future__ import annotations

import argparse
import json
import sys


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

    cfg = _load(args)
    try:
        source = make_source(cfg, wav=args.wav, realtime=args.realtime)
        if args.wav:
            _ = source.audio  # bad file: fail before loading models
        elif hasattr(source, "open"):
            source.open()     # no PortAudio / no device: fail before loading models
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
    from audio_frontend.calibration import compute_tau, write_calibration
    from audio_frontend.errors import CalibrationError, VoiceError
    from audio_frontend.labelled import find_labelled, score_files

    cfg = _load(args)
    out_path = args.out or cfg.prosody.calibration_path
    try:
        if args.wav_dir:
            files, unknown = find_labelled(args.wav_dir)
            for u in unknown:
                print(f"protamer: skipping {u}: no pos/neg label in its folder or name", file=sys.stderr)
        else:
            files = None
            recorded = _record_prompts(cfg, args.n)
        from audio_frontend.scorers import ProsodyScorer
        scorer = ProsodyScorer(cfg, need_tau=False)
        if files is not None:
            rows = score_files(files, cfg, lambda x: scorer.valence(x))
            for r in rows:
                if r.error:
                    print(f"protamer: skipping {r.error}", file=sys.stderr)
            samples = [(r.label, r.value) for r in rows if r.error is None]
        else:
            samples = [(lab, scorer.valence(x)[0]) for lab, x in recorded]
        record = compute_tau(samples, cfg.prosody.min_samples_per_sign, cfg.prosody.min_tau)
        record.update(model=cfg.prosody.model, positive_label=cfg.prosody.positive_label,
                      negative_label=cfg.prosody.negative_label, user=args.user)
        path = write_calibration(out_path, record)
    except CalibrationError as e:
        print(f"protamer: calibration refused: {e}", file=sys.stderr)
        return e.exit_code
    except VoiceError as e:
        return _fail(e)
    if args.json:
        print(json.dumps({**record, "path": str(path)}, sort_keys=True))
    else:
        print(f"tau = {record['tau']:.4f} from {record['n_pos']} positive and {record['n_neg']} negative samples "
              f"(sign accuracy {record['sign_accuracy']:.2f}); written to {path}")
    return 0


def cmd_validate(args) -> int:
    from audio_frontend.errors import VoiceError
    from audio_frontend.labelled import find_labelled, score_files
    from audio_frontend.report import format_table, summarize
    from audio_frontend.scorers import make_scorer

    cfg = _load(args)
    try:
        files, unknown = find_labelled(args.dir)
        if not files:
            print(f"protamer: no labelled recordings in {args.dir}: put them in pos/ and neg/ subfolders or "
                  f"name them pos_*.wav / neg_*.wav", file=sys.stderr)
            return 3
        if args.scorer == "prosody":
            scorer = make_scorer(cfg, "prosody", need_tau=False)   # the sign of tanh(v/tau) is the sign of v
            fn = lambda x: (scorer.valence(x)[0], {})  # noqa: E731
        else:
            scorer = make_scorer(cfg, "whisper")
            fn = scorer.score
        rows = score_files(files, cfg, fn)
    except VoiceError as e:
        return _fail(e)
    summary = summarize(rows, args.scorer)
    summary["skipped_unlabelled"] = [str(u) for u in unknown]
    if args.json:
        print(json.dumps(summary, sort_keys=True))
    else:
        print(format_table(summary))
    return 0 if summary["n_scored"] else 3


def register(subparsers) -> None:
    p = subparsers.add_parser("listen", help="voice feedback: microphone (or WAV) -> VAD -> scorer -> events",
                              description="Print one JSON feedback event per utterance (stdout).")
    _common(p)
    p.add_argument("--scorer", choices=("prosody", "whisper"), default="prosody")
    p.add_argument("--wav", default=None, help="read this file instead of the microphone")
    p.add_argument("--realtime", action="store_true", help="with --wav: play the file at real-time speed")
    p.add_argument("--save-segments", default=None, metavar="DIR", help="save each scored segment as WAV here")
    p.add_argument("--log", default=None, metavar="FILE", help="also append events to this JSONL feedback log")
    p.add_argument("--max-events", type=int, default=None, help="stop after this many utterances")
    p.add_argument("--uncalibrated", action="store_true", help="prosody without calibration (tau = 1)")
    p.set_defaults(handler=cmd_listen)

    p = subparsers.add_parser("calibrate", help="per-user prosody calibration: tau = median |valence|",
                              description="Record prompted positive/negative samples (or read --wav-dir) "
                                          "and write the calibration file.")
    _common(p)
    p.add_argument("--wav-dir", default=None, help="labelled recordings: pos/ and neg/ subfolders or pos_*/neg_* files")
    p.add_argument("--n", type=int, default=5, help="samples per sign when recording (default 5)")
    p.add_argument("--out", default=None, help="calibration file (default: prosody.calibration_path)")
    p.add_argument("--user", default="", help="a name stored in the calibration file")
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=cmd_calibrate)

    p = subparsers.add_parser("validate-voice", help="sign accuracy / confusion / latency on labelled recordings",
                              description="The paper's protocol: e.g. 10 positive and 10 negative recordings.")
    _common(p)
    p.add_argument("dir", help="folder with pos/ and neg/ subfolders or pos_*/neg_* files")
    p.add_argument("--scorer", choices=("prosody", "whisper"), default="prosody")
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=cmd_validate)
