"""Output directories of `pretrain`, `reproduce table2`, `reproduce rescore` and `reproduce live` (outdir.claim):
new, empty, or the command's own kind of run to continue; anything else refused in one line (exit 2) that says
what is there, before JAX starts, the directory unchanged. `--out` is locked for the life of the run; a run
refused after its claim (a bad setting found later, not enough memory) leaves no trace.

The runs themselves are stood in for where only the claim is tested (`run_pretrain`, `run_table2`,
`run_live_effect` monkeypatched): no compile.
"""

from __future__ import annotations

import json
import shutil

import pytest
from reliability_helpers import run_cli, tree_digest

from mjx_protamer.errors import OutputDirError
from mjx_protamer.outdir import LOCK, MARK, claim


@pytest.fixture
def pretrain_run(tiny_run, tmp_path):
    """A copy of a pretrain run written before claims existed (no .protamer.json)."""
    run = tmp_path / "run"
    shutil.copytree(tiny_run[1], run)
    assert not (run / MARK).exists()
    return run


@pytest.fixture
def table2_run(tmp_path):
    """What a table2 run's directory holds (the files that identify it; no arrays needed to be refused)."""
    run = tmp_path / "t2"
    run.mkdir()
    (run / "config.yaml").write_text("seeds: [0]\n")
    (run / "condition_DDPG.json").write_text("{}")
    return run


def _toy_table2(tmp_path):
    path = tmp_path / "t2.yaml"
    path.write_text("pretrain: {env_name: toy, train: {episode_length: 25}}\n"
                    "feedback: {teacher: {rule: [{signal: reach, value: 1.0, above: 0.5}]}}\n")
    return path


def _stand_in(monkeypatch, module, name, kind, result=None):
    """Replace `module.name` (a run) by one that checks its --out is locked and marked with `kind`."""
    calls = []

    def run(*args, **kwargs):
        out = args[1] if len(args) > 1 else (args[0].out if hasattr(args[0], "out") else kwargs["out"])
        with pytest.raises(OutputDirError, match="in use by another protamer run"):
            claim(out, kind, resume=True)  # locked while the run runs
        assert json.loads((out / MARK).read_text())["kind"] == kind
        calls.append(out)
        return result(out) if result else {}

    monkeypatch.setattr(module, name, run)
    return calls


def test_pretrain_refuses_what_is_not_new_empty_or_its_own_run(pretrain_run, table2_run, tmp_path, capsys):
    before = {d: tree_digest(d) for d in (pretrain_run, table2_run)}
    (tmp_path / "afile").write_text("x")
    cases = [
        (["--out", pretrain_run], "is not empty (it holds a pretrain run (checkpoints, config.yaml"),
        (["--out", pretrain_run], "or --resume to continue it"),  # a run written before claims: its config.yaml
        (["--out", table2_run], "is not empty (it holds condition_DDPG.json, config.yaml); give a new or empty"),
        (["--out", tmp_path / "afile"], "is a file, not a directory"),
        (["--out", tmp_path / "afile" / "below"], "cannot be created"),
    ]
    for argv, says in cases:
        code, err = run_cli(capsys, "pretrain", "--set", "env_name=toy", *argv)
        assert code == 2 and len(err) == 1 and err[0].startswith("protamer: output directory error: --out "), err
        assert says in err[0], (argv, err)
    assert {d: tree_digest(d) for d in before} == before
    # --resume of a directory written before claims, with a config.yaml (pretrain's own file) but no checkpoint:
    # refused by the run, and the directory is left as it was (not marked as a pretrain run)
    code, err = run_cli(capsys, "pretrain", "--resume", "--out", table2_run)
    assert code == 2 and len(err) == 1 and "holds no checkpoint to continue from" in err[0], err
    assert tree_digest(table2_run) == before[table2_run] and not (table2_run / MARK).exists()
    # a table2 run marked as one: named by its kind
    claim(table2_run, "table2", resume=True, own=("condition_DDPG.json",)).release()
    code, err = run_cli(capsys, "pretrain", "--resume", "--out", table2_run)
    assert code == 2 and "holds a table2 run, not a pretrain to continue" in err[0], err


def test_pretrain_claims_and_locks_its_out_for_the_whole_run_and_old_runs_still_resume(pretrain_run, tmp_path,
                                                                                      capsys, monkeypatch):
    from mjx_protamer.experiments import pretrain

    calls = _stand_in(monkeypatch, pretrain, "run_pretrain", "pretrain")
    monkeypatch.setattr(pretrain, "report", lambda result: "")
    new = tmp_path / "new"
    assert run_cli(capsys, "pretrain", "--set", "env_name=toy", "--out", new)[0] == 0
    assert run_cli(capsys, "pretrain", "--resume", "--out", pretrain_run)[0] == 0  # written before claims existed
    assert run_cli(capsys, "pretrain", "--resume", "--out", new)[0] == 0  # its own kind
    assert calls == [new, pretrain_run, new]
    claim(new, "pretrain", resume=True).release()  # unlocked once the run is over
    held = claim(new, "pretrain", resume=True)  # another run holds it
    try:
        code, err = run_cli(capsys, "pretrain", "--resume", "--out", new)
        assert code == 2 and len(err) == 1 and "is in use by another protamer run" in err[0], err
    finally:
        held.release()


def test_a_run_refused_after_its_claim_leaves_no_trace(tmp_path, capsys):
    # not enough memory: found after the claim (the estimate needs the env), the directory made for it is gone
    code, err = run_cli(capsys, "pretrain", "--set", "env_name=toy", "--set", "train.episode_length=25",
                        "--set", "ddpg.replay_size=100000000000", "--out", tmp_path / "out")
    assert code == 2 and "not enough memory" in err[0]
    assert not (tmp_path / "out").exists()
    # an empty directory that was there stays empty
    (tmp_path / "empty").mkdir()
    code, err = run_cli(capsys, "pretrain", "--set", "env_name=toy", "--set", "train.episode_length=25",
                        "--set", "ddpg.replay_size=100000000000", "--out", tmp_path / "empty")
    assert code == 2 and list((tmp_path / "empty").iterdir()) == []


def test_table2_refuses_what_is_not_new_empty_or_its_own_run(pretrain_run, table2_run, tmp_path, capsys,
                                                           monkeypatch):
    from mjx_protamer.experiments import table2

    cfg = _toy_table2(tmp_path)
    before = tree_digest(pretrain_run)
    for argv, says in [(["--out", pretrain_run], "is not empty (it holds a pretrain run"),
                       (["--resume", "--out", pretrain_run], "holds a pretrain run (checkpoints, config.yaml"),
                       (["--out", table2_run], "or --resume to continue it")]:
        code, err = run_cli(capsys, "reproduce", "table2", "--config", cfg, *argv)
        assert code == 2 and len(err) == 1 and says in err[0], (argv, err)
    assert tree_digest(pretrain_run) == before
    # a table2 run written before claims (its condition files) continues; the lock is held while it runs
    written = {}

    def result(out):
        (out / "table2.md").write_text("table")
        written[out] = True
        return {"table_md": str(out / "table2.md"), "wall_s": 0.0, "out_dir": str(out), "region_frequencies": {},
                **{k: "" for k in ("table_json", "figure1", "figure2", "training_csv")}}

    calls = _stand_in(monkeypatch, table2, "run_table2", "table2", result)
    assert run_cli(capsys, "reproduce", "table2", "--config", cfg, "--resume", "--out", table2_run)[0] == 0
    assert run_cli(capsys, "reproduce", "table2", "--config", cfg, "--out", tmp_path / "fresh")[0] == 0
    assert calls == [table2_run, tmp_path / "fresh"]


def test_rescore_refuses_an_out_that_is_not_new_or_empty(table2_run, tmp_path, capsys):
    (tmp_path / "used").mkdir()
    (tmp_path / "used" / "notes.txt").write_text("mine")
    code, err = run_cli(capsys, "reproduce", "rescore", table2_run, "--out", tmp_path / "used")
    assert code == 2 and len(err) == 1 and "is not empty (it holds notes.txt); give a new or empty directory" in err[0]
    assert "--resume" not in err[0]  # rescore has none to suggest
    assert (tmp_path / "used" / "notes.txt").read_text() == "mine" and len(list((tmp_path / "used").iterdir())) == 1


def test_reproduce_live_continues_its_own_directory_and_refuses_others(pretrain_run, tmp_path, capsys, monkeypatch):
    from mjx_protamer.live import effect as live_effect

    def result(out):
        (out / "live_effect.md").write_text("table")
        return {"wall_s": 0.0}

    calls = _stand_in(monkeypatch, live_effect, "run_live_effect", "live-effect", result)
    out = tmp_path / "live"
    argv = ["reproduce", "live", "--checkpoints", pretrain_run, "--minutes", "0.1"]
    assert run_cli(capsys, *argv, "--out", out)[0] == 0
    (out / "none_0").mkdir()  # a finished session it keeps
    assert run_cli(capsys, *argv, "--out", out)[0] == 0  # its own kind: always continued
    assert calls == [out, out] and (out / "none_0").is_dir()
    # one written before claims existed (its sessions' directories) is continued too
    old = tmp_path / "old"
    (old / "none_0").mkdir(parents=True)
    assert run_cli(capsys, *argv, "--out", old)[0] == 0
    # another command's directory is not
    before = tree_digest(pretrain_run)
    code, err = run_cli(capsys, *argv, "--out", pretrain_run)
    assert code == 2 and len(err) == 1 and "is not empty (it holds a pretrain run" in err[0], err
    assert "--resume" not in err[0] and tree_digest(pretrain_run) == before


def test_abandon_leaves_a_directory_the_run_wrote_into(tmp_path):
    held = claim(tmp_path / "d", "pretrain")
    (tmp_path / "d" / "metrics.csv").write_text("chunk\n1\n")
    held.abandon()
    assert sorted(p.name for p in (tmp_path / "d").iterdir()) == sorted([LOCK, MARK, "metrics.csv"])
    claim(tmp_path / "d", "pretrain", resume=True).release()  # unlocked
