"""Table II's schema: the run schema (`FeedbackRunConfig`: pretrain, feedback, batched, session, coach) with the
conditions and the seeds, and the loader of a table2 YAML."""

from __future__ import annotations

import dataclasses
from typing import Literal

from mjx_protamer.config import ConfigError, check, check_seed, from_dict, read_raw, shipped_config
from mjx_protamer.human.feedback_config import FeedbackRunConfig


@dataclasses.dataclass(frozen=True)
class Condition:
    name: str  # the row's name in table2.md/.json and the files it writes (DDPG, DTK, ...); unique in a run
    # the simulated teacher's channel: none (no feedback: DDPG), keyboard, prosody or speech (its delay and noise)
    channel: Literal["none", "keyboard", "prosody", "speech"] = "none"
    # which steps an event is about (human/credit.py): the channel's delay distribution, the authors' 15-step
    # window, or Deep TAMER's Uniform[0.2, 4] s window
    credit: Literal["channel", "step_window", "time_window"] = "channel"
    beta_scale: float = 1.0  # multiplies ddpg.reward_beta for this condition (a value: no recompile)

    def validate(self) -> None:
        check(bool(self.name), "name", "must not be empty")
        check(self.beta_scale >= 0, "beta_scale", f"must be >= 0, got {self.beta_scale}")


DEFAULT_CONDITIONS = (Condition("DDPG", "none"), Condition("DTK", "keyboard"), Condition("DTW", "speech"),
                      Condition("DTP", "prosody"))


@dataclasses.dataclass(frozen=True)
class Table2Config(FeedbackRunConfig):
    """One run's sections (table2 reads pretrain, feedback and batched; session and coach may be present) with the
    conditions trained side by side on the seeds."""

    conditions: tuple[Condition, ...] = DEFAULT_CONDITIONS
    seeds: tuple[int, ...] = (0, 1, 2, 3, 4)  # the issue-8 protocol: 5 seeds, vmapped
    moving_average: int = 10  # chunks in Figure 1's moving average

    def validate(self) -> None:
        super().validate()
        check(len(self.conditions) >= 1, "conditions", "needs at least one condition")
        names = [c.name for c in self.conditions]
        check(len(set(names)) == len(names), "conditions", f"names must be unique, got {names}")
        check(len(self.seeds) >= 1, "seeds", "needs at least one seed")
        for i, seed in enumerate(self.seeds):
            check_seed(seed, f"seeds[{i}]")
        check(self.moving_average >= 1, "moving_average", f"must be >= 1, got {self.moving_average}")
        self.pretrain.ddpg.check_batched("a table2 run (batched)", "pretrain.ddpg.")


# What `reproduce table2` runs without --config (a file shipped with the package, `config.shipped_config`): the
# setting whose Table II meets issue 8's targets on 5 seeds (docs/results/table2_attention_asinh/); what it changes
# against `Table2Config()` and each change's measurement: the file's comments and docs/experiments.md.
DEFAULT_CONFIG = "table2_attention.yaml"


def load_table2_config(path=None, overrides=None, seeds: int | None = None) -> Table2Config:
    """From a YAML file, by default the shipped DEFAULT_CONFIG (its missing keys take `Table2Config()`'s
    defaults), with `a.b=value` overrides."""
    raw = read_raw(shipped_config(DEFAULT_CONFIG) if path is None else path, overrides)
    if seeds is not None:
        if seeds < 1:
            raise ConfigError(f"--seeds must be >= 1, got {seeds}")
        raw["seeds"] = list(range(seeds))
    return from_dict(Table2Config, raw)

