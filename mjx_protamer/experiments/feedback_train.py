"""DDPG + DeepTAMER with simulated teachers, all inside one jit per chunk (no host round-trip per step).

`make_feedback_train(config, env, feedback, batched)` wraps the DDPG trainer's chunk:

1. the DDPG chunk (`chunk_steps` vectorised steps under `lax.scan`, `Trainer.chunk_body`) with the human
   reward `gain * r_hat(params, s, a)` relabelled at sample time (`gain` 0 is DDPG alone, bit for bit the same
   reward; the reward-model params are an argument: no recompile when they change). Its scan emits the
   chunk's transitions, (T, B, ...) in stepping order, and beside them the region mask of each step; the
   teacher signals are read from those steps (`teachers.rule_signals`: reward terms by name, `obs:i`,
   `action:i`, `obs_norm:...`, `region:NAME`, `regions_touched`);
2. one simulated teacher per env (`teachers.batched_teacher`, on the same core as the host teacher) scores the
   steps; feedback reaches the learner at arrival step = judged step + (reaction delay + utterance +
   processing latency) / dt, through a pending ring;
3. credit by lag from the arrival step (`credit.lag_weights`: by default the channel's reaction-delay
   distribution; the authors' 15-step window and Deep TAMER's Uniform[0.2, 4.0] s stay selectable): for
   each event `rows_per_event` lags are drawn in proportion to their credit weight (a Monte-Carlo estimate of
   the weighted loss: a time window spans 760 steps at 200 Hz, `batched.draw_credited_steps`). A window
   reaches back into earlier chunks: the (obs, action) of the last H = lag_len - 1 steps of every env are
   carried in `FeedbackState.history` (H, B, ...), so a credited step is read from the history or from the
   chunk's own transitions, never from the DDPG replay;
   Steps whose credit window closed with no arrival (the teacher watched in silence) are drawn too
   (`batched.draw_silent_steps`, `silence_rows_per_chunk` rows) as target 0, each silent step weighing
   `credit.silence_weight` events; the arrivals of the last H steps are carried for that (and, with
   `credit.silence_needs_attention`, whether the teacher watched them: only steps it watched are silent);
4. the rows go to the device feedback ring (1e4 rows, `batched.ring_add`) and the reward model takes
   `updates_per_feedback` minibatch steps on the chunk's new rows plus `chunk_steps // replay_every`
   replay minibatches (weighted squared loss, Adam, `batched.reward_model_updates`).

With a silent teacher (`teach` 0: DDPG alone), steps 3 and 4 are skipped (`lax.cond` on a value every seed
shares, so vmapped seeds skip it too): no row would have weight and no update would be live, so every output
is the same (the trace's credited rows are zeros instead of weight-0 draws; a silent condition starts from
`init`, whose ring is empty, so no replay update is lost), and DDPG's condition of Table II costs about what
plain DDPG costs (measured in docs/environment.md, "Table II's wall time").

`collect_chunk` is the same chunk with a `ChunkTrace` beside its outputs: the steps the teacher judged, the
rule's signals, the teacher's output per step and the rows written to the feedback ring (the DDPG chunk's
`collect_chunk` and its transitions, one level up). `chunk` is `collect_chunk` with the trace dropped: the
trace holds values the chunk computes anyway, so `chunk` is the same program, and nobody pays for the trace
unless they ask (a diagnostic reads it through the runner's progress callback, `runner.ChunkInfo.extra`).

Devices: the feedback chunk runs on the DDPG trainer's mesh, inside one `shard_map` over the env axis
("data"). Per env (split over devices): the env batch, its teacher and pending ring, the credit history.
Replicated: the reward model, its optimiser and feedback ring. Each device draws its own events' credited
rows; the rows are all-gathered, and every device then makes the same reward-model updates on the same rows
with the same key, so the replicas stay equal without any gradient averaging (the reward model is small:
redundant updates cost less than a second protocol). `max_events_per_chunk` is per device. On one device
there is no gather and the program is the single-device one.

The channel (keyboard / prosody / speech), the credit weights and the gain are *values*
(`FeedbackParams`), so the four conditions of Table II, and every `--feedback simulated:KIND`, share one
compiled program. Random numbers of the feedback path come from their own key: DDPG's random stream is the
same with and without feedback, so conditions with the same seed start from the same networks, envs and
noise.
"""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import struct
from jax.sharding import PartitionSpec as P

from mjx_protamer.config import ConfigError
from mjx_protamer.human.batched import (FeedbackRing, draw_credited_steps, draw_silent_steps, reward_model_updates,
                                        ring_add, ring_init)
from mjx_protamer.human.credit import CreditConfig, lag_weights, posterior_weights
from mjx_protamer.human.feedback_config import BatchedFeedbackConfig
from mjx_protamer.human.reward_model import reward_nets
from mjx_protamer.human.teachers import (BatchedTeacherState, TeacherConfig, batched_teacher, batched_teacher_init,
                                         env_signal_columns, rule_signals, with_channel)
from mjx_protamer.step_size import decay_scale

KINDS = ("keyboard", "prosody", "speech")


def human_reward(apply):
    """r_hat gated by a gain: `human_params = {"params": ..., "gain": scalar}`. Gain 0 (DDPG alone) skips the
    model: a branch, where the gain is one value for every vmapped seed (Table II's conditions), so DDPG's
    condition does not run the reward model on every minibatch to multiply it by 0 (5% of its chunk)."""

    def fn(hp, obs, action):
        return jax.lax.cond(hp["gain"] != 0, lambda: hp["gain"] * apply(hp["params"], obs, action),
                            lambda: jnp.zeros(obs.shape[:-1]))

    return fn


class FeedbackParams(NamedTuple):
    """Per-condition values (no recompile between conditions)."""
    kind: jax.Array  # int32 index into KINDS
    teach: jax.Array  # float 1/0: the teacher speaks
    gain: jax.Array  # float: multiplies r_hat in the DDPG reward (0 = DDPG alone)
    lag_w: jax.Array  # (L,) credit weight of lag j from the arrival step
    silence_w: jax.Array  # float: weight of a silent step's 0 label, in events (0: events alone)


class CreditHistory(NamedTuple):
    """The (obs, action) of every env's last H steps, oldest first: what credit windows reaching back past the
    chunk's first step read. H = the longest compiled credit window less one (`FeedbackTrainer.history_len`)."""
    obs: jax.Array  # (H, B, obs)
    action: jax.Array  # (H, B, act)
    arrived: jax.Array  # (H, B) bool: feedback reached the learner at that step (for the silent steps)
    watching: jax.Array  # (H, B) bool: the teacher watched that step (`credit.silence_needs_attention`)


@struct.dataclass
class FeedbackState:
    teacher: BatchedTeacherState  # one teacher per env and its pending ring of feedback not yet arrived
    rm_params: Any
    rm_opt_state: Any
    ring: FeedbackRing
    rng: jax.Array
    totals: jax.Array  # (5,) float: events, positive, negative, credited rows, reward-model updates
    history: CreditHistory


class CreditedRows(NamedTuple):
    """Rows of the feedback ring's shape: each event's credited steps, then the silent steps, gathered over the
    devices in device order; `batched.ring_add` keeps those of weight > 0."""
    obs: jax.Array  # (R, obs)
    action: jax.Array  # (R, act)
    weight: jax.Array  # (R,)
    target: jax.Array  # (R,) the event's value; 0 for a silent step


class ChunkTrace(NamedTuple):
    """What a feedback chunk did (`FeedbackTrainer.collect_chunk`), per step and env in stepping order."""
    obs: jax.Array  # (T, B, obs) the steps the teacher judged (the chunk's transitions)
    action: jax.Array  # (T, B, act)
    signals: jax.Array  # (T, B, C) the teacher rule's signals (`teachers.rule_signals`)
    teacher: dict  # (T, B) each: value, valid (feedback arrived), about (the step judged), score, watching
    credited: CreditedRows  # the rows the chunk handed to the feedback ring


TOTAL_NAMES = ("feedback_total", "feedback_pos_total", "feedback_neg_total", "credited_rows_total", "rm_updates_total")


class FeedbackTrainer(NamedTuple):
    trainer: Any  # the DDPG Trainer (human_reward_fn = gated r_hat)
    init: Any  # (seed) -> FeedbackState
    chunk: Any  # jitted (train_state, feedback_state, FeedbackParams) -> (ts, fs, metrics, events)
    collect_chunk: Any  # jitted: the same and its ChunkTrace, (ts, fs, metrics, events, trace)
    params: Any  # (kind | None, CreditConfig) -> FeedbackParams
    lag_len: int
    max_events: int
    apply: Any  # r_hat(params, obs, action)
    chunk_fn: Any  # `chunk` before jit (shard_mapped over the mesh when sharded), to vmap over seeds
    signals: Any  # (obs, action, reward_terms, region_mask) (..., dims) -> (..., C) the teacher rule's signals
    history_len: int  # H: steps of (obs, action) per env carried for credit into earlier chunks


def make_feedback_train(config, env, feedback, batched: BatchedFeedbackConfig | None = None) -> FeedbackTrainer:
    """`config` a PretrainConfig, `feedback` a FeedbackConfig (teacher rule, reward model, credit, dt)."""
    from mjx_protamer.agents.ddpg.train import AXIS, make_train, noisy_env_count

    batched = batched or BatchedFeedbackConfig()
    tc, fc = config.train, feedback
    B, T = tc.num_envs, tc.chunk_steps
    rmc = fc.reward_model
    nets = reward_nets(rmc)
    trainer = make_train(config, env, human_reward_fn=human_reward(nets.apply))
    n_dev = trainer.num_devices
    sharded = trainer.mesh is not None
    local_B = B // n_dev
    apply, net = nets.apply, nets.net
    opt = optax.adam(rmc.learning_rate)
    obs_size, act_size = env.observation_size, env.action_size
    cols = env_signal_columns(fc.teacher.signals, env)
    dt = fc.dt
    kind_cfgs = [with_channel(fc.teacher, k) for k in KINDS]
    L = max(len(lag_weights(dataclasses.replace(fc.credit, scheme=s), dt, c.channel))
            for s in ("channel", "step_window", "time_window") for c in kind_cfgs)
    H = max(L - 1, 1)  # lag j <= L - 1 from an arrival at the chunk's first step reaches L - 1 steps back
    teach_envs = batched.teach_envs or B
    if teach_envs > B:
        raise ConfigError(f"config field 'batched.teach_envs': {teach_envs} > train.num_envs ({B})")
    first_taught = 0  # envs first_taught .. first_taught + teach_envs - 1 have a teacher
    if batched.teach_quiet:
        noisy = noisy_env_count(B, config.ddpg.noise)
        if noisy == B:
            raise ConfigError("config field 'batched.teach_quiet': no env acts without noise; set "
                              "pretrain.ddpg.noise.quiet_fraction > 0 (e.g. 0.25) or teach_quiet false")
        if config.ddpg.noise.quiet_rotation_steps:
            raise ConfigError("config field 'batched.teach_quiet': the quiet envs rotate "
                              "(pretrain.ddpg.noise.quiet_rotation_steps > 0); set it to 0 or teach_quiet false")
        first_taught, teach_envs = noisy, B - noisy
    E = batched.max_events_per_chunk or min(512, teach_envs * -(-T // max(fc.teacher.min_gap_steps, 1)))
    K = batched.rows_per_event
    n_replay = (T // rmc.replay_every if rmc.replay_every else 0) if batched.replay_updates_per_chunk < 0 \
        else batched.replay_updates_per_chunk
    S = batched.silence_rows_per_chunk
    attention = fc.credit.silence_needs_attention  # the teacher's attention gates the silent steps
    if fc.credit.silence_weight > 0 and S == 0:
        raise ConfigError("config field 'batched.silence_rows_per_chunk': 0 draws no silent step, and "
                          f"feedback.credit.silence_weight is {fc.credit.silence_weight}; set rows > 0 or the weight 0")
    n_fresh = rmc.updates_per_feedback * -(-E // 3) if batched.fresh_updates_per_chunk < 0 \
        else batched.fresh_updates_per_chunk

    def params_for(kind: str | None, credit: CreditConfig) -> FeedbackParams:
        w = np.zeros((L,), np.float32)
        if kind is not None:
            lw = lag_weights(credit, dt, with_channel(fc.teacher, kind).channel)
            if len(lw) > L:
                raise ConfigError(f"credit window of {len(lw)} steps exceeds the compiled {L}")
            w[:len(lw)] = lw
        return FeedbackParams(kind=jnp.int32(KINDS.index(kind) if kind else 0),
                              teach=jnp.float32(kind is not None), gain=jnp.float32(kind is not None),
                              lag_w=jnp.asarray(w),
                              silence_w=jnp.float32(credit.silence_weight if kind is not None else 0.0))

    def init(seed) -> FeedbackState:
        key = jax.random.fold_in(jax.random.PRNGKey(seed), 0x7A3E)
        k_net, k_run = jax.random.split(key)
        p = net.init(k_net, jnp.zeros((1, obs_size)), jnp.zeros((1, act_size)))
        return FeedbackState(
            teacher=batched_teacher_init(kind_cfgs, B, dt), rm_params=p, rm_opt_state=opt.init(p),
            ring=ring_init(rmc.buffer_size, obs_size, act_size), rng=k_run, totals=jnp.zeros((5,)),
            history=CreditHistory(jnp.zeros((H, B, obs_size)), jnp.zeros((H, B, act_size)), jnp.zeros((H, B), bool),
                                  jnp.zeros((H, B), bool)))

    # Per-env work runs on each device's envs; these join the devices where the replicated parts need all.
    def local_key(key):
        return jax.random.fold_in(key, jax.lax.axis_index(AXIS)) if sharded else key

    def psum(x):
        return jax.lax.psum(x, AXIS) if sharded else x

    def gather(x, axis=0):  # the devices' pieces, concatenated in device (= global env) order
        return jax.lax.all_gather(x, AXIS, axis=axis, tiled=True) if sharded else x

    def collect(ts, fs: FeedbackState, fp: FeedbackParams):
        it0 = ts.iteration
        hp = {"params": fs.rm_params, "gain": fp.gain}
        ts, metrics, steps, extras = trainer.chunk_body(ts, hp)
        obs, action, terms = steps.obs, steps.action, steps.reward_terms  # (T, local_B, ...)
        signals = rule_signals(cols, obs, action, terms, extras.get("region_mask"))
        rng, k_teach, k_lag, k_fresh = jax.random.split(fs.rng, 4)
        env_ids = (jax.lax.axis_index(AXIS) * local_B if sharded else 0) + jnp.arange(local_B)
        active = (fp.teach > 0) & (env_ids >= first_taught) & (env_ids < first_taught + teach_envs)
        teacher, out = batched_teacher(kind_cfgs, dt, fs.teacher, signals, local_key(k_teach), kind=fp.kind,
                                       active=active)
        value, valid, about, score = out["value"], out["valid"], out["about"], out["score"]

        seen_obs = jnp.concatenate([fs.history.obs, obs])  # (H + T, local_B, ...): step rel is row H + rel
        seen_act = jnp.concatenate([fs.history.action, action])
        seen_arrived = jnp.concatenate([fs.history.arrived, valid])
        seen_watching = jnp.concatenate([fs.history.watching, out["watching"]])

        def learn(_):
            # credit: K lags per event drawn by weight; (obs, action) from the history (earlier chunks) or the chunk
            rel, b_idx, ok, target, n_events = draw_credited_steps(value, valid, fp.lag_w, local_key(k_lag), E, K)
            ok = ok & (it0 + rel >= 0)  # no step before the run's first
            c_obs = seen_obs[H + rel, b_idx[:, None]].reshape(E * K, obs_size)
            c_act = seen_act[H + rel, b_idx[:, None]].reshape(E * K, act_size)
            w = ok.astype(jnp.float32)
            if fc.credit.posterior_temperature > 0:  # the model's agreement moves each event's weight among its rows
                w = posterior_weights(jnp, w, target, apply(fs.rm_params, c_obs, c_act).reshape(E, K),
                                      fc.credit.posterior_temperature)
            w = w.reshape(-1)
            h = target.reshape(-1)
            if S:  # silent steps, labelled 0 (their own key: the event draws are the same with and without)
                k_silent = jax.random.fold_in(local_key(k_lag), 1)
                s_rel, s_b, s_ok, n_silent = draw_silent_steps(seen_arrived, active, fp.lag_w, k_silent, H, S,
                                                               seen_watching if attention else None)
                s_ok = s_ok & (it0 + s_rel >= 0)
                # a silent step weighs silence_w events; an event's K rows weigh 1 each, a row stands for n_silent / S
                s_w = s_ok * fp.silence_w * K * n_silent / S
                c_obs = jnp.concatenate([c_obs, seen_obs[H + s_rel, s_b]])
                c_act = jnp.concatenate([c_act, seen_act[H + s_rel, s_b]])
                w = jnp.concatenate([w, s_w])  # rows of weight 0 never enter the ring
                h = jnp.concatenate([h, jnp.zeros((S,))])
            rows = CreditedRows(gather(c_obs), gather(c_act), gather(w), gather(h))
            ring = ring_add(fs.ring, *rows)
            p, o, losses, live = reward_model_updates(nets.fit, opt, fs.rm_params, fs.rm_opt_state, ring, rows,
                                                      k_fresh, n_fresh, n_replay, rmc.batch_size,
                                                      rmc.replay_min_rows,
                                                      rmc.balance_max if rmc.balance_signs else None,
                                                      decay_scale(it0, tc.iterations, rmc.lr_decay_from,
                                                                  rmc.lr_final_fraction))
            return rows, ring, p, o, losses, live, psum(jnp.sum(ok))

        def silent_teacher(_):
            # DDPG alone (teach 0): no event and no silent step has weight, so nothing enters the ring and no
            # update of the reward model is live; skipping that work leaves every output the same, and the
            # reward model untouched (the ring holds no row: a condition starts from `init`)
            n, r = max(n_fresh + n_replay, 1), n_dev * (E * K + S)
            rows = CreditedRows(jnp.zeros((r, obs_size)), jnp.zeros((r, act_size)), jnp.zeros((r,)), jnp.zeros((r,)))
            return rows, fs.ring, fs.rm_params, fs.rm_opt_state, jnp.zeros((n,)), jnp.zeros((n,), bool), jnp.int32(0)

        n_events = jnp.sum(valid)  # as `draw_credited_steps` counts and orders them
        t_idx, b_idx = jnp.nonzero(valid, size=E, fill_value=0)
        credited_rows, ring, p, o, losses, live, credited = jax.lax.cond(fp.teach > 0, learn, silent_teacher, None)
        n_live = jnp.sum(live)

        # diagnostics: r_hat on the chunk's steps (all envs), and how it tracks the hidden score
        rh = gather(apply(p, obs.reshape(-1, obs_size), action.reshape(-1, act_size)).reshape(T, local_B),
                    axis=1).reshape(-1)
        sc = gather(score, axis=1).reshape(-1)
        rc, scc = rh - rh.mean(), sc - sc.mean()
        corr = jnp.sum(rc * scc) / jnp.maximum(jnp.sqrt(jnp.sum(rc ** 2) * jnp.sum(scc ** 2)), 1e-12)
        used = psum(jnp.minimum(n_events, E))
        pos = psum(jnp.sum(valid & (value > 0)))
        neg = psum(jnp.sum(valid & (value < 0)))
        n_all = psum(n_events)
        totals = fs.totals + jnp.stack([used, pos, neg, credited, n_live]).astype(jnp.float32)
        nan = jnp.float32(jnp.nan)
        metrics = dict(metrics)
        metrics.update(
            feedback_events=n_all.astype(jnp.float32), feedback_pos=pos.astype(jnp.float32),
            feedback_neg=neg.astype(jnp.float32), feedback_dropped=(n_all - used).astype(jnp.float32),
            credited_rows=credited, rm_updates=n_live.astype(jnp.float32),
            rm_loss=jnp.where(n_live > 0, jnp.sum(jnp.where(live, losses, 0.0)) / jnp.maximum(n_live, 1), nan),
            r_hat_mean=rh.mean(), r_hat_std=rh.std(), r_hat_score_corr=corr,
            score_mean=sc.mean(), ring_size=ring.size.astype(jnp.float32),
            **{k: totals[i] for i, k in enumerate(TOTAL_NAMES)})
        present = jnp.arange(E) < n_events
        events = {"present": present, "arrival": it0 + t_idx,
                  "env": env_ids[b_idx], "value": value[t_idx, b_idx], "about": about[t_idx, b_idx]}
        history = CreditHistory(seen_obs[-H:], seen_act[-H:], seen_arrived[-H:], seen_watching[-H:])
        fs = fs.replace(teacher=teacher, rm_params=p, rm_opt_state=o, ring=ring, rng=rng, totals=totals,
                        history=history)
        trace = ChunkTrace(obs, action, signals, out, credited_rows)
        return ts, fs, metrics, events, trace

    def chunk(ts, fs: FeedbackState, fp: FeedbackParams):
        ts, fs, metrics, events, _ = collect(ts, fs, fp)
        return ts, fs, metrics, events

    if sharded:
        split = P(AXIS)
        fs_specs = FeedbackState(
            teacher=BatchedTeacherState(teacher=split, pending_value=split, pending_valid=split,
                                        pending_about=split, step=P()),
            rm_params=P(), rm_opt_state=P(), ring=P(), rng=P(), totals=P(),
            history=CreditHistory(P(None, AXIS), P(None, AXIS), P(None, AXIS), P(None, AXIS)))
        per_env = P(None, AXIS)  # (T, B, ...)
        trace_specs = ChunkTrace(per_env, per_env, per_env, per_env, P())
        in_specs = (trainer.state_specs, fs_specs, P())
        chunk_fn = jax.shard_map(chunk, mesh=trainer.mesh, in_specs=in_specs,
                                 out_specs=(trainer.state_specs, fs_specs, P(), split), check_vma=False)
        collect_fn = jax.shard_map(collect, mesh=trainer.mesh, in_specs=in_specs,
                                   out_specs=(trainer.state_specs, fs_specs, P(), split, trace_specs),
                                   check_vma=False)
    else:
        chunk_fn, collect_fn = chunk, collect
    return FeedbackTrainer(trainer=trainer, init=init, chunk=jax.jit(chunk_fn, donate_argnums=(0, 1)),
                           collect_chunk=jax.jit(collect_fn, donate_argnums=(0, 1)), params=params_for,
                           lag_len=L, max_events=E, apply=apply, chunk_fn=chunk_fn,
                           signals=lambda o, a, t, r: rule_signals(cols, o, a, t, r), history_len=H)


def log_events(log, events: dict, kind: str, feedback, dt: float) -> int:
    """Write a chunk's events (host arrays from `chunk`) to a FeedbackLog; returns how many.

    Times are on the run's virtual clock (global step x dt); `t_start` is the onset of the key press or
    utterance (arrival minus utterance length and processing latency)."""
    from mjx_protamer.human.events import FeedbackEvent

    ch = with_channel(feedback.teacher, kind).channel
    duration, latency = ch.get("duration_s"), ch.get("latency_s")
    n = 0
    for ok, arrival, env_i, value, about in zip(events["present"], events["arrival"], events["env"],
                                                events["value"], events["about"]):
        if not ok:
            continue
        t_arrival = float(arrival) * dt
        t0 = max(0.0, t_arrival - latency - duration)
        event = FeedbackEvent(t0, t0 + duration, "simulated", float(np.clip(value, -1.0, 1.0)),
                              {"channel": kind, "env": int(env_i), "about_step": int(about),
                               "arrival_step": int(arrival), "latency": latency})
        log.accepted(event, step=int(arrival))
        n += 1
    return n


def parse_feedback(spec: str) -> str:
    """'simulated:keyboard' -> 'keyboard' (the kinds the in-jit teacher simulates)."""
    if not spec.startswith("simulated:") or spec.split(":", 1)[1] not in KINDS:
        raise ConfigError(f"--feedback {spec!r}: pretrain takes simulated:keyboard, simulated:prosody or "
                          "simulated:speech (live keyboard feedback is `protamer finetune --feedback keyboard`)")
    return spec.split(":", 1)[1]


def step_window_note(kind: str, credit, dt: float) -> str | None:
    if credit.scheme == "step_window" and credit.window_steps * dt < 0.2:
        return (f"note: step_window credit covers {credit.window_steps * dt * 1000:.0f} ms before the arrival "
                f"step, less than the simulated {kind} reaction delay; time_window credits the judged steps")
    return None

