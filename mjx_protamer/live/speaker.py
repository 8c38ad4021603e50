"""A simulated person who watches the infant and speaks (`finetune --feedback prosody|whisper --listen-source
speaker`, or `speaker:words` for one who speaks in single words): the voice channels end to end, with nobody at
the microphone.

A host teacher with the session's hidden rule (`feedback.teacher`) scores each chunk's steps as they are shown;
when it decides to give feedback it waits its reaction delay (the voice channel's: prosody 0.6 +- 0.2 s, speech
0.8 +- 0.25 s, human/channels.py) and *says* praise or reproach: a command to an `audio_frontend.speaker.
SpeakerSource`, which plays a synthesised sentence in the matching tone (the synth-voice set's sentences, one
espeak-ng voice) at real-time pace into the real listener process: VAD -> prosody (calibrated on that voice's
calibration sentences, `calibrate_speaker`) or Whisper + sentiment -> the learner's queue. Like a person, it
does not talk over itself: a decision while it is still speaking (or pausing after) is not said. In sentences
("that's it, perfect") it says about one thing in 1.4 s; in single words ("yes", "no") about one a second, the
rate at which a keyboard teacher's words taught (docs/human_feedback.md, "How often a teacher must speak").

What it meant and what the pipeline delivered are kept side by side: `OUT/speaker.jsonl` has one line per
utterance (the step it was about, the sign meant, when the words were said, the event delivered: its value,
its latency from the end of the words, or that it was missed) and the session prints the totals (delivered,
sign accuracy, misses, latency). No JAX in the audio process; the teacher's scoring is the host teacher's.
"""

from __future__ import annotations

import dataclasses
import json
import queue as queue_lib
from pathlib import Path

import numpy as np

from mjx_protamer.live.sources import Source, VoiceSource

VOICE = "en-us"  # the speaker's espeak-ng voice (the synth-voice set's first)
# An utterance's typical length (the bank's test sentences average 0.91 s of words, its single words 0.45 s): the
# speaker is busy this long after it starts, plus the pause (audio_frontend.speaker.GAP_S).
SPEAKING_S = {"sentences": 0.9, "words": 0.45}
MATCH_BEFORE_S, MATCH_AFTER_S = 0.6, 0.3  # an event belongs to an utterance if its segment starts this close


def _bank_dir(voice: str, seed: int) -> Path:
    import os

    root = Path(os.environ.get("PROTAMER_SPEAKER_CACHE", Path.home() / ".cache" / "mjx_protamer" / "speaker"))
    return root / f"{voice.replace('+', '_')}-{seed}"


def speaker_voice_config(spec):
    """The voice config a speaker session listens with: the session's, with the prosody calibration fitted on
    the speaker's voice (cached beside its sentences, per front-end settings). Builds the sentences once."""
    import dataclasses as dc

    from audio_frontend.config import load_voice_config
    from audio_frontend.speaker import SpeakerBank, calibrate_speaker

    directory = _bank_dir(VOICE, spec.config.feedback.seed % 4)
    bank = SpeakerBank.build(directory, VOICE, seed=spec.config.feedback.seed % 4)
    cfg = load_voice_config(spec.voice_config, list(spec.voice_set))
    if spec.feedback == "prosody" and cfg.prosody.kind == "features":
        import hashlib

        settings = json.dumps(dc.asdict(cfg.prosody) | {"audio": dc.asdict(cfg.audio), "vad": dc.asdict(cfg.vad)},
                              sort_keys=True, default=str)
        path = directory / f"calibration-{hashlib.sha256(settings.encode()).hexdigest()[:12]}.json"
        if not path.is_file():  # the voice's calibration for these settings, fitted once
            calibrate_speaker(bank, cfg, path)
        cfg = dc.replace(cfg, prosody=dc.replace(cfg.prosody, calibration_path=str(path)))
    return cfg


def speaker_teacher(teacher, feedback: str):
    """The speaker's teacher: the session's rule and giving model, the voice channel's reaction delay, and its
    intent exact (what the pipeline makes of the words is the pipeline's own, not a channel model's)."""
    from mjx_protamer.human.channels import PRESETS, ChannelConfig

    preset = PRESETS["speech" if feedback == "whisper" else "prosody"]
    channel = ChannelConfig(kind="keyboard", delay_mean_s=preset["delay_mean_s"], delay_std_s=preset["delay_std_s"],
                            delay_min_s=preset["delay_min_s"], duration_s=0.0, latency_s=0.0)
    return dataclasses.replace(teacher, channel=channel)


class SimulatedSpeaker(Source):
    name = "simulated speaker"

    def __init__(self, spec, queue, env, segment: int):
        import multiprocessing as mp

        from audio_frontend.speaker import GAP_S, SpeakerSource, make_speaker_channel
        from mjx_protamer.human.teachers import HostTeacher, env_signal_columns

        fc = spec.config.feedback
        cfg = speaker_voice_config(spec)
        seed = fc.seed + 7919 * segment
        self.commands, self.spoken = make_speaker_channel(mp.get_context("spawn"))
        self.says = spec.speaker_says
        self.busy_s = SPEAKING_S[self.says] + GAP_S  # from the start of its words until it may speak again
        audio = SpeakerSource.from_config(cfg, _bank_dir(VOICE, fc.seed % 4), self.commands, self.spoken, seed=seed,
                                          says=self.says)
        self.voice = VoiceSource(queue, cfg, spec.feedback, audio, spec.listen_source,
                                 spec.save_segments or str(spec.out / "segments"))
        teacher = speaker_teacher(fc.teacher, spec.feedback)
        self.teacher = HostTeacher(teacher, fc.dt, seed=seed)
        self.columns = env_signal_columns(teacher.signals, env)
        self.path = spec.out / "speaker.jsonl"
        self.meant: dict[int, dict] = {}  # command id -> what the speaker meant, then what was said
        self.events: list = []  # every feedback event the learner drained
        self.credits: list = []  # for each, (first, last) step its credit covered, or None
        self.busy_until = -np.inf
        self.held_back = 0
        self._next_id = 0
        self.started = False

    def start(self) -> None:
        self.voice.start()
        self.started = True

    def observe(self, chunk) -> None:
        """Score the chunk's steps; say what the teacher gives, unless still speaking."""
        from mjx_protamer.human.teachers import rule_signals

        signals = rule_signals(self.columns, chunk.obs, chunk.action, chunk.reward_terms, chunk.region_mask, xp=np)
        self.teacher.observe(chunk.first_step, chunk.times, signals)
        decisions = self.teacher.take_scheduled()
        if not self.started:  # nobody listens before the listener runs: those decisions are not said
            return
        for event in decisions:
            if event.t_start < self.busy_until:
                self.held_back += 1
                continue
            cid = self._next_id
            self._next_id += 1
            self.busy_until = event.t_start + self.busy_s
            self.meant[cid] = {"id": cid, "about_step": event.details["about_step"], "sign": float(np.sign(event.value)),
                               "score": event.details["score"], "requested_t": event.t_start}
            self.commands.put({"id": cid, "t": event.t_start, "sign": int(np.sign(event.value))})
        self._read_spoken()

    def drained(self, outcomes) -> None:
        for o in outcomes:
            if o.event.source != "attention":
                self.events.append(o.event)
                steps = getattr(o.got, "steps", None)  # a DDPG credit: the steps it credited
                self.credits.append((min(steps), max(steps)) if steps else None)

    def _read_spoken(self) -> None:
        while True:
            try:
                r = self.spoken.get_nowait()
            except (queue_lib.Empty, OSError, EOFError):
                return
            if "error" in r:
                print(f"[speaker] command {r.get('id')} refused: {r['error']}", flush=True)
                continue
            self.meant.setdefault(r["id"], {}).update(said=r["text"], t_start=r["t_start"], t_end=r["t_end"],
                                                      delay_s=r["delay_s"])

    def poll(self) -> str | None:
        self._read_spoken()
        return self.voice.poll()

    @property
    def exit_code(self) -> int:
        return self.voice.exit_code

    def ready_line(self) -> str:
        return (f"the simulated speaker watches and speaks in {self.says} (its words go through the real "
                "listener)")

    def stop(self) -> None:
        from audio_frontend.speaker import END

        if self.voice.process is not None:
            self.commands.put(END)
        self.voice.stop()
        self._read_spoken()

    def finish(self) -> None:
        self.report()

    def report(self) -> dict:
        """Match each utterance with the event its words became (or none); write speaker.jsonl; print totals."""
        rows = []
        used: set[int] = set()
        for m in sorted(self.meant.values(), key=lambda m: m.get("requested_t", 0.0)):
            row = dict(m)
            if "t_start" not in m:
                row["outcome"] = "not said (the session ended first)"
                rows.append(row)
                continue
            match = None
            for i, e in enumerate(self.events):
                if i not in used and m["t_start"] - MATCH_BEFORE_S <= e.t_start <= m["t_end"] + MATCH_AFTER_S:
                    match = i
                    break
            if match is None:
                row["outcome"] = "missed"
            else:
                used.add(match)
                e = self.events[match]
                arrival = e.t_end + float(e.details.get("latency_s", 0.0))
                row.update(outcome="delivered", value=e.value, sign_right=bool(np.sign(e.value) == m["sign"]),
                           latency_s=arrival - m["t_end"], transcript=e.details.get("transcript"),
                           credited=self.credits[match])
                if self.credits[match] is not None:
                    lo, hi = self.credits[match]
                    row["credit_covers_meant_step"] = bool(lo <= m["about_step"] <= hi)
            rows.append(row)
        stray = [e for i, e in enumerate(self.events) if i not in used and e.value != 0]
        said = [r for r in rows if "t_start" in r]
        got = [r for r in said if r["outcome"] == "delivered"]
        signed = [r for r in got if r["value"] != 0]
        covers = [r["credit_covers_meant_step"] for r in got if "credit_covers_meant_step" in r]
        summary = {"meant": len(rows), "said": len(said), "delivered": len(got), "missed": len(said) - len(got),
                   "held_back": self.held_back,
                   "sign_accuracy": float(np.mean([r["sign_right"] for r in signed])) if signed else None,
                   "zero_valued": len(got) - len(signed),
                   "latency_s_median": float(np.median([r["latency_s"] for r in got])) if got else None,
                   "credit_covers_meant_step": float(np.mean(covers)) if covers else None,
                   "stray_events": len(stray)}
        with open(self.path, "w", encoding="utf-8") as fh:
            for r in rows:
                fh.write(json.dumps(r, sort_keys=True) + "\n")
            fh.write(json.dumps({"summary": summary}, sort_keys=True) + "\n")
        acc = "-" if summary["sign_accuracy"] is None else f"{summary['sign_accuracy']:.2f}"
        cov = "-" if summary["credit_covers_meant_step"] is None else f"{summary['credit_covers_meant_step']:.2f}"
        lat = "-" if summary["latency_s_median"] is None else f"{summary['latency_s_median']:.2f} s"
        print(f"[speaker] said {summary['said']} of {summary['meant']} meant ({self.held_back} held back while "
              f"speaking); delivered {summary['delivered']}, missed {summary['missed']}, sign accuracy {acc}, "
              f"{summary['zero_valued']} scored 0, latency from the end of the words {lat} (median); credit "
              f"covers the meant step for {cov} of the credited; "
              f"{summary['stray_events']} stray events; {self.path}", flush=True)
        return summary
