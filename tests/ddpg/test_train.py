"""The assembled learner on the toy env: it learns, resumes exactly, relabels with a human model, vmaps."""

from __future__ import annotations

import dataclasses
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_protamer.agents.ddpg.networks import Critic
from mjx_protamer.agents.ddpg.train import make_train
from mjx_protamer.envs.toy import PointReachEnv
from mjx_protamer.experiments.evaluate import eval_seed, evaluate, load_run
from mjx_protamer.experiments.pretrain import run_pretrain

from ddpg_helpers import replace_train, tiny_config


def test_ddpg_solves_point_reach(learned_run):
    """Threshold: a mean test return above -5 over 10 episodes of 25 steps. The untrained actor (actions ~0)
    and a uniform random policy both score about -26 (they stay ~1 away from the goal); a policy that
    heads for the goal reaches it in ~7 steps and collects the reach bonus."""
    config, out, result = learned_run
    assert result["finished"]
    trained = result["eval"]
    env = PointReachEnv(config.toy)
    untrained = jax.jit(make_train(config, env).init)(jax.random.PRNGKey(123)).actor_params
    baseline = evaluate(config, env, untrained, 10, eval_seed(config))
    random_return = _random_policy_return(env, episodes=10, length=config.train.episode_length)
    assert baseline["episode_return"] < -15 and random_return < -15
    assert trained["episode_return"] > -5, trained
    assert trained["contact_rate"] > 0.4  # "contact" = inside the goal radius
    assert trained["first_touch_step"] < 15


def _random_policy_return(env, episodes, length):
    def episode(key):
        k_reset, k_act = jax.random.split(key)
        state = env.reset(k_reset)
        actions = jax.random.uniform(k_act, (length, env.action_size), minval=-1, maxval=1)
        def step(s, a):
            s = env.step(s, a)
            return s, s.reward
        return jnp.sum(jax.lax.scan(step, state, actions)[1])
    return float(jnp.mean(jax.vmap(episode)(jax.random.split(jax.random.PRNGKey(7), episodes))))


def test_outputs_written(learned_run):
    config, out, result = learned_run
    for name in ("config.yaml", "metrics.csv", "training_curve.png", "eval.json"):
        assert (out / name).is_file(), name
    assert any((out / "tb").iterdir())
    lines = (out / "metrics.csv").read_text().strip().splitlines()
    assert len(lines) == 1 + config.train.num_chunks
    assert "reward_term/distance" in lines[0]


def test_resume_is_exact(learned_run, tmp_path):
    """Kill after 2 of 6 chunks (checkpoint every chunk), resume: same params as the uninterrupted run.
    (The checkpoint period does not change training; the learned run checkpoints every 5 chunks.)"""
    _, _, full = learned_run
    config = replace_train(learned_run[0], checkpoint_every_chunks=1)
    first = run_pretrain(config, tmp_path, progress=False, max_chunks=2, final_eval=False)
    assert not first["finished"] and first["chunks_done"] == 2
    resumed = run_pretrain(config, tmp_path, resume=True, progress=False, final_eval=False)
    assert resumed["finished"]
    leaves_full = jax.tree.leaves(full["state"])
    leaves_resumed = jax.tree.leaves(resumed["state"])
    assert len(leaves_full) == len(leaves_resumed)
    for a, b in zip(leaves_full, leaves_resumed):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    rows = (tmp_path / "metrics.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + config.train.num_chunks


def test_eval_command_reproduces_final_metrics(learned_run, capsys):
    import argparse

    from mjx_protamer.commands import train as train_cmd

    config, out, result = learned_run
    parser = argparse.ArgumentParser()
    train_cmd.register(parser.add_subparsers())
    args = parser.parse_args(["eval", "--checkpoint", str(out), "--json"])
    assert args.handler(args) == 0
    printed = json.loads(capsys.readouterr().out)
    for key in ("first_touch_step", "contact_rate", "unique_regions", "freeze_ratio"):
        assert printed[key] == result["eval"][key]
        assert len(printed["per_episode"][key]) == 10
    _, _, state, step = load_run(out / "checkpoints")
    assert step == config.train.num_chunks


def test_human_params_relabel_without_recompiling():
    """Only the last iteration of the chunk updates, so replay and minibatches are the same in both calls:
    the sampled reward differs by exactly beta * bias. A new value of the params does not recompile."""
    config = tiny_config(total_env_steps=200, warmup_env_steps=196)  # 50 iterations x 4 envs, 49 warm-up
    human = lambda params, obs, action: params["bias"] * jnp.ones(obs.shape[0])
    trainer = make_train(config, PointReachEnv(), human_reward_fn=human)
    out = []
    for bias in (0.0, 10.0):
        state = trainer.init(jax.random.PRNGKey(0))
        state, m = trainer.train_chunk(state, {"bias": jnp.float32(bias)})
        out.append(float(m["sampled_reward"]))
    np.testing.assert_allclose(out[1] - out[0], config.ddpg.reward_beta * 10.0, rtol=1e-4)
    trainer.train_chunk(state, {"bias": jnp.float32(-1.0)})  # a chunk's output state is a valid input
    assert trainer.train_chunk._cache_size() == 1


def test_action_biasing_on_its_own_step_size_moves_the_actor_when_actor_lr_is_tiny():
    """`ddpg.human_actor_lr`: the person's term has its own Adam. With actor_lr ~0 the actor still climbs r_hat
    at human_actor_lr; with one shared Adam (human_actor_lr 0) the same tiny actor_lr holds it still."""
    base = tiny_config(total_env_steps=200, warmup_env_steps=40)  # 50 iterations x 4 envs: 40 update steps
    w = jnp.array([1.0, -1.0], jnp.float32)
    human = lambda params, obs, action: action @ params["w"]  # r_hat: the first action up, the second down
    obs = jax.random.normal(jax.random.PRNGKey(5), (64, PointReachEnv().observation_size))

    def moved(**ddpg):
        config = dataclasses.replace(base, ddpg=dataclasses.replace(base.ddpg, actor_lr=1e-9, human_actor_coef=1.0,
                                                                    **ddpg))
        trainer = make_train(config, PointReachEnv(), human_reward_fn=human)
        state = trainer.init(jax.random.PRNGKey(0))
        before = trainer.act(state.actor_params, obs)
        state, _ = trainer.train_chunk(state, {"w": w})
        return float(jnp.mean((trainer.act(state.actor_params, obs) - before) @ w)), state

    own, state = moved(human_actor_lr=1e-2)
    shared, shared_state = moved(human_actor_lr=0.0)
    assert own > 0.2, own
    assert abs(shared) < 1e-3, shared
    assert state.human_opt_state is not None and shared_state.human_opt_state is None
    # the state follows from the config alone (a saved run restores from its config.yaml); without a model unused
    own_config = dataclasses.replace(base, ddpg=dataclasses.replace(base.ddpg, human_actor_coef=1.0,
                                                                    human_actor_lr=1e-2))
    no_model = make_train(own_config, PointReachEnv()).init(jax.random.PRNGKey(0))
    assert no_model.human_opt_state is not None


def test_a_critic_of_r_hat_alone_moves_the_actor_where_r_hat_has_no_action_gradient():
    """`ddpg.human_critic_coef`: r_hat here rewards being further right and ignores the action, so action biasing
    has nothing to climb; the critic of r_hat alone bootstraps it and learns that moving right leads there."""
    base = tiny_config(total_env_steps=1000, warmup_env_steps=40)
    human = lambda params, obs, action: obs[:, 0] * params["s"]
    obs = jax.random.uniform(jax.random.PRNGKey(5), (256, PointReachEnv().observation_size), minval=-1, maxval=1)

    def moved(**ddpg):  # the env's reward and r_hat out of the critic: only the person's terms teach the actor
        config = dataclasses.replace(base, ddpg=dataclasses.replace(base.ddpg, actor_lr=1e-3, tau=0.05,
                                                                    reward_alpha=0.0, reward_beta=0.0, **ddpg))
        trainer = make_train(config, PointReachEnv(), human_reward_fn=human)
        state = trainer.init(jax.random.PRNGKey(0))
        before = trainer.act(state.actor_params, obs)[:, 0]
        for _ in range(config.train.num_chunks):
            state, _ = trainer.train_chunk(state, {"s": jnp.float32(1.0)})
        return float(jnp.mean(trainer.act(state.actor_params, obs)[:, 0] - before)), state

    with_critic, state = moved(human_critic_coef=1.0, human_critic_gamma=0.9)
    biased, biased_state = moved(human_actor_coef=1.0)
    assert with_critic > 0.5 and abs(biased) < 0.3, (with_critic, biased)
    assert biased_state.human_critic_params is None
    # it starts as the critic's trunk with a zero output, and from the config alone (unused without a model)
    config = dataclasses.replace(base, ddpg=dataclasses.replace(base.ddpg, human_critic_coef=1.0))
    fresh = make_train(config, PointReachEnv()).init(jax.random.PRNGKey(0))
    critic = Critic(hidden=tuple(config.ddpg.critic_hidden))
    assert float(jnp.abs(critic.apply(fresh.human_critic_params, obs, obs[:, :2])).max()) == 0.0
    np.testing.assert_array_equal(fresh.human_critic_params["params"]["Dense_0"]["kernel"],
                                  fresh.critic_params["params"]["Dense_0"]["kernel"])


def test_the_anchor_holds_the_actor_by_its_weight():
    """`ddpg.anchor_coef`: a pull toward the actor the run started from. At weight 1 a strong anchor holds the
    actor against the person's term; the state's `anchor_weight` at 0 lets it climb r_hat as an unanchored
    actor does (a live session lowers it as the person teaches: live/tamer.py)."""
    base = tiny_config(total_env_steps=200, warmup_env_steps=40)
    w = jnp.array([1.0, -1.0], jnp.float32)
    human = lambda params, obs, action: action @ params["w"]
    obs = jax.random.normal(jax.random.PRNGKey(5), (64, PointReachEnv().observation_size))

    def moved(anchor_coef, weight=None):
        config = dataclasses.replace(base, ddpg=dataclasses.replace(base.ddpg, actor_lr=1e-2, human_actor_coef=1.0,
                                                                    anchor_coef=anchor_coef))
        trainer = make_train(config, PointReachEnv(), human_reward_fn=human)
        state = trainer.init(jax.random.PRNGKey(0))
        if weight is not None:
            state = state.replace(anchor_weight=jnp.float32(weight))
        before = trainer.act(state.actor_params, obs)
        state, _ = trainer.train_chunk(state, {"w": w})
        return float(jnp.mean((trainer.act(state.actor_params, obs) - before) @ w)), state

    free, free_state = moved(0.0)
    held, held_state = moved(1000.0)
    released, _ = moved(1000.0, weight=0.0)
    assert free_state.anchor_params is None and free_state.anchor_weight is None
    assert float(held_state.anchor_weight) == 1.0
    assert free > 0.2 and abs(held) < 0.2 * free, (free, held)
    assert released == pytest.approx(free, rel=0.05), (free, released)


def test_train_vmaps_over_seeds():
    config = tiny_config(total_env_steps=400)
    trainer = make_train(config, PointReachEnv())
    states, metrics = jax.jit(jax.vmap(trainer.train))(jax.random.split(jax.random.PRNGKey(0), 2))
    assert metrics["critic_loss"].shape == (2, config.train.num_chunks)
    assert np.isfinite(np.asarray(metrics["critic_loss"])[:, -1]).all()
    k = states.actor_params["params"]["Dense_0"]["kernel"]
    assert k.shape[0] == 2 and not np.allclose(k[0], k[1])
    assert np.asarray(states.iteration).tolist() == [config.train.iterations] * 2
    # Staggered episode clocks: the envs of a batch do not reset in lockstep.
    assert len(set(np.asarray(states.env_state.info["steps"])[0].tolist())) > 1
    # The replay holds every step of every env (no overflow at this size).
    assert np.asarray(states.replay.size).tolist() == [config.train.iterations * config.train.num_envs] * 2


def test_checkpoint_roundtrip_keeps_zero_size_leaves(tmp_path):
    """mjx.Data carries zero-size arrays (e.g. `act`), which orbax refuses: they are rebuilt on restore."""
    from mjx_protamer.experiments import checkpoints

    tree = {"a": jnp.arange(3.0), "empty": jnp.zeros((0, 4)), "n": {"k": jnp.ones((2, 2), jnp.int32)}}
    mngr = checkpoints.manager(tmp_path / "ck")
    checkpoints.save(mngr, 7, tree)
    assert mngr.latest_step() == 7
    back = checkpoints.restore(mngr, 7, jax.eval_shape(lambda: tree))
    assert back["empty"].shape == (0, 4)
    np.testing.assert_array_equal(back["a"], tree["a"])
    assert back["n"]["k"].dtype == jnp.int32


def test_quiet_envs_act_with_the_deterministic_actor():
    """`noise.quiet_fraction` 0.5 of 4 envs: envs 2 and 3 store exactly the deterministic actor's action, envs
    0 and 1 the actor's action plus noise (the replay rows of iteration i are i * 4 + env)."""
    config = tiny_config(total_env_steps=200, warmup_env_steps=4, updates_per_step=0)
    config = dataclasses.replace(config, ddpg=dataclasses.replace(
        config.ddpg, noise=dataclasses.replace(config.ddpg.noise, quiet_fraction=0.5)))
    trainer = make_train(config, PointReachEnv())
    state, _ = trainer.train_chunk(trainer.init(jax.random.PRNGKey(0)), None)
    rows = np.arange(4, 200).reshape(-1, 4)  # after the one warm-up iteration
    obs, action = np.asarray(state.replay.data.obs), np.asarray(state.replay.data.action)
    greedy = np.clip(np.asarray(trainer.act(state.actor_params, jnp.asarray(obs))), -1, 1)
    gap = np.abs(action - greedy).max(axis=-1)[rows]  # (iterations, envs)
    assert gap[:, 2:].max() < 1e-6  # the same actor, up to float rounding of a different batch shape
    assert gap[:, :2].min() > 1e-3


def test_chunk_emits_the_transitions_it_stores_and_train_chunk_does_not_pay_for_them():
    """`collect_chunk`'s scan emits every iteration's transitions, (T, B, ...): exactly the rows the replay
    received (iteration i, env b at row ptr + i B + b), and the same state and metrics as `train_chunk`.
    `train_chunk` drops them: its compiled program is no larger than a chunk that never stacked them. One update
    a step: two are unrolled (`_updates`), and their temporaries alone outgrow this toy trajectory."""
    config = tiny_config(num_envs=8, chunk_steps=100, total_env_steps=1600, updates_per_step=1)
    trainer = make_train(config, PointReachEnv())
    tc = config.train
    a = trainer.init(jax.random.PRNGKey(0))
    b = trainer.init(jax.random.PRNGKey(0))
    mem_train = trainer.train_chunk.lower(a, None).compile().memory_analysis()
    mem_collect = trainer.collect_chunk.lower(a, None).compile().memory_analysis()
    for _ in range(2):  # the second chunk wraps the 1000-row replay (2 x 800 rows)
        ptr0 = int(b.replay.ptr)
        a, ma = trainer.train_chunk(a, None)
        b, mb, steps, extras = trainer.collect_chunk(b, None)
        assert extras == {}  # the toy env has no body regions: nothing beside the transitions
        assert steps.obs.shape == (tc.chunk_steps, tc.num_envs, 6) and steps.terminal.shape == (100, 8)
        rows = (ptr0 + np.arange(tc.chunk_steps)[:, None] * tc.num_envs + np.arange(tc.num_envs)) % 1000
        for field, emitted in zip(steps._fields, steps):
            np.testing.assert_array_equal(np.asarray(getattr(b.replay.data, field))[rows], np.asarray(emitted),
                                          err_msg=field)
        assert np.asarray(steps.terminal).sum() == 0 and np.abs(np.asarray(steps.action)).max() <= 1.0
        jax.tree.map(lambda x, y: np.testing.assert_array_equal(np.asarray(x), np.asarray(y)), (a, ma), (b, mb))
    traj_bytes = sum(x.nbytes for x in jax.tree.leaves(steps))
    extra_out = mem_collect.output_size_in_bytes - mem_train.output_size_in_bytes
    assert traj_bytes <= extra_out <= traj_bytes + 8 * len(steps)  # + one tuple slot per emitted field
    assert mem_train.temp_size_in_bytes < traj_bytes <= mem_collect.temp_size_in_bytes + traj_bytes
    assert mem_train.temp_size_in_bytes <= mem_collect.temp_size_in_bytes


def test_step_size_decay_scales_the_update_and_leaves_the_start_alone():
    """`lr_final_fraction`: Adam's step is linear in its rate, so the decayed run's first update is the constant
    run's scaled by the schedule at that iteration (the critic's exactly: same params, batch and Adam state);
    before `lr_decay_from` nothing differs."""
    base = tiny_config(total_env_steps=44, warmup_env_steps=40, chunk_steps=11, updates_per_step=1)  # 1 update

    def moved(final, decay_from):
        config = dataclasses.replace(base, ddpg=dataclasses.replace(base.ddpg, lr_final_fraction=final,
                                                                      lr_decay_from=decay_from))
        trainer = make_train(config, PointReachEnv())
        start = trainer.init(jax.random.PRNGKey(0))
        before = jax.device_get((start.critic_params, start.actor_params))
        end, _ = trainer.train_chunk(start, None)
        return jax.tree.map(lambda a, b: np.asarray(a) - b, (end.critic_params, end.actor_params), before)

    const, decayed, late = moved(1.0, 0.5), moved(0.5, 0.0), moved(0.5, 0.99)
    scale = 1.0 - (10 / 11) * 0.5  # the update runs at iteration 10 of 11
    for c, d in zip(jax.tree.leaves(const[0]), jax.tree.leaves(decayed[0])):
        np.testing.assert_allclose(d, scale * c, rtol=1e-4, atol=1e-9)
    ratio = [np.linalg.norm(d) / np.linalg.norm(c) for c, d in zip(jax.tree.leaves(const[1]),
                                                                   jax.tree.leaves(decayed[1]))]
    assert np.allclose(ratio, scale, rtol=0.05), ratio  # the actor's, against the (scaled) new critic
    for c, d in zip(jax.tree.leaves(const), jax.tree.leaves(late)):  # the decay starts after iteration 10
        np.testing.assert_array_equal(c, d)
