"""`reproduce live`'s sessions: what each arm's `protamer finetune` is asked to run, and what the command refuses."""

from __future__ import annotations

from pathlib import Path

import pytest

from mjx_protamer.live.effect import Plan, _session_argv


def _flag(argv: list[str], name: str) -> str:
    return argv[argv.index(name) + 1]


@pytest.mark.parametrize("speaker,source", [("sentences", "speaker"), ("words", "speaker:words")])
def test_voice_arms_listen_to_the_simulated_speaker_the_plan_names_and_run_paced(tmp_path, speaker, source):
    plan = Plan((tmp_path / "ck",), tmp_path / "out", ("keyboard", "prosody", "whisper"), speaker=speaker)
    for arm in ("prosody", "whisper"):
        argv = _session_argv(plan, tmp_path / "ck", arm, 3, tmp_path / f"{arm}_0")
        assert _flag(argv, "--feedback") == arm and _flag(argv, "--listen-source") == source
        assert "--no-pace" not in argv and "feedback.seed=3" in argv
    for arm in ("none", "keyboard"):   # no speaker there, whatever it says: unpaced, as before
        argv = _session_argv(plan, tmp_path / "ck", arm, 3, tmp_path / f"{arm}_0")
        assert "--listen-source" not in argv and "--no-pace" in argv


def test_a_speaker_without_a_voice_channel_is_refused_in_one_line(tmp_path, capsys):
    from mjx_protamer.cli import main

    code = main(["reproduce", "live", "--checkpoints", str(tmp_path), "--out", str(tmp_path / "o"),
                 "--speaker", "words"])
    err = capsys.readouterr().err
    assert code == 2 and "--speaker words: only the prosody and whisper sessions have a speaker" in err
    assert len(err.strip().splitlines()) == 1 and not Path(tmp_path / "o").exists()
