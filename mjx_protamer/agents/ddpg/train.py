"""DDPG in pure JAX: a batch of envs, a device-resident replay, the whole train step in one jit.

Shaped like PureJaxRL. `make_train(config, env)` returns pure functions:

- `init(rng) -> TrainState`: networks, optimisers, targets, env batch, noise, empty replay;
- `train_chunk(train_state, human_params) -> (train_state, metrics)`: `chunk_steps` iterations under
  `lax.scan`; an iteration steps every env once (`_env_step`) and then makes `updates_per_step` gradient
  updates (`_update`: critic, actor, soft target update). Jitted once; `human_params` is an argument, so a
  new human-reward model never recompiles. The host (logging, progress, checkpoints) runs between chunks;
- `collect_chunk(train_state, human_params) -> (train_state, metrics, transitions, extras)`: the same chunk,
  and the scan's per-iteration `replay.Transition`s, (chunk_steps, num_envs, ...), in the order they were
  stepped (PureJaxRL's trajectory), with `extras`: per-step env outputs the replay does not store, beside
  them (`region_mask`, (chunk_steps, num_envs, regions), for an env with body regions: what a teacher rule's
  region signals read; {} otherwise). `train_chunk` is this function with both dropped: XLA removes the
  unused stacked outputs (the compiled temp and output sizes are those of a chunk that never emits them,
  checked in tests/ddpg/test_train.py), so nobody pays for them unless they ask;
- `chunk_body`: `collect_chunk` before jit and shard_map (the per-device body over axis `AXIS`, with
  `state_specs`), for callers that add work inside the same program (the feedback path);
- `train(rng, human_params=None) -> (train_state, metrics per chunk)`: init and every chunk in one pure
  function, to `jax.jit(jax.vmap(train))` over seeds (single device only).

Data parallelism: with more than one device the env batch, the replay and the per-update minibatch are split
over a 1-D mesh (axis "data") with `shard_map`; parameters are replicated and gradients are averaged with
`pmean`, so every device applies the same update. The same config runs on 1 CPU or on N GPUs.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import struct
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P

from mjx_protamer.agents.ddpg import losses, noise, replay
from mjx_protamer.agents.ddpg.losses import HumanRewardFn
from mjx_protamer.agents.ddpg.networks import Actor, Critic
from mjx_protamer.config import ConfigError
from mjx_protamer.envs.base import State
from mjx_protamer.envs.wrappers import wrap_for_training
from mjx_protamer.step_size import decay_scale

AXIS = "data"


@struct.dataclass
class TrainState:
    actor_params: Any
    critic_params: Any
    target_actor_params: Any
    target_critic_params: Any
    actor_opt_state: Any
    critic_opt_state: Any
    env_state: State  # batch of num_envs worlds (sharded over devices)
    noise_state: jax.Array  # (num_envs, action_size)
    replay: replay.ReplayBuffer  # (replay_size, ...) rows (sharded over devices)
    rng: jax.Array  # replicated PRNG key; devices fold in their index where they must differ
    iteration: jax.Array  # vectorised env steps taken so far
    episode_return: jax.Array  # (num_envs,) return of each env's running episode
    # the actor `ddpg.anchor_coef` pulls toward (None without an anchor: checkpoints of such runs hold no copy)
    anchor_params: Any = None
    # the anchor's weight, a float32 scalar in [0, 1] multiplying `anchor_coef` (None without an anchor): 1 for a
    # run; a live session lowers it as the person teaches (`ddpg.anchor_release_events`, live/tamer.py)
    anchor_weight: Any = None
    # action biasing's own Adam (`ddpg.human_actor_coef` and `ddpg.human_actor_lr` > 0: from the config alone, so a
    # saved run restores from its config.yaml; unused without a human reward model; None otherwise)
    human_opt_state: Any = None
    # the critic of r_hat alone, its target and its Adam (`ddpg.human_critic_coef` > 0: from the config alone;
    # unused without a human reward model; None otherwise)
    human_critic_params: Any = None
    target_human_critic_params: Any = None
    human_critic_opt_state: Any = None


class Learner(NamedTuple):
    """What one gradient update changes."""
    actor_params: Any
    critic_params: Any
    target_actor_params: Any
    target_critic_params: Any
    actor_opt_state: Any
    critic_opt_state: Any
    human_opt_state: Any = None
    human_critic_params: Any = None
    target_human_critic_params: Any = None
    human_critic_opt_state: Any = None


class Trainer(NamedTuple):
    init: Callable[[jax.Array], TrainState]
    train_chunk: Callable[[TrainState, Any], tuple[TrainState, dict]]
    # + the (T, B, ...) steps and their extras
    collect_chunk: Callable[[TrainState, Any], tuple[TrainState, dict, replay.Transition, dict]]
    chunk_body: Callable  # collect_chunk unjitted, per device (inside shard_map over AXIS when sharded)
    train: Callable | None  # None when sharded over several devices
    act: Callable[[Any, jax.Array], jax.Array]  # deterministic actor
    env: Any  # the wrapped, batched env
    mesh: Mesh | None
    state_sharding: Any  # TrainState of NamedSharding (None when unsharded)
    num_devices: int
    state_specs: Any  # TrainState of PartitionSpec prefixes (None when unsharded)
    # (train_state, human_params, n) -> train_state after n more updates (one device only; None when sharded)
    extra_updates: Callable | None = None


def _anchor(ts: TrainState):
    """(anchor params, weight) for the actor's loss, or None: a run without an anchor holds neither."""
    return None if ts.anchor_params is None else (ts.anchor_params, ts.anchor_weight)


def _learner(ts: TrainState) -> Learner:
    return Learner(ts.actor_params, ts.critic_params, ts.target_actor_params, ts.target_critic_params,
                   ts.actor_opt_state, ts.critic_opt_state, ts.human_opt_state, ts.human_critic_params,
                   ts.target_human_critic_params, ts.human_critic_opt_state)


def _with_learner(ts: TrainState, lr: Learner) -> TrainState:
    return ts.replace(**lr._asdict())


def human_critic_from(critic_params):
    """The critic of r_hat alone as it starts: the critic's trunk (what it learned of the body's dynamics) with a
    zero output layer, so Q_h is 0 until the person's reward has been bootstrapped into it."""
    layers = dict(critic_params["params"])
    last = max(layers, key=lambda name: int(name.rsplit("_", 1)[1]))  # Dense_N: the output layer
    layers[last] = jax.tree.map(jnp.zeros_like, layers[last])
    trunk = jax.tree.map(lambda x: jnp.array(x, copy=True), {k: v for k, v in layers.items() if k != last})
    return {**critic_params, "params": {**trunk, last: layers[last]}}


def _strong(tree):
    """Drop weak types, so the state a chunk returns has exactly the types of the one it took (or the
    second call would compile again: wrappers may produce weakly-typed leaves such as a `where(.., 1.0, 0.0)`)."""
    return jax.tree.map(lambda x: x.astype(x.dtype) if isinstance(x, jax.Array) else x, tree)


def noisy_env_count(num_envs: int, noise) -> int:
    """How many envs act with exploration noise; the rest act with the deterministic actor."""
    return num_envs - int(round(noise.quiet_fraction * num_envs))


def noisy_envs_at(env_ids, iteration, num_envs: int, noise):
    """Which envs (global ids) act with noise at `iteration`: the first `noisy_env_count` ones, or with
    `noise.quiet_rotation_steps` N > 0 a quiet block that moves on by its own size every N steps."""
    noisy = noisy_env_count(num_envs, noise)
    if noise.quiet_rotation_steps <= 0 or noisy == num_envs:
        return env_ids < noisy
    shift = (iteration // noise.quiet_rotation_steps) * (num_envs - noisy)
    return (env_ids + shift) % num_envs < noisy


def resolve_devices(num_devices: int) -> list:
    """This process's devices (all of them for 0): under jax.distributed every process trains its own agents on
    its own devices (`jax.devices()` would name other processes' too)."""
    devices = jax.local_devices()
    if num_devices == 0:
        return devices
    if num_devices > len(devices):
        raise ConfigError(
            f"config field 'train.num_devices': asks for {num_devices} devices, only {len(devices)} present"
        )
    return devices[:num_devices]


def make_train(config, env, human_reward_fn: HumanRewardFn | None = None, devices: list | None = None,
               feedback_rows_fn: Callable | None = None) -> Trainer:
    """Build DDPG for `env` (one world, the env contract) from a config with `.ddpg` and `.train` sections.

    `human_reward_fn(human_params, obs, action) -> (B,)` adds `beta * r_hat` to the reward at sample time;
    its parameters are passed to `train_chunk` on every call (None when there is no model).
    `feedback_rows_fn(human_params, key, n, sign) -> (obs, action, weight)`: n rows of what the person praised
    (sign +1) or reproached (-1), for `ddpg.praise_imitation_coef` and `reproach_avoid_coef` (a live session's
    feedback ring: live/reward_model.py; None: neither).
    """
    dc, tc = config.ddpg, config.train
    devices = resolve_devices(tc.num_devices) if devices is None else devices
    n_dev = len(devices)
    for name, value in (("train.num_envs", tc.num_envs), ("ddpg.replay_size", dc.replay_size),
                        ("ddpg.batch_size", dc.batch_size)):
        if value % n_dev:
            raise ConfigError(f"config field '{name}': {value} is not divisible by the {n_dev} devices")
    local_envs, local_capacity, local_batch = tc.num_envs // n_dev, dc.replay_size // n_dev, dc.batch_size // n_dev
    if local_capacity < local_envs:
        raise ConfigError(f"config field 'ddpg.replay_size': {dc.replay_size} holds less than one step of every env")
    sharded = n_dev > 1
    axis = AXIS if sharded else None

    venv = wrap_for_training(env, tc.episode_length)
    obs_size, act_size = env.observation_size, env.action_size
    num_terms = len(env.reward_term_names)
    weights = jnp.asarray(env.reward_weights, jnp.float32)
    actor = Actor(action_size=act_size, hidden=tuple(dc.actor_hidden))
    critic = Critic(hidden=tuple(dc.critic_hidden))
    actor_opt = optax.adam(dc.actor_lr)
    critic_opt = optax.adam(dc.critic_lr)
    bias_coef = dc.human_actor_coef if human_reward_fn is not None else 0.0
    # action biasing on its own Adam: the person's term keeps its step size while actor_lr slows the intrinsic
    # reward's (DDPGConfig.human_actor_lr). Its state follows from the config alone, so that a saved run restores
    # from its config.yaml (a session without feedback carries it unused)
    human_opt = optax.adam(dc.human_actor_lr) if dc.human_actor_coef > 0 and dc.human_actor_lr > 0 else None
    has_human_critic = dc.human_critic_coef > 0  # its state (from the config alone)
    human_critic_coef = dc.human_critic_coef * (1.0 - dc.human_critic_gamma) if human_reward_fn is not None else 0.0
    has_rows = feedback_rows_fn is not None and human_reward_fn is not None
    imitation_coef = dc.praise_imitation_coef if has_rows else 0.0
    avoid_coef = dc.reproach_avoid_coef if has_rows else 0.0
    warmup_iterations = tc.warmup_iterations
    # The region mask rides beside the transitions for teacher rules, never into the replay (it would grow
    # every row for a signal the learner never reads).
    emit_regions = bool(getattr(env, "region_names", ()))

    def local_key(key):
        """Per-device randomness (env resets, noise, minibatches); the carried key stays replicated."""
        return jax.random.fold_in(key, jax.lax.axis_index(axis)) if sharded else key

    def pmean(x):
        return jax.lax.pmean(x, axis) if sharded else x

    def psum(x):
        return jax.lax.psum(x, axis) if sharded else x

    def init(rng: jax.Array) -> TrainState:
        k_actor, k_critic, k_env, k_stagger, k_run = jax.random.split(rng, 5)
        actor_params = actor.init(k_actor, jnp.zeros((obs_size,)))
        critic_params = critic.init(k_critic, jnp.zeros((obs_size,)), jnp.zeros((act_size,)))
        env_state = venv.reset(jax.random.split(local_key(k_env), local_envs))
        if tc.stagger_episodes and tc.num_envs > 1:
            # Start the envs' episode clocks at random points, so that the batch does not reset in lockstep
            # and the replay holds every phase of an episode at all times (the first episodes are shorter:
            # time-limit truncations, bootstrapped through).
            steps = env_state.info["steps"]
            offsets = jax.random.randint(local_key(k_stagger), steps.shape, 0, tc.episode_length)
            env_state = env_state.replace(info=dict(env_state.info, steps=offsets.astype(steps.dtype)))
        return _strong(TrainState(
            actor_params=actor_params,
            critic_params=critic_params,
            target_actor_params=actor_params,
            target_critic_params=critic_params,
            actor_opt_state=actor_opt.init(actor_params),
            critic_opt_state=critic_opt.init(critic_params),
            env_state=env_state,
            noise_state=noise.init(dc.noise, (local_envs, act_size)),
            replay=replay.init(local_capacity, obs_size, act_size, num_terms),
            rng=k_run,
            iteration=jnp.zeros((), jnp.int32),
            episode_return=jnp.zeros((local_envs,)),
            anchor_params=actor_params if dc.anchor_coef > 0 else None,
            anchor_weight=jnp.ones((), jnp.float32) if dc.anchor_coef > 0 else None,
            human_opt_state=human_opt.init(actor_params) if human_opt is not None else None,
            **(_fresh_human_critic(critic_params) if has_human_critic else {}),
        ))

    def _fresh_human_critic(critic_params) -> dict:
        params = human_critic_from(critic_params)
        return dict(human_critic_params=params, target_human_critic_params=human_critic_from(critic_params),
                    human_critic_opt_state=critic_opt.init(params))

    def _step_scale(iteration):
        """The step-size multiplier at `iteration` (`DDPGConfig.lr_final_fraction`, step_size.decay_scale)."""
        return decay_scale(iteration, tc.iterations, dc.lr_decay_from, dc.lr_final_fraction)

    def _update(lr: Learner, key, buffer: replay.ReplayBuffer, human_params, scale, anchor=None):
        """One DDPG update from a fresh minibatch: critic, then actor against the new critic, then targets."""
        batch = replay.sample(buffer, local_key(key), local_batch)
        reward = losses.relabel(batch, weights, dc.reward_alpha, dc.reward_beta, human_reward_fn, human_params)
        next_action = actor.apply(lr.target_actor_params, batch.next_obs)
        next_q = critic.apply(lr.target_critic_params, batch.next_obs, next_action)
        target_q = losses.td_target(reward, next_q, batch.terminal, dc.gamma)
        (c_loss, q_mean), c_grads = jax.value_and_grad(losses.critic_loss, has_aux=True)(
            lr.critic_params, critic.apply, batch, target_q)
        c_updates, critic_opt_state = critic_opt.update(pmean(c_grads), lr.critic_opt_state, lr.critic_params)
        critic_params = optax.apply_updates(lr.critic_params, jax.tree.map(lambda u: u * scale, c_updates))

        human_critic_params, human_critic_opt_state = lr.human_critic_params, lr.human_critic_opt_state
        if human_critic_coef > 0:  # Q_h's own TD step on r_hat alone, the same minibatch and target actor
            r_hat = jnp.reshape(human_reward_fn(human_params, batch.obs, batch.action), target_q.shape)
            next_qh = critic.apply(lr.target_human_critic_params, batch.next_obs, next_action)
            target_qh = losses.td_target(r_hat, next_qh, batch.terminal, dc.human_critic_gamma)
            (_, _), h_grads = jax.value_and_grad(losses.critic_loss, has_aux=True)(
                lr.human_critic_params, critic.apply, batch, target_qh)
            h_updates, human_critic_opt_state = critic_opt.update(pmean(h_grads), lr.human_critic_opt_state,
                                                                  lr.human_critic_params)
            human_critic_params = optax.apply_updates(lr.human_critic_params,
                                                      jax.tree.map(lambda u: u * scale, h_updates))

        bias = None
        if bias_coef > 0 or human_critic_coef > 0:
            bias = losses.HumanTerm(human_reward_fn, human_params, bias_coef, critic.apply, human_critic_params,
                                    human_critic_coef)
        if anchor is not None:  # (params, weight) of the state -> (params, coef) of the loss
            anchor = (anchor[0], dc.anchor_coef * anchor[1])
        imitate = avoid = None  # own streams: the minibatches stay those of a run without them
        if imitation_coef > 0:
            imitate = (*feedback_rows_fn(human_params, jax.random.fold_in(key, 0x1417), local_batch, 1.0),
                       imitation_coef)
        if avoid_coef > 0:
            avoid = (*feedback_rows_fn(human_params, jax.random.fold_in(key, 0x1418), local_batch, -1.0), avoid_coef)
        own = human_opt is not None and bias is not None
        a_loss, a_grads = jax.value_and_grad(losses.actor_loss)(
            lr.actor_params, actor.apply, critic_params, critic.apply, batch.obs, dc.actor_preact_coef,
            dc.actor_preact_free, None if own else bias, anchor, imitate, avoid)
        a_updates, actor_opt_state = actor_opt.update(pmean(a_grads), lr.actor_opt_state, lr.actor_params)
        human_opt_state = lr.human_opt_state
        if own:
            h_loss, h_grads = jax.value_and_grad(losses.human_actor_loss)(lr.actor_params, actor.apply, batch.obs,
                                                                          bias)
            h_updates, human_opt_state = human_opt.update(pmean(h_grads), lr.human_opt_state, lr.actor_params)
            a_updates = jax.tree.map(jnp.add, a_updates, h_updates)
            a_loss = a_loss + h_loss
        actor_params = optax.apply_updates(lr.actor_params, jax.tree.map(lambda u: u * scale, a_updates))

        new = Learner(
            actor_params=actor_params,
            critic_params=critic_params,
            target_actor_params=losses.soft_update(lr.target_actor_params, actor_params, dc.tau),
            target_critic_params=losses.soft_update(lr.target_critic_params, critic_params, dc.tau),
            actor_opt_state=actor_opt_state,
            critic_opt_state=critic_opt_state,
            human_opt_state=human_opt_state,
            human_critic_params=human_critic_params,
            target_human_critic_params=(losses.soft_update(lr.target_human_critic_params, human_critic_params, dc.tau)
                                        if human_critic_coef > 0 else lr.target_human_critic_params),
            human_critic_opt_state=human_critic_opt_state,
        )
        return new, jnp.stack([c_loss, a_loss, q_mean, jnp.mean(reward)])

    def _updates(lr: Learner, key, buffer, human_params, scale, anchor):
        def body(lr, k):
            return _update(lr, k, buffer, human_params, scale, anchor)
        # Unrolled (up to 4 updates a loop iteration, so a high update-to-data ratio stays cheap to compile): the
        # 5-seed Table II chunk with 2 updates a step ran 8% faster than as a loop of 2, in an interleaved A/B
        # (docs/environment.md, "Table II's wall time"); XLA then fuses across the updates, which changes rounding
        lr, stats = jax.lax.scan(body, lr, jax.random.split(key, tc.updates_per_step),
                                 unroll=min(tc.updates_per_step, 4))
        return lr, jnp.sum(stats, axis=0), jnp.float32(tc.updates_per_step)

    def _no_updates(lr: Learner, key, buffer, human_params, scale, anchor):
        return lr, jnp.zeros((4,)), jnp.float32(0.0)

    def _env_step(ts: TrainState, k_noise, k_random):
        """Act on every env (random during warm-up, else actor + noise), step, store the transitions."""
        obs = ts.env_state.obs
        noise_state = noise.step(dc.noise, ts.noise_state, local_key(k_noise))
        first = jax.lax.axis_index(axis) * local_envs if sharded else 0
        noisy = noisy_envs_at(first + jnp.arange(local_envs), ts.iteration, tc.num_envs, dc.noise)[:, None]
        # a live session's option (`noise_follows_hold`): as much noise as the person's words have let the hold go
        added = (1.0 - ts.anchor_weight) * noise_state if dc.noise_follows_hold else noise_state
        explore = jnp.clip(actor.apply(ts.actor_params, obs) + jnp.where(noisy, added, 0.0), -1.0, 1.0)
        uniform = jax.random.uniform(local_key(k_random), explore.shape, minval=-1.0, maxval=1.0)
        action = jnp.where(ts.iteration < warmup_iterations, uniform, explore)

        env_state = venv.step(ts.env_state, action)
        done = env_state.done
        terminal = done * (1.0 - env_state.info["truncation"])
        transition = replay.Transition(obs, action, env_state.metrics["reward_terms"],
                                       env_state.info["final_obs"], terminal)
        extras = {"region_mask": env_state.metrics["region_mask"]} if emit_regions else {}
        episode_return = ts.episode_return + env_state.reward
        stats = {
            "episodes": jnp.sum(done),
            "return_sum": jnp.sum(episode_return * done),
            "reward": jnp.sum(env_state.reward),
            "contact": jnp.sum(env_state.metrics.get("self_contact", jnp.zeros_like(done))),
            "reward_terms": jnp.sum(env_state.metrics["reward_terms"], axis=0),
        }
        ts = ts.replace(
            env_state=env_state,
            noise_state=noise.reset_done(dc.noise, noise_state, done),
            replay=replay.add(ts.replay, transition),
            episode_return=jnp.where(done > 0, 0.0, episode_return),
        )
        return ts, stats, (transition, extras)

    def _iteration(ts: TrainState, human_params):
        rng, k_noise, k_random, k_update = jax.random.split(ts.rng, 4)
        ts, stats, emitted = _env_step(ts, k_noise, k_random)
        if tc.updates_per_step > 0:
            learn = ts.iteration >= warmup_iterations
            lr, update_stats, n_updates = jax.lax.cond(
                learn, _updates, _no_updates, _learner(ts), k_update, ts.replay, human_params,
                _step_scale(ts.iteration), _anchor(ts))
            ts = _with_learner(ts, lr)
        else:
            update_stats, n_updates = jnp.zeros((4,)), jnp.float32(0.0)
        stats.update(update_stats=update_stats, updates=n_updates)
        return _strong(ts.replace(rng=rng, iteration=ts.iteration + 1)), (stats, emitted)

    def _collect_chunk(ts: TrainState, human_params):
        ts, (stats, (transitions, extras)) = jax.lax.scan(lambda t, _: _iteration(t, human_params), ts, None,
                                                          length=tc.chunk_steps)
        total = jax.tree.map(lambda x: psum(jnp.sum(x, axis=0)), stats)
        env_steps = tc.chunk_steps * tc.num_envs
        updates = jnp.maximum(total["updates"] / (n_dev if sharded else 1), 1.0)
        u = total["update_stats"] / (n_dev if sharded else 1)
        has_updates = total["updates"] > 0
        nan = jnp.float32(jnp.nan)
        metrics = {
            "env_steps": ts.iteration * tc.num_envs,
            "episodes": total["episodes"],
            "episode_return": jnp.where(total["episodes"] > 0,
                                        total["return_sum"] / jnp.maximum(total["episodes"], 1), nan),
            "step_reward": total["reward"] / env_steps,
            "contact_rate": total["contact"] / env_steps,
            "reward_terms": total["reward_terms"] / env_steps,
            "critic_loss": jnp.where(has_updates, u[0] / updates, nan),
            "actor_loss": jnp.where(has_updates, u[1] / updates, nan),
            "q_mean": jnp.where(has_updates, u[2] / updates, nan),
            "sampled_reward": jnp.where(has_updates, u[3] / updates, nan),
        }
        return ts, metrics, transitions, extras

    def _chunk(ts: TrainState, human_params):
        ts, metrics, _, _ = _collect_chunk(ts, human_params)
        return ts, metrics

    def _extra_updates(ts: TrainState, human_params, n):
        """`n` more updates from the replay (a traced count: any n, one compile), beside the chunk's: a live
        session spends the time a chunk is shown on them (docs/human_feedback.md, "How a session learns")."""
        def body(_, carry):
            lr, rng = carry
            rng, k = jax.random.split(rng)
            lr, _ = _update(lr, k, ts.replay, human_params, _step_scale(ts.iteration), _anchor(ts))
            return lr, rng

        lr, rng = jax.lax.fori_loop(0, n, body, (_learner(ts), ts.rng))
        return _strong(_with_learner(ts, lr).replace(rng=rng))

    def act(actor_params, obs):
        return actor.apply(actor_params, obs)

    if not sharded:
        def train(rng, human_params=None):
            ts = init(rng)
            return jax.lax.scan(lambda t, _: _chunk(t, human_params), ts, None, length=tc.num_chunks)

        return Trainer(init=jax.jit(init), train_chunk=jax.jit(_chunk, donate_argnums=0),
                       collect_chunk=jax.jit(_collect_chunk, donate_argnums=0), chunk_body=_collect_chunk,
                       train=train, act=jax.jit(act), env=venv, mesh=None, state_sharding=None, num_devices=1,
                       state_specs=None, extra_updates=jax.jit(_extra_updates, donate_argnums=0))

    mesh = Mesh(np.array(devices), (AXIS,))
    specs = _state_specs()
    sharded_init = jax.jit(jax.shard_map(init, mesh=mesh, in_specs=P(), out_specs=specs, check_vma=False))
    sharded_chunk = jax.jit(
        jax.shard_map(_chunk, mesh=mesh, in_specs=(specs, P()), out_specs=(specs, P()), check_vma=False),
        donate_argnums=0,
    )
    sharded_collect = jax.jit(
        jax.shard_map(_collect_chunk, mesh=mesh, in_specs=(specs, P()),
                      out_specs=(specs, P(), P(None, AXIS), P(None, AXIS)), check_vma=False),
        donate_argnums=0,
    )
    abstract = jax.eval_shape(sharded_init, jax.random.PRNGKey(0))
    state_sharding = jax.tree.map(
        lambda spec, sub: jax.tree.map(lambda _: NamedSharding(mesh, spec), sub),
        specs, abstract, is_leaf=lambda x: isinstance(x, P))
    return Trainer(init=sharded_init, train_chunk=sharded_chunk, collect_chunk=sharded_collect,
                   chunk_body=_collect_chunk, train=None, act=jax.jit(act), env=venv, mesh=mesh,
                   state_sharding=state_sharding, num_devices=n_dev, state_specs=specs)


def _state_specs() -> TrainState:
    """Partition specs as a prefix of TrainState: per-env and per-row arrays split, the rest replicated."""
    split = P(AXIS)
    return TrainState(
        actor_params=P(), critic_params=P(), target_actor_params=P(), target_critic_params=P(),
        actor_opt_state=P(), critic_opt_state=P(),
        env_state=split, noise_state=split,
        replay=replay.ReplayBuffer(data=split, ptr=P(), size=P()),
        rng=P(), iteration=P(), episode_return=split, anchor_params=P(), anchor_weight=P(), human_opt_state=P(),
        human_critic_params=P(), target_human_critic_params=P(), human_critic_opt_state=P(),
    )
