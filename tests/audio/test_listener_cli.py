"""The host process (in-process loop and spawned Process) and the voice commands."""

import json
import time

import numpy as np
import pytest
import soundfile as sf

from audio_frontend.synth import with_silence
from mjx_protamer.human.events import validate_event
from mjx_protamer.human.queue import FeedbackQueue
from voice_helpers import SR, run_cli, voice_config, write_wav

pytestmark = pytest.mark.audio


def two_utterances(speech):
    a = with_silence(speech["good job"], 1.0, 1.0)
    b = with_silence(speech["no"], 0.0, 1.0)
    return np.concatenate([a, b]), (1.0, a.size / SR)


def test_run_listener_one_event_per_utterance_with_times_and_saved_segments(tiny_models, speech, tmp_path):
    from audio_frontend.listen import run_listener
    from audio_frontend.scorers import ProsodyScorer
    from audio_frontend.sources import ArraySource

    x, (on1, on2) = two_utterances(speech)
    cfg = voice_config("prosody.kind=wav2vec2", f"prosody.model={tiny_models['prosody_hap']}", "prosody.tau=0.5")
    q = FeedbackQueue()
    t0 = time.time() - x.size / SR - 1.0      # as if the audio had just been captured
    stats = run_listener(q, cfg, ProsodyScorer(cfg), ArraySource(x, SR, 0.25, t0=t0), save_dir=str(tmp_path), log=None)
    events = q.drain()
    assert stats["events"] == 2 and len(events) == 2
    for ev, onset in zip(events, (on1, on2)):
        validate_event(ev)
        assert ev.source == "prosody" and ev.value > 0
        assert ev.details["t_onset"] - t0 == pytest.approx(onset, abs=0.25)
        assert ev.t_start <= ev.details["t_onset"] < ev.t_end
        audio, sr = sf.read(ev.details["segment_path"], dtype="float32")
        assert sr == SR and audio.size / SR == pytest.approx(ev.t_end - ev.t_start, abs=1e-3)
    lines = (tmp_path / "segments.jsonl").read_text().splitlines()
    assert [json.loads(line_)["value"] for line_ in lines] == [ev.value for ev in events]


def test_start_listener_process_puts_events_and_reports_death(tiny_models, speech, tmp_path):
    from audio_frontend.listen import listener_status, start_listener
    from audio_frontend.sources import ArraySource

    x, _ = two_utterances(speech)
    q = FeedbackQueue()
    cfg = voice_config("prosody.kind=wav2vec2", f"prosody.model={tiny_models['prosody_hap']}", "prosody.tau=0.5")
    proc = start_listener(q, cfg, scorer="prosody", source=ArraySource(x, SR, 0.25, t0=time.time() - 10))
    events = []
    deadline = time.time() + 90
    while len(events) < 2 and time.time() < deadline:
        events += q.drain(timeout=1.0)
    proc.join(30)
    assert len(events) == 2 and all(e.source == "prosody" for e in events)
    assert proc.exitcode == 0 and "stopped normally" in listener_status(proc)
    # missing weights: the process exits with the MissingWeightsError code and the learner is told
    bad = voice_config("prosody.kind=wav2vec2", f"prosody.model={tmp_path / 'absent'}", "prosody.tau=0.5")
    proc = start_listener(q, bad, scorer="prosody", source=ArraySource(x, SR, 0.25))
    proc.join(60)
    assert proc.exitcode == 5
    assert "MissingWeightsError" in listener_status(proc) and "goes on without voice" in listener_status(proc)


@pytest.fixture
def labelled_dir(tmp_path, speech):
    d = tmp_path / "rec"
    for i, w in enumerate(["good job", "yes", "good job"]):
        write_wav(d / "pos" / f"p{i}.wav", with_silence(speech[w], 0.3, 0.5))
    for i, w in enumerate(["no", "bad", "no"]):
        write_wav(d / f"neg_{i}.wav", with_silence(speech[w], 0.3, 0.5))
    (d / "pos" / "broken.wav").write_bytes(b"RIFF....WAVEjunk")
    write_wav(d / "unlabelled.wav", speech["yes"])
    return d


def test_validate_voice_reports_accuracy_confusion_and_bad_files(tiny_models, labelled_dir, capsys):
    w2v = ["--set", "prosody.kind=wav2vec2", "--set", f"prosody.model={tiny_models['prosody_hap']}"]
    rc = run_cli("validate-voice", str(labelled_dir), "--json", *w2v)
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    # the tiny model always hears 'hap': positives right, negatives wrong
    assert out["confusion"] == {"pos": {"pos": 3, "neg": 0, "zero": 0}, "neg": {"pos": 3, "neg": 0, "zero": 0}}
    assert out["sign_accuracy"] == pytest.approx(0.5)
    assert out["n_errors"] == 1 and out["n_scored"] == 6 and out["mean_latency_s"] > 0
    assert any("broken.wav" in r["file"] and "not a readable" in r["error"] for r in out["rows"])
    assert out["skipped_unlabelled"][0].endswith("unlabelled.wav")
    rc = run_cli("validate-voice", str(labelled_dir), *w2v)
    table = capsys.readouterr().out
    assert "sign accuracy: 0.500 over 6 signed recordings (1 unusable)" in table and "outcomes" in table


def test_calibrate_refuses_one_sign_and_writes_a_good_calibration(tiny_models, labelled_dir, tmp_path, capsys,
                                                                   monkeypatch):
    out = tmp_path / "cal.json"
    base = ["calibrate", "--wav-dir", str(labelled_dir), "--out", str(out),
            "--set", "prosody.kind=wav2vec2", "--set", f"prosody.model={tiny_models['prosody_hap']}"]
    assert run_cli(*base) == 6                     # the tiny model gives every sample positive valence
    assert "all 6 samples have positive valence" in capsys.readouterr().err and not out.exists()
    # a scorer whose valence follows the folder label: calibration succeeds, tau = median |valence|
    from audio_frontend.scorers import ProsodyScorer
    vals = iter([-0.1, -0.3, -0.5, 0.2, 0.4, 0.6])   # files in name order: neg_0..2, then pos/p0..2
    monkeypatch.setattr(ProsodyScorer, "valence", lambda self, x: (next(vals), {}))
    assert run_cli(*base, "--json") == 0
    rec = json.loads(capsys.readouterr().out)
    assert rec["tau"] == pytest.approx(0.35) and json.loads(out.read_text())["tau"] == pytest.approx(0.35)
    assert rec["n_pos"] == 3 and rec["n_neg"] == 3 and rec["sign_accuracy"] == 1.0
    monkeypatch.undo()
    (labelled_dir / "neg_2.wav").unlink()
    (labelled_dir / "neg_1.wav").unlink()
    assert run_cli(*base) == 6
    assert "too few samples: 3 positive and 1 negative" in capsys.readouterr().err


def test_listen_command_on_a_wav_and_missing_calibration(tiny_models, speech, tmp_path, capsys):
    x, _ = two_utterances(speech)
    wav = write_wav(tmp_path / "session.wav", x)
    model = f"prosody.model={tiny_models['prosody_hap']}"
    rc = run_cli("listen", "--wav", str(wav), "--set", "prosody.kind=wav2vec2", "--set", model,
                 "--set", f"prosody.calibration_path={tmp_path / 'no.json'}")
    assert rc == 6 and "protamer calibrate" in capsys.readouterr().err
    rc = run_cli("listen", "--wav", str(wav), "--set", "prosody.kind=wav2vec2", "--set", model,
                 "--set", "prosody.tau=0.5", "--save-segments", str(tmp_path / "segs"), "--log", str(tmp_path / "fb.jsonl"))
    assert rc == 0
    events = [json.loads(line_) for line_ in capsys.readouterr().out.splitlines()]
    assert len(events) == 2 and {e["source"] for e in events} == {"prosody"}
    assert len(list((tmp_path / "segs").glob("*.wav"))) == 2
    from mjx_protamer.human.queue import FeedbackLog
    assert len(FeedbackLog.read(tmp_path / "fb.jsonl")) == 2
    empty = tmp_path / "empty.wav"
    empty.write_bytes(b"")
    assert run_cli("listen", "--wav", str(empty), "--set", "prosody.kind=wav2vec2", "--set", model,
                   "--set", "prosody.tau=0.5") == 3
    assert "empty" in capsys.readouterr().err


def test_the_listener_warms_the_scorer_up_before_the_first_utterance():
    """Whisper's first call allocates (0.5-0.9 s measured); the listener pays it before listening."""
    from audio_frontend.listen import run_listener
    from audio_frontend.scorers import WhisperScorer
    from audio_frontend.sources import ArraySource

    calls = []

    class Recorder:
        def transcribe(self, audio):
            calls.append(audio.size)
            return "good job"

    cfg = voice_config("sentiment.kind=vader")
    scorer = WhisperScorer(cfg, transcriber=Recorder(), load_classifier=False)
    x = np.concatenate([np.zeros(SR, np.float32), 0.3 * np.sin(np.arange(SR) * 0.1).astype(np.float32),
                        np.zeros(SR, np.float32)])
    events = []
    run_listener(None, cfg, scorer, ArraySource(x, SR, 0.25), on_event=lambda ev, ok: events.append(ev), log=None)
    assert calls[0] == SR // 2 and len(calls) == 2          # the warm-up on silence, then the utterance
    assert [e.value for e in events] == [1.0]
