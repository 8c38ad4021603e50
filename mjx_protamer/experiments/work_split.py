"""How a table2 run on N processes shares its work: each process gets one rectangle of the (condition x seed)
grid, a group of conditions and a block of seeds, and trains that group with the block's seeds vmapped in one
program (`table2.train_table2`).

`split`:
- `seeds`: every process trains every condition on a contiguous block of the seeds (needs N <= seeds).
- `conditions`: every process trains all the seeds on a contiguous group of the conditions (needs N <=
  conditions).
- `both` (the default): the conditions in g = gcd(N, conditions) equal groups, the seeds in N / g blocks. With 2
  processes and 4 conditions, each trains 2 conditions on all the seeds; 8 processes and 4 conditions: each one
  condition on half the seeds; 3 processes and 4 conditions: every condition on a third of the seeds.
  Conditions are split first because a process that trains all the seeds runs the one-process program (every
  seed in one vmapped program): its per-seed results are bit for bit those of one process running the whole
  command. A seed block gives those of one process running that block (another program layout: the same up to
  float rounding, not bit for bit).

Pure Python: every process computes the same split from the same arguments, without talking to the others.
"""

from __future__ import annotations

import dataclasses
import math

from mjx_protamer.config import ConfigError

SPLITS = ("both", "seeds", "conditions")


@dataclasses.dataclass(frozen=True)
class Share:
    """What one process trains: `conditions` (names, in the run's order) on `seeds`."""

    conditions: tuple[str, ...]
    seeds: tuple[int, ...]


def contiguous_blocks(items, count: int) -> list[tuple]:
    """`items` in `count` contiguous blocks, in order, the first `len(items) % count` one item longer."""
    items = tuple(items)
    size, extra = divmod(len(items), count)
    blocks, start = [], 0
    for k in range(count):
        end = start + size + (k < extra)
        blocks.append(items[start:end])
        start = end
    return blocks


def seed_blocks(seeds, count: int) -> list[tuple[int, ...]]:
    """`seeds` in `count` contiguous blocks (`contiguous_blocks`); refused where a block would be empty."""
    seeds = tuple(seeds)
    if count < 1:
        raise ConfigError(f"the number of processes must be >= 1, got {count}")
    if len(seeds) < count:
        raise ConfigError(f"{count} processes need at least {count} seeds (each trains a block of them), the run "
                          f"has {len(seeds)}: give more --seeds or fewer processes")
    return contiguous_blocks(seeds, count)


def split_work(conditions, seeds, count: int, split: str = "both") -> list[Share]:
    """Each of `count` processes' share of the run (process k's is element k): condition groups outer, seed
    blocks inner, so consecutive processes train the same conditions."""
    conditions, seeds = tuple(conditions), tuple(seeds)
    if split not in SPLITS:
        raise ConfigError(f"--split must be one of {', '.join(SPLITS)}, got {split!r}")
    if count < 1:
        raise ConfigError(f"the number of processes must be >= 1, got {count}")
    groups = {"seeds": 1, "conditions": count, "both": math.gcd(count, len(conditions))}[split]
    if groups > len(conditions):
        raise ConfigError(f"--split conditions: {count} processes need at least {count} conditions (each trains a "
                          f"group of them), the run has {len(conditions)}: use --split both or seeds, or fewer "
                          "processes")
    blocks = count // groups
    if len(seeds) < blocks:
        raise ConfigError(f"--split {split}: {count} processes on {len(conditions)} conditions train {blocks} "
                          f"blocks of seeds, the run has {len(seeds)} seed(s): give more --seeds or fewer processes")
    return [Share(group, block) for group in contiguous_blocks(conditions, groups)
            for block in contiguous_blocks(seeds, blocks)]
