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
- `coach`: Deep COACH, a Gaussian policy learned from the feedback alone, on the run's env (its mean the
  run's actor by default, `--coach-init scratch` a fresh policy, `--coach-policy FILE` one saved by an
  earlier session); each event corrects the window of steps before it (docs/human_feedback.md).

The session's settings: the checkpoint's networks, env and DDPG hyper-parameters; the feedback config's
(`--config`, default configs/feedback_keyboard.yaml, and `--set`) credit, reward model and reward weights
`pretrain.ddpg.reward_alpha` / `reward_beta`.

Each chunk prints a status line; each key press is confirmed at once and each drained event is shown with
what it credited. On exit (q, --seconds, --max-chunks, Ctrl-C) everything is saved into --out:
DDPG: checkpoints/ + config.yaml (loadable by `protamer eval --checkpoint OUT` and by finetune again),
reward_model.msgpack; COACH: coach_policy.msgpack; both: feedback.jsonl, feedback_config.yaml.

Watching (`--view`): `web` (the default without a display) serves a live page on 127.0.0.1 with a random
token (printed as `[view] http://127.0.0.1:PORT/?token=...`): the infant at real-time pace, the regions
touched now, the last feedback and what it credited, the reward model's prediction, the learner's status,
and + / - / 0 buttons that feed the same queue as the terminal keys. `window`: MuJoCo's viewer (with a
display). The view runs in its own process; chunks it cannot keep up with are dropped, never waited for.

Never lost: every --autosave-s seconds (30) the checkpoint, reward model / COACH policy and configs are
saved atomically; `--resume --out DIR` continues a session. Every session is recorded (session.json,
session_chunks.jsonl: the checkpoint's hash, seeds, config, every drained event with its chunk);
`--replay DIR --out NEW` reruns it headless to the same final parameters, bit for bit.

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

LIVE = ("keyboard", "prosody", "whisper", "web")
FEEDBACK_CHOICES = ("keyboard", "prosody", "whisper", "web", "simulated:keyboard", "simulated:prosody",
                    "simulated:speech", "none")
# How long a live session waits for the voice listener to load torch and its model before going on.
LISTENER_LOAD_TIMEOUT_S = 300.0
# A session's feedback config without --config (the channel follows --feedback: the three shipped files differ in
# it alone). Without it a session would run the dataclass defaults: an unbounded reward model, no silences, beta 0.1.
DEFAULT_FEEDBACK_CONFIG = Path(__file__).resolve().parents[2] / "configs" / "feedback_keyboard.yaml"
# Of a feedback config's pretrain section a session takes only the reward DDPG trains on; the rest (networks,
# env, noise) is the checkpoint's.
SESSION_PRETRAIN_KEYS = ("pretrain.ddpg.reward_alpha", "pretrain.ddpg.reward_beta")
# Deep COACH from a pretrained actor: the initial log std of its Gaussian policy (docs/human_feedback.md)
COACH_ACTOR_LOG_STD = -1.0


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "finetune",
        help="fine-tune a pretrained policy live with human feedback (keyboard or voice)",
        description="Runs one env live from a pretrain checkpoint; give feedback with + / - / 0 (q to stop) or "
        "by voice (prosody or Whisper). Saves the checkpoint, reward model / policy and feedback log on exit "
        "or Ctrl-C.",
    )
    p.add_argument("--feedback", choices=FEEDBACK_CHOICES, default="keyboard",
                   help="where feedback comes from (web: the live page's buttons and keys only, no terminal needed; "
                   "simulated:* for a dry run without a human; none: no feedback)")
    p.add_argument("--learner", choices=("ddpg", "coach"), default="ddpg",
                   help="ddpg: the checkpoint's DDPG + DeepTAMER reward model; coach: Deep COACH on the same env")
    p.add_argument("--checkpoint", type=Path, default=None,
                   help="a pretrain run directory or checkpoint in it (not with --resume / --replay)")
    p.add_argument("--config", type=Path, default=None, help="feedback YAML (default: configs/feedback_keyboard.yaml; "
                   "the channel follows --feedback); of its pretrain section only ddpg.reward_alpha and "
                   "ddpg.reward_beta apply, the rest is the checkpoint's")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a feedback config value, e.g. --set feedback.credit.scheme=time_window or "
                   "--set pretrain.ddpg.reward_beta=0.5")
    p.add_argument("--out", type=Path, default=None, help="output directory (default: runs/finetune-<time>)")
    p.add_argument("--chunk-ms", type=float, default=250.0, help="simulated time per jitted chunk (ms)")
    p.add_argument("--seconds", type=float, default=0.0,
                   help="stop this long after the session is ready (compiling and loading a voice model do not "
                   "count; 0: until q or Ctrl-C)")
    p.add_argument("--max-chunks", type=int, default=0, help="stop after this many chunks (0: no limit)")
    p.add_argument("--no-pace", action="store_true",
                   help="do not pace live chunks to real time (they are shown as fast as they are computed)")
    w = p.add_argument_group("watching, autosave, resume and replay")
    w.add_argument("--view", choices=("web", "window", "none"), default=None,
                   help="web: a live page on 127.0.0.1 (default without a display); window: MuJoCo's viewer "
                   "(default with a display); none")
    w.add_argument("--port", type=int, default=0, help="--view web: the port (default: a free one)")
    w.add_argument("--autosave-s", type=float, default=30.0,
                   help="save checkpoint, reward model and configs atomically this often (s; 0: only at exit)")
    w.add_argument("--resume", action="store_true", help="continue the session in --out (after a crash or stop)")
    w.add_argument("--fresh-replay", action="store_true",
                   help="start DDPG's replay empty instead of with the checkpoint's experience (sessions before "
                   "5 December did; the policy then moves within seconds whatever the feedback)")
    w.add_argument("--calibrate", default=None, metavar="TOUCH",
                   help="measure your reaction delay: give feedback each time TOUCH begins (head, a body region, "
                   "left_hand or right_hand); at the end the session's delay is fitted (`protamer reaction-delay`) "
                   "and the --set values for credit printed; OUT/reaction_delay.json and .png")
    w.add_argument("--replay", type=Path, default=None, metavar="SESSION_DIR",
                   help="rerun a recorded session headless into --out, reaching the same final parameters")
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
    c.add_argument("--coach-init", choices=("actor", "scratch"), default="actor",
                   help="actor (default): the policy's mean starts as the checkpoint's DDPG actor, so feedback "
                   "corrects the pretrained behaviour; scratch: a fresh policy, as Deep COACH was published")
    c.add_argument("--coach-log-std", type=float, default=None,
                   help=f"the policy's initial log std (default {COACH_ACTOR_LOG_STD} from the actor, "
                   "-0.5 from scratch): its exploration is the direction each correction takes")
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
    if args.autosave_s < 0:
        raise ConfigError("--autosave-s must be >= 0")
    if not 0 <= args.port <= 65535:
        raise ConfigError(f"--port must be in 0..65535, got {args.port}")
    if args.calibrate is not None:
        from mjx_protamer.envs.body import REGIONS
        from mjx_protamer.human.touches import HANDS

        if args.replay is not None:
            return _fail("--calibrate measures a session as it is given; for a recorded one run "
                         "`protamer reaction-delay SESSION --touch TOUCH`")
        if args.calibrate not in (*REGIONS, *HANDS):
            return _fail(f"--calibrate {args.calibrate!r}: not a touch; use one of " + ", ".join((*REGIONS, *HANDS)))
        if args.feedback == "none":
            return _fail("--calibrate measures how fast feedback follows a touch: it needs feedback (keyboard, web, "
                         "whisper, prosody; a simulated teacher reacts to its rule, not to the touch)")
    if args.replay is not None:
        from mjx_protamer.commands.finetune_replay import replay
        return replay(args)
    if args.resume:
        problem = _resume_problem(args)
        if problem:
            return _fail(problem)
        args.checkpoint = _resume_source(args)
    elif args.checkpoint is None:
        return _fail("--checkpoint is required (a pretrain run directory), unless --resume or --replay")
    else:
        problem = _session_config_problem(args)  # before the checkpoint's minutes of loading
        if problem:
            return _fail(problem)
    live = args.feedback in LIVE
    from mjx_protamer.commands.finetune_view import default_view
    if args.feedback == "web" and (args.view or default_view()) != "web":
        return _fail("--feedback web takes feedback from the live page: it needs --view web")
    if live and args.learner == "ddpg" and (args.view or default_view()) != "web" and _needs_attention(args):
        return _fail("feedback.credit.silence_needs_attention counts a silence only while the live page is "
                     "visible: it needs --view web (or set it false)")
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
        run_dir = resolve_checkpoint(ckpt)[0]
    except CheckpointError as e:
        return _fail(f"--checkpoint: {e} (expected DIR/config.yaml and DIR/checkpoints/<step>/)")
    if args.calibrate is not None and _env_name(run_dir) != "self_touch":
        return _fail(f"--calibrate needs a self-touch checkpoint (touches to react to); {ckpt} is a "
                     f"{_env_name(run_dir)} run")

    from mjx_protamer.commands.train import _enable_compile_cache

    _enable_compile_cache()  # the next session on this checkpoint starts in seconds
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
    if not args.resume:
        loaded = _live_env(*loaded)
    elif _recorded_backend(args.out):  # the env the session recorded (COACH resumes from the pretrain config)
        loaded = _live_env(*loaded, _recorded_backend(args.out))
    return _session(args, live, voice, *loaded)


def _session_config_problem(args) -> str | None:
    """A new session's feedback config, checked before anything heavy: the default file when --config is not
    given (set on `args`), --set keys the session would drop, and what the config cannot run with. A bad key or
    value raises ConfigError (one line, exit 2)."""
    from mjx_protamer.human.tamer_loop import load_feedback_config

    if args.config is None and DEFAULT_FEEDBACK_CONFIG.is_file():
        args.config = DEFAULT_FEEDBACK_CONFIG
    for o in args.overrides:
        key = o.split("=", 1)[0].strip()
        if key.startswith("pretrain") and key not in SESSION_PRETRAIN_KEYS:
            return (f"--set {key}: a session takes its pretraining settings from the checkpoint; of the pretrain "
                    f"section only {' and '.join(SESSION_PRETRAIN_KEYS)} apply")
    if args.config is not None and not Path(args.config).is_file():
        return f"--config {args.config}: no such file (a feedback YAML such as configs/feedback_keyboard.yaml)"
    fb = _with_feedback_channel(load_feedback_config(args.config, args.overrides).feedback, args.feedback)
    if fb.credit.silence_needs_attention and args.feedback.startswith("simulated:") and args.learner == "ddpg":
        return ("feedback.credit.silence_needs_attention: the host's simulated teachers report no attention; set "
                "it false here (the in-jit teachers of pretrain/reproduce and a live session's page do)")
    return None


def _env_name(run_dir: Path) -> str:
    """The env of a run directory, from its config.yaml without loading it (self_touch when unnamed)."""
    import yaml

    try:
        return str((yaml.safe_load((run_dir / "config.yaml").read_text()) or {}).get("env_name", "self_touch"))
    except (OSError, yaml.YAMLError, AttributeError):
        return "unreadable"


def _needs_attention(args) -> bool:
    """Whether the session's feedback config gates silences on the teacher's attention."""
    from mjx_protamer.human.tamer_loop import load_feedback_config

    return load_feedback_config(args.config, args.overrides).feedback.credit.silence_needs_attention


def _load(args, ckpt: Path):
    """(pretrain config, env, loaded train state, step)."""
    from mjx_protamer.experiments.run_loader import load_run
    return load_run(ckpt)


def _live_env(pre, env, loaded, step, backend: str | None = None):
    """The loaded checkpoint with the live env in place of the checkpoint's: one world on the backend that
    steps it fastest here (or `backend`, the one a recorded session used), and the config that says so
    (saved as the session's config.yaml and its manifest's `env_backend`)."""
    from mjx_protamer.experiments.env_factory import live_config, make_live_env

    if pre.env_name != "self_touch":
        return pre, env, loaded, step
    how = "recorded by the session" if backend else "the fastest for one world here"
    if live_config(pre, backend).env.backend == pre.env.backend == getattr(env, "backend", None):
        print(f"[finetune] physics backend: {pre.env.backend} ({how})", flush=True)
        return pre, env, loaded, step  # the loaded env is already the one
    env, pre = make_live_env(pre, backend)
    print(f"[finetune] physics backend: {pre.env.backend} ({how})", flush=True)
    return pre, env, loaded, step


def _recorded_backend(session: Path) -> str | None:
    """The physics backend a recorded session's live env ran on (None for sessions recorded before the
    live env had its own: they ran on the checkpoint's)."""
    import json

    from mjx_protamer.human.session_record import MANIFEST

    return json.loads((session / MANIFEST).read_text()).get("env_backend")


def _with_feedback_channel(fb, feedback: str):
    """Credit (and a simulated teacher) use the delay model of the channel the feedback comes through."""
    import dataclasses

    from mjx_protamer.human.teachers import with_channel

    kind = {"whisper": "speech", "prosody": "prosody"}.get(feedback)
    if feedback.startswith("simulated:"):
        kind = feedback.split(":", 1)[1]
    return fb if kind is None else dataclasses.replace(fb, teacher=with_channel(fb.teacher, kind))


# --------------------------------------------------------------------------- resume

def _resume_problem(args) -> str | None:
    from mjx_protamer.human.session_record import MANIFEST

    if args.out is None:
        return "--resume needs --out, the directory of the session to continue"
    if not (args.out / MANIFEST).is_file():
        return f"--resume: {args.out} holds no finetune session ({MANIFEST} is missing)"
    if args.checkpoint is not None:
        return "--resume continues from the session's own autosave: leave out --checkpoint"
    return None


def _resume_source(args) -> Path:
    """What a resumed session loads: its own autosaved checkpoint (DDPG) or the checkpoint it started
    from (COACH, whose policy is in coach_policy.msgpack)."""
    import json

    from mjx_protamer.human.session_record import MANIFEST

    manifest = json.loads((args.out / MANIFEST).read_text())
    if manifest["learner"] != args.learner:
        from mjx_protamer.config import ConfigError
        raise ConfigError(f"--resume: the session in {args.out} used --learner {manifest['learner']}")
    if args.learner == "coach":
        _coach_args_from(manifest, args)
        if (args.out / "coach_policy.msgpack").is_file():
            args.coach_policy = args.out / "coach_policy.msgpack"
        return Path(manifest["checkpoint"])
    if not (args.out / "checkpoints").is_dir():
        from mjx_protamer.config import ConfigError
        raise ConfigError(f"--resume: {args.out} has no autosaved checkpoint yet (it stopped before the first "
                          f"autosave); start a new session")
    return args.out


def _coach_args_from(manifest: dict, args) -> None:
    """A recorded COACH session's policy settings (sessions recorded before --coach-init started from scratch)."""
    args.coach_delay_s = manifest["coach_delay_s"]
    args.coach_init = manifest.get("coach_init") or "scratch"
    args.coach_log_std = manifest.get("coach_log_std")


# --------------------------------------------------------------------------- the run

def _build_run(args, pre, env, loaded, step, fb, chunk_steps: int, out: Path, feedback_mode, queue=None,
               weights: tuple[float, float] | None = None):
    """The learner of a session (TamerRun or CoachRun) on the loaded checkpoint; `feedback_mode` is what
    the run is told (None, "queue" or "simulated:KIND"); `weights` (alpha, beta) of DDPG's reward
    `alpha r_env + beta r_hat`, the session's (None: the checkpoint's). Returns (run, saved_config)."""
    import dataclasses

    if args.learner == "coach":
        from mjx_protamer.agents.coach import CoachConfig
        from mjx_protamer.human.coach_loop import CoachRun, CoachRunConfig

        from_actor = args.coach_init == "actor"
        coach = CoachConfig(human_delay_steps=round(args.coach_delay_s / fb.dt))
        if from_actor:
            coach = dataclasses.replace(coach, hidden=tuple(pre.ddpg.actor_hidden), activation="relu",
                                        init_log_std=COACH_ACTOR_LOG_STD)
        if args.coach_log_std is not None:
            coach = dataclasses.replace(coach, init_log_std=float(args.coach_log_std))
        ccfg = CoachRunConfig(coach=coach, chunk_steps=chunk_steps, episode_length=pre.train.episode_length, dt=fb.dt,
                              queue_size=fb.queue_size, min_interval_steps=fb.credit.min_interval_steps,
                              seed=fb.seed)
        run = CoachRun(ccfg, env, feedback=None if feedback_mode in (None, "queue") else feedback_mode,
                       queue=queue, log_path=out / "feedback.jsonl", teacher=fb.teacher)
        if args.coach_policy is not None:
            run.load_policy(args.coach_policy)
        elif from_actor:
            run.start_from_actor(loaded.actor_params)
        return run, {"coach": dataclasses.asdict(ccfg), "pretrain_run": str(args.checkpoint),
                     "coach_init": args.coach_init}
    from mjx_protamer.human.tamer_loop import FeedbackRunConfig, TamerRun

    train = dataclasses.replace(pre.train, num_envs=1, chunk_steps=chunk_steps, warmup_env_steps=0,
                                total_env_steps=max(pre.train.total_env_steps, chunk_steps), num_devices=1)
    # The pretraining run's experience seeds the replay: DDPG's first updates in a session would otherwise
    # fit the few dozen transitions of its first chunk and move the policy within seconds, feedback or not
    # (docs/human_feedback.md). A resumed session has its own replay.
    carry = not args.resume and not getattr(args, "fresh_replay", False)
    replay_size = int(loaded.replay.capacity) if args.resume else max(pre.ddpg.batch_size, 20_000, chunk_steps)
    # a session is open-ended: the full step size, whatever decay the pretraining run's budget had
    ddpg = dataclasses.replace(pre.ddpg, replay_size=replay_size, lr_final_fraction=1.0)
    if weights is not None:  # a pretraining run without feedback never used its beta (0.1 by default)
        ddpg = dataclasses.replace(ddpg, reward_alpha=float(weights[0]), reward_beta=float(weights[1]))
    config = FeedbackRunConfig(pretrain=dataclasses.replace(pre, train=train, ddpg=ddpg),
                               feedback=dataclasses.replace(fb, watch_env=0, reward_model=dataclasses.replace(
                                   fb.reward_model, lr_final_fraction=1.0)))
    run = TamerRun(config, env, feedback=feedback_mode, queue=queue, log_path=out / "feedback.jsonl")
    if args.resume:  # the session's own single-env state: learner, env, replay, noise
        run.state = loaded
        if (out / "reward_model.msgpack").is_file():
            run.model.load(out / "reward_model.msgpack")
    else:  # the pretrained learner on a fresh single-env state (env batch and noise are new)
        from mjx_protamer.agents.ddpg.replay import newest

        run.state = run.state.replace(**{k: getattr(loaded, k) for k in (
            "actor_params", "critic_params", "target_actor_params", "target_critic_params",
            "actor_opt_state", "critic_opt_state")})
        if carry:
            run.state = run.state.replace(replay=newest(loaded.replay, replay_size))
    run.commit_state()  # restored arrays are uncommitted: the second chunk would compile again
    return run, None


def _checkpoint_identity(ckpt: Path, step: int) -> dict:
    """The checkpoint a session starts from: its step directory and the SHA-256 of its files."""
    from mjx_protamer.experiments.run_loader import resolve_checkpoint
    from mjx_protamer.human.session_record import tree_sha256

    run_dir, ckpt_dir, _ = resolve_checkpoint(ckpt)
    step_dir = next(p for p in ckpt_dir.iterdir() if p.is_dir() and p.name.isdigit() and int(p.name) == step)
    return {"checkpoint": str(run_dir.absolute()), "checkpoint_step_dir": str(step_dir.absolute()),
            "checkpoint_step": int(step), "checkpoint_sha256": tree_sha256(step_dir),
            "checkpoint_config_sha256": tree_sha256(run_dir / "config.yaml")}


def _session(args, live: bool, voice, pre, env, loaded, step) -> int:
    from mjx_protamer.config import to_dict
    from mjx_protamer.human.session_record import MANIFEST, SessionRecorder, write_json_atomic
    from mjx_protamer.human.tamer_loop import load_feedback_config

    resume = args.resume
    if resume:  # the session's own configs, whatever the flags say
        import json

        manifest = json.loads((args.out / MANIFEST).read_text())
        overrides, config_path = manifest["overrides"], manifest["config"]
        chunk_ms = manifest["chunk_ms"]
    else:
        overrides, config_path, chunk_ms = args.overrides, args.config, args.chunk_ms
    session_cfg = load_feedback_config(config_path, overrides)
    fb = _with_feedback_channel(session_cfg.feedback, args.feedback)
    # resumed: the session's own config.yaml (loaded as the checkpoint) holds the weights it ran with
    weights = None if resume else (session_cfg.pretrain.ddpg.reward_alpha, session_cfg.pretrain.ddpg.reward_beta)
    chunk_steps = max(1, round(chunk_ms / 1000.0 / fb.dt))
    out = args.out or Path("runs") / time.strftime("finetune-%Y%m%d-%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    # A live run's events are stamped on the wall clock; the queue validates against it too.
    sim = None if live or args.feedback == "none" else args.feedback
    mode = None if args.feedback == "none" else ("queue" if live else sim)
    if args.learner == "coach":
        mode = sim
    run, saved_config = _build_run(args, pre, env, loaded, step, fb, chunk_steps, out, mode, weights=weights)
    if resume:
        manifest.setdefault("resumed", []).append({"at_step": int(step), "time": time.time()})
        run.first_step = int(step) if args.learner == "ddpg" else _coach_resume_step(out)
    else:
        manifest = {"version": 1, "learner": args.learner, "feedback": args.feedback, "chunk_ms": chunk_ms,
                    "chunk_steps": chunk_steps, "config": str(args.config) if args.config else None,
                    "overrides": list(args.overrides), "coach_delay_s": args.coach_delay_s,
                    "coach_policy": str(args.coach_policy) if args.coach_policy else None,
                    "coach_init": args.coach_init if args.learner == "coach" else None,
                    "coach_log_std": args.coach_log_std if args.learner == "coach" else None,
                    "seeds": {"train": pre.train.seed, "feedback": fb.seed},
                    "feedback_config": to_dict(fb), "listen_source": args.listen_source,
                    "segments": str(args.save_segments or (out / "segments")) if voice is not None else None,
                    "env_backend": pre.env.backend if pre.env_name == "self_touch" else None,
                    "calibrate": args.calibrate,
                    "reward_weights": list(weights) if args.learner == "ddpg" else None,
                    "replay_from_checkpoint": args.learner == "ddpg" and not args.fresh_replay,
                    "started": time.time(), **_checkpoint_identity(Path(args.checkpoint), step)}
    if getattr(run, "attention", None) is not None:
        print("[finetune] credit.silence_needs_attention: a silent step teaches 'nothing to say' only while the "
              "live page is visible", flush=True)
    recorder = SessionRecorder(out)
    write_json_atomic(out / MANIFEST, manifest)
    if run.log is not None:
        run.log.note(event="resume" if resume else "start", feedback=args.feedback, learner=args.learner,
                     checkpoint=str(args.checkpoint), checkpoint_step=int(step), chunk_steps=chunk_steps, dt=fb.dt)

    from mjx_protamer.commands.finetune_view import (calibration_prompt, default_view, last_event as _last_event,
                                                     snapshot, start_view)

    view_kind = args.view or default_view()
    keys = listener = stop_event = view = None
    listener_said = wav_over = listener_died = False
    interrupted = False
    last_event = None
    with _Stopper() as stopper:
        try:
            print(f"[finetune] {args.learner} from {args.checkpoint} (step {step}); chunks of {chunk_steps} steps "
                  f"({chunk_steps * fb.dt * 1000:.0f} ms); feedback {args.feedback}; output {out}"
                  + (f"; resumed at step {run.first_step}" if resume else ""), flush=True)
            if args.learner == "ddpg" and args.feedback != "none":
                d = run.config.pretrain.ddpg
                print(f"[finetune] DDPG trains on {d.reward_alpha:g} r_env + {d.reward_beta:g} r_hat; feedback config "
                      f"{config_path or 'the built-in defaults'}", flush=True)
            _warm_up(run, args.learner)
            t_end = float("inf")  # --seconds counts from the first chunk shown: compiles and model loads do not
            chunks = 0
            slow_said = False
            last_save = time.time()
            while time.time() < t_end and stopper.signum is None and not (keys and keys.stop_requested.is_set()):
                if args.max_chunks and chunks >= args.max_chunks:
                    break
                t0 = time.time()
                m = run.step_chunk(t0=t0 if live else None)
                chunks += 1
                c = run.last_chunk
                recorder.chunk(chunks - 1, c["first_step"], c["t0"], [o[0] for o in run.outcomes], c.get("touches"))
                last_event = _last_event(run, args.learner) or last_event
                if view is not None:
                    view.offer(snapshot(run, args, m, t0, fb.dt, last_event))
                _print_chunk(run, m, args.learner)
                _print_outcomes(run, args.learner)
                if chunks == 1:  # compiled and running: now the feedback sources and the view start
                    if stopper.signum is not None:
                        break
                    view = start_view(view_kind, pre, run, args.port)
                    if args.feedback == "keyboard":
                        from mjx_protamer.human.keyboard import KeyboardFeedback
                        keys = KeyboardFeedback(run.queue).start()
                    elif voice is not None:
                        import multiprocessing as mp

                        from audio_frontend.listen import start_listener
                        vcfg, source = voice
                        stop_event = mp.get_context("spawn").Event()
                        ready_event = mp.get_context("spawn").Event()
                        listener = start_listener(run.queue, vcfg, scorer=args.feedback, source=source,
                                                  save_dir=args.save_segments or str(out / "segments"),
                                                  stop_event=stop_event, ready_event=ready_event, scorer_kwargs=(
                                                      {"load_classifier": False} if args.keywords_only
                                                      and args.feedback == "whisper" else None))
                        print(f"[finetune] voice listener ({args.feedback}, {args.listen_source}) started, pid "
                              f"{listener.pid}; its lines start with [voice]; waiting for it to load its model",
                              flush=True)
                        _wait_for_listener(listener, ready_event)
                    if live:
                        how = (" (+ good, - bad, 0 neutral, q quit)" if keys is not None else
                               " (the page's + / - / 0)" if args.feedback == "web" else " (speak)")
                        print("[finetune] ready: give feedback now" + how, flush=True)
                    if args.calibrate is not None:
                        print(f"[calibrate] {calibration_prompt(args.calibrate)}; at the end your reaction "
                              "delay is fitted", flush=True)
                    if args.seconds > 0:
                        t_end = time.time() + args.seconds
                if args.autosave_s > 0 and time.time() - last_save >= args.autosave_s:
                    t_save = time.time()
                    _save(run, out, args.learner, saved_config, final=False)
                    last_save = time.time()
                    print(f"[finetune] autosaved at step {run.first_step} ({last_save - t_save:.1f} s)", flush=True)
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
            recorder.final([o[0] for o in run.outcomes])
            recorder.close()
            _print_outcomes(run, args.learner)
            if view is not None:
                view.close()
                print(f"[view] closed: {view.offered} chunks offered, {view.dropped} dropped", flush=True)
            _save(run, out, args.learner, saved_config)
            print(f"[finetune] saved {'coach policy' if args.learner == 'coach' else 'checkpoint, reward model'} "
                  f"and feedback log in {out}: {run.events} events{' since the resume' if resume else ''}, queue "
                  f"{run.queue.stats()}", flush=True)
    fit_code = 0  # measure()'s exit code: 2 when the calibration's delay could not be fitted
    if args.calibrate is not None:  # the session is saved whatever the fit says
        from mjx_protamer.commands.reaction_delay import measure

        for old in (out / "reaction_delay.json", out / "reaction_delay.png"):  # an earlier stretch's fit
            old.unlink(missing_ok=True)
        print(f"[calibrate] the reaction delay of this session ({args.calibrate} onsets):", flush=True)
        fit_code = measure(out, args.calibrate, json_path=out / "reaction_delay.json",
                         plot_path=out / "reaction_delay.png", who="[calibrate] no fit",
                         rerun=f"protamer reaction-delay {out}")
    if stopper.signum is not None:
        return 128 + stopper.signum  # 130 for Ctrl-C, 143 for SIGTERM
    if listener_died and not interrupted:  # the run went on without voice feedback: not a success
        print(f"[finetune] exit code {max(listener.exitcode, 1)}: the voice listener died during the session "
              f"(see above); everything up to then is saved", flush=True)
        return max(listener.exitcode, 1)
    if interrupted:
        return 130
    if fit_code:
        print(f"[finetune] exit code {fit_code}: the session is saved, its reaction delay could not be fitted "
              "(above)", flush=True)
    return fit_code


def _coach_resume_step(out: Path) -> int:
    import json

    p = out / "coach_progress.json"
    return int(json.loads(p.read_text())["step"]) if p.is_file() else 0


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



def _wait_for_listener(listener, ready_event, timeout_s: float = LISTENER_LOAD_TIMEOUT_S) -> None:
    """Hold the session until the voice listener is ready to hear (or has died: its exit is reported by the
    session loop). What a person says before the model is loaded would be lost, and "give feedback now"
    would be untrue."""
    t0 = time.time()
    while not ready_event.is_set() and listener.is_alive() and time.time() - t0 < timeout_s:
        ready_event.wait(0.2)
    if listener.is_alive() and not ready_event.is_set():
        print(f"[finetune] note: the voice listener is still loading after {timeout_s:.0f} s; going on, its "
              "events will arrive once it is ready", flush=True)

def _print_chunk(run, m, learner: str) -> None:
    if learner == "coach":
        print(f"[step {run.first_step:>7}] contact {m['contact_rate']:.2f} reward {m['step_reward']:+.3f} "
              f"events {run.events} corrections {run.corrections} coach updates {run.learner.updates}", flush=True)
    else:
        print(f"[step {run.first_step:>7}] contact {float(m['contact_rate']):.2f} "
              f"reward {float(m['step_reward']):+.3f} events {run.events} credited {run.credited} "
              f"r_hat updates {run.model.updates}", flush=True)


def _print_outcomes(run, learner: str) -> None:
    from mjx_protamer.commands.feedback_text import outcome_text

    from mjx_protamer.human.attention import is_attention

    for event, got, why in run.outcomes:
        if is_attention(event):
            print(f"[attention] {why}", flush=True)
            continue
        label = event.details.get("transcript") or event.details.get("key") or ""
        head = f"[event] {event.source} {event.value:+.2f}" + (f" ({label!r})" if label else "")
        print(f"{head}: {outcome_text(run, got, why, learner)}", flush=True)
    run.outcomes = []


def _atomic_write(path: Path, write) -> None:
    """`write(tmp_path)`, then rename onto `path`: a kill mid-save leaves the previous file whole."""
    import os

    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    write(tmp)
    os.replace(tmp, path)


def _save(run, out: Path, learner: str, saved_config, final: bool = True) -> None:
    """Save what a session has learnt, each file atomically (autosave: final=False keeps the run open)."""
    import yaml

    from mjx_protamer.config import to_dict
    from mjx_protamer.human.session_record import write_json_atomic

    def text(s: str):
        return lambda p: p.write_text(s)

    if learner == "coach":
        _atomic_write(out / "coach_policy.msgpack", run.save_policy)
        _atomic_write(out / "feedback_config.yaml", text(yaml.safe_dump(_plain(saved_config), sort_keys=False)))
        write_json_atomic(out / "coach_progress.json", {"step": int(run.first_step), "events": int(run.events)})
    else:
        import jax

        from mjx_protamer.experiments import checkpoints

        mngr = checkpoints.manager(out / "checkpoints")
        if mngr.latest_step() != run.first_step:  # (an autosave may have saved this very step)
            checkpoints.save(mngr, run.first_step, jax.device_get(run.state))  # orbax: atomic rename
        _atomic_write(out / "reward_model.msgpack", run.model.save)
        _atomic_write(out / "config.yaml", text(yaml.safe_dump(to_dict(run.config.pretrain), sort_keys=False)))
        _atomic_write(out / "feedback_config.yaml",
                      text(yaml.safe_dump(to_dict(run.config.feedback), sort_keys=False)))
    if final:
        run.close()


def _plain(x):
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    return x
