"""The training benchmark runs end to end and reports its keys (slow: two 400-300 compiles and SB3)."""

from __future__ import annotations

import argparse

import pytest


@pytest.mark.slow
def test_bench_train_reports_the_keys_on_the_toy_env():
    from mjx_protamer.experiments.bench_train import add_arguments, run_train_benchmark

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(["--env", "toy", "--steps", "50", "--sb3-steps", "50", "--batched-envs", "16",
                              "--batched-iterations", "5", "--repeats", "1"])
    r = run_train_benchmark(args)
    for key in ("steps_per_s", "sb3_steps_per_s", "ratio_vs_sb3", "batched256_steps_per_s"):
        assert r[key] > 0, key
    assert r["ratio_vs_sb3"] == pytest.approx(r["steps_per_s"] / r["sb3_steps_per_s"])
