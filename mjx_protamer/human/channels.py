"""Feedback channels: how long a person takes to react, speak and be understood, per modality. No JAX.

One place for the numbers that both the simulated teachers (`teachers.py`: when a feedback arrives) and
credit assignment (`credit.py`, scheme "channel": which steps a feedback is about) use, so the learner
credits a feedback over the delay distribution of the channel it came through.

A feedback about the step shown at time t starts (key press onset, utterance onset) at t + reaction delay,
delay ~ max(delay_min_s, Normal(delay_mean_s, delay_std_s)); an utterance lasts duration_s; the pipeline
(VAD end-of-speech, transcription or scoring) adds latency_s before the event reaches the learner's queue.

Sources of the presets (each number is an assumption from the literature or a measurement of ours):
- reaction delay (delay_mean/std/min_s), all channels: assumed, from human reaction-time studies (a key press
  to a judged event 0.35 +- 0.1 s; starting to speak is slower, 0.6-0.8 s). No human was measured here.
- utterance length (duration_s) and pipeline latency (latency_s: end of speech to event on the queue, VAD
  hangover included) of prosody and speech: medians measured on our voice front end,
  docs/results/voice_channels.json (`protamer validate-voice DIR --per-speaker --scorer both` on the
  `protamer synth-voice` set: 6 espeak-ng voices, 168 signed test utterances, unseen sentences).
- prosody noise: the offline prosody scorer's measured sign accuracy 0.970 means P(sign flip) = 0.030; with
  value tanh(gain * score + N(0, noise_std)) and gain 2 that is noise_std = 2 / z(0.970) = 1.06.
- speech confusion: the measured outcome rates of Whisper tiny.en (10 s encoder window padded with silence,
  beam 5, keywords of the other hypotheses within 1.0, the filler gate) + rules + VADER (rows intended +1,
  0, -1; columns recognised +1, 0, -1; the 0 row pools neutral sentences and fillers), on the set
  regenerated with fillers said as fillers (`synth-voice` 2026-12-02; espeak had spelled "mm" as "em-em" and
  its Scottish voice glided "er" into "yeah").
- both latencies were measured on a 2-core machine shared with other jobs (load average 2-3.2): scoring
  is slower there than on an idle machine; the VAD's wait (0.355 s median) is not. Whisper's includes the
  filler gate's forced decode on short signed transcripts.
Synthesised voices are not real recordings: real speech will differ, and a person's own delays more so.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Literal

from mjx_protamer.config import check

KINDS = ("keyboard", "prosody", "speech")

PRESETS = {
    # reaction delay mean/std/min (s), utterance duration (s), processing latency (s), prosody noise, speech confusion
    "keyboard": dict(delay_mean_s=0.35, delay_std_s=0.1, delay_min_s=0.15, duration_s=0.0, latency_s=0.0,
                     noise_std=0.0, confusion=(1, 0, 0, 0, 1, 0, 0, 0, 1)),
    "prosody": dict(delay_mean_s=0.6, delay_std_s=0.2, delay_min_s=0.25, duration_s=0.865, latency_s=0.365,
                    noise_std=1.06, confusion=(1, 0, 0, 0, 1, 0, 0, 0, 1)),
    "speech": dict(delay_mean_s=0.8, delay_std_s=0.25, delay_min_s=0.3, duration_s=0.865, latency_s=0.528,
                   noise_std=0.0, confusion=(72 / 84, 12 / 84, 0 / 84, 0 / 36, 34 / 36, 2 / 36, 1 / 84, 8 / 84, 75 / 84)),
}
MEASURED_IN = "docs/results/voice_channels.json"  # where the prosody and speech measurements come from


@dataclasses.dataclass(frozen=True)
class ChannelConfig:
    # the channel the feedback comes through; its PRESETS fill the fields left null
    kind: Literal["keyboard", "prosody", "speech"] = "keyboard"
    delay_mean_s: float | None = None  # reaction delay mean (s); None: the kind's preset
    delay_std_s: float | None = None  # reaction delay std; None: the kind's preset
    # the fastest reaction (the delay is max(delay_min_s, Normal(mean, std))); None: the kind's preset
    delay_min_s: float | None = None
    duration_s: float | None = None  # key press 0; an utterance's length (t_end - t_start)
    latency_s: float | None = None  # processing after t_end before the event reaches the queue
    gain: float = 2.0  # prosody: value = tanh(gain * score + noise)
    noise_std: float | None = None  # prosody: the std of the noise in the value above; None: the kind's preset
    # speech: P(recognised | intended), rows intended (+1, 0, -1), columns recognised (+1, 0, -1); None: preset
    confusion: tuple[float, ...] | None = None

    def validate(self) -> None:
        if self.confusion is not None:
            check(len(self.confusion) == 9, "confusion", f"needs 9 entries (3x3), got {len(self.confusion)}")
            for r in range(3):
                row = self.confusion[3 * r:3 * r + 3]
                check(min(row) >= 0 and abs(sum(row) - 1.0) < 1e-6, "confusion",
                      f"row {r} must be a distribution, got {row}")
        check(self.noise_std is None or self.noise_std >= 0, "noise_std", f"must be >= 0, got {self.noise_std}")
        for name in ("delay_mean_s", "delay_std_s", "delay_min_s", "duration_s", "latency_s"):
            v = getattr(self, name)
            check(v is None or v >= 0, name, f"must be >= 0, got {v}")

    def get(self, name: str) -> float:
        v = getattr(self, name)
        return float(PRESETS[self.kind][name] if v is None else v)

    @property
    def confusion_matrix(self) -> tuple[float, ...]:
        return tuple(PRESETS[self.kind]["confusion"] if self.confusion is None else self.confusion)

    @property
    def arrival_offset_s(self) -> float:
        """Time from the onset of a feedback (its t_start) to its arrival at the learner."""
        return self.get("duration_s") + self.get("latency_s")


def delay_cdf(x: float, channel: ChannelConfig) -> float:
    """P(reaction delay <= x) for delay = max(delay_min_s, Normal(delay_mean_s, delay_std_s))."""
    lo, mean, std = channel.get("delay_min_s"), channel.get("delay_mean_s"), channel.get("delay_std_s")
    if x < lo - 1e-9:  # (step boundaries often fall exactly on the fastest reaction)
        return 0.0
    if std == 0:
        return 1.0 if x >= max(mean, lo) else 0.0
    return 0.5 * (1.0 + math.erf((x - mean) / (std * math.sqrt(2.0))))


def delay_quantile_span(channel: ChannelConfig, mass: float = 0.999) -> tuple[float, float]:
    """(earliest, latest) reaction delay holding `mass` of the distribution (for window lengths)."""
    mean, std, lo = channel.get("delay_mean_s"), channel.get("delay_std_s"), channel.get("delay_min_s")
    z = 3.3 if mass >= 0.999 else 2.6
    return max(lo, mean - z * std), max(lo, mean + z * std)
