"""`reproduce table2` on several processes (jax.distributed) and `protamer launch`: the conditions split in groups
give bit for bit the per-seed results of one process running the whole command, the seeds split in blocks those
of one process running the same blocks; a dead or absent process is reported in one line within the stated
timeout; bad input is refused in one line. The tiny toy config and 2-seed blocks are
test_table2.py's shapes, so the persistent compile cache serves both."""

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import yaml

from mjx_protamer.cli import main
from multiprocess_checks import assert_refused_in_one_line, srun_argv_of
from mjx_protamer.experiments.work_split import Share, seed_blocks, split_work

from toy_feedback import toy_feedback_config

ROOT = Path(__file__).resolve().parents[2]
CONFIG = {
    **toy_feedback_config(total_env_steps=600, chunk_steps=50, eval_episodes=3),
    "conditions": [{"name": "DDPG", "channel": "none"}, {"name": "DTK", "channel": "keyboard", "credit": "step_window"}],
    "moving_average": 2,
}


@pytest.fixture
def config(tmp_path):
    path = tmp_path / "t2.yaml"
    path.write_text(yaml.safe_dump(CONFIG))
    return path


def _protamer(*args) -> list[str]:
    return [sys.executable, "-m", "mjx_protamer.cli", *map(str, args)]


class Lines:
    """A process's stdout read line by line on a thread, so a test can wait for a line with a timeout."""

    def __init__(self, proc):
        self.lines, self.cond = [], threading.Condition()
        threading.Thread(target=self._read, args=(proc.stdout,), daemon=True).start()

    def _read(self, stream):
        for line in stream:
            with self.cond:
                self.lines.append(line.rstrip("\n"))
                self.cond.notify_all()

    def wait_for(self, pattern: str, timeout: float) -> re.Match:
        end = time.monotonic() + timeout
        with self.cond:
            while True:
                for line in self.lines:
                    if m := re.search(pattern, line):
                        return m
                left = end - time.monotonic()
                assert left > 0, f"no line matching {pattern!r} within {timeout} s:\n" + "\n".join(self.lines[-30:])
                self.cond.wait(left)


def test_seed_blocks_are_contiguous_and_cover_every_seed():
    assert seed_blocks(range(4), 2) == [(0, 1), (2, 3)]
    assert seed_blocks(range(5), 2) == [(0, 1, 2), (3, 4)]
    assert seed_blocks((7, 3, 9), 3) == [(7,), (3,), (9,)]
    assert seed_blocks(range(3), 1) == [(0, 1, 2)]
    with pytest.raises(ValueError, match="3 processes need at least 3 seeds"):
        seed_blocks(range(2), 3)


def test_split_work_gives_each_process_one_rectangle_of_conditions_and_seeds():
    c4 = ("DDPG", "DTK", "DTW", "DTP")
    # both: conditions first, gcd(processes, conditions) groups; the seeds in blocks for the rest
    assert split_work(c4, range(5), 2) == [Share(("DDPG", "DTK"), (0, 1, 2, 3, 4)), Share(("DTW", "DTP"), (0, 1, 2, 3, 4))]
    assert split_work(c4, range(4), 8) == [Share((c,), b) for c in c4 for b in ((0, 1), (2, 3))]
    assert split_work(c4, range(3), 3) == [Share(c4, (k,)) for k in range(3)]
    assert split_work(c4, range(3), 1) == [Share(c4, (0, 1, 2))]
    assert split_work(c4, range(4), 2, "seeds") == [Share(c4, (0, 1)), Share(c4, (2, 3))]
    assert split_work(c4, range(2), 3, "conditions") == [Share(("DDPG", "DTK"), (0, 1)), Share(("DTW",), (0, 1)),
                                                         Share(("DTP",), (0, 1))]
    with pytest.raises(ValueError, match="--split conditions: 5 processes need at least 5 conditions"):
        split_work(c4, range(8), 5, "conditions")
    with pytest.raises(ValueError, match="--split both: 3 processes on 4 conditions train 3 blocks of seeds, the run "
                                         "has 2 seed"):
        split_work(c4, range(2), 3)
    with pytest.raises(ValueError, match="--split must be one of both, seeds, conditions"):
        split_work(c4, range(2), 2, "rows")


@pytest.mark.parametrize("argv, says", [
    (["launch", "--processes", "0", "--", "reproduce", "table2"], "--processes must be a whole number within 1..1024"),
    (["launch", "--processes", "2", "--port", "70000", "--", "reproduce", "table2"], "--port must be a whole number "
                                                                                     "within 1..65535"),
    (["launch", "--processes", "2.5", "--", "reproduce", "table2"], "--processes must be a whole number"),
    (["launch", "--processes", "2"], "give the command after --"),
    (["launch", "--processes", "2", "--", "reproduce", "rescore", "x"], "`protamer reproduce rescore` does not run "
                                                                        "on several processes"),
    (["launch", "--processes", "2", "--", "reproduce", "table2", "--process-id", "1"], "leave --process-id to protamer"),
    (["launch", "--processes", "2", "--", "reproduce", "table2", "--no-such-flag"],
     "not a protamer command line: unrecognized arguments: --no-such-flag"),
    (["reproduce", "table2", "--coordinator", "127.0.0.1:1234", "--processes", "2", "--out", "x"],
     "--coordinator needs --process-id too"),
    (["reproduce", "table2", "--coordinator", "127.0.0.1:1234", "--processes", "2", "--process-id", "2", "--out", "x"],
     "--process-id must be a whole number within 0..1, got '2'"),
    (["reproduce", "table2", "--coordinator", "localhost", "--processes", "2", "--process-id", "0", "--out", "x"],
     "--coordinator must be HOST:PORT"),
    (["reproduce", "table2", "--coordinator", "h:0", "--processes", "2", "--process-id", "0", "--out", "x"],
     "--coordinator's port must be a whole number within 1..65535"),
    (["reproduce", "table2", "--coordinator", "h:1", "--processes", "1", "--process-id", "0"], "--out is needed"),
    (["reproduce", "table2", "--distributed", "--processes", "2", "--out", "x"], "leave out --processes"),
    (["reproduce", "table2", "--distributed", "--join-timeout", "0", "--out", "x"], "--join-timeout must be"),
    (["reproduce", "table2", "--split", "seeds", "--out", "x"], "--split shares the work of several processes"),
])
def test_bad_input_is_one_line(argv, says, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # nothing is written anywhere
    assert_refused_in_one_line(argv, says, capsys, tmp_path)


def test_port_in_use_is_refused(capsys):
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        assert main(["launch", "--processes", "2", "--port", str(port), "--", "reproduce", "table2"]) == 2
    assert f"--port {port} cannot be used on 127.0.0.1" in capsys.readouterr().err


def test_distributed_outside_a_cluster_is_one_line(config, tmp_path):
    env = {k: v for k, v in os.environ.items() if not k.startswith(("SLURM_", "OMPI_"))}
    r = subprocess.run(_protamer("reproduce", "table2", "--config", config, "--distributed", "--out", tmp_path / "o"),
                       capture_output=True, text=True, cwd=ROOT, env=env, timeout=120)
    assert r.returncode == 2
    assert r.stderr.strip().splitlines()[-1] == (
        "protamer: configuration error: --distributed: no SLURM or Open MPI job found to join; give --coordinator, "
        "--processes and --process-id, or start the processes with `protamer launch`")


def test_an_absent_process_is_reported_within_the_join_timeout(config, tmp_path):
    from mjx_protamer.launch import free_port

    port = free_port()
    t0 = time.monotonic()
    r = subprocess.run(_protamer("reproduce", "table2", "--config", config, "--coordinator", f"127.0.0.1:{port}",
                                 "--processes", 2, "--process-id", 0, "--join-timeout", 3, "--out", tmp_path / "o"),
                       capture_output=True, text=True, cwd=ROOT, timeout=120)
    took = time.monotonic() - t0
    assert r.returncode == 1
    assert r.stderr.strip().splitlines()[-1] == (
        f"protamer: distributed run error: process 0 of 2: not every process joined the coordinator at "
        f"127.0.0.1:{port} within 3 s (--join-timeout); is one missing, or is another job using the port?")
    assert took < 3 + 30  # the timeout plus Python's and JAX's start on a loaded 2-core machine
    assert not (tmp_path / "o").exists()  # nothing claimed before every process joined


def test_a_killed_process_stops_the_others_with_one_line(config, tmp_path):
    out = tmp_path / "o"
    proc = subprocess.Popen(_protamer("launch", "--processes", 2, "--grace", 5, "--", "reproduce", "table2",
                                      "--config", config, "--seeds", 4, "--out", out),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        lines = Lines(proc)
        pids = [int(p) for p in lines.wait_for(r"^protamer launch: 2 process\(es\), coordinator 127\.0\.0\.1:\d+, "
                                               r"pids (\d+), (\d+)$", 60).groups()]
        lines.wait_for(r"^\[1\] process 1/2: conditions \['DTK'\], seeds \[0, 1, 2, 3\] into ", 120)  # joined, training
        os.kill(pids[1], signal.SIGKILL)
        t_kill = time.monotonic()
        proc.wait(timeout=60)
        took = time.monotonic() - t_kill
        err = proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 1
    last = err.strip().splitlines()[-1]
    m = re.fullmatch(rf"protamer: distributed run error: process 1 \(pid {pids[1]}\) was killed by signal 9 "
                     r"\(SIGKILL\); stopped the other 1 process\(es\) in (\d+\.\d) s; what each process finished is "
                     r"kept in OUT: the same command with --resume continues it", last)
    assert m, last
    assert float(m[1]) < 5  # the survivor ended on SIGTERM, before --grace's SIGKILL (JAX's preemption service is off)
    assert took < 5  # the launcher looks every second
    with pytest.raises(ProcessLookupError):
        os.kill(pids[0], 0)  # the survivor is gone too
    assert not (out / "table2.json").exists()


def _run_launch(*args, timeout=600):
    r = subprocess.run(_protamer("launch", *args), capture_output=True, text=True, cwd=ROOT, timeout=timeout)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    return r.stdout


def _per_seed(out: Path, cond: str, seed: int) -> dict:
    ev = json.loads((out / f"eval_{cond}_seed{seed}.json").read_text())
    ev.pop("train_wall_s")
    return ev


def _rows(out: Path) -> dict:
    import csv

    with (out / "training.csv").open() as f:
        return {(r["condition"], int(r["seed"]), int(r["chunk"])): r for r in csv.DictReader(f)}


def test_two_processes_splitting_the_conditions_give_the_results_of_one_process(config, tmp_path):
    """The default split of 2 processes and 2 conditions: each process trains one condition on all 4 seeds (the
    one-process program), and process 0 pools the reward models of both: bit for bit one process's run."""
    multi, one = tmp_path / "multi", tmp_path / "one"
    printed = _run_launch("--processes", 2, "--", "reproduce", "table2", "--config", config, "--seeds", 4,
                          "--out", multi, "--quiet")
    assert "[0] | Contact rate ↑ |" in printed
    assert main(["reproduce", "table2", "--config", str(config), "--seeds", "4", "--out", str(one), "--quiet"]) == 0
    assert json.loads((multi / "processes.json").read_text()) == {
        "count": 2, "split": "both", "condition_groups": [["DDPG"], ["DTK"]], "seed_blocks": [[0, 1, 2, 3]] * 2}
    for k, cond in enumerate(("DDPG", "DTK")):
        assert [p.name for p in sorted((multi / f"process_{k}").glob("condition_*.json"))] == [f"condition_{cond}.json"]
        for seed in range(4):
            ev = _per_seed(multi, cond, seed)
            assert ev == _per_seed(one, cond, seed), (cond, seed)
            assert "r_hat_corr_pooled" in ev  # pooled over both conditions, by process 0
    assert _rows(multi) == _rows(one)
    summary, ref = (json.loads((d / "table2.json").read_text()) for d in (multi, one))
    for cond in ("DDPG", "DTK"):
        assert {k: v for k, v in summary["conditions"][cond].items() if k != "train_wall_s"} == \
            {k: v for k, v in ref["conditions"][cond].items() if k != "train_wall_s"}, cond
    assert summary["processes"]["train_wall_s"]["DTK"][0] is None  # process 0 did not train DTK


def test_two_processes_splitting_the_seeds_give_the_results_of_one_process_running_the_same_blocks(config, tmp_path):
    multi = tmp_path / "multi"
    printed = _run_launch("--processes", 2, "--", "reproduce", "table2", "--config", config, "--seeds", 4,
                          "--split", "seeds", "--out", multi, "--quiet")
    assert "[0] | Contact rate ↑ |" in printed and f"[0] table_json    {multi / 'table2.json'}" in printed
    # one process, the same program layout: 2 seeds vmapped per program
    one = {0: tmp_path / "one_a", 2: tmp_path / "one_b"}
    for first, out in one.items():
        assert main(["reproduce", "table2", "--config", str(config), "--set", f"seeds=[{first}, {first + 1}]",
                     "--out", str(out), "--quiet"]) == 0
    summary = json.loads((multi / "table2.json").read_text())
    assert summary["seeds"] == [0, 1, 2, 3]
    assert summary["processes"]["seed_blocks"] == [[0, 1], [2, 3]]
    assert json.loads((multi / "processes.json").read_text()) == {
        "count": 2, "split": "seeds", "condition_groups": [["DDPG", "DTK"]] * 2, "seed_blocks": [[0, 1], [2, 3]]}
    rows = _rows(multi)
    for first, out in one.items():
        ref_summary, ref_rows = json.loads((out / "table2.json").read_text()), _rows(out)
        for cond in ("DDPG", "DTK"):
            for seed in (first, first + 1):
                assert _per_seed(multi, cond, seed) == _per_seed(out, cond, seed), (cond, seed)
                assert _per_seed(multi / f"process_{first // 2}", cond, seed) == _per_seed(out, cond, seed)
            for metric in ("unique_regions", "freeze_ratio", "teacher_score", "r_hat_corr_pooled"):
                assert (summary["conditions"][cond][metric]["seed_values"][first:first + 2]
                        == ref_summary["conditions"][cond][metric]["seed_values"]), (cond, metric)
        assert {k: v for k, v in rows.items() if k[1] in (first, first + 1)} == ref_rows
    assert len(rows) == 2 * 4 * 3  # conditions x seeds x chunks
    for name in ("table2.md", "figure1_training_reward.png", "figure2_unique_regions.png", "config.yaml"):
        assert (multi / name).stat().st_size > 0, name
    assert summary["conditions"]["DTK"]["feedback"]["feedback_total"] > 0


def test_a_run_of_several_processes_is_not_resumed_by_one(config, tmp_path, capsys):
    out = tmp_path / "o"
    out.mkdir()
    (out / "processes.json").write_text(json.dumps({"count": 2, "seed_blocks": [[0, 1], [2, 3]]}))
    assert main(["reproduce", "table2", "--config", str(config), "--seeds", "4", "--out", str(out), "--resume"]) == 2
    assert "is a run of several processes" in capsys.readouterr().err


@pytest.mark.slow
def test_resume_continues_every_process_to_the_same_table(config, tmp_path):
    """A run (conditions split: process 0 DDPG, process 1 DTK) stopped before process 1 finished: --resume keeps
    what finished (process 0 trains nothing) and ends with the table of an uninterrupted run; another split is
    refused."""
    out = tmp_path / "o"
    _run_launch("--processes", 2, "--", "reproduce", "table2", "--config", config, "--seeds", 4, "--out", out, "--quiet")
    first = json.loads((out / "table2.json").read_text())
    kept = (out / "process_0" / "condition_DDPG.json").read_bytes()
    for path in (out / "process_1" / "condition_DTK.json", out / "table2.json"):
        path.unlink()
    r = subprocess.run(_protamer("launch", "--processes", 2, "--", "reproduce", "table2", "--config", config,
                                 "--seeds", 4, "--out", out, "--quiet"), capture_output=True, text=True, cwd=ROOT,
                       timeout=300)
    assert r.returncode == 1 and "is not empty" in r.stdout + r.stderr  # not without --resume
    printed = _run_launch("--processes", 2, "--", "reproduce", "table2", "--config", config, "--seeds", 4,
                          "--out", out, "--resume")
    assert "[0] [DDPG] kept from" in printed and "[1] [DTK, 4 seeds] chunk 3/3" in printed
    assert (out / "process_0" / "condition_DDPG.json").read_bytes() == kept
    again = json.loads((out / "table2.json").read_text())
    for cond in ("DDPG", "DTK"):
        for metric in ("unique_regions", "freeze_ratio", "teacher_score", "r_hat_corr_pooled"):
            assert again["conditions"][cond][metric]["seed_values"] == first["conditions"][cond][metric]["seed_values"]
    # the work split differently: refused in one line before anything is trained
    for differently in (["--processes", 1], ["--processes", 2, "--split", "seeds"]):
        r = subprocess.run(_protamer("launch", *differently[:2], "--", "reproduce", "table2", "--config", config,
                                     "--seeds", 4, "--out", out, "--resume", *differently[2:]), capture_output=True,
                           text=True, cwd=ROOT, timeout=300)
        assert r.returncode == 1 and "continue it with the same --processes, --split and --seeds" in r.stdout, \
            r.stdout[-2000:]
        assert [x for x in r.stdout.splitlines() if "configuration error" in x][0].endswith(
            "continue it with the same --processes, --split and --seeds")
    # a run of one process is continued by one process
    single = tmp_path / "single"
    single.mkdir()
    (single / "condition_DDPG.json").write_text("{}")
    r = subprocess.run(_protamer("launch", "--processes", 2, "--", "reproduce", "table2", "--config", config,
                                 "--seeds", 4, "--out", single, "--resume"), capture_output=True, text=True, cwd=ROOT,
                       timeout=300)
    assert r.returncode == 1 and "is a run of one process; continue it with one process" in r.stdout


def test_the_sbatch_example_runs_a_valid_protamer_command(tmp_path):
    """scripts/table2_slurm.sbatch parses (bash -n), and what it hands srun is a protamer command line that joins
    the SLURM job (--distributed) with the run's settings: run under a stand-in srun that records it."""
    from mjx_protamer.cli import build_parser
    from mjx_protamer.commands.processes import processes_of
    from mjx_protamer.commands.reproduce import _table2
    from mjx_protamer.experiments.distributed import Processes
    from mjx_protamer.experiments.table2 import load_table2_config

    argv = srun_argv_of("table2_slurm.sbatch", tmp_path, ["--set", "pretrain.train.total_env_steps=64000"])
    args = build_parser().parse_args(argv)
    assert args.handler is _table2 and args.distributed
    assert processes_of(args) == Processes(coordinator=None, count=None, index=None, join_timeout_s=300,
                                         heartbeat_timeout_s=120)
    assert args.out == Path("runs/table2-slurm-77")
    cfg = load_table2_config(args.config, args.overrides, int(args.seeds))
    assert cfg.seeds == tuple(range(10)) and cfg.pretrain.train.total_env_steps == 64000
