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


def test_update_flops_counts_the_paper_networks():
    """One update of the paper's 400-300 actor and critic (critic takes the action at layer 2) on a batch
    of 64 from the 84-dim observation and 14-dim action: 4 A + 7 C multiply-adds per sample, with
    A = 84*400 + 400*300 + 300*14 and C = 84*400 + (400+14)*300 + 300*1, two FLOPs each."""
    from mjx_protamer.experiments.bench_train import update_flops

    a = 84 * 400 + 400 * 300 + 300 * 14
    c = 84 * 400 + 414 * 300 + 300
    assert update_flops(84, 14, (400, 300), (400, 300), 64) == 2 * 64 * (4 * a + 7 * c) == 222_451_200
    # A third hidden layer adds its multiply-adds to both networks.
    a3 = 84 * 400 + 400 * 300 + 300 * 200 + 200 * 14
    c3 = 84 * 400 + 414 * 300 + 300 * 200 + 200
    assert update_flops(84, 14, (400, 300, 200), (400, 300, 200), 64) == 2 * 64 * (4 * a3 + 7 * c3)
