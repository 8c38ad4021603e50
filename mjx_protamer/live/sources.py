"""Where a live session's feedback comes from: each source puts FeedbackEvents into the learner's queue.

- `KeyboardSource`: + / - / 0 in the terminal (a host thread; q asks the session to stop);
- the page: the live view's + / - / 0 buttons feed the same queue from the view process (live/sinks.py starts
  the view; nothing to run here);
- `VoiceSource`: the voice listener process (audio_frontend: microphone or WAV -> VAD -> prosody or Whisper +
  sentiment -> queue);
- `SimulatedTeacher`: a host teacher with a hidden rule who watches the chunks and presses keys after its
  reaction delay, on the session's clock;
- `SimulatedSpeaker` (live/speaker.py): a host teacher who, after its reaction delay, speaks: synthesised
  praise or reproach streamed at real-time pace into a `VoiceSource`'s listener.

A source has `start()` (once the first chunk has run: compiled and shown), `observe(chunk)` (after each chunk),
`drained(outcomes)` (what the learner then drained), `finish()` (after the last drain), `poll()` (a line to print once: the listener died, the WAV is over), `finished` (the session should end: a
recording is over), `stop_requested` (the person asked to stop), `stop()` and `exit_code` (non-zero when it
died). Sources never import JAX beyond what the host teacher needs.
"""

from __future__ import annotations

import multiprocessing as mp
import time

# How long a live session waits for the voice listener to load torch and its model before going on.
LISTENER_LOAD_TIMEOUT_S = 300.0


class Source:
    name = "source"
    finished = False
    exit_code = 0

    def start(self) -> None:
        pass

    def observe(self, chunk) -> None:
        pass

    def drained(self, outcomes) -> None:
        """The learner drained these (a simulated speaker matches what it said with what arrived)."""

    def poll(self) -> str | None:
        return None

    @property
    def stop_requested(self) -> bool:
        return False

    def finish(self) -> None:
        """After the session's last drain."""

    def stop(self) -> None:
        pass

    def ready_line(self) -> str | None:
        """What the person is told to do once the source runs."""
        return None


class KeyboardSource(Source):
    name = "keyboard"

    def __init__(self, queue):
        self.queue = queue
        self.keys = None

    def start(self) -> None:
        from mjx_protamer.human.keyboard import KeyboardFeedback

        self.keys = KeyboardFeedback(self.queue).start()

    @property
    def stop_requested(self) -> bool:
        return self.keys is not None and self.keys.stop_requested.is_set()

    def stop(self) -> None:
        if self.keys is not None:
            self.keys.stop()

    def ready_line(self) -> str:
        return "give feedback now (+ good, - bad, 0 neutral, q quit)"


class PageSource(Source):
    """The live page's buttons: the view process feeds the queue; this source only says so."""
    name = "page"

    def ready_line(self) -> str:
        return "give feedback now (the page's + / - / 0)"


class SimulatedTeacher(Source):
    """A simulated teacher at the keyboard (or any channel's giving and delay model): scores each chunk's steps
    with its hidden rule and puts the events it gives into the queue once their arrival time has come."""

    name = "simulated teacher"

    def __init__(self, queue, teacher, dt: float, seed: int, env, clock):
        from mjx_protamer.human.teachers import HostTeacher, env_signal_columns

        self.queue = queue
        self.teacher = HostTeacher(teacher, dt, seed=seed)
        self.columns = env_signal_columns(teacher.signals, env)
        self.clock = clock

    def observe(self, chunk) -> None:
        import numpy as np

        from mjx_protamer.human.teachers import rule_signals

        signals = rule_signals(self.columns, chunk.obs, chunk.action, chunk.reward_terms, chunk.region_mask, xp=np)
        self.teacher.observe(chunk.first_step, chunk.times, signals)
        self.teacher.emit_due(self.queue, self.clock())


class VoiceSource(Source):
    """The voice listener in its own process (spawn; no JAX there), started once the session runs."""

    name = "voice"

    def __init__(self, queue, voice_config, scorer: str, audio, listen_source: str, save_dir: str | None,
                 keywords_only: bool = False):
        self.queue, self.config, self.scorer = queue, voice_config, scorer
        self.audio, self.listen_source, self.save_dir = audio, listen_source, save_dir
        self.keywords_only = keywords_only
        self.process = None
        self.stop_event = None
        self._said = False
        self._over = False

    def start(self) -> None:
        from audio_frontend.listen import start_listener

        ctx = mp.get_context("spawn")
        self.stop_event, ready = ctx.Event(), ctx.Event()
        kwargs = {"load_classifier": False} if self.keywords_only and self.scorer == "whisper" else None
        self.process = start_listener(self.queue, self.config, scorer=self.scorer, source=self.audio,
                                      save_dir=self.save_dir, stop_event=self.stop_event, ready_event=ready,
                                      scorer_kwargs=kwargs)
        print(f"[finetune] voice listener ({self.scorer}, {self.listen_source}) started, pid {self.process.pid}; "
              "its lines start with [voice]; waiting for it to load its model", flush=True)
        # What a person says before the model is loaded would be lost, and "speak now" would be untrue.
        t0 = time.time()
        while not ready.is_set() and self.process.is_alive() and time.time() - t0 < LISTENER_LOAD_TIMEOUT_S:
            ready.wait(0.2)
        if self.process.is_alive() and not ready.is_set():
            print(f"[finetune] note: the voice listener is still loading after {LISTENER_LOAD_TIMEOUT_S:.0f} s; "
                  "going on, its events will arrive once it is ready", flush=True)

    def poll(self) -> str | None:
        from audio_frontend.listen import listener_status

        if self.process is None or self._said:
            return None
        said = listener_status(self.process)
        if said is None:
            return None
        self._said = True
        if self.process.exitcode == 0 and self.listen_source.startswith("wav:"):
            # a recorded session replayed: its last events are in; one more chunk drains them
            self._over = True
            return "the WAV file is over: finishing"
        self.exit_code = max(self.process.exitcode or 1, 1)
        return said

    @property
    def finished(self) -> bool:
        return self._over

    def ready_line(self) -> str:
        return "give feedback now (speak)"

    def stop(self) -> None:
        from audio_frontend.listen import listener_status

        p = self.process
        if p is None:
            return
        if p.is_alive() and self.listen_source.startswith("wav:") and not self._said:
            # A recording ends on its own: give a listener that is still loading (slow on a busy machine) a
            # moment to finish or fail, so its outcome is reported.
            p.join(10.0)
        said = listener_status(p)
        if said is not None and not self._said and p.exitcode != 0:
            print(f"[finetune] {said}", flush=True)
        if p.exitcode not in (None, 0):  # died before we stopped it
            self.exit_code = max(p.exitcode, 1)
        self.stop_event.set()
        p.join(2.0)
        if p.is_alive():
            p.terminate()
            p.join(2.0)


def voice_setup(voice_config_path, voice_set, listen_source: str):
    """(voice config, audio source) for a microphone or a WAV, or raise VoiceError / ConfigError before
    anything heavy is loaded (the speaker's source is built by live/speaker.py)."""
    from audio_frontend.config import load_voice_config
    from audio_frontend.sources import check_input_device, make_source
    from mjx_protamer.config import ConfigError

    cfg = load_voice_config(voice_config_path, list(voice_set))
    if listen_source == "mic":
        check_input_device(cfg.audio.device)  # AudioDeviceError with the fix when there is no microphone
        return cfg, make_source(cfg)
    if listen_source.startswith("wav:") and len(listen_source) > 4:
        source = make_source(cfg, wav=listen_source[4:], realtime=True)
        _ = source.audio  # a missing, corrupt or silent file fails here, with its reason
        return cfg, source
    raise ConfigError(f"--listen-source must be 'mic', 'wav:PATH', 'speaker' or 'speaker:words', got "
                      f"{listen_source!r}")
