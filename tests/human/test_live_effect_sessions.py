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


def _finished(plan, ckpt, arm, k, d, argv=None):
    """A session directory as `_run_session` leaves it when its process exited 0 (no process run)."""
    import json

    from mjx_protamer.live.effect import DONE, session_identity

    d.mkdir(parents=True)
    argv = argv or _session_argv(plan, ckpt, arm, k, d)
    (d / DONE).write_text(json.dumps({"argv": session_identity(argv, arm)}))


def test_a_kept_session_of_another_plan_is_refused_before_anything_runs(tmp_path):
    """Finished sessions are kept and pooled with new ones: one another plan ran must not mix in silently."""
    from mjx_protamer.config import ConfigError
    from mjx_protamer.live.effect import _check_kept

    a, b, out = tmp_path / "seed_15", tmp_path / "seed_25", tmp_path / "out"
    plan = Plan((a,), out, ("prosody",), overrides=("pretrain.ddpg.anchor_praise_hold=true",))
    _finished(plan, a, "prosody", 0, out / "prosody_0")
    _check_kept(_session_argv(plan, a, "prosody", 0, out / "prosody_0"), "prosody", out / "prosody_0")  # its own plan
    # the same directory under a plan whose first checkpoint is another, or with another setting
    with pytest.raises(ConfigError,
                       match=r"prosody_0 holds a session another plan ran \(.*seed_15; this plan: .*seed_25\)"):
        _check_kept(_session_argv(plan, b, "prosody", 0, out / "prosody_0"), "prosody", out / "prosody_0")
    other = Plan((a,), out, ("prosody",), overrides=("pretrain.ddpg.anchor_praise_hold=false",))
    with pytest.raises(ConfigError, match="anchor_praise_hold=true; this plan: pretrain.ddpg.anchor_praise_hold=false"):
        _check_kept(_session_argv(other, a, "prosody", 0, out / "prosody_0"), "prosody", out / "prosody_0")
    # a session without feedback serves plans that differ only in the teacher's rule (it takes no event), and
    # a copy of it elsewhere (another directory, another interpreter) is the same session
    _finished(plan, a, "none", 0, tmp_path / "elsewhere" / "none_0",
              argv=["/other/venv/python", "-m", "mjx_protamer.cli"]
              + _session_argv(plan, a, "none", 0, tmp_path / "elsewhere" / "none_0")[3:])
    head = Plan((a,), out, ("prosody",), rule_config=Path("mjx_protamer/configs/table2_head.yaml"),
                overrides=plan.overrides)
    import shutil

    shutil.copytree(tmp_path / "elsewhere" / "none_0", out / "none_0")
    _check_kept(_session_argv(head, a, "none", 0, out / "none_0"), "none", out / "none_0")
    with pytest.raises(ConfigError, match="--feedback none; this plan: --feedback prosody"):
        _check_kept(_session_argv(head, a, "prosody", 0, out / "none_0"), "prosody", out / "none_0")


def test_a_session_finished_before_done_recorded_its_plan_is_checked_by_checkpoint_and_feedback(tmp_path):
    import json

    from mjx_protamer.config import ConfigError
    from mjx_protamer.live.effect import DONE, _check_kept

    a, b, d = tmp_path / "seed_15", tmp_path / "seed_25", tmp_path / "out" / "none_0"
    d.mkdir(parents=True)
    (d / DONE).write_text("ok")
    (d / "session.json").write_text(json.dumps({"checkpoint": str(a.absolute()), "feedback": "none"}))
    plan = Plan((a,), tmp_path / "out", ("prosody",))
    _check_kept(_session_argv(plan, a, "none", 0, d), "none", d)
    with pytest.raises(ConfigError, match="--checkpoint .*seed_15; this plan: --checkpoint .*seed_25"):
        _check_kept(_session_argv(plan, b, "none", 0, d), "none", d)
