"""A live session's specification: everything it needs, checked once, before anything heavy, frozen.

`SessionSpec.create(...)` takes what the command line gives (`protamer finetune`), validates every number like a
config value (finite, in range), resolves the feedback config (the file, `--set`, the channel the feedback comes
through) and refuses what the session could not run with, in one line each. The same spec is written into
session.json (`manifest()`) and read back by `--resume` and `--replay` (`from_manifest`), so a resumed or
replayed session runs the settings it was started with, whatever the flags say.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

from mjx_protamer.cli_numbers import number as _number  # noqa: F401  (commands import it from here)
from mjx_protamer.config import MAX_CONFIG_BYTES, ConfigError, check_config_size, shipped_config, to_dict  # noqa: F401
from mjx_protamer.human.feedback_config import SESSION_DDPG_KEYS, FeedbackRunConfig, load_feedback_config
from mjx_protamer.live.kinds import LEARNER_KINDS, LEARNERS

LIVE = ("keyboard", "prosody", "whisper", "web")
SIMULATED = ("simulated:keyboard", "simulated:prosody", "simulated:speech")
FEEDBACK_CHOICES = (*LIVE, *SIMULATED, "none")
# The simulated speaker's --listen-source for what it says praise and reproach in (`reproduce live --speaker`)
SPEAKER_SOURCES = {"sentences": "speaker", "words": "speaker:words"}
# A session's feedback config without --config (the channel follows --feedback: the shipped files differ in it
# alone). Without it a session would run the dataclass defaults: an unbounded reward model, no silences, beta 0.1.
DEFAULT_FEEDBACK_CONFIG = shipped_config("feedback_keyboard.yaml")


def check_config_file(path: Path | None, flag: str = "--config") -> None:
    if path is None:
        return
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{flag} {p}: no such file (a feedback YAML such as configs/feedback_keyboard.yaml)")
    check_config_size(p, flag)  # the config loader's own limit (config.MAX_CONFIG_BYTES)


def channel_kind(feedback: str) -> str | None:
    """The feedback channel whose delay model credit uses: keyboard, prosody or speech (None: keyboard-like)."""
    if feedback.startswith("simulated:"):
        return feedback.split(":", 1)[1]
    return {"whisper": "speech", "prosody": "prosody"}.get(feedback)


@dataclasses.dataclass(frozen=True)
class SessionSpec:
    learner: str
    feedback: str
    out: Path
    checkpoint: Path | None
    config_path: str | None
    overrides: tuple[str, ...]
    config: FeedbackRunConfig  # the session's feedback config, channel applied
    chunk_ms: float = 250.0
    seconds: float = 0.0
    max_chunks: int = 0
    pace: bool = True
    view: str = "none"
    port: int = 0
    autosave_s: float = 30.0
    snapshot_every_s: float = 0.0  # the policy every this many shown seconds into OUT/snapshots (0: none)
    fresh_replay: bool = False
    calibrate: str | None = None
    listen_source: str = "mic"
    voice_config: str | None = None
    voice_set: tuple[str, ...] = ()
    keywords_only: bool = False
    save_segments: str | None = None
    coach_policy: Path | None = None
    coach_delay_s: float = 0.3
    coach_init: str = "actor"
    coach_log_std: float | None = None

    @property
    def chunk_steps(self) -> int:
        return max(1, round(self.chunk_ms / 1000.0 / self.config.feedback.dt))

    @property
    def learner_kind(self):
        """The learner's traits (live/kinds.py)."""
        return LEARNER_KINDS[self.learner]

    @property
    def live(self) -> bool:
        return self.feedback in LIVE

    @property
    def voice(self) -> bool:
        return self.feedback in ("prosody", "whisper")

    @property
    def speaker(self) -> bool:
        return self.voice and self.listen_source in SPEAKER_SOURCES.values()

    @property
    def speaker_says(self) -> str:
        """What the simulated speaker says praise and reproach in: sentences, or single words (speaker:words)."""
        return next(says for says, source in SPEAKER_SOURCES.items() if source == self.listen_source)

    def ddpg_overrides(self) -> dict:
        """The DDPG values a session takes from its feedback config (the rest is the checkpoint's)."""
        d = self.config.pretrain.ddpg
        return {k: getattr(d, k) for k in SESSION_DDPG_KEYS}

    @classmethod
    def create(cls, *, learner: str, feedback: str, out: Path | None, checkpoint: Path | None, config: Path | None,
               overrides=(), chunk_ms=250.0, seconds=0.0, max_chunks=0, pace=True, view: str = "none", port=0,
               autosave_s=30.0, snapshot_every_s=0.0, fresh_replay=False, calibrate=None, listen_source="mic",
               voice_config=None,
               voice_set=(), keywords_only=False, save_segments=None, coach_policy=None, coach_delay_s=0.3,
               coach_init="actor", coach_log_std=None) -> "SessionSpec":
        """A new session's spec from the command line's values; ConfigError (one line, exit 2) on a bad one."""
        if learner not in LEARNERS:
            raise ConfigError(f"--learner must be one of {', '.join(LEARNERS)}, got {learner!r}")
        if feedback not in FEEDBACK_CHOICES:
            raise ConfigError(f"--feedback must be one of {', '.join(FEEDBACK_CHOICES)}, got {feedback!r}")
        chunk_ms = _number("--chunk-ms", chunk_ms, 1.0, 10_000.0)
        seconds = _number("--seconds", seconds, 0.0, 1e7)
        max_chunks = _number("--max-chunks", max_chunks, 0, 1e9, integer=True)
        port = _number("--port", port, 0, 65535, integer=True)
        autosave_s = _number("--autosave-s", autosave_s, 0.0, 1e6)
        snapshot_every_s = _number("--snapshot-every-s", snapshot_every_s, 0.0, 1e7)
        coach_delay_s = _number("--coach-delay-s", coach_delay_s, 0.0, 10.0)
        if coach_log_std is not None:
            coach_log_std = _number("--coach-log-std", coach_log_std, -10.0, 2.0)
        if config is None and DEFAULT_FEEDBACK_CONFIG.is_file():
            config = DEFAULT_FEEDBACK_CONFIG
        check_config_file(config)
        for o in overrides:
            key = o.split("=", 1)[0].strip()
            if key.startswith("pretrain") and key not in {f"pretrain.ddpg.{k}" for k in SESSION_DDPG_KEYS}:
                raise ConfigError(f"--set {key}: a session takes its pretraining settings from the checkpoint; of "
                                  "the pretrain section only " + ", ".join(f"pretrain.ddpg.{k}" for k in SESSION_DDPG_KEYS)
                                  + " apply")
        cfg = resolve_config(config, list(overrides), feedback)
        spec = cls(learner=learner, feedback=feedback, out=out or Path("runs") / time.strftime("finetune-%Y%m%d-%H%M%S"),
                   checkpoint=checkpoint, config_path=str(config) if config else None, overrides=tuple(overrides),
                   config=cfg, chunk_ms=chunk_ms, seconds=seconds, max_chunks=max_chunks, pace=pace, view=view,
                   port=port, autosave_s=autosave_s, snapshot_every_s=snapshot_every_s, fresh_replay=fresh_replay,
                   calibrate=calibrate,
                   listen_source=listen_source, voice_config=voice_config, voice_set=tuple(voice_set),
                   keywords_only=keywords_only, save_segments=save_segments, coach_policy=coach_policy,
                   coach_delay_s=coach_delay_s, coach_init=coach_init, coach_log_std=coach_log_std)
        spec.check()
        return spec

    def check(self) -> None:
        """What the session cannot run with, refused before anything heavy."""
        from mjx_protamer.envs.body import REGIONS
        from mjx_protamer.human.touches import HANDS

        credit = self.config.feedback.credit
        if self.calibrate is not None:
            if self.calibrate not in (*REGIONS, *HANDS):
                raise ConfigError(f"--calibrate {self.calibrate!r}: not a touch; use one of "
                                  + ", ".join((*REGIONS, *HANDS)))
            if self.feedback == "none":
                raise ConfigError("--calibrate measures how fast feedback follows a touch: it needs feedback (keyboard, "
                                  "web, whisper, prosody; a simulated teacher reacts to its rule, not to the touch)")
        if self.feedback == "web" and self.view != "web":
            raise ConfigError("--feedback web takes feedback from the live page: it needs --view web")
        if credit.silence_needs_attention and self.learner_kind.counts_silences and self.feedback != "none":
            if not self.live or self.speaker:
                raise ConfigError("feedback.credit.silence_needs_attention: simulated teachers report no attention "
                                  "here; set it false (the in-jit teachers of pretrain/reproduce and a live "
                                  "session's page do)")
            if self.view != "web":
                raise ConfigError("feedback.credit.silence_needs_attention counts a silence only while the live "
                                  "page is visible: it needs --view web (or set it false)")
        if self.voice and not (self.listen_source in ("mic", *SPEAKER_SOURCES.values())
                               or (self.listen_source.startswith("wav:") and len(self.listen_source) > 4)):
            raise ConfigError(f"--listen-source must be 'mic', 'wav:PATH', 'speaker' or 'speaker:words', got "
                              f"{self.listen_source!r}")
        if self.speaker and not self.pace:
            raise ConfigError(f"--listen-source {self.listen_source} speaks at real-time pace into the listener: "
                              "leave out --no-pace")
        if self.coach_policy is not None and not Path(self.coach_policy).exists():
            raise ConfigError(f"--coach-policy {self.coach_policy}: no such file or directory (the --out of an "
                              "earlier `protamer finetune --learner coach`)")

    def manifest(self) -> dict:
        """What session.json keeps of the spec (with the identity of the checkpoint, added by the session)."""
        fb = self.config.feedback
        return {"version": 2, "learner": self.learner, "feedback": self.feedback, "chunk_ms": self.chunk_ms,
                "chunk_steps": self.chunk_steps, "config": self.config_path, "overrides": list(self.overrides),
                "coach_delay_s": self.coach_delay_s,
                "coach_policy": str(self.coach_policy) if self.coach_policy else None,
                "coach_init": self.coach_init if self.learner_kind.gaussian_policy else None,
                "coach_log_std": self.coach_log_std if self.learner_kind.gaussian_policy else None,
                "seeds": {"feedback": fb.seed}, "feedback_config": to_dict(fb), "run_config": to_dict(self.config),
                "session_config": to_dict(self.config.session), "listen_source": self.listen_source,
                "voice_config": self.voice_config, "voice_set": list(self.voice_set),
                "keywords_only": self.keywords_only, "pace": self.pace, "snapshot_every_s": self.snapshot_every_s,
                "segments": str(self.save_segments or (self.out / "segments")) if self.voice else None,
                "calibrate": self.calibrate,
                "session_ddpg": self.ddpg_overrides() if self.learner_kind.pretrain_run else None,
                "replay_from_checkpoint": self.learner_kind.pretrain_run and not self.fresh_replay}

    @classmethod
    def from_manifest(cls, manifest: dict, out: Path, **flags) -> "SessionSpec":
        """The spec a recorded session ran (`flags`: what a resume may change: view, port, seconds, ...)."""
        from mjx_protamer.errors import SessionRecordError

        if int(manifest.get("version", 1)) < 2:
            raise SessionRecordError(f"{out} was recorded before 6 December, by a session whose learner this version "
                                     "no longer has (host reward-model updates, no extra updates): it cannot be "
                                     "resumed or replayed here; its checkpoint still loads (`protamer eval`)")
        try:
            feedback = manifest["feedback"]
            from mjx_protamer.config import from_dict

            cfg = from_dict(FeedbackRunConfig, manifest["run_config"])  # as resolved then, whatever the file says now
            base = dict(learner=manifest["learner"], feedback=feedback, out=out, checkpoint=None,
                        config_path=manifest["config"], overrides=tuple(manifest["overrides"]), config=cfg,
                        chunk_ms=float(manifest["chunk_ms"]),
                        snapshot_every_s=float(manifest.get("snapshot_every_s") or 0.0),
                        fresh_replay=not manifest.get("replay_from_checkpoint"),
                        calibrate=manifest.get("calibrate"), listen_source=manifest.get("listen_source", "mic"),
                        voice_config=manifest.get("voice_config"), voice_set=tuple(manifest.get("voice_set") or ()),
                        keywords_only=bool(manifest.get("keywords_only")),
                        coach_policy=Path(manifest["coach_policy"]) if manifest.get("coach_policy") else None,
                        coach_delay_s=float(manifest.get("coach_delay_s", 0.3)),
                        coach_init=manifest.get("coach_init") or "scratch", coach_log_std=manifest.get("coach_log_std"))
        except (KeyError, TypeError, ValueError) as e:
            if isinstance(e, ConfigError):
                raise
            raise SessionRecordError(f"{out / 'session.json'} is not a finetune session's manifest "
                                     f"({type(e).__name__}: {e}); the record is damaged") from None
        base.update(flags)
        return cls(**base)


def resolve_config(path, overrides: list[str], feedback: str) -> FeedbackRunConfig:
    """The session's feedback config: the file and `--set`, with credit (and a simulated teacher) on the delay
    model of the channel the feedback comes through."""
    from mjx_protamer.human.teachers import with_channel

    cfg = load_feedback_config(path, overrides)
    kind = channel_kind(feedback)
    if kind is None:
        return cfg
    return dataclasses.replace(cfg, feedback=dataclasses.replace(cfg.feedback,
                                                                 teacher=with_channel(cfg.feedback.teacher, kind)))
