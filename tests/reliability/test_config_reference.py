"""docs/config.md, the configuration reference, holds every knob of every schema with its default, its meaning and
the shipped files that set it; it is written from the dataclasses (mjx_protamer/config_reference.py), so a field
added, renamed, removed or given another default changes the page, and these tests fail until it is rewritten."""

from __future__ import annotations

import dataclasses
import json
import typing

import pytest

from mjx_protamer import config_reference as ref

# Table2's conditions are defined in experiments/table2.py, which issue 41 (item 6) splits into a package: their
# fields get their comments there.


def knobs() -> list[tuple[type, dataclasses.Field]]:
    """Every leaf field (not a section) of every schema's section classes."""
    sections: dict[type, list[str]] = {}
    for _, cls, _, _ in ref.schemas():
        ref.walk(cls, "", sections)
    return [(cls, f) for cls in sections for f in dataclasses.fields(cls)
            if ref.section_type(typing.get_type_hints(cls)[f.name]) is None]


def row(page: str, cls: type, name: str) -> str:
    section = page.split(f"\n## {cls.__name__}\n", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in section.splitlines() if line.startswith(f"| `{name}` |")]
    assert len(rows) == 1, f"{cls.__name__}.{name}: {len(rows)} rows on the page"
    return rows[0]


def test_the_page_is_what_the_code_writes():
    assert ref.PAGE.read_text() == ref.render(), (
        "docs/config.md is stale: rewrite it with `python -m mjx_protamer.config_reference`")


def test_every_knob_is_on_the_page_under_its_section_with_its_default():
    page = ref.render()
    found = knobs()
    assert len(found) > 200  # the walk reaches nested sections, tuples of sections (rule, conditions), voice
    for cls, f in found:
        line = row(page, cls, f.name)
        if f.default is not dataclasses.MISSING:
            assert f"`{json.dumps(list(f.default) if isinstance(f.default, tuple) else f.default)}`" in line, line


def test_every_knob_says_what_it_means():
    missing = sorted(f"{cls.__name__}.{f.name}" for cls, f in knobs()
                     if not ref.field_comments(cls).get(f.name))
    assert missing == [], "give these fields a comment: what they mean"


def test_set_in_names_the_shipped_files_that_set_a_key(tmp_path, monkeypatch):
    (tmp_path / "pretrain.yaml").write_text("env:\n  reward: paper\ntrain:\n  seed: 3\n")
    (tmp_path / "paper_single_env.yaml").write_text("train:\n  seed: 4\n  num_envs: 1\n")
    monkeypatch.setattr(ref, "CONFIGS", tmp_path)
    page = ref.render()
    from mjx_protamer.agents.ddpg.config import DDPGConfig, TrainConfig
    from mjx_protamer.envs.config import EnvConfig

    assert "| all pretrain |" in row(page, TrainConfig, "seed")
    assert "| paper_single_env |" in row(page, TrainConfig, "num_envs")
    assert "| pretrain |" in row(page, EnvConfig, "reward")  # a preset name sets the whole section
    assert "| - |" in row(page, DDPGConfig, "gamma")


def test_a_config_file_no_schema_reads_is_refused(tmp_path, monkeypatch):
    (tmp_path / "stray.yaml").write_text("train:\n  seed: 3\n")
    monkeypatch.setattr(ref, "CONFIGS", tmp_path)
    with pytest.raises(ValueError, match="configs/stray.yaml: no schema"):
        ref.render()


def test_a_field_comment_is_the_lines_above_it_and_its_own():
    from mjx_protamer.envs.config import EnvConfig

    comments = ref.field_comments(EnvConfig)
    assert comments["action_filter_s"].startswith("Time constant (s) of the low-pass")
    assert comments["action_filter_s"].endswith("See docs/experiments.md for why 0.1 s.")
    assert comments["oscillator_hz"].startswith("Frequency (Hz)")  # not the comment of the field before


def test_help_prints_what_the_command_does_and_writes_nothing(capsys, monkeypatch, tmp_path):
    page = tmp_path / "config.md"
    monkeypatch.setattr(ref, "PAGE", page)
    monkeypatch.setattr(ref, "ROOT", tmp_path)
    with pytest.raises(SystemExit) as exit_info:
        ref.main(["--help"])
    assert exit_info.value.code == 0 and "config.md" in capsys.readouterr().out and not page.exists()
    with pytest.raises(SystemExit) as exit_info:
        ref.main(["--bogus"])
    assert exit_info.value.code == 2 and not page.exists()
    ref.main([])
    assert page.read_text() == ref.render()
