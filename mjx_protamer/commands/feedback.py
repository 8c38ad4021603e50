"""`protamer finetune`: one env, live, learning from your keys or your voice.

    protamer finetune --checkpoint RUN --feedback keyboard                     # + / - / 0, q to stop
    protamer finetune --checkpoint RUN --feedback whisper --listen-source mic  # say "good job" / "no"
    protamer finetune --checkpoint RUN --feedback prosody --listen-source wav:session.wav
    protamer finetune --checkpoint RUN --feedback prosody --listen-source speaker   # a simulated person speaks
    protamer finetune --checkpoint RUN --feedback keyboard --learner coach     # Deep COACH instead of DDPG

This module only registers the arguments and turns them into a `live.spec.SessionSpec`; the session itself
(loading, learners, feedback sources, the live view, the record, autosave, resume, replay) is the library
`mjx_protamer/live/` (docs/human_feedback.md, "`protamer finetune`: live fine-tuning").
"""

from __future__ import annotations

import argparse
from pathlib import Path

from mjx_protamer.human.feedback_config import SESSION_DDPG_KEYS
from mjx_protamer.live.kinds import LEARNERS
from mjx_protamer.live.spec import FEEDBACK_CHOICES


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
    p.add_argument("--learner", choices=LEARNERS, default="ddpg",
                   help="ddpg: the checkpoint's DDPG + DeepTAMER reward model; coach: Deep COACH on the same env")
    p.add_argument("--checkpoint", type=Path, default=None,
                   help="a pretrain run directory or checkpoint in it (not with --resume / --replay)")
    p.add_argument("--config", type=Path, default=None, help="feedback YAML (default: configs/feedback_keyboard.yaml; "
                   "the channel follows --feedback); its session section, and of its pretrain section the DDPG keys "
                   + ", ".join(SESSION_DDPG_KEYS) + " apply; the rest is the checkpoint's")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a feedback config value, e.g. --set feedback.credit.scheme=time_window or "
                   "--set pretrain.ddpg.human_actor_coef=0 or --set session.max_updates_per_step=4")
    p.add_argument("--out", type=Path, default=None,
                   help="output directory, new or empty (default: runs/finetune-<time>)")
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
                   help="save the learner, reward model and configs atomically this often (s; 0: only at exit)")
    w.add_argument("--snapshot-every-s", type=float, default=0.0,
                   help="save the policy every this many seconds of shown time into OUT/snapshots/step_<n> (what "
                   "`reproduce live --snapshot-minutes` scores; 0: none)")
    w.add_argument("--resume", action="store_true", help="continue the session in --out (after a crash or stop)")
    w.add_argument("--fresh-replay", action="store_true",
                   help="start DDPG's replay empty instead of with the checkpoint's experience (the policy then "
                   "moves within seconds whatever the feedback)")
    w.add_argument("--calibrate", default=None, metavar="TOUCH",
                   help="measure your reaction delay: give feedback each time TOUCH begins (head, a body region, "
                   "left_hand or right_hand); at the end the session's delay is fitted (`protamer reaction-delay`) "
                   "and the --set values for credit printed; OUT/reaction_delay.json and .png")
    w.add_argument("--replay", type=Path, default=None, metavar="SESSION_DIR",
                   help="rerun a recorded session headless into --out, reaching the same final parameters")
    v = p.add_argument_group("voice (--feedback prosody|whisper)")
    v.add_argument("--listen-source", default="mic", metavar="mic|wav:PATH|speaker|speaker:words",
                   help="the microphone (default), a WAV file played at real-time pace (the run ends with it), or "
                   "speaker: a simulated person who watches the infant and speaks praise or reproach by the "
                   "config's hidden teacher rule (synthesised speech through the real listener), in sentences; "
                   "speaker:words: the same person in single words (\"yes\", \"no\"), about one a second")
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
                   help="start from the policy of an earlier finetune --learner coach (its --out)")
    c.add_argument("--coach-delay-s", type=float, default=0.3,
                   help="human reaction delay: an event corrects the window ending this long before it began")
    c.add_argument("--coach-init", choices=("actor", "scratch"), default="actor",
                   help="actor (default): the policy's mean starts as the checkpoint's DDPG actor, so feedback "
                   "corrects the pretrained behaviour; scratch: a fresh policy, as Deep COACH was published")
    c.add_argument("--coach-log-std", type=float, default=None,
                   help="the policy's initial log std (default -1.0 from the actor, -0.5 from scratch): its "
                   "exploration is the direction each correction takes")
    p.set_defaults(handler=_finetune)


def _view(args) -> str:
    from mjx_protamer.view.live import default_kind

    return args.view or default_kind()


def _finetune(args: argparse.Namespace) -> int:
    from mjx_protamer.config import ConfigError
    from mjx_protamer.live import session
    from mjx_protamer.live.spec import SessionSpec

    if args.replay is not None:
        if args.calibrate is not None:
            raise ConfigError("--calibrate measures a session as it is given; for a recorded one run "
                              "`protamer reaction-delay SESSION --touch TOUCH`")
        if args.out is None:
            raise ConfigError("--replay needs --out, a new directory for the rerun")
        return session.replay(args.replay, args.out)
    if args.resume:
        if args.out is None:
            raise ConfigError("--resume needs --out, the directory of the session to continue")
        if args.checkpoint is not None:
            raise ConfigError("--resume continues from the session's own autosave: leave out --checkpoint")
        from mjx_protamer.live.spec import _number

        return session.resume(args.out, view=_view(args), port=_number("--port", args.port, 0, 65535, True),
                              seconds=_number("--seconds", args.seconds, 0, 1e7),
                              max_chunks=_number("--max-chunks", args.max_chunks, 0, 1e9, True),
                              autosave_s=_number("--autosave-s", args.autosave_s, 0, 1e6), pace=not args.no_pace)
    spec = SessionSpec.create(
        learner=args.learner, feedback=args.feedback, out=args.out, checkpoint=args.checkpoint, config=args.config,
        overrides=args.overrides, chunk_ms=args.chunk_ms, seconds=args.seconds, max_chunks=args.max_chunks,
        pace=not args.no_pace, view=_view(args), port=args.port, autosave_s=args.autosave_s,
        snapshot_every_s=args.snapshot_every_s,
        fresh_replay=args.fresh_replay, calibrate=args.calibrate, listen_source=args.listen_source,
        voice_config=args.voice_config, voice_set=args.voice_set, keywords_only=args.keywords_only,
        save_segments=args.save_segments, coach_policy=args.coach_policy, coach_delay_s=args.coach_delay_s,
        coach_init=args.coach_init, coach_log_std=args.coach_log_std)
    return session.start(spec)
