"""The one atomic writer (mjx_protamer/atomic.py): a write that fails leaves the old file and no temporary."""

import os

import pytest

from mjx_protamer.atomic import replacing, write_atomic


def test_write_replaces_the_content_and_leaves_nothing_else(tmp_path):
    path = tmp_path / "eval.json"
    write_atomic(path, "old")
    write_atomic(path, b"new \xff")
    assert path.read_bytes() == b"new \xff"
    assert os.listdir(tmp_path) == ["eval.json"]


def test_a_writer_that_fails_midway_leaves_the_old_file_intact(tmp_path):
    path = tmp_path / "metrics.csv"
    write_atomic(path, "chunk\n1\n")
    with pytest.raises(OSError, match="No space"):
        with replacing(path) as tmp:
            tmp.write_text("chunk\n1\n2")  # half of the new content, then the disk is full
            raise OSError(28, "No space left on device")
    assert path.read_text() == "chunk\n1\n"
    assert os.listdir(tmp_path) == ["metrics.csv"]


def test_the_temporary_path_keeps_the_suffix_a_writer_picks_its_format_from(tmp_path):
    with replacing(tmp_path / "body_map.png") as tmp:
        assert tmp.parent == tmp_path and tmp.suffix == ".png" and tmp.name.startswith(".")
        tmp.write_bytes(b"png")
    assert (tmp_path / "body_map.png").read_bytes() == b"png"


def test_a_missing_folder_is_the_file_systems_own_error(tmp_path):
    with pytest.raises(FileNotFoundError):
        write_atomic(tmp_path / "absent" / "config.yaml", "a: 1\n")
