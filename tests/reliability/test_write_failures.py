"""Writes that fail in the middle of a run (a full disk, no permission): `pretrain` and `reproduce table2` end with
one line naming the path and the last good checkpoint (exit 1, no traceback); what was saved before is intact and
`--resume` goes on from it to the uninterrupted run's end state.

A full disk is played in process: the checkpoint save (`experiments/checkpoints.save`) or the metrics log raises
OSError(28, 'No space left on device', path) on its Nth call, as the file system would.
"""

from __future__ import annotations

import errno
import json

import pytest
import yaml
from reliability_helpers import run_cli, tiny_config

from mjx_protamer.experiments import checkpoints

@pytest.fixture
def tiny_yaml(tmp_path):
    """The shared run's config as a file: `--config` it and the run is the shared run, bit for bit."""
    from mjx_protamer.config import to_dict

    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(to_dict(tiny_config()), sort_keys=False))
    return path


def _full_disk_on(monkeypatch, n: int):
    """checkpoints.save fails as a full disk would on its nth call (nothing of that save is written)."""
    real, calls = checkpoints.save, [0]

    def save(mngr, step, state):
        calls[0] += 1
        if calls[0] == n:
            raise OSError(errno.ENOSPC, "No space left on device", str(checkpoints.step_dir(mngr, step)))
        return real(mngr, step, state)

    monkeypatch.setattr(checkpoints, "save", save)


def _sha(step_dir) -> str:
    return json.loads((step_dir / checkpoints.MANIFEST).read_text())["sha256"]


@pytest.mark.parametrize("what", ["checkpoint", "metrics.csv"])
def test_pretrain_stopped_by_a_full_disk_says_so_in_one_line_and_resumes_exactly(tiny_run, tiny_yaml, tmp_path,
                                                                                 capsys, monkeypatch, what):
    from mjx_protamer.experiments import run_log

    out = tmp_path / "run"
    if what == "checkpoint":
        _full_disk_on(monkeypatch, 3)  # the save after chunk 3
        path = out / "checkpoints" / "3"
    else:
        real = run_log.RunLog.write

        def write(self, row):
            if row["chunk"] == 3:
                raise OSError(errno.ENOSPC, "No space left on device", str(self.csv_path))
            return real(self, row)

        monkeypatch.setattr(run_log.RunLog, "write", write)
        path = out / "metrics.csv"
    code, err = run_cli(capsys, "pretrain", "--no-progress", "--out", out, "--config", tiny_yaml)
    assert code == 1 and len(err) == 1, err
    assert err[0] == (f"protamer: write failed: {path}: No space left on device; the last good checkpoint is "
                      f"{out / 'checkpoints' / '2'}; free some space (or fix the permissions), then continue with "
                      f"`protamer pretrain --resume --out {out}` (the same --config and --set)"), err
    # the last good checkpoint is intact: the uninterrupted run's step 2, bit for bit, and it restores
    assert checkpoints.available_steps(out / "checkpoints")[-1] == 2
    assert _sha(out / "checkpoints" / "2") == _sha(tiny_run[1] / "checkpoints" / "2")
    from mjx_protamer.experiments.run_loader import load_run

    assert load_run(out / "checkpoints" / "2")[3] == 2
    monkeypatch.undo()  # space again
    code, err = run_cli(capsys, "pretrain", "--no-progress", "--resume", "--out", out, "--config", tiny_yaml)
    assert code == 0, err
    assert _sha(out / "checkpoints" / "3") == _sha(tiny_run[1] / "checkpoints" / "3")  # as if never stopped


def test_pretrain_that_fails_before_its_first_checkpoint_says_there_is_none(tiny_yaml, tmp_path, capsys,
                                                                             monkeypatch):
    _full_disk_on(monkeypatch, 1)
    out = tmp_path / "run"
    code, err = run_cli(capsys, "pretrain", "--no-progress", "--out", out, "--config", tiny_yaml)
    assert code == 1 and len(err) == 1, err
    assert f"{out / 'checkpoints' / '1'}: No space left on device; no checkpoint had been saved yet" in err[0], err
    assert err[0].endswith("then start again with a new or empty --out"), err


TABLE2 = {
    "pretrain": {"env_name": "toy", "ddpg": {"actor_hidden": [16], "critic_hidden": [16, 16], "replay_size": 2000,
                                             "batch_size": 16, "reward_beta": 1.0},
                 "train": {"num_envs": 4, "episode_length": 25, "total_env_steps": 600, "warmup_env_steps": 100,
                           "chunk_steps": 50, "eval_episodes": 3}},
    "feedback": {"dt": 0.05, "reward_model": {"hidden": [16]},
                 "teacher": {"min_gap_steps": 2, "rule": [{"signal": "reach", "value": 1.0, "above": 0.5},
                                                          {"signal": "action:1", "value": -1.0, "below": -0.5}]}},
    "conditions": [{"name": "DDPG", "channel": "none"}, {"name": "DTK", "channel": "keyboard",
                                                         "credit": "step_window"}],
    "moving_average": 2,
}  # tests/experiments/test_table2.py's toy setting (its compiled shapes), two conditions


def test_table2_stopped_by_a_full_disk_keeps_its_finished_conditions_and_resumes(tmp_path, capsys, monkeypatch):
    cfg = tmp_path / "t2.yaml"
    cfg.write_text(yaml.safe_dump(TABLE2))
    out = tmp_path / "t2"
    # one condition at a time, so that the saves come in a known order: per condition its reward models, then its
    # agents; the 4th is DTK's agents, after DTK's reward models (two at a time interleave them)
    argv = ["reproduce", "table2", "--config", cfg, "--seeds", "2", "--out", out, "--quiet", "--conditions-at-once", "1"]
    _full_disk_on(monkeypatch, 4)
    code, err = run_cli(capsys, *argv)
    assert code == 1 and len(err) == 1, err
    assert err[0] == (f"protamer: write failed: {out / 'agents' / 'DTK' / '0'}: No space left on device; the "
                      f"conditions finished before it are kept (DDPG: {out}/condition_<name>.json and their agents); "
                      f"free some space (or fix the permissions), then continue with `protamer reproduce table2 "
                      f"--resume --out {out}` (the same --config, --set and --seeds)"), err
    kept = (out / "condition_DDPG.json").read_bytes()
    assert not (out / "condition_DTK.json").exists() and (out / "reward_models" / "DTK" / "0").is_dir()
    monkeypatch.undo()
    code, err = run_cli(capsys, *argv, "--resume")
    assert code == 0, err
    assert (out / "condition_DDPG.json").read_bytes() == kept  # not trained again
    summary = json.loads((out / "table2.json").read_text())
    assert list(summary["conditions"]) == ["DDPG", "DTK"] and summary["seeds"] == [0, 1]
    assert (out / "agents" / "DTK" / "0" / checkpoints.MANIFEST).is_file()
