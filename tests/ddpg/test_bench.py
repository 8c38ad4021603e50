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


def test_update_dot_shapes_are_the_matmuls_autodiff_lowers():
    """The roofline's matmul list is the update's: the critic loss's and the actor loss's value-and-grad and
    the targets, lowered by JAX, contain exactly these dot shapes (as a multiset, lhs and rhs transposes
    aside), so a change to the networks or the losses that the list misses fails here."""
    import collections
    import re

    import jax
    import jax.numpy as jnp

    from mjx_protamer.agents.ddpg import losses
    from mjx_protamer.agents.ddpg.networks import Actor, Critic
    from mjx_protamer.agents.ddpg.replay import Transition
    from mjx_protamer.experiments.bench_train import update_dot_shapes

    obs_n, act_n, batch = 86, 14, 64
    actor, critic = Actor(action_size=act_n), Critic()
    ap = actor.init(jax.random.PRNGKey(0), jnp.zeros((obs_n,)))
    cp = critic.init(jax.random.PRNGKey(1), jnp.zeros((obs_n,)), jnp.zeros((act_n,)))
    b = Transition(jnp.zeros((batch, obs_n)), jnp.zeros((batch, act_n)), jnp.zeros((batch, 3)),
                   jnp.zeros((batch, obs_n)), jnp.zeros((batch,)))

    def update(ap, cp, b):
        next_q = critic.apply(cp, b.next_obs, actor.apply(ap, b.next_obs))
        target = losses.td_target(jnp.zeros((batch,)), next_q, b.terminal, 0.99)
        (_, _), c_grads = jax.value_and_grad(losses.critic_loss, has_aux=True)(cp, critic.apply, b, target)
        a_loss, a_grads = jax.value_and_grad(losses.actor_loss)(ap, actor.apply, cp, critic.apply, b.obs, 1.0, 2.0)
        return c_grads, a_grads, a_loss

    text = jax.jit(update).lower(ap, cp, b).as_text()
    lowered = collections.Counter()
    for lhs, rhs, out in re.findall(r"stablehlo\.dot_general.*?\(tensor<([\dx]+)xf32>, tensor<([\dx]+)xf32>\) "
                                    r"-> tensor<([\dx]+)xf32>", text):
        lhs, rhs, out = ([int(v) for v in t.split("x")] for t in (lhs, rhs, out))
        contracted = (lhs[0] * lhs[1] * rhs[0] * rhs[1] // (out[0] * out[1])) ** 0.5
        lowered[tuple(sorted((out[0], out[1]))) + (round(contracted),)] += 1
    listed = collections.Counter(tuple(sorted((m, n))) + (k,)
                                 for m, k, n in update_dot_shapes(obs_n, act_n, (400, 300), (400, 300), batch))
    assert lowered == listed


def test_batched_roofline_reports_one_and_vmapped_seeds(tmp_path):
    """`bench train`'s batched-trainer section times a run's chunk after its warm-up, alone and with seeds vmapped,
    and splits its roofline into the updates' matmul time and the env's own time (a tiny toy run)."""
    from mjx_protamer.agents.ddpg.config import PretrainConfig
    from mjx_protamer.config import load_config
    from mjx_protamer.experiments.bench_train import batched_roofline

    config = load_config(PretrainConfig, None, [
        "env_name=toy", "train.num_envs=8", "train.episode_length=25", "train.total_env_steps=4000",
        "train.warmup_env_steps=80", "train.updates_per_step=2", "train.chunk_steps=10",
        "ddpg.actor_hidden=[32,32]", "ddpg.critic_hidden=[32,32]", "ddpg.batch_size=16", "ddpg.replay_size=1000"])
    r = batched_roofline(config, [1, 2], chunks=1, repeats=1)
    assert r["config"]["updates_per_step"] == 2 and r["update_matmul_s"] > 0
    assert set(r["seeds"]) == {"1", "2"}
    for seeds, s in r["seeds"].items():
        n = int(seeds)
        assert s["roofline_chunk_s"] == pytest.approx(s["roofline_update_s"] + s["roofline_env_s"])
        assert s["roofline_update_s"] == pytest.approx(10 * 2 * n * r["update_matmul_s"])
        assert s["fraction_of_roofline"] == pytest.approx(s["roofline_chunk_s"] / s["chunk_s"])
        # the env timed on the trainer's own worlds: the same chunk without updates
        assert s["no_update_chunk_s"] > 0
        assert s["roofline_trained_worlds_chunk_s"] == pytest.approx(s["roofline_update_s"] + s["no_update_chunk_s"])
        assert s["updates_per_s"] * s["chunk_s"] == pytest.approx(10 * 2 * n)
        assert s["run_train_s_projected"] == pytest.approx(config.train.num_chunks * s["chunk_s"])
    # vmapped seeds are also timed as `reproduce table2` runs them, two programs at once
    two = r["seeds"]["2"]
    assert "two_at_once_chunk_s" not in r["seeds"]["1"] and two["two_at_once_chunk_s"] > 0
    assert two["fraction_of_roofline_two_at_once"] == pytest.approx(two["roofline_chunk_s"] / two["two_at_once_chunk_s"])


@pytest.mark.parametrize("argv, says", [
    (["bench", "train", "--env", "toy", "--skip-sb3", "--roofline-seeds", "0"], "--roofline-seeds must be"),
    (["bench", "env", "--batch-sizes", "1,x"], "--batch-sizes must be")])
def test_bench_refuses_bad_counts_in_one_line_before_any_work(argv, says, capsys):
    from mjx_protamer.cli import main

    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and says in err[0]
