"""The one run schema: a run's pretraining, its human side (credit, reward model, simulated teacher, timing), the
in-jit feedback path's sizing, a live session's learner and Deep COACH's.

`FeedbackRunConfig` is what every command that trains with feedback reads, through the one validating loader
(`mjx_protamer.config.load_config`): `configs/feedback_*.yaml` (`pretrain --feedback-config`, `finetune
--config`) and, extended by the conditions and seeds, table2's files (`experiments/table2/config.py`
`Table2Config`). Its sections: pretrain (a PretrainConfig: what `pretrain --feedback` trains; a live session
takes the checkpoint's instead, except the DDPG keys in `SESSION_DDPG_KEYS`), feedback, batched (how the in-jit
feedback path of `pretrain --feedback` and table2 is sized), session (a live session's learner) and coach (what a
`finetune --learner coach` session's Deep COACH learns with; `--coach-delay-s` and `--coach-init actor` set its
delay and its network's shape on top). A command reads the sections it uses; the others may be present in its
file, and are validated all the same.
"""

from __future__ import annotations

import dataclasses

from mjx_protamer.agents.coach.config import CoachConfig
from mjx_protamer.agents.ddpg.config import PretrainConfig
from mjx_protamer.config import check
from mjx_protamer.human.credit import CreditConfig
from mjx_protamer.human.reward_model import RewardModelConfig
from mjx_protamer.human.teachers import TeacherConfig

# Of a feedback config's pretrain section a live session takes only what DDPG learns from and how fast: the
# reward weights, action biasing (its own step size, the critic of r_hat alone), the anchor and the step sizes.
# The rest (networks, env, noise) is the checkpoint's. (Sessions recorded before 6 December took the two reward
# weights alone.)
SESSION_DDPG_KEYS = ("reward_alpha", "reward_beta", "human_actor_coef", "human_actor_lr", "human_critic_coef",
                     "human_critic_gamma", "anchor_coef", "anchor_release_events", "anchor_praise_release",
                     "anchor_praise_hold", "noise_follows_hold",
                     "praise_imitation_coef", "reproach_avoid_coef",
                     "actor_lr", "critic_lr")


@dataclasses.dataclass(frozen=True)
class FeedbackConfig:
    """The human side of a run: credit, reward model, simulated teacher and timing."""

    credit: CreditConfig = dataclasses.field(default_factory=CreditConfig)
    reward_model: RewardModelConfig = dataclasses.field(default_factory=RewardModelConfig)
    teacher: TeacherConfig = dataclasses.field(default_factory=TeacherConfig)
    dt: float = 0.005  # presentation period of one env step (s): the env's control period in real time
    watch_env: int = 0  # the env of the batch the teacher (or human) watches
    # a live session's feedback queue (events waiting for the learner; more are dropped and logged)
    queue_size: int = 256
    seed: int = 0  # a live session's host streams (teacher, credit draws, the simulated speaker's voice)

    def validate(self) -> None:
        check(self.dt > 0, "dt", f"must be > 0, got {self.dt}")
        check(self.watch_env >= 0, "watch_env", f"must be >= 0, got {self.watch_env}")
        check(self.queue_size >= 1, "queue_size", f"must be >= 1, got {self.queue_size}")
        check(0 <= self.seed < 2 ** 32, "seed", f"must be in 0..2^32-1, got {self.seed}")


@dataclasses.dataclass(frozen=True)
class BatchedFeedbackConfig:
    """How the in-jit feedback path is sized (the `batched` section of a feedback or table2 config)."""

    teach_envs: int = 0  # envs that have a teacher (the first n); 0 = every env
    # Teachers watch only the envs that act without exploration noise (the last `ddpg.noise.quiet_fraction` of
    # them): the behaviour the deterministic test episodes measure, as a TAMER teacher watches a greedy agent.
    # Under noise the arms rarely stop, so a teacher of every env scolds a freeze too rarely for r_hat to learn
    # it. Measured worse than a teacher on every env (a quarter of the events; docs/experiments.md, "Where r_hat
    # errs on the learner's own test states"), so it is off by default.
    teach_quiet: bool = False
    max_events_per_chunk: int = 0  # events credited per chunk (static shape); 0 = auto from num_envs and min gap
    rows_per_event: int = 32  # credited steps drawn per event, in proportion to their credit weight
    replay_updates_per_chunk: int = -1  # reward-model replay minibatches per chunk; -1 = chunk_steps // replay_every
    # minibatches on the chunk's newly credited rows; -1 = updates_per_feedback x ceil(max events / 3), about one
    # per event given (Deep TAMER updates on every feedback)
    fresh_updates_per_chunk: int = -1
    # steps the teacher watched in silence (labelled 0, each weighing `credit.silence_weight` events) are
    # represented by this many rows a chunk (per device), drawn uniformly among them; 0: events alone
    silence_rows_per_chunk: int = 1024

    def validate(self) -> None:
        check(self.teach_envs >= 0, "teach_envs", f"must be >= 0, got {self.teach_envs}")
        check(not (self.teach_quiet and self.teach_envs), "teach_quiet",
              f"picks the envs with a teacher itself: set teach_envs 0 (got {self.teach_envs}) or teach_quiet false")
        check(self.max_events_per_chunk >= 0, "max_events_per_chunk", f"must be >= 0, got {self.max_events_per_chunk}")
        check(self.rows_per_event >= 1, "rows_per_event", f"must be >= 1, got {self.rows_per_event}")
        check(self.fresh_updates_per_chunk >= -1, "fresh_updates_per_chunk",
              f"must be >= -1, got {self.fresh_updates_per_chunk}")
        check(self.silence_rows_per_chunk >= 0, "silence_rows_per_chunk",
              f"must be >= 0, got {self.silence_rows_per_chunk}")
        check(self.replay_updates_per_chunk >= -1, "replay_updates_per_chunk",
              f"must be >= -1, got {self.replay_updates_per_chunk}")


@dataclasses.dataclass(frozen=True)
class SessionConfig:
    """How a live session's learner spends the machine and the person's feedback (mjx_protamer/live/;
    docs/human_feedback.md, "How a session learns")."""

    # DDPG updates interleaved with the env steps of a chunk (one per step, as pretraining does per env)
    updates_per_step: int = 1
    # Paced sessions: the time a chunk is shown and not computed goes to more updates, up to this many per shown
    # step in all (the count is recorded per chunk, so a replay makes the same updates)
    max_updates_per_step: float = 8.0
    spare_fraction: float = 0.8  # the share of the measured spare time given to them (the rest absorbs jitter)
    # Unpaced sessions (replays of nothing, `reproduce live`): this many updates per shown step in all, the pace
    # issue 39 asks of a paced one (which makes about 1.3 with Whisper and the page on 2 cores: `protamer bench live`)
    unpaced_updates_per_step: float = 2.0
    # DDPG on the person's clock (0: off, updates by the clock as above). With N > 0 the chunks make no updates of
    # their own and each event the reward model takes buys N, made after its drain within what the pace allows per
    # chunk (max_updates_per_step; a backlog carries over): a session nobody speaks to does not learn, and the
    # intrinsic reward moves the actor only as far as the person's events pay for
    updates_per_event: float = 0.0
    # the pretraining run's latest transitions a session's DDPG replay starts with (0: an empty replay)
    replay_from_checkpoint: int = 20_000
    # False: the infant acts with its deterministic actor, no exploration noise (the checkpoint's noise otherwise).
    # The person then judges the policy a test measures and the session hands over, not the jitter around it
    explore: bool = True
    max_events_per_chunk: int = 16  # feedback events credited per chunk (more are logged and dropped)
    rows_per_event: int = 32  # credited steps drawn per event in proportion to their credit weight (batched: same)

    @property
    def chunk_updates_per_step(self) -> int:
        """The DDPG updates a chunk makes per step of its own: none on the person's clock (`updates_per_event`)."""
        return 0 if self.updates_per_event > 0 else self.updates_per_step

    def validate(self) -> None:
        check(self.updates_per_step >= 1, "updates_per_step", f"must be >= 1, got {self.updates_per_step}")
        check(self.max_updates_per_step >= self.updates_per_step, "max_updates_per_step",
              f"must be >= updates_per_step ({self.updates_per_step}), got {self.max_updates_per_step}")
        check(0.0 < self.spare_fraction <= 1.0, "spare_fraction", f"must be in (0, 1], got {self.spare_fraction}")
        check(self.unpaced_updates_per_step >= self.updates_per_step, "unpaced_updates_per_step",
              f"must be >= updates_per_step ({self.updates_per_step}), got {self.unpaced_updates_per_step}")
        check(self.updates_per_event >= 0, "updates_per_event",
              f"must be >= 0 (0: updates by the clock), got {self.updates_per_event}")
        check(self.replay_from_checkpoint >= 0, "replay_from_checkpoint",
              f"must be >= 0, got {self.replay_from_checkpoint}")
        check(self.max_events_per_chunk >= 1, "max_events_per_chunk", f"must be >= 1, got {self.max_events_per_chunk}")
        check(self.rows_per_event >= 1, "rows_per_event", f"must be >= 1, got {self.rows_per_event}")


@dataclasses.dataclass(frozen=True)
class FeedbackRunConfig:
    """One run: a pretrain config (env, ddpg, train), the feedback section, the in-jit path's sizing, a live
    session's learner and Deep COACH's (configs/feedback_*.yaml; table2's files extend it)."""

    pretrain: PretrainConfig = dataclasses.field(default_factory=PretrainConfig)
    feedback: FeedbackConfig = dataclasses.field(default_factory=FeedbackConfig)
    batched: BatchedFeedbackConfig = dataclasses.field(default_factory=BatchedFeedbackConfig)
    session: SessionConfig = dataclasses.field(default_factory=SessionConfig)
    coach: CoachConfig = dataclasses.field(default_factory=CoachConfig)

    def validate(self) -> None:
        check(self.feedback.watch_env < self.pretrain.train.num_envs, "feedback.watch_env",
              f"must be < train.num_envs ({self.pretrain.train.num_envs})")


def load_feedback_config(path=None, overrides=None) -> FeedbackRunConfig:
    """Load a FeedbackRunConfig from a YAML file (its defaults when path is None) with `a.b=value` overrides."""
    from mjx_protamer.config import load_config

    return load_config(FeedbackRunConfig, path, overrides)
