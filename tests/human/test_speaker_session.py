"""A live session with the simulated speaker: the voice channel end to end through the real listener process.

A simulated person with a hidden rule watches the toy infant at real-time pace and, after its reaction delay,
says praise or reproach (synthesised speech, `audio_frontend/speaker.py`); the listener (VAD -> prosody,
calibrated on that voice) puts events on the learner's queue; the learner credits them. What it meant and what
was delivered are compared in OUT/speaker.jsonl.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
RULE = "feedback.teacher.rule=[{signal: 'action:0', value: 1.0, above: 0.0}, {signal: 'action:0', value: -1.0, below: 0.0}]"


@pytest.mark.audio
@pytest.mark.parametrize("source", ["speaker", "speaker:words"])
def test_the_speakers_words_reach_the_learner_as_events_whose_credit_covers_the_step_it_meant(toy_run, tmp_path,
                                                                                              source):
    from audio_frontend.synth import missing_tools

    if missing_tools():
        pytest.skip(f"needs {', '.join(missing_tools())} (apt-get install espeak-ng sox); CI installs them")
    pytest.importorskip("parselmouth")
    out = tmp_path / "speaker"
    env = {**os.environ, "JAX_PLATFORMS": "cpu", "PYTHONUNBUFFERED": "1",
           "PROTAMER_SPEAKER_CACHE": str(tmp_path / "speaker-cache")}
    p = subprocess.run([sys.executable, "-m", "mjx_protamer.cli", "finetune", "--checkpoint", str(toy_run),
                        "--out", str(out), "--view", "none", "--feedback", "prosody", "--listen-source", source,
                        "--seconds", "15", "--set", RULE],
                       capture_output=True, text=True, env=env, cwd=ROOT, timeout=600)
    text = p.stdout + p.stderr
    assert p.returncode == 0, text
    rows = [json.loads(line) for line in (out / "speaker.jsonl").read_text().splitlines()]
    summary = rows[-1]["summary"]
    said = [r for r in rows[:-1] if "t_start" in r]
    delivered = [r for r in said if r["outcome"] == "delivered"]
    # the speaker spoke, the pipeline heard it: events with the meant sign, credited over the meant step
    assert len(said) >= 4 and len(delivered) >= 0.75 * len(said), summary
    assert all(r["sign"] in (1.0, -1.0) and r["requested_t"] <= r["t_start"] + 0.05 for r in said)
    # about nine in ten heard with the meant sign: a 15 s session delivers 9-12 utterances, so one heard wrong
    # is 0.89 (with the shipped step size 3e-4 one of 9 was, in 3 of 4 runs; with 1e-3 none)
    assert summary["sign_accuracy"] >= 0.85, summary
    covered = [r["credit_covers_meant_step"] for r in delivered if "credit_covers_meant_step" in r]
    assert len(covered) >= 3 and sum(covered) >= 0.6 * len(covered), delivered
    # the learner took them as prosody events, and the reward model learnt from them
    events = [json.loads(line) for line in (out / "feedback.jsonl").read_text().splitlines()]
    accepted = [e for e in events if e.get("status") == "accepted" and e.get("source") == "prosody"]
    assert len(accepted) >= len(delivered) and "accepted, credited steps" in text
    assert "[speaker] said" in text and "[voice] prosody" in text
    manifest = json.loads((out / "session.json").read_text())
    assert manifest["listen_source"] == source and manifest["measured_pace"][-1]["realtime"] > 0.9
    # in sentences, or (speaker:words) one keyword at a time, about one a second
    from audio_frontend.speaker import SPEAKER_WORDS

    words = {w for group in SPEAKER_WORDS for w in group}
    assert all((r["said"] in words) == (source == "speaker:words") for r in said), [r["said"] for r in said]
