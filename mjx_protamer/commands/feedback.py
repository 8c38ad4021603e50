"""`protamer finetune`: one env, live, learning from your keys or your voice.

    protamer finetune --checkpoint RUN --feedback keyboard                     # + / - / 0, q to stop
    protamer finetune --checkpoint RUN --feedback whisper --listen-source mic  # say "good job" / "no"
    protamer finetune --checkpoint RUN --feedback prosody --listen-source wav:session.wav
    protamer finetune --checkpoint RUN --feedback keyboard --learner coach     # Deep COACH instead of DDPG

Loads a pretrain run, runs ONE env in short jitted chunks (`--chunk-ms` of simulated time, 250 ms by
default) paced to real time, and between chunks drains the FeedbackQueue that the keyboard thread or the
voice listener process feeds. Learners:

- `ddpg` (default): the run's actor and critic go on learning with DDPG; each accepted event is credited
  to the steps shown before it and updates the DeepTAMER reward model, whose params enter the next chunk
  (reward `alpha * r_env + beta * r_hat`).
- `coach`: Deep COACH, a Gaussian policy learned from the feedback alone, on the run's env (a fresh
  policy, or `--coach-policy FILE` saved by an earlier session); each event corrects the window of steps
  before it (docs/human_feedback.md).

Each chunk prints a status line; each key press is confirmed at once and each drained event is shown with
what it credited. On exit (q, --seconds, --max-chunks, Ctrl-C) everything is saved into --out:
DDPG: checkpoints/ + config.yaml (loadable by `protamer eval --checkpoint OUT` and by finetune again),
reward_model.msgpack; COACH: coach_policy.msgpack; both: feedback.jsonl, feedback_config.yaml.
Exit codes: 0 normal end, 130 Ctrl-C / 143 SIGTERM (after saving), 2 a bad argument, checkpoint or terminal,
the voice front end's codes (3 audio input, 4 audio device, 5 missing weights, 6 calibration) when the audio
source, weights or calibration are unusable (checked before loading), or, at the end of a session that went on
without it, when the voice listener died.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from pathlib import Path

LIVE = ("keyboard", "prosody", "whisper")
FEEDBACK_CHOICES = ("keyboard", "prosody", "whisper", "simulated:keyboard", "simulated:prosody",
                    "simulated:speech", "none")


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "finetune",
        help="fine-tune a pretrained policy live with human feedback (keyboard or voice)",
        description="Runs one env live from a pretrain checkpoint; give feedback with + / - / 0 (q to stop) or "
        "by voice (prosody or Whisper). Saves the checkpoint, reward model / policy and feedback log on exit "
        "or Ctrl-C.",
    )
    p.add_argument("--feedback", choices=FEEDBACK_CHOICES, default="keyboard",
                   help="where feedback comes from (simulated:* for a dry run without a human; none: no feedback)")
    p.add_argument("--learner", choices=("ddpg", "coach"), default="ddpg",
                   help="ddpg: the checkpoint's DDPG + DeepTAMER reward model; coach: Deep COACH on the same env")
    p.add_argument("--checkpoint", type=Path, required=True, help="a pretrain run directory or checkpoint in it")
    p.add_argument("--config", type=Path, default=None, help="feedback YAML (configs/feedback_keyboard.yaml); "
                   "its pretrain section is replaced by the checkpoint's")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a feedback config value, e.g. --set feedback.credit.scheme=time_window")
    p.add_argument("--out", type=Path, default=None, help="output directory (default: runs/finetune-<time>)")
    p.add_argument("--chunk-ms", type=float, default=250.0, help="simulated time per jitted chunk (ms)")
    p.add_argument("--seconds", type=float, default=0.0, help="stop after this long (0: until q or Ctrl-C)")
    p.add_argument("--max-chunks", type=int, default=0, help="stop after this many chunks (0: no limit)")
    p.add_argument("--no-pace", action="store_true",
                   help="do not pace live chunks to real time (they are shown as fast as they are computed)")
    v = p.add_argument_group("voice (--feedback prosody|whisper)")
    v.add_argument("--listen-source", default="mic", metavar="mic|wav:PATH",
                   help="the microphone (default) or a WAV file played at real-time pace (the run ends with it)")
    v.add_argument("--voice-config", default=None, help="front-end YAML (default: configs/voice.yaml)")
    v.add_argument("--voice-set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a voice config field, e.g. --voice-set prosody.tau=0.2 (repeatable)")
    v.add_argument("--keywords-only", action="store_true",
                   help="whisper: decide by the keyword rules alone (no sentiment classifier weights needed); "
                   "an utterance that is not a single keyword gives 0")
    v.add_argument("--save-segments", default=None, metavar="DIR",
                   help="save each scored utterance as WAV there (default: OUT/segments)")
    c = p.add_argument_group("Deep COACH (--learner coach)")
    c.add_argument("--coach-policy", type=Path, default=None,
                   help="start from a coach_policy.msgpack of an earlier finetune --learner coach")
    c.add_argument("--coach-delay-s", type=float, default=0.3,
                   help="human reaction delay: an event corrects the window ending this long before it began")
    p.set_defaults(handler=_finetune)


def _fail(msg: str, code: int = 2) -> int:
    print(f"protamer finetune: {msg}", file=sys.stderr, flush=True)
    return code


def _voice_setup(args):
    """(voice config, audio source) or raise VoiceError / ConfigError before anything heavy is loaded."""
    from audio_frontend.config import load_voice_config
    from audio_frontend.sources import check_input_device, make_source
    from mjx_protamer.config import ConfigError

    cfg = load_voice_config(args.voice_config, args.voice_set)
    spec = args.listen_source
    if spec == "mic":
        check_input_device(cfg.audio.device)  # AudioDeviceError with the fix when there is no microphone
        return cfg, make_source(cfg)
    if spec.startswith("wav:") and len(spec) > 4:
        source = make_source(cfg, wav=spec[4:], realtime=True)
        _ = source.audio  # a missing, corrupt or silent file fails here, with its reason
        return cfg, source
    raise ConfigError(f"--listen-source must be 'mic' or 'wav:PATH', got {spec!r}")


class _Stopper:
    """SIGINT/SIGTERM: the first one stops after the current chunk (which then gets saved); a second
    SIGINT interrupts at once (still saving what there is)."""

    def __init__(self):
        self.signum: int | None = None
        self._old = {}

    def __enter__(self):
        for s in (signal.SIGINT, signal.SIGTERM):
            self._old[s] = signal.signal(s, self._handle)
        return self

    def _handle(self, signum, frame):
        if self.signum is not None and signum == signal.SIGINT:
            raise KeyboardInterrupt
        self.signum = signum
        name = "Ctrl-C" if signum == signal.SIGINT else "SIGTERM"
        print(f"\n[finetune] {name}: stopping after this chunk, then saving (Ctrl-C again to stop at once)",
              flush=True)

    def __exit__(self, *exc):
        for s, h in self._old.items():
            signal.signal(s, h)


def _finetune(args: argparse.Namespace) -> int:
    from mjx_protamer.config import ConfigError

    if args.chunk_ms <= 0:
        raise ConfigError("--chunk-ms must be > 0")
    if args.coach_delay_s < 0:
        raise ConfigError("--coach-delay-s must be >= 0")
    live = args.feedback in LIVE
    # Fail fast, before the minutes of loading and compiling, on what a live user can get wrong.
    if args.feedback == "keyboard" and not sys.stdin.isatty():
        return _fail("--feedback keyboard reads keys from the terminal, but stdin is not a terminal (tty). "
                     "Run it in an interactive terminal (or tmux/screen), or use --feedback simulated:keyboard "
                     "for a run without a human.")
    if args.learner == "coach" and args.coach_policy is not None and not args.coach_policy.is_file():
        return _fail(f"--coach-policy {args.coach_policy}: no such file (a coach_policy.msgpack written by "
                     f"`protamer finetune --learner coach`)")
    voice = None
    if args.feedback in ("prosody", "whisper"):
        from audio_frontend.errors import VoiceError
        try:
            voice = _voice_setup(args)
            from audio_frontend.preflight import check_voice_feedback  # calibration, weights: fail before loading
            print("[finetune] voice: " + "; ".join(check_voice_feedback(voice[0], args.feedback, args.keywords_only)),
                  flush=True)
        except VoiceError as e:
            from audio_frontend.errors import AudioDeviceError
            hint = " (here: --listen-source wav:PATH)" if isinstance(e, AudioDeviceError) else ""
            return _fail(f"{e}{hint}", e.exit_code)
    ckpt = Path(args.checkpoint)
    if not ckpt.exists():
        return _fail(f"--checkpoint {ckpt}: no such file or directory. Give a pretrain run directory "
                     f"(made by `protamer pretrain --out DIR`) or a finetune output directory.")
    from mjx_protamer.errors import CheckpointError
    from mjx_protamer.experiments.run_loader import resolve_checkpoint
    try:
        resolve_checkpoint(ckpt)
    except CheckpointError as e:
        return _fail(f"--checkpoint: {e} (expected DIR/config.yaml and DIR/checkpoints/<step>/)")

    print(f"[finetune] loading {ckpt} (the first chunk compiles: this can take a minute or two)", flush=True)
    try:
        loaded = _load(args, ckpt)
    except CheckpointError as e:
        return _fail(f"--checkpoint: {e}")
    except (FileNotFoundError, ValueError, KeyError) as e:
        return _fail(f"--checkpoint {ckpt} cannot be loaded: {type(e).__name__}: {e}")
    except Exception as e:  # orbax / msgpack errors of a truncated or foreign checkpoint
        if isinstance(e, ConfigError):
            raise
        return _fail(f"--checkpoint {ckpt} cannot be restored (corrupt, incomplete, or from another version of "
                     f"the config): {type(e).__name__}: {e}")
    return _session(args, live, voice, *loaded)


def _load(args, ckpt: Path):
    """(pretrain config, env, loaded train state, step)."""
    from mjx_protamer.experiments.run_loader import load_run
    return load_run(ckpt)


def _with_feedback_channel(fb, feedback: str):
    """Credit (and a simulated teacher) use the delay model of the channel the feedback comes through."""
    import dataclasses

    from mjx_protamer.human.teachers import with_channel

    kind = {"whisper": "speech", "prosody": "prosody"}.get(feedback)
    if feedback.startswith("simulated:"):
        kind = feedback.split(":", 1)[1]
    return fb if kind is None else dataclasses.replace(fb, teacher=with_channel(fb.teacher, kind))


def _session(args, live: bool, voice, pre, env, loaded, step) -> int:
    import dataclasses

    from mjx_protamer.human.tamer_loop import load_feedback_config

    fb = load_feedback_config(args.config, args.overrides).feedback
    fb = _with_feedback_channel(fb, args.feedback)
    chunk_steps = max(1, round(args.chunk_ms / 1000.0 / fb.dt))
    out = args.out or Path("runs") / time.strftime("finetune-%Y%m%d-%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    # A live run's events are stamped on the wall clock; the queue validates against it too.
    sim = None if live or args.feedback == "none" else args.feedback
    if args.learner == "coach":
        from mjx_protamer.human.coach_loop import CoachRun, CoachRunConfig
        from mjx_protamer.agents.coach import CoachConfig

        ccfg = CoachRunConfig(coach=CoachConfig(human_delay_steps=round(args.coach_delay_s / fb.dt)),
                              chunk_steps=chunk_steps, episode_length=pre.train.episode_length, dt=fb.dt,
                              queue_size=fb.queue_size, min_interval_steps=fb.credit.min_interval_steps,
                              seed=fb.seed)
        run = CoachRun(ccfg, env, feedback=sim, log_path=out / "feedback.jsonl", teacher=fb.teacher)
        if args.coach_policy is not None:
            run.load_policy(args.coach_policy)
        saved_config = {"coach": dataclasses.asdict(ccfg), "pretrain_run": str(args.checkpoint)}
    else:
        from mjx_protamer.human.tamer_loop import FeedbackRunConfig, TamerRun

        train = dataclasses.replace(pre.train, num_envs=1, chunk_steps=chunk_steps, warmup_env_steps=0,
                                    total_env_steps=max(pre.train.total_env_steps, chunk_steps), num_devices=1)
        ddpg = dataclasses.replace(pre.ddpg, replay_size=max(pre.ddpg.batch_size, 20_000, chunk_steps))
        config = FeedbackRunConfig(pretrain=dataclasses.replace(pre, train=train, ddpg=ddpg),
                                   feedback=dataclasses.replace(fb, watch_env=0))
        run = TamerRun(config, env, feedback=None if args.feedback == "none" else ("queue" if live else sim),
                       log_path=out / "feedback.jsonl")
        # The pretrained learner on a fresh single-env state (env batch, noise and replay are new).
        run.state = run.state.replace(**{k: getattr(loaded, k) for k in (
            "actor_params", "critic_params", "target_actor_params", "target_critic_params",
            "actor_opt_state", "critic_opt_state")})
        run.commit_state()  # restored arrays are uncommitted: the second chunk would compile again
        saved_config = None
    if run.log is not None:
        run.log.note(event="start", feedback=args.feedback, learner=args.learner, checkpoint=str(args.checkpoint),
                     checkpoint_step=int(step), chunk_steps=chunk_steps, dt=fb.dt)

    keys = listener = stop_event = None
    listener_said = wav_over = listener_died = False
    interrupted = False
    with _Stopper() as stopper:
        try:
            print(f"[finetune] {args.learner} from {args.checkpoint} (step {step}); chunks of {chunk_steps} steps "
                  f"({chunk_steps * fb.dt * 1000:.0f} ms); feedback {args.feedback}; output {out}", flush=True)
            _warm_up(run, args.learner)
            t_end = time.time() + args.seconds if args.seconds > 0 else float("inf")
            chunks = 0
            slow_said = False
            while time.time() < t_end and stopper.signum is None and not (keys and keys.stop_requested.is_set()):
                if args.max_chunks and chunks >= args.max_chunks:
                    break
                t0 = time.time()
                m = run.step_chunk(t0=t0 if live else None)
                chunks += 1
                _print_chunk(run, m, args.learner)
                _print_outcomes(run, args.learner)
                if chunks == 1:  # compiled and running: now the feedback sources start
                    if stopper.signum is not None:
                        break
                    if args.feedback == "keyboard":
                        from mjx_protamer.human.keyboard import KeyboardFeedback
                        keys = KeyboardFeedback(run.queue).start()
                    elif voice is not None:
                        import multiprocessing as mp

                        from audio_frontend.listen import start_listener
                        vcfg, source = voice
                        stop_event = mp.get_context("spawn").Event()
                        listener = start_listener(run.queue, vcfg, scorer=args.feedback, source=source,
                                                  save_dir=args.save_segments or str(out / "segments"),
                                                  stop_event=stop_event, scorer_kwargs=(
                                                      {"load_classifier": False} if args.keywords_only
                                                      and args.feedback == "whisper" else None))
                        print(f"[finetune] voice listener ({args.feedback}, {args.listen_source}) started, pid "
                              f"{listener.pid}; its lines start with [voice]", flush=True)
                    if live:
                        print("[finetune] ready: give feedback now" + (" (+ good, - bad, 0 neutral, q quit)"
                              if keys is not None else " (speak)"), flush=True)
                if listener is not None and not listener_said:
                    from audio_frontend.listen import listener_status
                    said = listener_status(listener)
                    if said is not None:
                        listener_said = True
                        if listener.exitcode == 0 and args.listen_source.startswith("wav:"):
                            # a recorded session replayed: its last events are in; one more chunk drains them
                            print("[finetune] the WAV file is over: finishing", flush=True)
                            wav_over = True
                        else:
                            print(f"[finetune] {said}", flush=True)
                elif wav_over:
                    break
                if live and not args.no_pace:  # show the chunk at real-time pace
                    spare = t0 + chunk_steps * fb.dt - time.time()
                    if spare > 0:
                        time.sleep(spare)
                    elif chunks > 1 and not slow_said:
                        print(f"[finetune] note: this machine runs chunks slower than real time "
                              f"({chunk_steps * fb.dt / (time.time() - t0):.2f}x); feedback is mapped to "
                              f"the steps shown when you gave it", flush=True)
                        slow_said = True
        except KeyboardInterrupt:
            interrupted = True
            print("\n[finetune] interrupted: saving", flush=True)
        finally:
            interrupted = interrupted or stopper.signum is not None
            if keys is not None:
                keys.stop()
            if listener is not None:
                from audio_frontend.listen import listener_status
                if listener.is_alive() and args.listen_source.startswith("wav:") and not listener_said:
                    # A recording ends on its own: give a listener that is still loading (slow on a
                    # busy machine) a moment to finish or fail, so its outcome is reported.
                    listener.join(10.0)
                said = listener_status(listener)
                if said is not None and not listener_said and listener.exitcode != 0:
                    print(f"[finetune] {said}", flush=True)
                listener_died = listener.exitcode not in (None, 0)  # before we stop it ourselves
                stop_event.set()
                listener.join(2.0)
                if listener.is_alive():
                    listener.terminate()
                    listener.join(2.0)
            # whatever arrived last
            run.process_events(step=max(0, run.first_step - 1))
            _print_outcomes(run, args.learner)
            _save(run, out, args.learner, saved_config)
            print(f"[finetune] saved {'coach policy' if args.learner == 'coach' else 'checkpoint, reward model'} "
                  f"and feedback log in {out}: {run.events} events, queue {run.queue.stats()}", flush=True)
    if stopper.signum is not None:
        return 128 + stopper.signum  # 130 for Ctrl-C, 143 for SIGTERM
    if listener_died and not interrupted:  # the run went on without voice feedback: not a success
        print(f"[finetune] exit code {max(listener.exitcode, 1)}: the voice listener died during the session "
              f"(see above); everything up to then is saved", flush=True)
        return max(listener.exitcode, 1)
    return 130 if interrupted else 0


def _warm_up(run, learner: str) -> None:
    """Compile the feedback update before the first event (a first key press must not stall a chunk)."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    print("[finetune] compiling (first chunk and feedback update)...", flush=True)
    if learner == "coach":
        lr, c = run.learner, run.learner.config
        w, L = c.batch_windows, c.window
        batch = (np.zeros((w, L, lr.obs_size), np.float32), np.zeros((w, L, lr.action_size), np.float32),
                 np.zeros((w, L), np.float32), np.zeros((w, L), np.float32), np.zeros((w,), np.float32))
        jax.block_until_ready(lr._update(lr.params, lr.opt_state, *map(jnp.asarray, batch)))
    elif run.use_model:
        m = run.model
        n = m.config.batch_size
        batch = (np.zeros((n, m.obs_size), np.float32), np.zeros((n, m.action_size), np.float32),
                 np.zeros(n, np.float32), np.zeros(n, np.float32))
        jax.block_until_ready(m._update(m.params, m.opt_state, *map(jnp.asarray, batch)))


def _print_chunk(run, m, learner: str) -> None:
    if learner == "coach":
        print(f"[step {run.first_step:>7}] contact {m['contact_rate']:.2f} reward {m['step_reward']:+.3f} "
              f"events {run.events} corrections {run.corrections} coach updates {run.learner.updates}", flush=True)
    else:
        print(f"[step {run.first_step:>7}] contact {float(m['contact_rate']):.2f} "
              f"reward {float(m['step_reward']):+.3f} events {run.events} credited {run.credited} "
              f"r_hat updates {run.model.updates}", flush=True)


def _print_outcomes(run, learner: str) -> None:
    for event, got, why in run.outcomes:
        label = event.details.get("transcript") or event.details.get("key") or ""
        head = f"[event] {event.source} {event.value:+.2f}" + (f" ({label!r})" if label else "")
        if why is not None:
            print(f"{head}: accepted, not used: {why}", flush=True)
        elif learner == "coach":
            c = run.learner.config
            end = got - c.human_delay_steps
            print(f"{head}: accepted, corrects steps {end - c.window + 1}..{end} (the window "
                  f"{c.human_delay_steps} steps before step {got})", flush=True)
        else:
            print(f"{head}: accepted, credited steps {min(got.steps)}..{max(got.steps)} (lands on step {got.step})",
                  flush=True)
    run.outcomes = []


def _save(run, out: Path, learner: str, saved_config) -> None:
    import yaml

    from mjx_protamer.config import to_dict

    if learner == "coach":
        run.save_policy(out / "coach_policy.msgpack")
        (out / "feedback_config.yaml").write_text(yaml.safe_dump(_plain(saved_config), sort_keys=False))
    else:
        import jax

        from mjx_protamer.experiments import checkpoints

        mngr = checkpoints.manager(out / "checkpoints")
        checkpoints.save(mngr, run.first_step, jax.device_get(run.state))
        if hasattr(mngr, "wait_until_finished"):
            mngr.wait_until_finished()
        run.model.save(out / "reward_model.msgpack")
        (out / "config.yaml").write_text(yaml.safe_dump(to_dict(run.config.pretrain), sort_keys=False))
        (out / "feedback_config.yaml").write_text(yaml.safe_dump(to_dict(run.config.feedback), sort_keys=False))
    run.close()


def _plain(x):
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    return x
