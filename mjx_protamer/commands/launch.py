"""`protamer launch --processes N [--port P] -- COMMAND ...`: N local processes of a protamer command joined in a
jax.distributed job (mjx_protamer/launch.py)."""

from __future__ import annotations

import argparse


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "launch",
        help="run a command as N local processes on jax.distributed (reproduce table2, pretrain --seeds)",
        description="Starts N local processes of a protamer command that runs on several processes (reproduce "
        "table2: each process trains a share of the conditions and seeds, process 0 writes the table; pretrain "
        "--seeds N: each process trains a contiguous block of the seeds, process 0 writes seeds.json), with a "
        "coordinator on 127.0.0.1; forwards their output prefixed by the process index. If a process dies or "
        "fails, the others are stopped (SIGTERM, then SIGKILL after --grace seconds) and the launch fails with one "
        "line naming it. On SLURM or Open MPI, run the command with --distributed under srun/mpirun instead "
        "(scripts/table2_slurm.sbatch, scripts/pretrain_slurm.sbatch).",
        usage="protamer launch --processes N [--port P] [--grace S] -- COMMAND [ARGS ...]",
    )
    p.add_argument("--processes", required=True, help="how many processes (>= 1)")
    p.add_argument("--port", default=None, help="the coordinator's port on 127.0.0.1 (default: a free one)")
    p.add_argument("--grace", default=10, help="seconds the other processes get to stop after one failed, before "
                   "SIGKILL (default 10)")
    p.add_argument("command", nargs=argparse.REMAINDER, help="the protamer command after --, e.g. -- reproduce "
                   "table2 --seeds 4 --out runs/t2")
    p.set_defaults(handler=_launch)


def _launch(args: argparse.Namespace) -> int:
    from mjx_protamer.cli_numbers import number, port
    from mjx_protamer.commands.processes import MAX_PROCESSES
    from mjx_protamer.launch import launch

    processes = number("--processes", args.processes, 1, MAX_PROCESSES, integer=True)
    chosen = None if args.port is None else port("--port", args.port)
    grace = number("--grace", args.grace, 0, 3600)
    return launch(args.command, processes, chosen, grace)
