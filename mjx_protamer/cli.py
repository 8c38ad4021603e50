"""The `protamer` command line. Each subcommand lives in a module with `register(subparsers)`.

Modules import their heavy dependencies (JAX, torch) inside the handler, so `protamer --help` is fast
and the voice commands never import JAX.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from mjx_protamer.config import ConfigError
from mjx_protamer.errors import (CheckpointError, DistributedError, OutOfMemoryEstimate, OutputDirError,
                                 SessionRecordError, WriteFailed)

# Each module registers one or more subcommands; the order is the order shown in --help.
COMMAND_MODULES = (
    "mjx_protamer.commands.bench",
    "mjx_protamer.commands.voice",
    "mjx_protamer.commands.train",
    "mjx_protamer.commands.feedback",
    "mjx_protamer.commands.reaction_delay",
    "mjx_protamer.commands.reproduce",
    "mjx_protamer.commands.analyze",
    "mjx_protamer.commands.render",
    "mjx_protamer.commands.launch",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="protamer",
        description="Self-touch exploration in MuJoCo-MJX with human (voice) feedback.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


# What each error is called on the one line the command prints, and its exit code.
ONE_LINE_ERRORS = ((ConfigError, "configuration error", 2), (CheckpointError, "checkpoint error", 2),
                   (SessionRecordError, "session record error", 2), (OutputDirError, "output directory error", 2),
                   (OutOfMemoryEstimate, "not enough memory", 2), (WriteFailed, "write failed", 1),
                   (DistributedError, "distributed run error", 1))


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.handler(args) or 0)
    except tuple(cls for cls, _, _ in ONE_LINE_ERRORS) as e:
        name, code = next((n, c) for cls, n, c in ONE_LINE_ERRORS if isinstance(e, cls))
        print(f"protamer: {name}: {e}", file=sys.stderr)
        return _leave(code)
    except KeyboardInterrupt:
        print("protamer: interrupted", file=sys.stderr)
        return _leave(130)
    except Exception:  # a bug: a process of a multi-process run prints its traceback and leaves at once too
        dist = sys.modules.get("mjx_protamer.experiments.distributed")
        if dist is not None and dist.joined():
            import traceback

            traceback.print_exc()
            dist.exit_if_joined(1)
        raise


def _leave(code: int) -> int:
    """A process of a multi-process run leaves at once after its one line (experiments/distributed.py)."""
    dist = sys.modules.get("mjx_protamer.experiments.distributed")
    if dist is not None:
        dist.exit_if_joined(code)
    return code


if __name__ == "__main__":
    sys.exit(main())
