"""DDPG hyper-parameters and the run settings of batched training, as validated frozen dataclasses.

The defaults of `DDPGConfig` are the paper's reference learner (spec, "The reference learners"): actor and
critic 400-300, Adam 1e-3 both, gamma 0.99, tau 0.001, batch 64, replay 1e5, OU noise theta 0.15 sigma 0.6.
Every float is also checked finite by the loader (`mjx_protamer.config`).
`TrainConfig` says how the learner meets the env: how many envs step together, for how long, how many
gradient updates per vectorised env step, and how the run is cut into jitted chunks.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from mjx_protamer.config import check, check_seed
from mjx_protamer.envs.config import EnvConfig
from mjx_protamer.envs.toy import ToyEnvConfig


@dataclass(frozen=True)
class NoiseConfig:
    # exploration noise added to the actor's action: ou (Ornstein-Uhlenbeck), gaussian or none
    kind: Literal["ou", "gaussian", "none"] = "ou"
    # Ornstein-Uhlenbeck with dt = 1: x' = x + theta (mu - x) + sigma N(0, 1), one process per env and per
    # action dim, reset at episode start. Stationary std = sigma / sqrt(2 theta - theta^2) (1.14 here).
    theta: float = 0.15
    sigma: float = 0.6  # for "gaussian": the std of the independent per-step noise
    mu: float = 0.0  # the OU process's mean (0: noise around the actor's action)
    # The last `quiet_fraction` of the envs act with the deterministic actor (no noise added). A policy
    # trained only on noisy behaviour is judged on states its critic never saw: the deterministic actor of
    # the self-touch env froze once the noise was off (issue 8). Quiet envs put the test policy's own states
    # and their returns into the replay (like Ape-X's per-actor exploration levels), and let a simulated
    # teacher judge the behaviour the test measures.
    quiet_fraction: float = 0.0
    # 0: the same envs stay quiet all run. N > 0: every N steps the quiet block moves on to the next envs, so
    # each env alternates between the deterministic actor and noise, and noise starts from the states the
    # deterministic actor leads to: a test policy that holds a press is shown, in training, what leaving it
    # is worth (the noisy envs never reach that state; docs/experiments.md, "the reproach can be learned").
    quiet_rotation_steps: int = 0

    def validate(self) -> None:
        check(0.0 < self.theta <= 1.0, "theta", f"must be in (0, 1], got {self.theta}")
        check(self.quiet_rotation_steps >= 0, "quiet_rotation_steps",
              f"must be >= 0 (0: the quiet envs stay the same), got {self.quiet_rotation_steps}")
        check(self.sigma >= 0.0, "sigma", f"must be >= 0, got {self.sigma}")
        check(0.0 <= self.quiet_fraction < 1.0, "quiet_fraction",
              f"must be in [0, 1) (the share of envs acting without noise), got {self.quiet_fraction}")


@dataclass(frozen=True)
class DDPGConfig:
    actor_hidden: tuple[int, ...] = (400, 300)  # the actor MLP's hidden layer widths (the paper's 400-300)
    critic_hidden: tuple[int, ...] = (400, 300)  # the action enters at the second layer
    actor_lr: float = 1e-3  # Adam step size of the actor
    critic_lr: float = 1e-3  # Adam step size of the critic
    gamma: float = 0.99  # discount per env step
    tau: float = 0.001  # soft target update: target = tau x online + (1 - tau) x target, every update
    batch_size: int = 64  # replay rows per gradient update
    # transitions the replay keeps, over all envs (split among devices; the oldest are overwritten)
    replay_size: int = 100_000
    # Sample-time reward: alpha * (reward_terms @ env weights) + beta * human_reward_fn(params, obs, action).
    reward_alpha: float = 1.0
    reward_beta: float = 0.1  # beta of the sample-time reward above: the weight of the human reward model's r_hat
    actor_preact_coef: float = 0.0  # penalty on the actor's pre-tanh activations (losses.actor_loss)
    actor_preact_free: float = 0.0  # pre-tanh magnitude the penalty leaves free (0: a pull toward 0 everywhere)
    # Step-size decay over a run (actor and critic): 1 until `lr_decay_from` of the run's iterations, then
    # linear to `lr_final_fraction` of the rate at the last one. 1.0 = constant (the paper). A fine-tuning
    # session is open-ended: a constant rate, its feedback config's actor_lr / critic_lr (live/tamer.py).
    lr_final_fraction: float = 1.0
    lr_decay_from: float = 0.5  # the share of the run before the step-size decay starts (see lr_final_fraction)
    # Action biasing (losses.actor_loss): the actor also climbs `human_actor_coef * r_hat(s, mu(s))` of the human
    # reward model, beside the critic's Q (whose scale is a return: tens per unit of step reward). 0: the paper's
    # DDPG, where r_hat reaches the policy only through `reward_beta` and the critic.
    human_actor_coef: float = 0.0
    # The step size of action biasing's own Adam (0: one Adam over the actor's whole loss, at actor_lr). Adam
    # normalises a gradient's scale away, so a smaller actor_lr is the only way to slow what the intrinsic
    # reward alone changes in a session (a session without feedback has no other term); with its own optimiser
    # the person's term keeps this step size while actor_lr slows the rest (docs/human_feedback.md).
    human_actor_lr: float = 0.0
    # A critic of r_hat alone (0: none): Q_h(s, a) = r_hat(s, a) + human_critic_gamma * Q_h(s', mu'(s')), learned
    # beside the critic on the same minibatches, and the actor climbs `human_critic_coef * (1 - gamma_h) * Q_h`
    # (r_hat's units). r_hat's own action gradient only ranks the actions at the step the person judged; Q_h ranks
    # them by what they lead to. It starts as the critic's trunk with a zero output (losses.HumanTerm,
    # train.human_critic_from). Its state follows from the config alone; unused without a human reward model.
    human_critic_coef: float = 0.0
    human_critic_gamma: float = 0.99  # Q_h's discount per env step (0.99: the person's praise reaches ~0.5 s back)
    # A pull of the actor toward the actor the run started from (a session: its checkpoint's), weighing
    # `anchor_coef * |mu(s) - mu_0(s)|^2`: bounds what the intrinsic reward alone changes in a session.
    anchor_coef: float = 0.0
    # How many of a session's feedback events let the anchor go (0: it never does): its weight falls from 1 by
    # 1/N with each event the reward model learns from. A session nobody speaks to stays anchored (it keeps
    # what the checkpoint did); once a person teaches, the intrinsic reward and the person's term move the
    # actor freely (docs/human_feedback.md, "Holding still until the person speaks").
    anchor_release_events: int = 0
    # What a praise (an event of positive value) takes off the anchor, as a share of a reproach's 1/N: 1 every
    # event alike; 0 only reproach lets the anchor go; below 0 a praise gives that share back (weight at most 1), so
    # the hold follows the balance of the person's words. Praise says "keep doing this": an infant the person is
    # pleased with then keeps what it does instead of drifting with the intrinsic reward once released.
    anchor_praise_release: float = 1.0
    # A praise holds what was praised (False: off): the anchor becomes the actor of the moment the praise is taken
    # (its weight as `anchor_praise_release` sets it). The checkpoint's actor is not what the person saw once the
    # session has moved it. A session nobody speaks to keeps the checkpoint's anchor; with a praise that gives weight
    # back, one the person is pleased with keeps what pleased them and one mostly reproached learns.
    anchor_praise_hold: bool = False
    # The infant explores as far as the person's words have let the hold go (False: off): the exploration noise is
    # scaled by 1 - the anchor's weight. Nobody has spoken: the person sees the deterministic actor, the one a test
    # runs and a praise holds; reproach lets the hold go and the noise come back, so a checkpoint doing the wrong
    # thing shows the person alternatives to praise, and praise (with `anchor_praise_release` below 0) quiets it
    # again. Needs the anchor and events that move its weight (`anchor_coef`, `anchor_release_events` > 0).
    noise_follows_hold: bool = False
    # Praise as a demonstration (0: off): the actor is also pulled toward the actions the person praised, weighing
    # `praise_imitation_coef * |mu(s) - a|^2` over (s, a) rows the session's feedback ring credited to praise
    # (drawn in proportion to weight x value). Action biasing follows r_hat's gradient wherever it points; this
    # says "keep doing what you did when I said good". Needs a live session's ring (live/tamer.py; table2 and
    # pretrain refuse it). Measured at a voice's rate and not shipped (docs/human_feedback.md, "A word as a
    # demonstration").
    praise_imitation_coef: float = 0.0
    # Reproach as a counter-demonstration (0: off): `reproach_avoid_coef * max(0, 1 - |mu(s) - a|^2)` over the rows
    # the person reproached, a push away from what was done there until the action differs by 1 (squared, over
    # the action's dimensions; exploration noise of 0.2 per dimension makes ~0.6). Needs the ring, as above.
    reproach_avoid_coef: float = 0.0
    noise: NoiseConfig = field(default_factory=NoiseConfig)

    def validate(self) -> None:
        check(0.0 < self.lr_final_fraction <= 1.0, "lr_final_fraction",
              f"must be in (0, 1] (1 = a constant step size), got {self.lr_final_fraction}")
        check(0.0 <= self.lr_decay_from < 1.0, "lr_decay_from",
              f"must be in [0, 1) (the share of the run before the decay starts), got {self.lr_decay_from}")
        check(len(self.actor_hidden) >= 1 and min(self.actor_hidden) > 0, "actor_hidden",
              f"needs at least one positive layer width, got {self.actor_hidden}")
        check(len(self.critic_hidden) >= 2 and min(self.critic_hidden) > 0, "critic_hidden",
              f"needs at least two positive layer widths (the action enters the second), got {self.critic_hidden}")
        check(self.actor_lr > 0, "actor_lr", f"must be > 0, got {self.actor_lr}")
        check(self.critic_lr > 0, "critic_lr", f"must be > 0, got {self.critic_lr}")
        check(0.0 <= self.gamma < 1.0, "gamma", f"must be in [0, 1), got {self.gamma}")
        check(0.0 < self.tau <= 1.0, "tau", f"must be in (0, 1], got {self.tau}")
        check(self.actor_preact_coef >= 0, "actor_preact_coef", f"must be >= 0, got {self.actor_preact_coef}")
        check(self.actor_preact_free >= 0, "actor_preact_free", f"must be >= 0, got {self.actor_preact_free}")
        check(self.batch_size >= 1, "batch_size", f"must be >= 1, got {self.batch_size}")
        check(self.reward_alpha >= 0.0, "reward_alpha", f"must be >= 0, got {self.reward_alpha}")
        check(self.reward_beta >= 0.0, "reward_beta", f"must be >= 0, got {self.reward_beta}")
        check(self.human_actor_coef >= 0.0, "human_actor_coef", f"must be >= 0, got {self.human_actor_coef}")
        check(self.human_actor_lr >= 0.0, "human_actor_lr",
              f"must be >= 0 (0: action biasing shares the actor's optimiser), got {self.human_actor_lr}")
        check(self.human_critic_coef >= 0.0, "human_critic_coef",
              f"must be >= 0 (0: no critic of r_hat alone), got {self.human_critic_coef}")
        check(0.0 <= self.human_critic_gamma < 1.0, "human_critic_gamma",
              f"must be in [0, 1), got {self.human_critic_gamma}")
        check(self.anchor_coef >= 0.0, "anchor_coef", f"must be >= 0, got {self.anchor_coef}")
        check(self.anchor_praise_release <= 1.0, "anchor_praise_release",
              f"must be <= 1 (1: a praise lets go as much as a reproach; < 0: a praise gives weight back), "
              f"got {self.anchor_praise_release}")
        check(not self.anchor_praise_hold or self.anchor_coef > 0, "anchor_praise_hold",
              "needs anchor_coef > 0 (a praise holds the actor through the anchor's pull)")
        check(not self.noise_follows_hold or (self.anchor_coef > 0 and self.anchor_release_events > 0),
              "noise_follows_hold", "needs anchor_coef > 0 and anchor_release_events > 0 (the noise follows the "
              "anchor's weight, which only the person's events move)")
        check(self.praise_imitation_coef >= 0.0, "praise_imitation_coef",
              f"must be >= 0 (0: praise is not imitated), got {self.praise_imitation_coef}")
        check(self.reproach_avoid_coef >= 0.0, "reproach_avoid_coef",
              f"must be >= 0 (0: reproach does not push away), got {self.reproach_avoid_coef}")
        check(self.anchor_release_events >= 0, "anchor_release_events",
              f"must be >= 0 (0: the anchor never lets go), got {self.anchor_release_events}")
        check(self.replay_size >= self.batch_size, "replay_size",
              f"must be >= batch_size ({self.batch_size}), got {self.replay_size}")

    def check_batched(self, run: str, prefix: str) -> None:
        """Refuse the options only a live session can act on, for a batched `run` (`protamer pretrain`, `reproduce
        table2`; `prefix`: where this section sits in its config): they read what the person said on the host,
        which a batched run has not."""
        for key in ("praise_imitation_coef", "reproach_avoid_coef"):  # they read a live session's feedback ring
            check(getattr(self, key) == 0, f"{prefix}{key}",
                  f"is a live session's option (finetune, reproduce live): {run} has no session ring to draw the "
                  "person's words from; set it to 0")
        check(not self.anchor_praise_hold, f"{prefix}anchor_praise_hold",
              f"is a live session's option (finetune, reproduce live): {run} takes no praise on the host to hold "
              "the actor by; set it to false")
        check(not self.noise_follows_hold, f"{prefix}noise_follows_hold",
              f"is a live session's option (finetune, reproduce live): {run} takes no events on the host to let "
              "the hold go by, so its envs would never explore; set it to false")


@dataclass(frozen=True)
class TrainConfig:
    """Defaults: the batched pretraining default (configs/pretrain.yaml); the paper's single-env setting is
    configs/paper_single_env.yaml."""

    seed: int = 0  # the run's seed: networks, noise, envs, replay draws (test episodes use seeds derived from it)
    num_envs: int = 32  # envs stepped together, in one batch (vmapped)
    episode_length: int = 1000  # env steps per episode; must equal env.episode_length for the self-touch env
    total_env_steps: int = 256_000  # over all envs; rounded up to whole chunks
    warmup_env_steps: int = 4_000  # uniform random actions, no updates, before learning starts
    updates_per_step: int = 2  # gradient updates per vectorised env step (one step of every env)
    stagger_episodes: bool = True  # random initial episode clocks, so a batch of envs does not reset in lockstep
    chunk_steps: int = 100  # vectorised env steps per jitted chunk; host work happens between chunks
    checkpoint_every_chunks: int = 5  # a checkpoint every this many chunks (and after the last)
    num_devices: int = 0  # data-parallel devices to shard over; 0 = all of this process's (jax.local_devices())
    eval_episodes: int = 10  # deterministic test episodes at the end of a run (eval.json)
    # The test policy: 0, the last actor (the paper); N > 0, the best of the actors after every N-th chunk
    # from `select_from` of the run (and the last), by the learner's objective on `select_episodes`
    # validation episodes (agents/ddpg/selection.py says why)
    select_every_chunks: int = 0
    select_from: float = 0.5  # the share of the run before snapshots are validated (see select_every_chunks)
    select_episodes: int = 4  # validation episodes per snapshot (see select_every_chunks)

    def validate(self) -> None:
        check_seed(self.seed, "seed")
        check(self.num_envs >= 1, "num_envs", f"must be >= 1, got {self.num_envs}")
        check(self.episode_length >= 1, "episode_length", f"must be >= 1, got {self.episode_length}")
        check(self.total_env_steps >= self.num_envs, "total_env_steps",
              f"must be >= num_envs ({self.num_envs}), got {self.total_env_steps}")
        check(self.warmup_env_steps >= 0, "warmup_env_steps", f"must be >= 0, got {self.warmup_env_steps}")
        check(self.updates_per_step >= 1, "updates_per_step",
              f"must be >= 1 (0 would only collect data and learn nothing), got {self.updates_per_step}")
        check(self.chunk_steps >= 1, "chunk_steps", f"must be >= 1, got {self.chunk_steps}")
        check(self.checkpoint_every_chunks >= 1, "checkpoint_every_chunks",
              f"must be >= 1, got {self.checkpoint_every_chunks}")
        check(self.num_devices >= 0, "num_devices", f"must be >= 0, got {self.num_devices}")
        check(self.eval_episodes >= 1, "eval_episodes", f"must be >= 1, got {self.eval_episodes}")
        check(self.select_every_chunks >= 0, "select_every_chunks",
              f"must be >= 0 (0 tests the last actor), got {self.select_every_chunks}")
        check(0.0 <= self.select_from < 1.0, "select_from",
              f"must be in [0, 1) (the share of the run before snapshots are validated), got {self.select_from}")
        check(self.select_episodes >= 1, "select_episodes", f"must be >= 1, got {self.select_episodes}")

    @property
    def iterations(self) -> int:
        """Vectorised env steps, rounded up to whole chunks."""
        per_chunk = self.chunk_steps
        steps = -(-self.total_env_steps // self.num_envs)
        return -(-steps // per_chunk) * per_chunk

    @property
    def num_chunks(self) -> int:
        return self.iterations // self.chunk_steps

    @property
    def warmup_iterations(self) -> int:
        return -(-self.warmup_env_steps // self.num_envs)


def batched_ddpg() -> DDPGConfig:
    """The batched default's learner: the paper's, with tau 0.005 and exploration on a human time scale.

    OU theta 0.01 (correlation time 100 steps = 0.5 s) with sigma 0.042 (stationary std 0.3): the paper's
    theta 0.15 changes the target every 5 ms step, and stiff 200 Hz servos turn that into 10-20 rad/s of
    jitter (the movement band is then never met and the critic never sees a slow or frozen arm). With the
    paper's sigma 0.6 and tau 0.001, batched self-touch training collapses after ~30k env steps. A quarter of the
    envs act without noise (`quiet_fraction`): over 5 seeds at 256k env steps the test policy's freeze ratio
    was 0.12 +- 0.11 (seed std 0.09) with them and 0.19 +- 0.23 (std 0.18) without (docs/experiments.md).
    A wall on the actor's pre-tanh activations past 2 (|a| > 0.96): with feedback, a seed's actor sat with 91%
    of its action dimensions at |a| > 0.99, where tanh passes no gradient, frozen in the teacher's disapproval;
    with the wall 0.2% (docs/experiments.md). A plain L2 pull (coef 0.1, free 0) also removed the saturation
    but biased every action toward 0 and changed the baseline (freeze 0.22, seed std 0.18)."""
    return DDPGConfig(tau=0.005, noise=NoiseConfig(kind="ou", theta=0.01, sigma=0.042, quiet_fraction=0.25),
                      actor_preact_coef=1.0, actor_preact_free=2.0)


@dataclass(frozen=True)
class PretrainConfig:
    """A whole `protamer pretrain` run: which env (with its config), the learner, the run settings."""

    env_name: Literal["self_touch", "toy"] = "self_touch"  # the infant (the env section) or the 2-D point (toy)
    env: EnvConfig = field(default_factory=EnvConfig)  # the self-touch env (used when env_name is self_touch)
    toy: ToyEnvConfig = field(default_factory=ToyEnvConfig)
    ddpg: DDPGConfig = field(default_factory=batched_ddpg)
    train: TrainConfig = field(default_factory=TrainConfig)

    def validate(self) -> None:
        check(self.train.warmup_env_steps < self.train.iterations * self.train.num_envs, "train.warmup_env_steps",
              "is longer than the whole run, so nothing would be learned")
        if self.env_name == "self_touch":
            check(self.train.episode_length == self.env.episode_length, "train.episode_length",
                  f"must equal env.episode_length ({self.env.episode_length}), got {self.train.episode_length}")
