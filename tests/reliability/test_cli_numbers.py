"""Command-line numbers of pretrain's neighbours (eval, render, reproduce table2/live, calibrate, listen, synth-voice)
are checked like config values before anything is loaded: NaN, infinities, out-of-range values, a fraction where a
count is meant, a seed outside uint32 or of 5,000 digits. Each is one line on stderr naming the flag, exit code 2,
nothing written. Seeds in configs (`train.seed`, a table2 run's `seeds`, `env.reset_pool_seed`) are uint32 too.
"""

from __future__ import annotations

import pytest
import yaml
from reliability_helpers import run_cli

HUGE = "9" * 5000  # int() refuses it (Python's 4,300-digit limit); float() makes it inf
BAD = {"nan": "nan", "inf": "inf", "negative": "-5", "huge": "1e12", "2^64+1": str(2 ** 64 + 1), "5000 digits": HUGE,
       "not a number": "abc"}
FRACTION = "1.5"  # where a whole number is meant


def _toy_table2(tmp_path):
    path = tmp_path / "t2.yaml"
    path.write_text(yaml.safe_dump({"pretrain": {"env_name": "toy", "train": {"episode_length": 25}},
                                    "feedback": {"teacher": {"rule": [{"signal": "reach", "value": 1.0,
                                                                       "above": 0.5}]}}}))
    return path


# command line (with {run}: a saved run, {cfg}: a toy table2 config, {out}: a fresh path); the flag; bad values
CASES = {
    "eval --episodes": (["eval", "--checkpoint", "{run}", "--episodes", "{v}"], "--episodes",
                        [*BAD.values(), "0", FRACTION]),
    "eval --seed": (["eval", "--checkpoint", "{run}", "--seed", "{v}"], "--seed",
                    [*BAD.values(), str(2 ** 32), FRACTION]),
    "render --episodes": (["render", "--checkpoint", "{run}", "--out", "{out}.mp4", "--episodes", "{v}"], "--episodes",
                          [*BAD.values(), "0"]),
    "render --seed": (["render", "--checkpoint", "{run}", "--out", "{out}.mp4", "--seed", "{v}"], "--seed",
                      [*BAD.values(), str(2 ** 32)]),
    "render --fps": (["render", "--checkpoint", "{run}", "--out", "{out}.mp4", "--fps", "{v}"], "--fps",
                     [*BAD.values(), "0"]),
    "render --size": (["render", "--checkpoint", "{run}", "--out", "{out}.mp4", "--size", "{v}"], "--size",
                      [*BAD.values(), "32", FRACTION]),
    "reproduce table2 --seeds": (["reproduce", "table2", "--config", "{cfg}", "--out", "{out}", "--seeds", "{v}"],
                                 "--seeds", [*BAD.values(), "0", FRACTION]),
    "reproduce live --minutes": (["reproduce", "live", "--checkpoints", "{run}", "--out", "{out}", "--minutes", "{v}"],
                                 "--minutes", list(BAD.values())),
    "reproduce live --episodes": (["reproduce", "live", "--checkpoints", "{run}", "--out", "{out}", "--episodes",
                                   "{v}"], "--episodes", [*BAD.values(), FRACTION]),
    "reproduce live --parallel": (["reproduce", "live", "--checkpoints", "{run}", "--out", "{out}", "--parallel",
                                   "{v}"], "--parallel", list(BAD.values())),
    "reproduce live --snapshot-minutes": (["reproduce", "live", "--checkpoints", "{run}", "--out", "{out}",
                                           "--snapshot-minutes", "{v}"], "--snapshot-minutes", list(BAD.values())),
    "reproduce live --pretrain-seeds": (["reproduce", "live", "--pretrain-seeds", "{v}", "--out", "{out}"],
                                        "--pretrain-seeds", list(BAD.values())),
    "calibrate --n": (["calibrate", "--n", "{v}", "--out", "{out}"], "--n", [*BAD.values(), "0"]),
    "listen --max-events": (["listen", "--wav", "{out}.wav", "--max-events", "{v}"], "--max-events",
                            [*BAD.values(), "0"]),
    "synth-voice --seed": (["synth-voice", "{out}", "--seed", "{v}"], "--seed", [*BAD.values(), str(2 ** 32)]),
    "synth-voice --noise-dbfs": (["synth-voice", "{out}", "--noise-dbfs", "{v}"], "--noise-dbfs",
                                 ["nan", "inf", "5", HUGE, "abc"]),
}


@pytest.mark.parametrize("case", list(CASES))
def test_a_bad_command_line_number_is_refused_in_one_line_before_loading(tiny_run, tmp_path, capsys, case):
    argv, flag, values = CASES[case]
    cfg = _toy_table2(tmp_path)
    for i, value in enumerate(values):
        out = tmp_path / f"o{i}"
        code, err = run_cli(capsys, *[a.format(run=tiny_run[1], cfg=cfg, out=out, v=value) for a in argv])
        assert code == 2 and len(err) == 1, (value, err)
        assert err[0].startswith(f"protamer") and flag in err[0], (value, err)
        assert ("within" in err[0] or "must be a number" in err[0]), (value, err)
        assert len(err[0]) < 300, err  # a 5,000-digit value is not echoed whole
        assert not [p for p in tmp_path.iterdir() if p.name.startswith(f"o{i}")], (value, list(tmp_path.iterdir()))


def test_good_numbers_pass_the_checks():
    from mjx_protamer.cli_numbers import number, seed

    assert number("--episodes", "10", 1, 100, integer=True) == 10
    assert number("--episodes", "1e1", 1, 100, integer=True) == 10
    assert number("--fps", "12.5", 0.01, 1000) == 12.5
    assert seed("--seed", str(2 ** 32 - 1)) == 2 ** 32 - 1 and seed("--seed", None) is None


SEED_OVERRIDES = [
    (["pretrain", "--set", f"train.seed={2 ** 32}"], "'train.seed': must be a seed in 0..2^32-1"),
    (["pretrain", "--set", "train.seed=-1"], "'train.seed': must be a seed"),
    (["pretrain", "--set", f"train.seed={2 ** 64 + 1}"], "'train.seed': must be a seed"),
    (["pretrain", "--set", "env.reset_pool_seed=-3"], "'env.reset_pool_seed': must be a seed"),
    (["reproduce", "table2", "--set", f"seeds=[0, {2 ** 32}]"], "'seeds[1]': must be a seed"),
]


@pytest.mark.parametrize("argv, says", SEED_OVERRIDES, ids=[a[-1] for a, _ in SEED_OVERRIDES])
def test_a_config_seed_outside_uint32_is_refused(tmp_path, capsys, argv, says):
    code, err = run_cli(capsys, *argv, "--out", tmp_path / "out")
    assert code == 2 and len(err) == 1 and says in err[0], err
    assert not (tmp_path / "out").exists()


def test_table2_seeds_up_to_2_32_minus_1_are_accepted_by_the_config():
    from mjx_protamer.experiments.table2 import load_table2_config

    assert load_table2_config(None, [f"seeds=[0, {2 ** 32 - 1}]"]).seeds == (0, 2 ** 32 - 1)
