"""A live session's files: output directories that are not the session's, damaged records, bad numbers.

Each refusal is one line on stderr with exit code 2, before anything heavy is loaded, and loses nothing: the
directory a session was pointed at is unchanged (`tree_digest`).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from reliability_helpers import run_cli, tree_digest

TEACHER = ["--set", "feedback.teacher.rule=[{signal: 'action:0', value: 1.0, above: 0.0}, "
           "{signal: 'action:0', value: -1.0, below: 0.0}]", "--set", "feedback.teacher.min_gap_steps=10"]


def finetune(capsys, *argv):
    return run_cli(capsys, "finetune", "--view", "none", *argv)


@pytest.fixture(scope="module")
def recorded(tiny_run, tmp_path_factory):
    """A short simulated session of the tiny run (6 chunks, autosaved), recorded; tests damage copies of it."""
    from mjx_protamer.cli import main

    out = tmp_path_factory.mktemp("sessions") / "session"
    assert main(["finetune", "--view", "none", "--feedback", "simulated:keyboard", "--checkpoint", str(tiny_run[1]),
                 "--out", str(out), "--max-chunks", "6", "--no-pace", *TEACHER]) == 0
    return out


def test_a_session_refuses_an_output_directory_that_is_not_new_or_empty(tiny_run, recorded, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(tiny_run[1], run)
    before = tree_digest(run)
    # the pretrain run it starts from, as its own output: refused, the run untouched
    code, err = finetune(capsys, "--feedback", "none", "--checkpoint", run, "--out", run, "--max-chunks", "1")
    assert code == 2 and len(err) == 1 and "is not empty (it holds a pretrain run" in err[0], err
    assert tree_digest(run) == before
    # an existing session without --resume: refused, with the way to continue it
    session = tmp_path / "session"
    shutil.copytree(recorded, session)
    before = tree_digest(session)
    code, err = finetune(capsys, "--feedback", "none", "--checkpoint", run, "--out", session, "--max-chunks", "1")
    assert code == 2 and "or --resume to continue it" in err[0], err
    assert tree_digest(session) == before
    # a file, and a place below a file
    (tmp_path / "afile").write_text("x")
    for out, said in ((tmp_path / "afile", "is a file"), (tmp_path / "afile" / "below", "cannot be created")):
        code, err = finetune(capsys, "--feedback", "none", "--checkpoint", run, "--out", out, "--max-chunks", "1")
        assert code == 2 and said in err[0], err
    # --resume of a directory that holds another kind of run
    code, err = finetune(capsys, "--resume", "--out", run)
    assert code == 2 and "not a finetune-session to continue" in err[0], err
    assert tree_digest(run) == tree_digest(tiny_run[1])


def test_a_session_directory_in_use_is_locked(tiny_run, tmp_path, capsys):
    from mjx_protamer.errors import OutputDirError
    from mjx_protamer.outdir import claim

    out = tmp_path / "live"
    held = claim(out, "finetune-session")  # another session holds it
    try:
        code, err = finetune(capsys, "--feedback", "none", "--checkpoint", tiny_run[1], "--out", out)
        assert code == 2 and "in use by another protamer run" in err[0], err
        with pytest.raises(OutputDirError, match="in use by another protamer run"):
            claim(out, "finetune-session", resume=True)
    finally:
        held.release()
    claim(out, "finetune-session", resume=True).release()  # free again once the holder is gone


@pytest.mark.parametrize("flag,value", [("--seconds", "-5"), ("--seconds", "nan"), ("--autosave-s", "nan"),
                                        ("--max-chunks", "-1"), ("--chunk-ms", "nan"), ("--chunk-ms", "1e12"),
                                        ("--coach-delay-s", "nan"), ("--port", "70000"),
                                        ("--snapshot-every-s", "-1"), ("--snapshot-every-s", "inf")])
def test_every_number_is_checked_like_a_config_value_before_loading(tiny_run, tmp_path, capsys, flag, value):
    code, err = finetune(capsys, "--feedback", "none", "--checkpoint", tiny_run[1], "--out", tmp_path / "o",
                         flag, value)
    assert code == 2 and len(err) == 1 and flag in err[0] and "within" in err[0], err
    assert not (tmp_path / "o").exists()


def test_a_feedback_seed_outside_uint32_and_an_oversized_config_are_refused(tiny_run, tmp_path, capsys):
    code, err = finetune(capsys, "--feedback", "none", "--checkpoint", tiny_run[1], "--out", tmp_path / "o",
                         "--set", f"feedback.seed={2 ** 64 + 1}")
    assert code == 2 and "feedback.seed" in err[0], err
    big = tmp_path / "big.yaml"
    big.write_text("# padding\n" * 200_000)
    code, err = finetune(capsys, "--feedback", "none", "--checkpoint", tiny_run[1], "--out", tmp_path / "o",
                         "--config", big)
    assert code == 2 and "a config is a few KiB" in err[0], err
    assert not (tmp_path / "o").exists()


def _lines(session: Path) -> list[bytes]:
    return (session / "session_chunks.jsonl").read_bytes().split(b"\n")


def test_a_damaged_record_is_refused_naming_the_line_and_never_replayed_in_part(recorded, tmp_path, capsys):
    session = tmp_path / "session"
    shutil.copytree(recorded, session)
    lines = _lines(session)
    # a value edited in the middle of the record
    edited = json.loads(lines[2])
    edited["t0"] += 1.0
    (session / "session_chunks.jsonl").write_bytes(b"\n".join(lines[:2] + [json.dumps(edited).encode()] + lines[3:]))
    code, err = finetune(capsys, "--replay", session, "--out", tmp_path / "r1")
    assert code == 2 and len(err) == 1 and "line 3 is damaged" in err[0], err
    assert not (tmp_path / "r1").exists()
    # a record cut in half: its last line is torn
    data = b"\n".join(lines)
    (session / "session_chunks.jsonl").write_bytes(data[: len(data) // 2])
    code, err = finetune(capsys, "--replay", session, "--out", tmp_path / "r2")
    assert code == 2 and "is torn" in err[0] and "--resume" in err[0], err
    # lines lost from the middle
    (session / "session_chunks.jsonl").write_bytes(b"\n".join(lines[:1] + lines[2:]))
    code, err = finetune(capsys, "--replay", session, "--out", tmp_path / "r3")
    assert code == 2 and "out of place" in err[0], err
    # a manifest that is not one
    shutil.copy(recorded / "session_chunks.jsonl", session / "session_chunks.jsonl")
    for text in ("{not json", "[]", json.dumps({"version": 2})):
        (session / "session.json").write_text(text)
        code, err = finetune(capsys, "--replay", session, "--out", tmp_path / "r4")
        assert code == 2 and len(err) == 1 and "session" in err[0] and "damaged" in err[0], (text, err)


def test_resume_cuts_a_torn_last_line_before_it_appends(recorded, tmp_path, capsys):
    from mjx_protamer.live.record import read_session

    session = tmp_path / "session"
    shutil.copytree(recorded, session)
    whole = (session / "session_chunks.jsonl").read_bytes()
    (session / "session_chunks.jsonl").write_bytes(whole + b'{"n": 99, "chunk": 7, "first_st')  # killed mid-line
    code, err = finetune(capsys, "--resume", "--out", session, "--max-chunks", "1")
    assert code == 0, err
    _, records = read_session(session)  # whole again: every line checked
    assert [r["segment"] for r in records if "resume" in r] == [1]
    assert (session / "session_chunks.jsonl").read_bytes().startswith(whole)


def test_a_session_killed_mid_save_resumes_from_its_last_intact_save(recorded, tmp_path, capsys):
    """A save interrupted before its `saved` line was written: the record ends where that save was taken, and a
    resume continues from it (the line is written then)."""
    from mjx_protamer.live.record import read_session

    session = tmp_path / "session"
    shutil.copytree(recorded, session)
    lines = [ln for ln in _lines(session) if ln]
    last_saved = max(i for i, ln in enumerate(lines) if b'"saved"' in ln)
    (session / "session_chunks.jsonl").write_bytes(b"\n".join(lines[:last_saved]) + b"\n")
    code, err = finetune(capsys, "--resume", "--out", session, "--max-chunks", "1")
    assert code == 0, err
    _, records = read_session(session)
    assert sum(1 for r in records if "saved" in r) >= 2 and any("resume" in r for r in records)

