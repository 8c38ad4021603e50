"""The host process: source -> VAD -> scorer -> one FeedbackEvent per utterance on the FeedbackQueue.

The learner starts it with `start_listener(queue, config, scorer=..., source=...)`, which returns the
`multiprocessing.Process` (spawn context, daemon). It never imports JAX. If it dies, `proc.exitcode`
says how (see `audio_frontend.errors.describe_exit`); the learner keeps going without voice feedback.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import sys
import time
from pathlib import Path

import numpy as np

from audio_frontend.errors import VoiceError
from audio_frontend.vad import Segment, Segmenter
from mjx_protamer.human.events import FeedbackEvent


def save_segment(directory: str | Path, seg: Segment, source: str, value: float, details: dict) -> str:
    """One WAV per scored segment plus a line in segments.jsonl (for session replay)."""
    import soundfile as sf

    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    name = f"{seg.t_start:.3f}_{source}.wav"
    sf.write(str(d / name), seg.audio, seg.sample_rate, subtype="PCM_16")
    with open(d / "segments.jsonl", "a", encoding="utf-8") as fh:
        fh.write(json.dumps({"file": name, "t_start": seg.t_start, "t_end": seg.t_end, "source": source,
                             "value": value, "details": details}, sort_keys=True) + "\n")
    return str(d / name)


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return float(x) if np.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def event_for(seg: Segment, scorer, value: float, details: dict, t_done: float) -> FeedbackEvent:
    details = dict(details)
    details.update(segment_s=round(seg.duration_s, 3), vad_reason=seg.reason, t_onset=seg.t_onset,
                   latency_s=t_done - seg.t_end)
    return FeedbackEvent(t_start=seg.t_start, t_end=seg.t_end, source=scorer.source,
                         value=float(np.clip(value, -1.0, 1.0)), details=_jsonable(details))


def run_listener(queue, config, scorer, source, stop_event=None, save_dir: str | None = None,
                 max_events: int | None = None, on_event=None, log=sys.stderr, ready_event=None) -> dict:
    """Blocking loop (in this process). `scorer` is a loaded scorer object. Returns counters.
    `ready_event` (a multiprocessing Event) is set once the scorer is warm, just before listening."""
    a = config.audio
    segmenter = Segmenter(config.vad, a.sample_rate, a.chunk_s)
    save_dir = save_dir if save_dir is not None else (config.listen.save_segments_dir or None)
    stats = {"segments": 0, "events": 0, "rejected": 0, "dropped_short": 0}

    def handle(seg: Segment) -> None:
        value, details = scorer.score(seg.audio)
        ev = event_for(seg, scorer, value, details, time.time())
        if save_dir:
            path = save_segment(save_dir, seg, scorer.source, ev.value, ev.details)
            ev = FeedbackEvent(ev.t_start, ev.t_end, ev.source, ev.value, {**ev.details, "segment_path": path})
        ok = queue.put(ev) if queue is not None else True
        stats["segments"] += 1
        stats["events" if ok else "rejected"] += 1
        if on_event is not None:
            on_event(ev, ok)
        if log is not None and config.listen.log_every_event:
            extra = ev.details.get("transcript", ev.details.get("valence"))
            extra = round(extra, 3) if isinstance(extra, float) else extra
            print(f"[voice] {scorer.source} {ev.value:+.3f} ({extra!r}) seg {seg.duration_s:.2f}s "
                  f"latency {ev.details['latency_s']:.3f}s{'' if ok else ' NOT QUEUED'}", file=log, flush=True)

    warm_up = getattr(scorer, "warm_up", None)
    if warm_up is not None:   # the first call allocates: pay for it before the first utterance, not during it
        warm_up()
    if ready_event is not None:
        ready_event.set()
    try:
        for t, chunk in source.chunks():
            for seg in segmenter.feed(t, chunk):
                handle(seg)
            if (stop_event is not None and stop_event.is_set()) or (
                    max_events is not None and stats["segments"] >= max_events):
                break
        else:
            for seg in segmenter.flush():
                handle(seg)
    finally:
        source.close()
    stats["dropped_short"] = segmenter.dropped_short
    return stats


def _listener_main(queue, config, scorer_name, source, stop_event, save_dir, scorer_kwargs, ready_event=None):
    try:
        from audio_frontend.scorers import make_scorer

        scorer = make_scorer(config, scorer_name, **(scorer_kwargs or {}))
        print(f"[voice] listening ({scorer_name}); events go to the feedback queue", file=sys.stderr, flush=True)
        run_listener(queue, config, scorer, source, stop_event=stop_event, save_dir=save_dir, ready_event=ready_event)
    except VoiceError as e:
        print(f"[voice] listener stopped: {e}", file=sys.stderr, flush=True)
        sys.exit(e.exit_code)
    except KeyboardInterrupt:
        sys.exit(0)


def start_listener(queue, config, scorer: str = "prosody", source=None, save_dir: str | None = None,
                   stop_event=None, scorer_kwargs: dict | None = None, ctx=None, ready_event=None) -> mp.Process:
    """Start the voice listener as a daemon host process and return it.

    queue: a `mjx_protamer.human.queue.FeedbackQueue`; config: a `VoiceConfig`; scorer: "prosody" or
    "whisper"; source: an AudioSource (default: the microphone from config.audio); save_dir: save each
    scored segment as WAV there (default config.listen.save_segments_dir); stop_event: a multiprocessing
    Event that ends the loop (else terminate the process); ready_event: a multiprocessing Event the listener
    sets once its model is loaded and warm (loading torch and a model takes seconds, a minute on a busy
    machine: a learner that says "speak now" before that loses what is said). Check `proc.is_alive()` /
    `proc.exitcode`.
    """
    if scorer not in ("prosody", "whisper"):
        raise ValueError(f"unknown scorer {scorer!r}; use 'prosody' or 'whisper'")
    if source is None:
        from audio_frontend.sources import make_source
        source = make_source(config)
    ctx = ctx or mp.get_context("spawn")
    proc = ctx.Process(target=_listener_main, name=f"voice-{scorer}", daemon=True,
                       args=(queue, config, scorer, source, stop_event, save_dir, scorer_kwargs, ready_event))
    proc.start()
    return proc


def listener_status(proc: mp.Process | None) -> str | None:
    """None while the listener runs; otherwise the line the learner should print once."""
    from audio_frontend.errors import describe_exit

    if proc is None or proc.is_alive():
        return None
    return describe_exit(proc.exitcode) + "; training goes on without voice feedback"


os.environ.setdefault("TOKENIZERS_PARALLELISM", "false")
