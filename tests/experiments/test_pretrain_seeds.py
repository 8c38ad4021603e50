"""`protamer pretrain --seeds N`, on one process and on several (`protamer launch`): every OUT/seed_<k> is the run
of the plain command with `--set train.seed=k`, whatever the number of processes (the same test metrics, config
and checkpoint arrays); --resume keeps a finished seed and finishes the rest; bad input is one line. The toy run
is conftest.py's `toy_run` (its shapes: the persistent compile cache serves both), with a checkpoint every
chunk."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from mjx_protamer.cli import main
from multiprocess_checks import assert_refused_in_one_line, srun_argv_of

ROOT = Path(__file__).resolve().parents[2]
SETS = [x for kv in ("env_name=toy", "ddpg.actor_hidden=[16]", "ddpg.critic_hidden=[16,16]", "train.num_envs=4",
                     "train.episode_length=50", "train.total_env_steps=1200", "train.warmup_env_steps=400",
                     "train.chunk_steps=100", "train.checkpoint_every_chunks=1") for x in ("--set", kv)]


def _protamer(*args) -> list[str]:
    return [sys.executable, "-m", "mjx_protamer.cli", *map(str, args)]


def _eval(run: Path) -> dict:
    return json.loads((run / "eval.json").read_text())


def _array_digests(run: Path) -> dict:
    """Each checkpoint step's digest of its arrays (checkpoints.py's manifest)."""
    return {p.parent.name: json.loads(p.read_text())["sha256"] for p in (run / "checkpoints").glob("*/manifest.json")}


def _same_run(a: Path, b: Path) -> None:
    assert _eval(a) == _eval(b), (a, b)
    assert _array_digests(a) == _array_digests(b) != {}, (a, b)
    assert (a / "config.yaml").read_bytes() == (b / "config.yaml").read_bytes()


@pytest.fixture(scope="module")
def one_process(tmp_path_factory):
    """`pretrain --seeds 3` on one process."""
    out = tmp_path_factory.mktemp("seeds") / "one"
    assert main(["pretrain", *SETS, "--seeds", "3", "--out", str(out), "--no-progress"]) == 0
    return out


def test_two_processes_give_the_runs_of_one_process_and_of_the_plain_command(one_process, tmp_path, capsys):
    multi, plain = tmp_path / "multi", tmp_path / "plain"
    r = subprocess.run(_protamer("launch", "--processes", 2, "--", "pretrain", *SETS, "--seeds", 3, "--out", multi,
                                 "--no-progress"), capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert "[0] | seed | process | first_touch_step ↓ |" in r.stdout
    assert "[1] process 1/2: seeds [2] into " in r.stdout
    summary, ref = (json.loads((d / "seeds.json").read_text()) for d in (multi, one_process))
    assert summary["processes"] == {"count": 2, "seed_blocks": [[0, 1], [2]]}
    assert json.loads((multi / "processes.json").read_text()) == summary["processes"]
    assert [(s["seed"], s["process"], s["kept"]) for s in summary["per_seed"]] == [(0, 0, False), (1, 0, False),
                                                                                   (2, 1, False)]
    assert summary["metrics"] == ref["metrics"] and summary["seeds"] == ref["seeds"] == [0, 1, 2]
    assert summary["metrics"]["episode_return"]["seed_values"] == [_eval(multi / f"seed_{k}")["episode_return"]
                                                                   for k in range(3)]
    assert ref["metrics"]["contact_rate"]["ci95"] is not None
    assert "| mean ± 95% CI |" in (multi / "seeds.md").read_text()
    for k in range(3):
        _same_run(multi / f"seed_{k}", one_process / f"seed_{k}")
    # the plain command for seed 2; `eval` takes a seed's directory as it takes a plain run
    assert main(["pretrain", *SETS, "--set", "train.seed=2", "--out", str(plain), "--no-progress"]) == 0
    _same_run(plain, multi / "seed_2")
    capsys.readouterr()
    assert main(["eval", "--checkpoint", str(multi / "seed_2"), "--json", "--body-map", "none"]) == 0
    assert json.loads(capsys.readouterr().out)["episode_return"] == _eval(plain)["episode_return"]


def test_resume_keeps_a_finished_seed_and_finishes_the_others(one_process, tmp_path, capsys):
    """Seed 0 finished, seed 1 stopped after its first checkpoint, seed 2 not started: --resume keeps seed 0
    untouched and ends with the runs of the uninterrupted command; another split of the seeds, or another
    config, is refused in one line."""
    out = tmp_path / "o"
    shutil.copytree(one_process, out)
    (out / "seeds.json").unlink()
    (out / "seed_1" / "eval.json").unlink()
    steps = sorted((out / "seed_1" / "checkpoints").iterdir(), key=lambda p: int(p.name))
    for later in steps[1:]:
        shutil.rmtree(later)
    shutil.rmtree(out / "seed_2")
    kept = {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in (out / "seed_0").rglob("*") if p.is_file()}
    capsys.readouterr()
    assert main(["pretrain", *SETS, "--seeds", "3", "--out", str(out), "--resume", "--no-progress"]) == 0
    assert f"[seed 0] kept from {out / 'seed_0'} (finished)" in capsys.readouterr().out
    assert {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in kept} == kept  # not retrained, not rewritten
    summary = json.loads((out / "seeds.json").read_text())
    assert [(s["seed"], s["kept"], s["wall_s"] is None) for s in summary["per_seed"]] == [
        (0, True, True), (1, False, False), (2, False, False)]
    assert summary["metrics"] == json.loads((one_process / "seeds.json").read_text())["metrics"]
    for k in (1, 2):
        _same_run(out / f"seed_{k}", one_process / f"seed_{k}")
    for argv, says in ((["--seeds", "4"], f"--resume: {out} was run on 1 process(es) with seeds [[0, 1, 2]]; "
                                          "continue it with the same --processes and --seeds"),
                       (["--seeds", "3", "--set", "train.total_env_steps=1600"],
                        "--resume: the config differs from the one saved in")):
        assert main(["pretrain", *SETS, *argv, "--out", str(out), "--resume", "--no-progress"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("protamer: configuration error: ") and says in err[0], err


def test_reproduce_live_pretrains_its_checkpoints_as_pretrain_seeds_does(one_process, tmp_path, capsys):
    """`reproduce live --pretrain-seeds N` trains through `run_pretrain_seeds`: OUT/checkpoints/seed_<k> are the runs
    of `pretrain --seeds N`; run again, the finished seeds are kept, not retrained."""
    from mjx_protamer.agents.ddpg.config import PretrainConfig
    from mjx_protamer.config import apply_overrides, from_dict, to_dict
    from mjx_protamer.live.effect import pretrain_checkpoints

    config = from_dict(PretrainConfig, apply_overrides(to_dict(PretrainConfig()), SETS[1::2]))
    paths = pretrain_checkpoints(tmp_path, 2, config=config)
    assert paths == [tmp_path / "checkpoints" / "seed_0", tmp_path / "checkpoints" / "seed_1"]
    for k, run in enumerate(paths):
        _same_run(run, one_process / f"seed_{k}")
    assert json.loads((tmp_path / "checkpoints" / "seeds.json").read_text())["seeds"] == [0, 1]
    kept = {p: p.stat().st_mtime_ns for run in paths for p in run.rglob("*") if p.is_file()}
    capsys.readouterr()
    assert pretrain_checkpoints(tmp_path, 2, config=config) == paths
    assert "[seed 1] kept from" in capsys.readouterr().out
    assert {p: p.stat().st_mtime_ns for p in kept} == kept


@pytest.mark.parametrize("argv, says", [
    (["pretrain", "--seeds", "0"], "--seeds must be a whole number within 1..100000, got '0'"),
    (["pretrain", "--seeds", "2", "--set", "train.seed=3"], "--seeds N trains seeds 0..N-1 (train.seed of each); "
                                                             "leave out --set train.seed=3"),
    (["pretrain", "--seeds", "2", "--coordinator", "127.0.0.1:1", "--processes", "3", "--process-id", "0", "--out",
      "x"], "3 processes need at least 3 seeds (each trains a block of them), the run has 2"),
    (["pretrain", "--coordinator", "127.0.0.1:1", "--processes", "2", "--process-id", "0", "--out", "x"],
     "several processes train a pretrain run's seeds: give --seeds N"),
    (["pretrain", "--seeds", "2", "--distributed"], "--out is needed on several processes"),
    (["launch", "--processes", "2", "--", "pretrain"], "`protamer pretrain` runs on several processes with --seeds N"),
    (["launch", "--processes", "2", "--", "eval", "--checkpoint", "x"], "`protamer eval` does not run on several "
                                                                        "processes; `reproduce table2` and `pretrain "
                                                                        "--seeds N` do"),
])
def test_bad_input_is_one_line(argv, says, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # nothing is written anywhere
    assert_refused_in_one_line(argv, says, capsys, tmp_path)


def test_the_sbatch_example_runs_a_valid_pretrain_command(tmp_path):
    """scripts/pretrain_slurm.sbatch parses (bash -n), and what it hands srun is a `pretrain --seeds` command line
    that joins the SLURM job (--distributed): run under a stand-in srun that records it."""
    from mjx_protamer.cli import build_parser
    from mjx_protamer.commands.processes import processes_of
    from mjx_protamer.commands.train import _pretrain
    from mjx_protamer.experiments.distributed import Processes

    argv = srun_argv_of("pretrain_slurm.sbatch", tmp_path, ["--set", "train.total_env_steps=64000"], SEEDS="6")
    args = build_parser().parse_args(argv)
    assert args.handler is _pretrain and args.distributed and args.seeds == "6"
    assert processes_of(args) == Processes(coordinator=None, count=None, index=None, join_timeout_s=300,
                                           heartbeat_timeout_s=120)
    assert args.out == Path("runs/pretrain-slurm-77") and args.overrides == ["train.total_env_steps=64000"]
