"""Will a run's state fit in memory? Estimated from its abstract shapes (`jax.eval_shape`) before allocating.

Without this a replay that cannot fit (`ddpg.replay_size=1000000000`) ends in an XLA out-of-memory error
a minute later; with it the run is refused at once with the estimate, what is available and what to lower.
The estimate counts the whole state (replay, env batch, learner) and asks for HEADROOM on top: the train
step's temporaries and the host copies a checkpoint write makes.
"""

from __future__ import annotations

import os

import numpy as np

from mjx_protamer.errors import OutOfMemoryEstimate

HEADROOM = 1.5


def tree_bytes(tree) -> int:
    """Bytes of every array leaf (concrete or abstract) of a pytree."""
    import jax

    return int(sum(int(np.prod(x.shape)) * np.dtype(x.dtype).itemsize for x in jax.tree.leaves(tree)))


def host_available_bytes() -> int:
    """Memory the OS can give this process now: MemAvailable (free + reclaimable cache) on Linux."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")


def available_bytes(devices) -> int:
    """Free memory on `devices`: the accelerators' own (limit - in use, summed), host memory for CPUs."""
    free = 0
    for d in devices:
        stats = d.memory_stats() if d.platform != "cpu" else None
        if not stats or "bytes_limit" not in stats:
            return host_available_bytes()
        free += int(stats["bytes_limit"]) - int(stats.get("bytes_in_use", 0))
    return free


def _gb(n: float) -> str:
    return f"{n / 2**30:.2f} GiB" if n >= 2**27 else f"{n / 2**20:.1f} MiB"


def check_fits(state_like, devices, replay_like=None, replay_size: int | None = None, other=None) -> int:
    """Raise OutOfMemoryEstimate unless the state (plus `other`, e.g. the feedback state) fits in
    `available_bytes(devices)` with HEADROOM; return the estimated bytes. With the replay part and its size
    the message says how large a replay would fit."""
    need = tree_bytes(state_like) + (tree_bytes(other) if other is not None else 0)
    free = available_bytes(devices)
    if need * HEADROOM <= free:
        return need
    msg = f"the run's state needs about {_gb(need)}"
    hint = "lower ddpg.replay_size or train.num_envs"
    if replay_like is not None and replay_size:
        replay = tree_bytes(replay_like)
        per_row = replay / replay_size
        rest = need - replay
        fit = int((free / HEADROOM - rest) / per_row) if free / HEADROOM > rest else 0
        msg += f" ({_gb(replay)} of it the replay: {replay_size:,} transitions x {per_row:.0f} B)"
        hint = (f"lower ddpg.replay_size (about {fit:,} would fit here)" if fit > 0
                else "lower train.num_envs and ddpg.replay_size")
    raise OutOfMemoryEstimate(f"{msg}, {HEADROOM}x of which must be free, but {_gb(free)} is available; {hint}")


def check_seeds_fit(parts: dict[str, int], seeds: int, devices, what: str, hint: str) -> int:
    """Raise OutOfMemoryEstimate unless `seeds` copies of a run side by side fit (`parts`: bytes per seed by what
    holds them, e.g. {"learner state and replay": ..., "feedback state": ...}) in `available_bytes(devices)` with
    HEADROOM; return the estimated bytes. The message says how many seeds would fit and what else to lower."""
    per_seed = sum(parts.values())
    need = per_seed * seeds
    free = available_bytes(devices)
    if need * HEADROOM <= free:
        return need
    fit = int(free / HEADROOM // per_seed) if per_seed else 0
    shown = ", ".join(f"{name} {_gb(n)}" for name, n in parts.items() if n)
    lower = f"lower --seeds (about {fit:,} would fit here)" if fit >= 1 else "no single seed fits here"
    raise OutOfMemoryEstimate(f"{what} for {seeds:,} seeds needs about {_gb(need)} ({_gb(per_seed)} per seed: "
                              f"{shown}), {HEADROOM}x of which must be free, but {_gb(free)} is available; "
                              f"{lower}, or {hint}")
