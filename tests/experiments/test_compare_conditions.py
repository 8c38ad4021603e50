"""`protamer analyze compare-conditions`: conditions pool by name over runs, pair on the seeds both ran, and a
seed given twice is refused."""

import json
from pathlib import Path

import pytest

from mjx_protamer.cli import main


def compare_conditions(*argv) -> int:
    return main(["analyze", "compare-conditions", *argv])


def write_run(path: Path, seeds, conditions: dict) -> Path:
    path.mkdir()
    (path / "table2.json").write_text(json.dumps({"seeds": seeds, "conditions": {
        name: {"teacher_score": {"seed_values": values}} for name, values in conditions.items()}}))
    return path


def test_seeds_pool_over_runs_and_pair_with_the_reference_on_common_seeds(tmp_path, capsys):
    a = write_run(tmp_path / "a", [0, 1, 2], {"REF": [0.0, 0.1, 0.2], "X": [0.5, 0.7, 0.6]})
    b = write_run(tmp_path / "b", [3, 4], {"REF": [0.3, 0.4], "Y": [1.0, 1.0]})
    png = tmp_path / "cmp.png"
    assert compare_conditions(str(a), str(b), "--reference", "REF", "--metric", "teacher_score",
                              "--plot", str(png)) == 0
    out = json.loads(capsys.readouterr().out)["conditions"]
    ref = out["REF"]["teacher_score"]
    assert ref["seeds"] == [0, 1, 2, 3, 4] and ref["mean"] == pytest.approx(0.2)
    x = out["X"]["teacher_score"]["vs_reference"]
    assert x["seeds"] == [0, 1, 2] and x["paired"]["seed_values"] == pytest.approx([0.5, 0.6, 0.4])
    assert x["paired_beyond_zero"] is True
    y = out["Y"]["teacher_score"]["vs_reference"]
    assert y["seeds"] == [3, 4] and y["paired"]["seed_values"] == pytest.approx([0.7, 0.6])
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_seed_twice_and_an_unknown_name_are_one_line_errors(tmp_path, capsys):
    a = write_run(tmp_path / "a", [0, 1], {"REF": [0.0, 0.1]})
    b = write_run(tmp_path / "b", [1, 2], {"REF": [0.3, 0.4]})
    assert compare_conditions(str(a), str(b)) == 2
    assert "condition REF has seed 1 in two runs" in capsys.readouterr().err
    c = write_run(tmp_path / "c", [0, 1], {"REF": [0.2, 0.4]})
    assert compare_conditions(str(a), f"{c}@again", "--reference", "REF") == 0  # tagged: REF@again
    tagged = json.loads(capsys.readouterr().out)["conditions"]["REF@again"]["teacher_score"]["vs_reference"]
    assert tagged["seeds"] == [0, 1] and tagged["paired"]["seed_values"] == pytest.approx([0.2, 0.3])
    assert compare_conditions(str(a), "--names", "REF,NOPE") == 2
    assert "no run has a condition named 'NOPE'" in capsys.readouterr().err
    assert compare_conditions(str(tmp_path / "missing")) == 2
    assert "table2.json is missing" in capsys.readouterr().err
