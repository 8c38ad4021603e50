"""Table II and pretraining seeds on several processes (and hosts) with `jax.distributed`.

What both share: `join` the job, process 0 claims OUT first (`claimed_by_process_0`, the work's layout in
`processes.json`: `check_layout`), each process trains its share alone (`alone`), the shares go to process 0
(`hand_to_process_0`); `experiments/pretrain_seeds.py` runs the pretraining seeds on them. For Table II:

Every process joins one `jax.distributed` job (process 0 runs its coordinator), trains its share of the work
(`work_split`: a group of the conditions on a block of the seeds) with the one-process code
(`table2.train_table2`: the block's seeds vmapped in one program, on this process's devices) into its own
directory `OUT/process_<k>`, and hands its per-seed results to process 0, which writes the same table2.json /
table2.md / figures / training.csv into `OUT` as one process writes for the whole run. A seed's results do not
depend on the process that trains it nor on the other conditions (each seed's keys come from the seed alone),
so N processes give the per-seed results of one process running the same seed blocks. Where the conditions are
split, the pooled reward-model score (which needs every condition's reward models) is computed by process 0
from everyone's models, gathered after training (`table2.pool_shares`).

The hand-off is a collective (`multihost_utils.process_allgather` of each process's results as JSON bytes), not
files in a shared `OUT`: hosts of a cluster need not share a file system, the collective is also the barrier
that tells process 0 every block is finished, and a process that dies is caught by the same runtime (its
heartbeat; on CPU a peer's closed connection fails the collective at once) instead of by a poll with a timeout
of our own. Before it, the processes meet at a barrier of the coordination service, which waits as long as the
slowest block takes, so the collective itself never waits long.

Faults: a process that does not join within `join_timeout_s` stops with one line (a watchdog: JAX's own
timeout aborts the process with a stack trace); a process that dies later is noticed by the others within
`heartbeat_timeout_s` (JAX ends them), or at once by `protamer launch`, which stops the others. A process that
fails prints its one line and leaves at once (`exit_if_joined`) rather than waiting at JAX's shutdown barrier
for processes that are still training. What each process finished is kept in `OUT/process_<k>`; `--resume`
continues every process from it.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import sys
import threading
import time
from pathlib import Path

from mjx_protamer.config import ConfigError
from mjx_protamer.errors import DistributedError
from mjx_protamer.experiments.work_split import split_work

# The runtime's own join timeout is this much longer than ours, so the watchdog's one line comes first.
JOIN_MARGIN_S = 10
# How long the processes wait for each other's blocks at the barrier before the hand-off (the slowest block's
# training); a dead process ends the wait sooner, through the heartbeat.
TRAINED_BARRIER_S = 7 * 24 * 3600


@dataclasses.dataclass(frozen=True)
class Processes:
    """Where this process stands in a `jax.distributed` job. `coordinator` None: all three are detected from
    the cluster's environment (SLURM, Open MPI), as `jax.distributed.initialize()` does without arguments."""

    coordinator: str | None = None  # HOST:PORT of process 0's coordinator service
    count: int | None = None
    index: int | None = None
    join_timeout_s: int = 300  # every process must have joined within this
    heartbeat_timeout_s: int = 100  # a process silent this long is dead, and the others stop

    def who(self) -> str:
        index = self.index if self.index is not None else os.environ.get("SLURM_PROCID",
                                                                          os.environ.get("OMPI_COMM_WORLD_RANK"))
        return f"process {index}" + (f" of {self.count}" if self.count is not None else "") if index is not None \
            else "this process"


_joined = False


def join(spec: Processes) -> tuple[int, int]:
    """Join the `jax.distributed` job (before any JAX computation); (this process's index, process count)."""
    global _joined
    import jax

    # CPU collectives (the hand-off) through gloo: the default of jax 0.10, named for versions where it is not
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    # No preemption sync points here: JAX's preemption service would catch SIGTERM (the launcher's and SLURM's
    # stop) and the process would run on until SIGKILL; without it SIGTERM ends the process at once (every file
    # a run keeps is written atomically)
    jax.config.update("jax_enable_preemption_service", False)

    def not_joined():  # the runtime would abort with a stack trace JOIN_MARGIN_S later
        where = f" at {spec.coordinator}" if spec.coordinator else ""
        _print_and_exit(f"protamer: distributed run error: {spec.who()}: not every process joined the "
                        f"coordinator{where} within {spec.join_timeout_s} s (--join-timeout); is one missing, or is "
                        f"another job using the port?", 1)

    watchdog = threading.Timer(spec.join_timeout_s, not_joined)
    watchdog.daemon = True
    watchdog.start()
    try:
        jax.distributed.initialize(spec.coordinator, spec.count, spec.index,
                                   initialization_timeout=spec.join_timeout_s + JOIN_MARGIN_S,
                                   heartbeat_timeout_seconds=spec.heartbeat_timeout_s)
    except ValueError as e:  # auto-detection found no cluster to join
        if spec.coordinator is None:
            raise ConfigError("--distributed: no SLURM or Open MPI job found to join; give --coordinator, "
                              "--processes and --process-id, or start the processes with `protamer launch`") from None
        raise DistributedError(f"{spec.who()}: {e}") from None
    finally:
        watchdog.cancel()
    _joined = True
    return jax.process_index(), jax.process_count()


def joined() -> bool:
    """Whether this process joined a jax.distributed job (`join`)."""
    return _joined


def _print_and_exit(line: str, code: int) -> None:
    print(line, file=sys.stderr, flush=True)
    sys.stdout.flush()
    os._exit(code)


def exit_if_joined(code: int) -> None:
    """After a failed process printed its one line: leave now if it joined a job (JAX's exit handler would wait
    up to its shutdown timeout for the processes that are still training); nothing otherwise."""
    if _joined:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)


def _barrier(name: str, timeout_s: float) -> None:
    """Wait at the coordination service's barrier `name` for every process (no-op where that API is absent)."""
    from jax._src import distributed

    client = distributed.global_state.client
    if client is not None and hasattr(client, "wait_at_barrier"):
        client.wait_at_barrier(name, int(timeout_s * 1000))


def _collective(fn, what: str):
    try:
        return fn()
    except Exception as e:  # noqa: BLE001 - a peer that died: gloo reports its closed connection
        raise DistributedError(f"{what} failed: another process has stopped ({str(e).splitlines()[0][:200]})") \
            from None


def broadcast_ok(ok: bool, what: str) -> bool:
    """Process 0's `ok` on every process (the others pass anything)."""
    import numpy as np
    from jax.experimental import multihost_utils

    return bool(_collective(lambda: multihost_utils.broadcast_one_to_all(np.int32(ok)), what))


def gather_json(obj) -> list:
    """Every process's JSON-able `obj`, in process order (on every process)."""
    return [json.loads(b) for b in gather_bytes(json.dumps(obj).encode())]


def gather_bytes(blob: bytes) -> list[bytes]:
    """Every process's `blob`, in process order (on every process). The bytes are padded to a power of two so
    that runs of similar size reuse the compiled gather."""
    import numpy as np
    from jax.experimental import multihost_utils

    data = np.frombuffer(blob, np.uint8)
    sizes = np.asarray(_collective(lambda: multihost_utils.process_allgather(np.int32(data.size)),
                                   "the hand-off of the results")).reshape(-1)
    padded = np.zeros(1 << max(10, int(sizes.max() - 1).bit_length()), np.uint8)
    padded[:data.size] = data
    every = np.asarray(_collective(lambda: multihost_utils.process_allgather(padded), "the hand-off of the results"))
    return [bytes(every[k, :int(sizes[k])]) for k in range(len(sizes))]


@contextlib.contextmanager
def alone():
    """This process as the only one, for the libraries that ask `jax.process_count()` and `jax.process_index()`
    (orbax) while it trains its block: its checkpoints are its own, in its own directory (hosts need not share
    one), written and read as a one-process run writes them. Under jax.distributed, orbax would write host arrays
    from process 0 only, refuse this process's device arrays and wait for every process at each save. No
    collective runs inside (JAX's own code asks its runtime, not these names).

    Also the persistent compile cache: JAX writes entries from process 0 only, and on CPU a program's key holds
    its device, so without this every other process would compile its programs again on every run (about 30 s
    for the tiny toy programs of the tests, minutes for the self-touch chunk)."""
    import jax
    from jax._src import distributed

    saved = jax.process_count, jax.process_index, distributed.global_state.process_id
    jax.process_count, jax.process_index = (lambda *a, **k: 1), (lambda *a, **k: 0)
    distributed.global_state.process_id = 0
    try:
        yield
    finally:
        jax.process_count, jax.process_index, distributed.global_state.process_id = saved


def process_dir(out: Path, index: int) -> Path:
    return Path(out) / f"process_{index}"


LAYOUT = "processes.json"  # in OUT: how the work was split among the processes (`check_layout`)


@contextlib.contextmanager
def claimed_by_process_0(out: Path, index: int, kind: str, resume: bool, own: tuple[str, ...] = (),
                         check=lambda: None):
    """`out` claimed (outdir.claimed) for the block by process 0, and `check()` passed (a resumed run's layout),
    before any other process writes into it: the others wait for process 0's word and stop with one line where it
    refused. Outside a jax.distributed job (`join`), the claim and the check of one process."""
    from mjx_protamer.errors import OutputDirError
    from mjx_protamer.outdir import claimed

    with contextlib.ExitStack() as stack:
        if index == 0:
            try:
                stack.enter_context(claimed(out, kind, resume=resume, own=own))
                check()
            except (ConfigError, OutputDirError):
                if _joined:
                    broadcast_ok(False, "telling the others that --out was refused")
                raise
            if _joined:
                broadcast_ok(True, "telling the others that --out is ready")
        elif not broadcast_ok(False, "waiting for process 0 to claim --out"):
            raise OutputDirError(f"process {index}: process 0 refused --out {out} (its line says why)")
        yield


def hand_to_process_0(work: str, share) -> list:
    """Every process's JSON-able `share` of the `work` (in process order, on every process), once every process
    has finished its own: the coordination service's barrier waits as long as the slowest share takes (a dead
    process ends the wait through the heartbeat), so the collective after it never waits long."""
    _collective(lambda: _barrier(f"protamer/{work}/trained", TRAINED_BARRIER_S), "waiting for the other shares")
    return gather_json(share)


def run_table2_processes(cfg, out, spec: Processes, progress: bool = True, resume: bool = False,
                         claim_kind: str = "table2", own: tuple[str, ...] = (), split: str = "both",
                         at_once: int | None = None) -> dict | None:
    """This process's part of a table2 run on `spec`'s job: join, claim `out` (process 0) and `out/process_<k>`,
    train its share of the conditions and seeds (`work_split.split_work`), hand the results to process 0.
    Process 0 returns `write_table2`'s result for the whole run (written into `out`), the others None. Raises
    ConfigError / OutputDirError / DistributedError with one line."""
    from mjx_protamer.experiments import table2 as T2
    from mjx_protamer.experiments.table2 import pool_shares
    from mjx_protamer.outdir import claimed

    t_all = time.perf_counter()
    out = Path(out)
    index, count = join(spec)
    names = [c.name for c in cfg.conditions]
    shares = split_work(names, cfg.seeds, count, split)
    share = shares[index]
    layout = {"count": count, "split": split, "condition_groups": [list(s.conditions) for s in shares],
              "seed_blocks": [list(s.seeds) for s in shares]}
    # The pooled reward-model score of a seed needs every condition's reward models and test states: where a
    # process trains only some conditions, process 0 computes it from everyone's (gathered after training)
    pool_at_0 = any(len(s.conditions) < len(names) for s in shares)
    with claimed_by_process_0(out, index, claim_kind, resume, own,
                              lambda: _check_layout(out / LAYOUT, layout, resume, names)):
        mine = process_dir(out, index)
        if progress:
            print(f"process {index}/{count}: conditions {list(share.conditions)}, seeds {list(share.seeds)} into "
                  f"{mine}", flush=True)
        kept = {}

        def keep_for_process_0(ft, reward_models, untrained, test_states):
            kept.update(ft=ft, blob=pool_shares.pack_models(reward_models, test_states))
            return {}

        mine_cfg = dataclasses.replace(cfg, seeds=share.seeds,
                                       conditions=tuple(c for c in cfg.conditions if c.name in share.conditions))
        with claimed(mine, claim_kind, resume=resume, own=own), alone():
            # a process whose directory holds no run yet (it had not started) starts its share now
            trained = T2.train_table2(mine_cfg, mine, progress, resume and (mine / "config.yaml").is_file(),
                                      pooled=keep_for_process_0 if pool_at_0 else None,
                                      at_once=T2.AT_ONCE if at_once is None else at_once)
        parts = [T2.Trained(**p) for p in hand_to_process_0("table2", dataclasses.asdict(trained))]
        blobs = gather_bytes(kept["blob"]) if pool_at_0 else None
        if index != 0:
            if progress:
                print(f"process {index}/{count}: its share handed to process 0", flush=True)
            return None
        merged = _merge(parts, cfg)
        if pool_at_0:
            with alone():
                pool_shares.pool_shares(cfg, kept["ft"], shares, blobs, merged.evals)
        return _write_merged(cfg, out, merged, parts, layout, time.perf_counter() - t_all)


def _write_merged(cfg, out: Path, merged, parts: list, layout: dict, total_s: float) -> dict:
    """Process 0: what one process writes for the whole run, from every process's part; processes.json and
    table2.json's `processes` say which process trained which conditions and seeds, and for how long."""
    import yaml

    from mjx_protamer.config import to_dict
    from mjx_protamer.atomic import write_atomic
    from mjx_protamer.experiments.table2 import write_table2

    write_atomic(out / "config.yaml", yaml.safe_dump(to_dict(cfg), sort_keys=False))
    for name, per_seed in merged.evals.items():
        for seed, ev in per_seed.items():
            write_atomic(out / f"eval_{name}_seed{seed}.json", json.dumps(ev, indent=2))
    extra = {"processes": {**layout, "dirs": [process_dir(out, k).name for k in range(layout["count"])],
                           "train_wall_s": {c.name: [sum(p.wall[c.name]) if c.name in p.wall else None
                                                     for p in parts] for c in cfg.conditions}},
             "conditions_at_once": max(p.at_once for p in parts)}
    return write_table2(cfg, out, merged, total_s, extra)


def _check_layout(path: Path, layout: dict, resume: bool, names: list[str]) -> None:
    """A table2 run's `check_layout`; a run of one process (which writes no processes.json) is continued by one
    process."""
    if resume and not path.is_file() and any(path.parent.glob("condition_*.json")):
        raise ConfigError(f"--resume: {path.parent} is a run of one process; continue it with one process (without "
                          "protamer launch, --distributed or --coordinator)")

    def as_today(before: dict) -> dict:  # a run from before --split split the seeds only
        return {"count": before["count"], "split": before.get("split", "seeds"),
                "condition_groups": before.get("condition_groups", [names] * before["count"]),
                "seed_blocks": before["seed_blocks"]}

    check_layout(path, layout, resume, as_today, lambda before: (
        f"--resume: {path.parent} was run on {before['count']} process(es) with --split {before['split']} "
        f"(conditions {before['condition_groups']}, seeds {before['seed_blocks']}); continue it with the same "
        "--processes, --split and --seeds"))


def check_layout(path: Path, layout: dict, resume: bool, as_today, refusal) -> None:
    """`path` (processes.json) records how the work was split among the processes (`layout`); a resumed run must
    split it the same way, else ConfigError(`refusal(recorded layout)`). `as_today`: a recorded layout as this
    code writes it (files of older versions)."""
    from mjx_protamer.atomic import write_atomic

    if resume and path.is_file():
        before = as_today(json.loads(path.read_text()))
        if before != layout:
            raise ConfigError(refusal(before))
    write_atomic(path, json.dumps(layout))


def _merge(parts: list, cfg):
    """One `Trained` of every process's part (JSON turned the seeds into strings), the seeds in order; a
    condition's training seconds are the slowest of the processes that trained it (they ran side by side)."""
    from mjx_protamer.experiments.table2 import Trained

    evals = {c.name: {int(s): ev for p in parts for s, ev in p.evals.get(c.name, {}).items()} for c in cfg.conditions}
    missing = [s for s in cfg.seeds if any(s not in evals[c.name] for c in cfg.conditions)]
    if missing:
        raise DistributedError(f"the processes handed back no results for seeds {missing}")
    order = {c.name: i for i, c in enumerate(cfg.conditions)}
    seed_order = {s: i for i, s in enumerate(cfg.seeds)}  # one process's row order: condition, chunk, seed
    training = sorted((r for p in parts for r in p.training),
                      key=lambda r: (order[r["condition"]], r["chunk"], seed_order[r["seed"]]))
    evals = {c.name: {s: evals[c.name][s] for s in cfg.seeds} for c in cfg.conditions}
    wall = {c.name: [max(sum(p.wall[c.name]) for p in parts if c.name in p.wall)] for c in cfg.conditions}
    return Trained(training, evals, wall)
