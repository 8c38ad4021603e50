"""Every probed checkpoint failure: a one-line error and exit code 2 from `eval` (and `finetune`), nothing
lost; damaged checkpoints refused by their checksum with the previous one named; `--resume` falling back to
the newest intact checkpoint and still ending exactly where an uninterrupted run ends."""

from __future__ import annotations

import os
import random
import shutil
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import yaml
from flax import struct
from reliability_helpers import run_cli, tree_digest

ROOT = Path(__file__).resolve().parents[2]


def _largest_data_file(step_dir: Path) -> Path:
    return max((p for p in (step_dir / "default").rglob("d/*") if p.is_file()), key=lambda p: p.stat().st_size)


def _flip_bytes(path: Path, n: int = 400) -> None:
    data = bytearray(path.read_bytes())
    for i in random.Random(0).sample(range(len(data)), min(n, len(data))):
        data[i] ^= 0xFF
    path.write_bytes(bytes(data))


def _edit_config(run: Path, section: str, key: str, value) -> None:
    cfg = yaml.safe_load((run / "config.yaml").read_text())
    cfg[section][key] = value
    (run / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))


# (name, how to damage a copy of the run -> the path given to eval, what the one line must say)
CASES = [
    ("missing path", lambda run: run / "nope", "no such file or directory"),
    ("empty directory", lambda run: (run / "empty").mkdir() or run / "empty", "is not a pretrain run directory"),
    ("no checkpoint yet", lambda run: [shutil.rmtree(p) for p in (run / "checkpoints").iterdir()] and run,
     "no checkpoint in"),
    ("absent step", lambda run: run / "checkpoints" / "7", "checkpoint step 7 does not exist"),
    ("truncated file", lambda run: os.truncate(_largest_data_file(run / "checkpoints" / "3"), 100) or run,
     "is damaged"),
    ("0-byte files", lambda run: [p.write_bytes(b"") for p in (run / "checkpoints" / "3" / "default").rglob("d/*")]
     and run, "is damaged"),
    ("no _METADATA", lambda run: (run / "checkpoints" / "3" / "default" / "_METADATA").unlink() or run, "is damaged"),
    ("no manifest (an unfinished save)", lambda run: (run / "checkpoints" / "3" / "manifest.json").unlink() or run,
     "no manifest.json"),
    ("400 flipped bytes", lambda run: _flip_bytes(_largest_data_file(run / "checkpoints" / "3")) or run, "is damaged"),
    ("other num_envs", lambda run: _edit_config(run, "train", "num_envs", 8) or run, "does not fit this config"),
    ("other network", lambda run: _edit_config(run, "ddpg", "actor_hidden", [24, 32]) or run,
     "does not fit this config"),
]


@pytest.mark.filterwarnings("error::pytest.PytestUnraisableExceptionWarning")  # orbax's abandoned reads
@pytest.mark.parametrize("name, damage, says", CASES, ids=[c[0] for c in CASES])
def test_eval_refuses_a_bad_checkpoint_in_one_line(run_copy, capsys, name, damage, says):
    target = damage(run_copy)
    before = tree_digest(run_copy)
    code, err = run_cli(capsys, "eval", "--checkpoint", target, "--json")
    assert code == 2
    assert len(err) == 1 and err[0].startswith("protamer: checkpoint error: ") and says in err[0], err
    if "is damaged" in says:
        assert "use the previous one" in err[0] and str(run_copy / "checkpoints" / "2") in err[0]
    assert tree_digest(run_copy) == before  # nothing changed or lost
    assert capsys.readouterr().out == ""


@pytest.mark.parametrize("file_checksums", [True, False], ids=["files", "arrays only (format 2)"])
def test_wrong_arrays_under_an_intact_layout_fail_the_checksum(run_copy, capsys, file_checksums):
    """Step 2's arrays under step 3's manifest: orbax reads them without complaint; the file checksums refuse
    them before orbax opens them, and without those (a format-2 manifest) the arrays' checksum still does."""
    import json

    step2, step3 = run_copy / "checkpoints" / "2", run_copy / "checkpoints" / "3"
    shutil.rmtree(step3 / "default")
    shutil.copytree(step2 / "default", step3 / "default")
    if not file_checksums:
        manifest = json.loads((step3 / "manifest.json").read_text())
        del manifest["files"]
        (step3 / "manifest.json").write_text(json.dumps(manifest))
    code, err = run_cli(capsys, "eval", "--checkpoint", run_copy)
    assert code == 2 and len(err) == 1
    says = "its file default/" if file_checksums else "its arrays do not match their SHA-256 checksum"
    assert says in err[0] and "; use the previous one" in err[0], err


@pytest.mark.filterwarnings("error::pytest.PytestUnraisableExceptionWarning")  # orbax's orphaned reads
@pytest.mark.parametrize("damage", ["checksum", "unfinished save"])
def test_resume_falls_back_to_the_newest_intact_checkpoint_and_stays_exact(tiny_run, run_copy, capsys, damage):
    """The run was killed after chunk 3 of 3 was saved, and step 3 is bad: resume says so, moves it aside, goes
    on from step 2 and ends with exactly the uninterrupted run's state."""
    from mjx_protamer.experiments.pretrain import run_pretrain

    config, _, full = tiny_run
    step3 = run_copy / "checkpoints" / "3"
    if damage == "checksum":
        _flip_bytes(_largest_data_file(step3))
    else:
        (step3 / "manifest.json").unlink()
    resumed = run_pretrain(config, run_copy, resume=True, progress=False, final_eval=False)
    err = capsys.readouterr().err
    assert "--resume: skipping step 3" in err and "resuming from step 2, the newest intact checkpoint" in err
    assert resumed["finished"] and resumed["chunks_done"] == 3
    for a, b in zip(jax.tree.leaves(full["state"]), jax.tree.leaves(resumed["state"])):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    moved = list((run_copy / "checkpoints_damaged").iterdir())
    assert len(moved) == 1 and moved[0].name.startswith("3-")  # kept for inspection, not deleted
    assert sorted(p.name for p in (run_copy / "checkpoints").iterdir()) == ["2", "3"]
    rows = (run_copy / "metrics.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + config.train.num_chunks


@struct.dataclass
class _ActorFirst:
    actor: jax.Array
    target: jax.Array


@struct.dataclass
class _TargetFirst:  # the same fields in the other order
    target: jax.Array
    actor: jax.Array


def test_leaves_are_restored_by_their_path_not_their_position(tmp_path):
    """Reordering fields must not restore the actor into the target actor (it did with leaves by index)."""
    from mjx_protamer.errors import CheckpointError
    from mjx_protamer.experiments import checkpoints

    mngr = checkpoints.manager(tmp_path / "ck")
    checkpoints.save(mngr, 1, _ActorFirst(actor=jnp.ones(3), target=jnp.zeros(3)))
    back = checkpoints.restore(mngr, 1, jax.eval_shape(lambda: _TargetFirst(target=jnp.zeros(3), actor=jnp.zeros(3))))
    np.testing.assert_array_equal(back.actor, np.ones(3))
    np.testing.assert_array_equal(back.target, np.zeros(3))
    with pytest.raises(CheckpointError, match="does not fit this config: it lacks critic"):
        checkpoints.restore(mngr, 1, {"actor": jnp.zeros(3), "critic": jnp.zeros(3), "target": jnp.zeros(3)})


def test_finetune_on_a_truncated_checkpoint_prints_one_line(run_copy):
    """A real process (the 'Exception ignored' lines of the probe came at interpreter exit)."""
    os.truncate(_largest_data_file(run_copy / "checkpoints" / "3"), 100)
    before = tree_digest(run_copy)
    proc = subprocess.run([sys.executable, "-m", "mjx_protamer.cli", "finetune", "--feedback", "none",
                           "--checkpoint", str(run_copy), "--out", str(run_copy.parent / "ft")],
                          capture_output=True, text=True, cwd=ROOT, timeout=180,
                          env={**os.environ, "JAX_PLATFORMS": "cpu"})
    assert proc.returncode == 2
    err = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(err) == 1 and "is damaged" in err[0] and "use the previous one" in err[0], proc.stderr[-2000:]
    assert "Exception ignored" not in proc.stderr + proc.stdout
    assert tree_digest(run_copy) == before


@pytest.mark.slow  # ~20-40 s: a whole CLI process (imports, compile-cache load) before the kill
def test_kill_9_mid_run_then_resume_ends_exactly_like_the_uninterrupted_run(tiny_run, tmp_path):
    """SIGKILL the CLI as soon as its first checkpoint is on disk (mid-chunk or mid-save of the next one):
    --resume loses at most the last checkpoint interval, the logs stay readable, the end state is exact."""
    import signal
    import time

    from mjx_protamer.config import to_dict
    from mjx_protamer.experiments.pretrain import run_pretrain
    from mjx_protamer.experiments.run_log import read_rows

    config, _, full = tiny_run
    (tmp_path / "tiny.yaml").write_text(yaml.safe_dump(to_dict(config), sort_keys=False))
    out = tmp_path / "killed"
    proc = subprocess.Popen([sys.executable, "-m", "mjx_protamer.cli", "pretrain", "--config",
                             str(tmp_path / "tiny.yaml"), "--out", str(out), "--no-progress"], cwd=ROOT, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, env={**os.environ, "JAX_PLATFORMS": "cpu"})
    deadline = time.time() + 150
    while not list((out / "checkpoints").glob("*/manifest.json")):
        assert proc.poll() is None, proc.stderr.read().decode()[-2000:]
        assert time.time() < deadline, "no checkpoint within 150 s"
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait(30)
    proc.stderr.close()
    resumed = run_pretrain(config, out, resume=True, progress=False, final_eval=False)
    assert resumed["finished"]
    for a, b in zip(jax.tree.leaves(full["state"]), jax.tree.leaves(resumed["state"])):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    rows, skipped = read_rows(out / "metrics.csv")
    assert [r["chunk"] for r in rows] == [1.0, 2.0, 3.0] and skipped == 0


def test_resume_skips_a_step_that_only_one_of_two_managers_saved(tmp_path, capsys):
    """A kill between the train-state save and the feedback-state save of the same chunk: that step is
    incomplete, so resume takes the previous one where both are intact (and keeps the lone half aside)."""
    from mjx_protamer.experiments import checkpoints

    main, feedback = checkpoints.manager(tmp_path / "checkpoints"), checkpoints.manager(tmp_path / "checkpoints_fb")
    for step in (1, 2):
        checkpoints.save(main, step, {"w": jnp.full(3, float(step))})
        checkpoints.save(feedback, step, {"ring": jnp.full(2, 10.0 * step)})
    checkpoints.save(main, 3, {"w": jnp.full(3, 3.0)})  # killed before the feedback save of step 3
    lines = []
    step, (w, ring) = checkpoints.restore_newest_intact(
        [(main, {"w": jnp.zeros(3)}), (feedback, {"ring": jnp.zeros(2)})], lines.append)
    assert step == 2
    np.testing.assert_array_equal(w["w"], np.full(3, 2.0))
    np.testing.assert_array_equal(ring["ring"], np.full(2, 20.0))
    assert lines[0].startswith("--resume: skipping step 3: checkpoint ") and "is missing" in lines[0]
    assert lines[1] == "--resume: resuming from step 2, the newest intact checkpoint"
    assert checkpoints.available_steps(tmp_path / "checkpoints") == [2]  # max_to_keep=2 had dropped 1
    assert [p.name.split("-")[0] for p in (tmp_path / "checkpoints_damaged").iterdir()] == ["3"]
