"""A config file over the size limit (config.MAX_CONFIG_BYTES, 1 MiB) is refused by the one loader before it is
read, whichever command it is given to: a 64 MB YAML used to be parsed for minutes into gigabytes. One line,
exit 2, at once, nothing written."""

from __future__ import annotations

import shutil
import time

import pytest
from reliability_helpers import run_cli

# (command line with {f}: the file, {run}: a saved run, {out}: a fresh path)
COMMANDS = {
    "pretrain --config": ["pretrain", "--config", "{f}", "--out", "{out}"],
    "pretrain --feedback-config": ["pretrain", "--feedback", "simulated:keyboard", "--feedback-config", "{f}",
                                   "--out", "{out}"],
    "reproduce table2 --config": ["reproduce", "table2", "--config", "{f}", "--out", "{out}"],
    "reproduce rescore --config": ["reproduce", "rescore", "{run}", "--config", "{f}", "--out", "{out}"],
    "reproduce live --rule-config": ["reproduce", "live", "--checkpoints", "{run}", "--rule-config", "{f}",
                                     "--out", "{out}"],
    "calibrate --config (voice)": ["calibrate", "--config", "{f}", "--out", "{out}"],
}


def _sparse(path, size: int):
    with open(path, "wb") as fh:  # 64 MiB of zeros that take no disk
        fh.truncate(size)
    return path


@pytest.mark.parametrize("command", list(COMMANDS))
def test_a_config_over_the_limit_is_refused_before_it_is_read(tiny_run, tmp_path, capsys, command):
    big = _sparse(tmp_path / "big.yaml", 64 << 20)
    run = tmp_path / "run"
    shutil.copytree(tiny_run[1], run)
    t0 = time.perf_counter()
    code, err = run_cli(capsys, *[a.format(f=big, run=run, out=tmp_path / "out") for a in COMMANDS[command]])
    assert code == 2 and len(err) == 1, err
    assert "64.0 MiB; a config is a few KiB (the limit is 1 MiB)" in err[0] and str(big) in err[0], err
    assert time.perf_counter() - t0 < 20  # refused, not parsed (parsing took minutes)
    assert not (tmp_path / "out").exists()


def test_a_run_whose_config_yaml_is_over_the_limit_is_refused_by_eval_and_render(tiny_run, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(tiny_run[1], run)
    _sparse(run / "config.yaml", 8 << 20)
    for argv in (["eval", "--checkpoint", run], ["render", "--checkpoint", run, "--out", tmp_path / "x.png"]):
        code, err = run_cli(capsys, *argv)
        assert code == 2 and len(err) == 1 and "a config is a few KiB" in err[0], (argv, err)


def test_a_config_just_under_the_limit_still_loads(tmp_path):
    from mjx_protamer.agents.ddpg.config import PretrainConfig
    from mjx_protamer.config import MAX_CONFIG_BYTES, ConfigError, load_config

    path = tmp_path / "c.yaml"
    head = "train:\n  seed: 7\n"
    line = "# a long comment " + "x" * 46 + "\n"  # 64 bytes
    path.write_text(head + line * ((MAX_CONFIG_BYTES - len(head)) // len(line)))
    assert path.stat().st_size <= MAX_CONFIG_BYTES
    assert load_config(PretrainConfig, path).train.seed == 7
    with open(path, "a") as fh:
        fh.write(line)
    with pytest.raises(ConfigError, match="a config is a few KiB"):
        load_config(PretrainConfig, path)
