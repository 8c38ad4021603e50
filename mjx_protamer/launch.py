"""`protamer launch`: N local processes of one protamer command joined in a `jax.distributed` job.

The launcher picks a free coordinator port on 127.0.0.1 (or checks the one given), starts N processes of
`python -m mjx_protamer.cli COMMAND --coordinator 127.0.0.1:P --processes N --process-id K` (COMMAND:
`reproduce table2 ...` or `pretrain --seeds N ...`), forwards every line they print prefixed with `[K]`, and
waits. When a process dies or exits non-zero, the others are stopped (SIGTERM, then SIGKILL after `grace_s`) and
the launch fails with one line naming the process, how it ended and its last line. Pure Python (no JAX): the
processes import it. On SLURM or Open MPI the scheduler starts the processes instead (`--distributed`;
scripts/table2_slurm.sbatch, scripts/pretrain_slurm.sbatch).
"""

from __future__ import annotations

import contextlib
import io
import os
import signal
import socket
import subprocess
import sys
import threading
import time

from mjx_protamer.config import ConfigError
from mjx_protamer.errors import DistributedError

HOST = "127.0.0.1"
GRACE_S = 10.0  # a survivor gets SIGTERM, then SIGKILL this much later
# Flags the launcher gives each process; a command line that sets them itself is refused.
OWN_FLAGS = ("--coordinator", "--processes", "--process-id", "--distributed")


def free_port(host: str = HOST) -> int:
    """A TCP port nothing listens on now (the kernel's pick)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def check_port_free(port: int, host: str = HOST) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind((host, port))
        except OSError as e:
            raise ConfigError(f"--port {port} cannot be used on {host} ({e.strerror or e}); give another port or "
                              "leave --port out for a free one") from None


def prepare(command: list[str]) -> list[str]:
    """The protamer command line the processes run: checked with protamer's own parser (one line for a bad
    one), a command that runs on several processes, without the flags the launcher sets, with an --out (every
    process must name the same directory: the default one is named here, once)."""
    from mjx_protamer.cli import build_parser

    command = list(command[1:] if command[:1] == ["--"] else command)
    if not command:
        raise ConfigError("give the command after --, e.g. `protamer launch --processes 2 -- reproduce table2 "
                          "--seeds 4 --out runs/t2`")
    taken = [a for a in command if a.split("=", 1)[0] in OWN_FLAGS]
    if taken:
        raise ConfigError(f"leave {taken[0].split('=', 1)[0]} to protamer launch: it sets --coordinator, "
                          "--processes and --process-id for each process")
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            args = build_parser().parse_args(command)
    except SystemExit:
        lines = [x for x in err.getvalue().splitlines() if x.strip()]
        why = lines[-1].removeprefix("protamer: error: ") if lines else "it does not parse"
        raise ConfigError(f"the command after -- is not a protamer command line: {why}") from None
    named = args.experiment if command[0] == "reproduce" else command[0]  # table2, pretrain, eval, ...
    if not hasattr(args, "coordinator"):
        raise ConfigError(f"`protamer {' '.join(command[:2]) if command[0] == 'reproduce' else command[0]}` does "
                          "not run on several processes; `reproduce table2` and `pretrain --seeds N` do")
    if named == "pretrain" and args.seeds is None:
        raise ConfigError("`protamer pretrain` runs on several processes with --seeds N (each process trains a "
                          "block of the seeds)")
    if getattr(args, "out", None) is None:
        command += ["--out", os.path.join("runs", time.strftime(f"{named}-%Y%m%d-%H%M%S"))]
    return command


def _how(code: int) -> str:
    if code < 0:
        try:
            name = signal.Signals(-code).name
        except ValueError:
            name = "?"
        return f"was killed by signal {-code} ({name})"
    return f"exited with code {code}"


def launch(command: list[str], processes: int, port: int | None = None, grace_s: float = GRACE_S,
           out=sys.stdout) -> int:
    """Run `command` (a protamer command line, checked by `prepare`) as `processes` local processes; 0 when
    every one exits 0. A process that fails stops the others and raises DistributedError (one line)."""
    command = prepare(command)
    if port is None:
        port = free_port()
    else:
        check_port_free(port)
    coordinator = f"{HOST}:{port}"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    lock = threading.Lock()
    last: dict[int, str] = {}
    ended: dict[int, tuple[float, int]] = {}
    done = threading.Event()
    procs: list[subprocess.Popen] = []

    def forward(k: int, proc: subprocess.Popen) -> None:
        for raw in proc.stdout:
            line = raw.decode("utf-8", "replace").rstrip("\n")
            if line.strip():
                last[k] = line.strip()
            with lock:
                out.write(f"[{k}] {line}\n")
                out.flush()

    def wait(k: int, proc: subprocess.Popen) -> None:
        code = proc.wait()
        with lock:
            ended[k] = (time.monotonic(), code)
        done.set()

    threads = []
    try:
        for k in range(processes):
            proc = subprocess.Popen([sys.executable, "-m", "mjx_protamer.cli", *command, "--coordinator", coordinator,
                                     "--processes", str(processes), "--process-id", str(k)],
                                    stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env)
            procs.append(proc)
            threads += [threading.Thread(target=fn, args=(k, proc), daemon=True) for fn in (forward, wait)]
        with lock:
            out.write(f"protamer launch: {processes} process(es), coordinator {coordinator}, pids "
                      f"{', '.join(str(p.pid) for p in procs)}\n")
            out.flush()
        for t in threads:
            t.start()
        while True:
            done.wait(1.0)
            done.clear()
            with lock:
                failed = sorted((t, k) for k, (t, code) in ended.items() if code != 0)
                finished = len(ended) == processes
            if failed:
                k = failed[0][1]
                stopped, took = _stop(procs, grace_s)
                for t in threads:
                    t.join(timeout=2.0)
                said = f" (its last line: {last[k][:300]})" if k in last and ended[k][1] > 0 else ""
                raise DistributedError(
                    f"process {k} (pid {procs[k].pid}) {_how(ended[k][1])}{said}; stopped the other "
                    f"{stopped} process(es) in {took:.1f} s; what each process finished is kept in "
                    f"OUT: the same command with --resume continues it")
            if finished:
                break
    except KeyboardInterrupt:
        _stop(procs, grace_s, signal.SIGINT)
        raise
    for t in threads:
        t.join(timeout=5.0)
    return 0


def _stop(procs: list, grace_s: float, sig=signal.SIGTERM) -> tuple[int, float]:
    """Stop the processes still running (`sig`, then SIGKILL after `grace_s`): (how many, seconds taken)."""
    t0 = time.monotonic()
    alive = [p for p in procs if p.poll() is None]
    for p in alive:
        with contextlib.suppress(ProcessLookupError):
            p.send_signal(sig)
    for p in alive:
        try:
            p.wait(timeout=max(0.0, grace_s - (time.monotonic() - t0)))
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
    return len(alive), time.monotonic() - t0
