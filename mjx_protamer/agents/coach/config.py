"""Deep COACH hyper-parameters (spec, "The reference learners"; Arumugam et al. 2019)."""

from __future__ import annotations

from dataclasses import dataclass

from mjx_protamer.config import check


@dataclass(frozen=True)
class CoachConfig:
    # hidden layer widths of the Gaussian policy (finetune --coach-init actor takes the checkpoint actor's)
    hidden: tuple[int, ...] = (64, 64)
    window: int = 10  # L: steps per window (eligibility trace length)
    trace_decay: float = 0.35  # lambda: the eligibility trace weighs the j-th step before a window's last lambda^j
    human_delay_steps: int = 1  # feedback at step k judges the window ending at step k - delay
    learning_rate: float = 2.5e-4  # Adam step size
    entropy_coef: float = 1e-3  # weight of the policy's entropy bonus in the loss (keeps it exploring)
    # the policy's initial log standard deviation (a learned parameter per action dimension)
    init_log_std: float = -0.5
    min_log_std: float = -3.0  # the log std is floored here when acting and in the loss
    replay_size: int = 1000  # windows kept (the oldest are overwritten)
    batch_windows: int = 16  # windows per minibatch (16-32 in the paper); the newest is always included
    updates_per_feedback: int = 1  # gradient steps per feedback event
    activation: str = "tanh"  # hidden layers; "relu" to start from a DDPG actor (finetune --coach-init actor)

    def validate(self) -> None:
        check(len(self.hidden) >= 1 and min(self.hidden) > 0, "hidden", f"needs positive widths, got {self.hidden}")
        check(self.window >= 1, "window", f"must be >= 1, got {self.window}")
        check(0.0 < self.trace_decay <= 1.0, "trace_decay", f"must be in (0, 1], got {self.trace_decay}")
        check(self.human_delay_steps >= 0, "human_delay_steps", f"must be >= 0, got {self.human_delay_steps}")
        check(self.learning_rate > 0, "learning_rate", f"must be > 0, got {self.learning_rate}")
        check(self.entropy_coef >= 0, "entropy_coef", f"must be >= 0, got {self.entropy_coef}")
        check(self.replay_size >= self.batch_windows, "replay_size",
              f"must be >= batch_windows ({self.batch_windows}), got {self.replay_size}")
        check(self.batch_windows >= 1, "batch_windows", f"must be >= 1, got {self.batch_windows}")
        check(self.activation in ("tanh", "relu"), "activation", f"must be tanh or relu, got {self.activation!r}")
