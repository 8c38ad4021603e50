"""`reproduce live --merge`: runs of one plan over different checkpoints pool into the result one run over all of
them reports; runs of different plans, a checkpoint twice, or an --out that is one of the runs are refused."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mjx_protamer.experiments.stats import seed_stats
from mjx_protamer.live.effect import METRICS, rule_override, summarize

ROOT = Path(__file__).resolve().parents[2]


def _row(ckpt: str, start: float, none: float, keyboard: float) -> dict:
    m = lambda score: {k: (score if k == "teacher_score" else 0.1) for k in METRICS} | {"r_hat_corr": score / 2}
    return {"checkpoint": ckpt, "start": m(start), "none": m(none), "keyboard": {**m(keyboard), "events": 60}}


def _run(tmp_path: Path, name: str, rows: list[dict], **plan) -> Path:
    out = tmp_path / name
    out.mkdir()
    base = {"channels": ["keyboard"], "minutes": 2.0, "chunk_ms": 250.0, "rule_config": None, "overrides": [],
            "episodes": 10, "learner": "ddpg", "snapshot_minutes": 0.0, "speaker": "sentences",
            "checkpoints": [r["checkpoint"] for r in rows], "out": str(out)}
    summary = summarize({**base, **plan}, rows, f"protamer reproduce live --out {out}", 100.0)
    (out / "live_effect.json").write_text(json.dumps(summary))
    return out


def _merge(*argv) -> int:
    from mjx_protamer.cli import main

    return main(["reproduce", "live", *map(str, argv)])


def test_two_runs_pool_into_what_one_run_over_their_checkpoints_reports(tmp_path, capsys):
    rng = np.random.default_rng(0)
    rows = [_row(f"/ck/seed_{k}", *rng.normal(size=3)) for k in range(6)]
    head = ROOT / "configs" / "table2_head.yaml"
    elsewhere = tmp_path / "head_rule_copy.yaml"   # the same rule, named by another path (another machine)
    elsewhere.write_bytes(head.read_bytes())
    a = _run(tmp_path, "a", rows[:4], rule_config=str(head))
    b = _run(tmp_path, "b", rows[4:], rule_config=str(elsewhere))
    assert _merge("--merge", a, b, "--out", tmp_path / "m") == 0
    merged = json.loads((tmp_path / "m" / "live_effect.json").read_text())
    one = summarize({"channels": ["keyboard"]}, rows, "", 0.0)
    assert merged["per_checkpoint"] == rows
    for key in ("pooled", "paired", "drift", "r_hat_corr"):
        assert merged[key] == json.loads(json.dumps(one[key])), key
    paired = merged["paired"]["keyboard"]["teacher_score"]["paired"]
    want = seed_stats([r["keyboard"]["teacher_score"] - r["none"]["teacher_score"] for r in rows])
    assert paired["mean"] == pytest.approx(want["mean"]) and paired["ci95"] == pytest.approx(want["ci95"])
    assert [m["run"] for m in merged["merged_from"]] == [str(a), str(b)]
    assert merged["plan"]["checkpoints"] == [r["checkpoint"] for r in rows]
    assert merged["plan"]["rule"] == rule_override(head)
    md = (tmp_path / "m" / "live_effect.md").read_text()
    assert "6 checkpoints" in md and f"Pooled from {a} (4 checkpoints), {b} (2 checkpoints)" in md
    assert (tmp_path / "m" / "live_effect.png").stat().st_size > 10_000
    assert "json " in capsys.readouterr().out
    # a pooled result is replaced by pooling again; a run's own --out is never written over
    assert _merge("--merge", b, a, "--out", tmp_path / "m") == 0
    assert json.loads((tmp_path / "m" / "live_effect.json").read_text())["per_checkpoint"] == rows[4:] + rows[:4]
    before = (a / "live_effect.json").read_bytes()
    assert _merge("--merge", a, b, "--out", a) == 2
    assert "is one of the runs --merge pools" in capsys.readouterr().err
    assert (a / "live_effect.json").read_bytes() == before


@pytest.mark.parametrize("plan,message", [
    ({"minutes": 5.0}, "ran minutes=5.0 but"),
    ({"overrides": ["feedback.teacher.min_gap_steps=300"]}, "ran overrides="),
    ({"speaker": "words"}, "ran speaker='words' but"),
    ({"rule_config": str(ROOT / "configs" / "table2_head.yaml")}, "held another rule than"),  # a: the built-in
])
def test_runs_of_different_plans_are_refused_in_one_line(tmp_path, capsys, plan, message):
    a = _run(tmp_path, "a", [_row("/ck/seed_0", 0, 0, 1), _row("/ck/seed_1", 0, 0, 1)])
    b = _run(tmp_path, "b", [_row("/ck/seed_2", 0, 0, 1)], **plan)
    assert _merge("--merge", a, b, "--out", tmp_path / "m") == 2
    err = capsys.readouterr().err
    assert message in err and "only runs of one plan pool" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "m").exists()


def test_a_checkpoint_twice_a_missing_result_and_plan_flags_are_refused(tmp_path, capsys):
    a = _run(tmp_path, "a", [_row("/ck/seed_0", 0, 0, 1), _row("/ck/seed_1", 0, 0, 1)])
    b = _run(tmp_path, "b", [_row("/ck/seed_1", 0, 0, 1)])
    assert _merge("--merge", a, b, "--out", tmp_path / "m") == 2
    assert "checkpoint /ck/seed_1 is in both" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert _merge("--merge", a, tmp_path / "empty", "--out", tmp_path / "m") == 2
    assert "no live_effect.json there" in capsys.readouterr().err
    assert _merge("--merge", a, "--out", tmp_path / "m") == 2
    assert "two or more" in capsys.readouterr().err
    assert _merge("--merge", a, b, "--out", tmp_path / "m", "--channels", "prosody", "--minutes", "5") == 2
    assert "leave out --channels, --minutes" in capsys.readouterr().err
    assert not (tmp_path / "m").exists()
