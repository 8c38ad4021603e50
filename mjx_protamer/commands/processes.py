"""The flags of a command that runs as several processes of one jax.distributed job (`reproduce table2`,
`pretrain --seeds`): registered once here, read into `experiments.distributed.Processes`. `protamer launch` sets
--coordinator, --processes and --process-id for local processes (mjx_protamer/launch.py)."""

from __future__ import annotations

import argparse

MAX_PROCESSES = 1024


def add_process_flags(parser: argparse.ArgumentParser, description: str, sbatch: str):
    """The "several processes" group (returned, for a command's own flags of it): `description` says what each
    process does in this command, `sbatch` names its SLURM example script."""
    d = parser.add_argument_group("several processes", description)
    d.add_argument("--distributed", action="store_true", help="join the job SLURM or Open MPI started (srun, mpirun): "
                   f"coordinator, process count and index detected ({sbatch})")
    d.add_argument("--coordinator", default=None, metavar="HOST:PORT", help="process 0's address and a port for its "
                   "coordinator (with --processes and --process-id)")
    d.add_argument("--processes", default=None, metavar="N", help="how many processes the job has")
    d.add_argument("--process-id", default=None, metavar="K", help="this process's index, 0..N-1")
    d.add_argument("--join-timeout", default=300, metavar="S", help="seconds for every process to join, else each "
                   "stops with one line (default 300)")
    d.add_argument("--heartbeat-timeout", default=100, metavar="S", help="seconds after which a silent process "
                   "counts as dead and the others stop (default 100)")
    return d


def several(args: argparse.Namespace) -> bool:
    """Whether the command line asks for several processes (any of the group's job flags)."""
    return args.distributed or any(v is not None for v in (args.coordinator, args.processes, args.process_id))


def processes_of(args: argparse.Namespace):
    """The jax.distributed job this process joins (experiments/distributed.py), or None for one process."""
    from mjx_protamer.cli_numbers import address, number
    from mjx_protamer.config import ConfigError

    explicit = {"--coordinator": args.coordinator, "--processes": args.processes, "--process-id": args.process_id}
    given = [k for k, v in explicit.items() if v is not None]
    if not given and not args.distributed:
        return None
    if args.distributed and given:
        raise ConfigError(f"--distributed detects the job from SLURM or Open MPI; leave out {given[0]}, or leave "
                          "out --distributed and give --coordinator, --processes and --process-id")
    if given and len(given) < 3:
        missing = [k for k in explicit if k not in given]
        raise ConfigError(f"{given[0]} needs {' and '.join(missing)} too")
    if args.out is None:
        raise ConfigError("--out is needed on several processes: every process must name the same directory")
    from mjx_protamer.experiments.distributed import Processes

    join_s = number("--join-timeout", args.join_timeout, 1, 86_400, integer=True)
    heartbeat_s = number("--heartbeat-timeout", args.heartbeat_timeout, 1, 86_400, integer=True)
    if args.distributed:
        return Processes(join_timeout_s=join_s, heartbeat_timeout_s=heartbeat_s)
    count = number("--processes", args.processes, 1, MAX_PROCESSES, integer=True)
    return Processes(address("--coordinator", args.coordinator), count,
                     number("--process-id", args.process_id, 0, count - 1, integer=True), join_s, heartbeat_s)
