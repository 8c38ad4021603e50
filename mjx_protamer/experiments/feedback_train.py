"""DDPG + DeepTAMER with simulated teachers, all inside one jit per chunk (no host round-trip per step).

`make_feedback_train(config, env, feedback, batched)` wraps the DDPG trainer's chunk:

1. the DDPG chunk (`chunk_steps` vectorised steps under `lax.scan`) with the human reward
   `gain * r_hat(params, s, a)` relabelled at sample time (`gain` 0 is DDPG alone, bit for bit the same
   reward; the reward-model params are an argument: no recompile when they change);
2. the chunk's steps of every env are read back from the replay rows it wrote
   (row `ptr + i * num_envs + b` for iteration i, env b); the teacher signals are reward terms by name
   (or `obs:i` / `action:i`);
3. one simulated teacher per env (`teachers.teacher_step`, the same core as the host teacher) scores the
   steps; feedback reaches the learner at arrival step = judged step + (reaction delay + utterance +
   processing latency) / dt, through a pending ring;
4. credit by lag from the arrival step (`credit.lag_weights`: the authors' 15-step window or Deep TAMER's
   Uniform[0.2, 4.0] s time window): for each event `rows_per_event` lags are drawn in proportion to their
   credit weight (a Monte-Carlo estimate of the weighted loss: a time window spans 760 steps at 200 Hz) and
   the (obs, action) of those steps are gathered *from the DDPG replay*, so windows reaching into earlier
   chunks are credited too (up to replay capacity / num_envs steps back);
5. the rows go to the device feedback ring (1e4 rows, `batched.ring_add`) and the reward model takes
   `updates_per_feedback` minibatch steps on the chunk's new rows plus `chunk_steps // replay_every`
   replay minibatches (weighted squared loss, Adam).

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

from mjx_protamer.config import ConfigError, check
from mjx_protamer.human.batched import FeedbackRing, ring_add, ring_init
from mjx_protamer.human.credit import CreditConfig, lag_weights
from mjx_protamer.human.reward_model import RewardMLP, reward_fn, weighted_loss
from mjx_protamer.human.teachers import (TeacherConfig, TeacherState, max_delay_steps, obs_norm_indices, teacher_init,
                                         teacher_step, with_channel)

KINDS = ("keyboard", "prosody", "speech")


@dataclasses.dataclass(frozen=True)
class BatchedFeedbackConfig:
    """How the in-jit feedback path is sized (the `batched` section of a feedback or table2 config)."""

    teach_envs: int = 0  # envs that have a teacher (the first n); 0 = every env
    max_events_per_chunk: int = 0  # events credited per chunk (static shape); 0 = auto from num_envs and min gap
    rows_per_event: int = 32  # credited steps drawn per event, in proportion to their credit weight
    replay_updates_per_chunk: int = -1  # reward-model replay minibatches per chunk; -1 = chunk_steps // replay_every
    # minibatches on the chunk's newly credited rows; -1 = updates_per_feedback x ceil(max events / 3), about one
    # per event given (Deep TAMER updates on every feedback)
    fresh_updates_per_chunk: int = -1

    def validate(self) -> None:
        check(self.teach_envs >= 0, "teach_envs", f"must be >= 0, got {self.teach_envs}")
        check(self.max_events_per_chunk >= 0, "max_events_per_chunk", f"must be >= 0, got {self.max_events_per_chunk}")
        check(self.rows_per_event >= 1, "rows_per_event", f"must be >= 1, got {self.rows_per_event}")
        check(self.fresh_updates_per_chunk >= -1, "fresh_updates_per_chunk",
              f"must be >= -1, got {self.fresh_updates_per_chunk}")
        check(self.replay_updates_per_chunk >= -1, "replay_updates_per_chunk",
              f"must be >= -1, got {self.replay_updates_per_chunk}")


def human_reward(hidden):
    """r_hat gated by a gain: `human_params = {"params": ..., "gain": scalar}`."""
    apply = reward_fn(tuple(hidden))

    def fn(hp, obs, action):
        return hp["gain"] * apply(hp["params"], obs, action)

    return fn


class FeedbackParams(NamedTuple):
    """Per-condition values (no recompile between conditions)."""
    kind: jax.Array  # int32 index into KINDS
    teach: jax.Array  # float 1/0: the teacher speaks
    gain: jax.Array  # float: multiplies r_hat in the DDPG reward (0 = DDPG alone)
    lag_w: jax.Array  # (L,) credit weight of lag j from the arrival step


@struct.dataclass
class FeedbackState:
    teacher: TeacherState  # (B, ...)
    pending_value: jax.Array  # (B, D)
    pending_valid: jax.Array  # (B, D) bool
    pending_about: jax.Array  # (B, D) int32: global step judged
    rm_params: Any
    rm_opt_state: Any
    ring: FeedbackRing
    rng: jax.Array
    totals: jax.Array  # (5,) float: events, positive, negative, credited rows, reward-model updates


TOTAL_NAMES = ("feedback_total", "feedback_pos_total", "feedback_neg_total", "credited_rows_total", "rm_updates_total")


class FeedbackTrainer(NamedTuple):
    trainer: Any  # the DDPG Trainer (human_reward_fn = gated r_hat)
    init: Any  # (seed) -> FeedbackState
    chunk: Any  # jitted (train_state, feedback_state, FeedbackParams) -> (ts, fs, metrics, events)
    params: Any  # (kind | None, CreditConfig) -> FeedbackParams
    lag_len: int
    max_events: int
    apply: Any  # r_hat(params, obs, action)
    chunk_fn: Any  # `chunk` before jit, to vmap over seeds
    signals: Any  # (obs, action, reward_terms) (..., dims) -> (..., C) the teacher rule's signals


def _signal_columns(names, term_names, obs_size, act_size):
    cols = []
    for name in names:
        if name in term_names:
            cols.append(("terms", term_names.index(name)))
        elif name.startswith("obs_norm:"):  # L2 norm over obs slices, e.g. obs_norm:64:68,70:74 (arm speed)
            cols.append(("obs_norm", obs_norm_indices(name, obs_size)))
        elif name.startswith("obs:") and 0 <= int(name[4:]) < obs_size:
            cols.append(("obs", int(name[4:])))
        elif name.startswith("action:") and 0 <= int(name[7:]) < act_size:
            cols.append(("action", int(name[7:])))
        else:
            raise ConfigError(f"config field 'feedback.teacher.rule': signal {name!r} is not a reward term "
                              f"({', '.join(term_names)}), obs:i, obs_norm:a:b[,c:d] or action:i "
                              "(the in-jit teacher reads these)")
    return tuple(cols)


def rule_signals(cols, obs, action, terms):
    """The teacher rule's signal columns (`_signal_columns`) from per-step obs, action and reward terms."""
    src = {"terms": terms, "obs": obs, "action": action}
    return jnp.stack([jnp.linalg.norm(obs[..., jnp.asarray(i)], axis=-1) if s == "obs_norm" else src[s][..., i]
                      for s, i in cols], axis=-1)


def make_feedback_train(config, env, feedback, batched: BatchedFeedbackConfig | None = None) -> FeedbackTrainer:
    """`config` a PretrainConfig, `feedback` a FeedbackConfig (teacher rule, reward model, credit, dt)."""
    from mjx_protamer.agents.ddpg.train import make_train

    batched = batched or BatchedFeedbackConfig()
    tc, fc = config.train, feedback
    B, T = tc.num_envs, tc.chunk_steps
    rmc = fc.reward_model
    hidden = tuple(rmc.hidden)
    trainer = make_train(config, env, human_reward_fn=human_reward(hidden), devices=jax.devices()[:1])
    apply = reward_fn(hidden)
    net = RewardMLP(hidden)
    opt = optax.adam(rmc.learning_rate)
    obs_size, act_size = env.observation_size, env.action_size
    term_names = tuple(env.reward_term_names)
    cols = _signal_columns(fc.teacher.signals, term_names, obs_size, act_size)
    dt = fc.dt
    kind_cfgs = [with_channel(fc.teacher, k) for k in KINDS]
    extras = jnp.asarray([c.channel.get("duration_s") + c.channel.get("latency_s") for c in kind_cfgs])
    D = max(max_delay_steps(c, dt) for c in kind_cfgs)
    L = max(len(lag_weights(dataclasses.replace(fc.credit, scheme=s), dt, c.channel))
            for s in ("channel", "step_window", "time_window") for c in kind_cfgs)
    teach_envs = batched.teach_envs or B
    if teach_envs > B:
        raise ConfigError(f"config field 'batched.teach_envs': {teach_envs} > train.num_envs ({B})")
    E = batched.max_events_per_chunk or min(512, teach_envs * -(-T // max(fc.teacher.min_gap_steps, 1)))
    K = batched.rows_per_event
    n_replay = (T // rmc.replay_every if rmc.replay_every else 0) if batched.replay_updates_per_chunk < 0 \
        else batched.replay_updates_per_chunk
    n_fresh = rmc.updates_per_feedback * -(-E // 3) if batched.fresh_updates_per_chunk < 0 \
        else batched.fresh_updates_per_chunk
    cap = config.ddpg.replay_size
    if cap < T * B:
        raise ConfigError(f"config field 'ddpg.replay_size': {cap} rows cannot hold one chunk ({T} x {B} envs)")
    back_limit = cap // B - T  # steps before the chunk still in the replay

    def params_for(kind: str | None, credit: CreditConfig) -> FeedbackParams:
        w = np.zeros((L,), np.float32)
        if kind is not None:
            lw = lag_weights(credit, dt, with_channel(fc.teacher, kind).channel)
            if len(lw) > L:
                raise ConfigError(f"credit window of {len(lw)} steps exceeds the compiled {L}")
            w[:len(lw)] = lw
        return FeedbackParams(kind=jnp.int32(KINDS.index(kind) if kind else 0),
                              teach=jnp.float32(kind is not None), gain=jnp.float32(kind is not None),
                              lag_w=jnp.asarray(w))

    def init(seed) -> FeedbackState:
        key = jax.random.fold_in(jax.random.PRNGKey(seed), 0x7A3E)
        k_net, k_run = jax.random.split(key)
        p = net.init(k_net, jnp.zeros((1, obs_size)), jnp.zeros((1, act_size)))
        t = teacher_init(fc.teacher)
        return FeedbackState(
            teacher=jax.tree.map(lambda x: jnp.broadcast_to(x, (B, *x.shape)), t),
            pending_value=jnp.zeros((B, D)), pending_valid=jnp.zeros((B, D), bool),
            pending_about=jnp.zeros((B, D), jnp.int32), rm_params=p, rm_opt_state=opt.init(p),
            ring=ring_init(rmc.buffer_size, obs_size, act_size), rng=k_run, totals=jnp.zeros((5,)))

    def teach(fs: FeedbackState, fp: FeedbackParams, signals, step0, key):
        """signals (T, B, C) -> fs, value/valid/about/score (T, B), with the channel chosen by fp.kind."""
        extra = extras[fp.kind]
        rows = jnp.arange(B)

        def body(carry, xs):
            teacher, pv, pm, pa = carry
            sig, k, step = xs
            keys = jax.random.split(k, B)
            decs = [jax.vmap(lambda ts, x, kk, c=c: teacher_step(c, dt, ts, x, kk))(teacher, sig, keys)
                    for c in kind_cfgs]
            new_teacher = decs[0][0]  # the teacher state does not depend on the channel
            value = jnp.stack([d[1].value for d in decs])[fp.kind]
            delay = jnp.stack([d[1].delay_s for d in decs])[fp.kind]
            give, score = decs[0][1].give, decs[0][1].score
            give = give & (fp.teach > 0) & (rows < teach_envs)
            lag = jnp.clip(jnp.round((delay + extra) / dt).astype(jnp.int32), 1, D - 1)
            slot = (step + lag) % D
            write = give & ~pm[rows, slot]  # a slot already taken keeps its feedback
            pv = pv.at[rows, slot].set(jnp.where(write, value, pv[rows, slot]))
            pm = pm.at[rows, slot].set(write | pm[rows, slot])
            pa = pa.at[rows, slot].set(jnp.where(write, step, pa[rows, slot]))
            now = step % D
            out = (jnp.where(pm[:, now], pv[:, now], 0.0), pm[:, now], pa[:, now], score)
            pm = pm.at[:, now].set(False)
            return (new_teacher, pv, pm, pa), out

        steps = step0 + jnp.arange(T, dtype=jnp.int32)
        carry = (fs.teacher, fs.pending_value, fs.pending_valid, fs.pending_about)
        (teacher, pv, pm, pa), (value, valid, about, score) = jax.lax.scan(
            body, carry, (signals, jax.random.split(key, T), steps))
        return fs.replace(teacher=teacher, pending_value=pv, pending_valid=pm, pending_about=pa), \
            value, valid, about, score

    def chunk(ts, fs: FeedbackState, fp: FeedbackParams):
        ptr0, it0 = ts.replay.ptr, ts.iteration
        hp = {"params": fs.rm_params, "gain": fp.gain}
        ts, metrics = trainer.train_chunk(ts, hp)
        data = ts.replay.data
        rows = (ptr0 + jnp.arange(T)[:, None] * B + jnp.arange(B)[None, :]) % cap  # (T, B)
        obs, action, terms = data.obs[rows], data.action[rows], data.reward_terms[rows]
        signals = rule_signals(cols, obs, action, terms)
        rng, k_teach, k_lag, k_fresh = jax.random.split(fs.rng, 4)
        fs, value, valid, about, score = teach(fs, fp, signals, it0, k_teach)

        # credit: K lags per event drawn by weight; rows gathered from the replay (earlier chunks too)
        n_events = jnp.sum(valid)
        t_idx, b_idx = jnp.nonzero(valid, size=E, fill_value=0)
        present = jnp.arange(E) < n_events
        logw = jnp.log(jnp.maximum(fp.lag_w, 0.0) + 1e-30) + jnp.where(fp.lag_w > 0, 0.0, -1e30)
        lags = jax.random.categorical(k_lag, logw, shape=(E, K))
        rel = t_idx[:, None] - lags  # step relative to the chunk start
        ok = present[:, None] & (it0 + rel >= 0) & (rel >= -back_limit) & (jnp.sum(fp.lag_w) > 0)
        r = jnp.mod(ptr0 + rel * B + b_idx[:, None], cap).reshape(-1)
        w = ok.astype(jnp.float32).reshape(-1)
        h = jnp.broadcast_to(value[t_idx, b_idx][:, None], (E, K)).reshape(-1)
        c_obs, c_act = data.obs[r], data.action[r]
        ring = ring_add(fs.ring, c_obs, c_act, w, h)

        def sgd(carry, xs):
            p, o = carry
            k, fresh = xs
            kf, kr = jax.random.split(k)
            fi = jax.random.categorical(kf, jnp.where(w > 0, 0.0, -1e30), shape=(rmc.batch_size,))
            ri = jax.random.randint(kr, (rmc.batch_size,), 0, jnp.maximum(ring.size, 1))
            bo = jnp.where(fresh, c_obs[fi], ring.obs[ri])
            ba = jnp.where(fresh, c_act[fi], ring.action[ri])
            bw = jnp.where(fresh, w[fi], ring.weight[ri] * (ring.size >= min(rmc.replay_min_rows, rmc.buffer_size)))
            bh = jnp.where(fresh, h[fi], ring.target[ri])
            loss, g = jax.value_and_grad(weighted_loss)(p, apply, bo, ba, bw, bh)
            u, o = opt.update(g, o, p)
            live = jnp.sum(bw) > 0
            p = jax.tree.map(lambda a, b: jnp.where(live, a, b), optax.apply_updates(p, u), p)
            o = jax.tree.map(lambda a, b: jnp.where(live, a, b), o, carry[1])
            return (p, o), (loss, live)

        n_up = max(n_fresh + n_replay, 1)
        fresh = jnp.arange(n_up) < max(n_fresh, n_up - n_replay)
        (p, o), (losses, live) = jax.lax.scan(sgd, (fs.rm_params, fs.rm_opt_state),
                                              (jax.random.split(k_fresh, n_up), fresh))
        n_live = jnp.sum(live)

        # diagnostics: r_hat on the chunk's steps, and how it tracks the hidden score
        flat_o, flat_a = obs.reshape(T * B, -1), action.reshape(T * B, -1)
        rh = apply(p, flat_o, flat_a)
        sc = score.reshape(-1)
        rc, scc = rh - rh.mean(), sc - sc.mean()
        corr = jnp.sum(rc * scc) / jnp.maximum(jnp.sqrt(jnp.sum(rc ** 2) * jnp.sum(scc ** 2)), 1e-12)
        used = jnp.minimum(n_events, E)
        credited = jnp.sum(w)
        pos = jnp.sum(valid & (value > 0))
        neg = jnp.sum(valid & (value < 0))
        totals = fs.totals + jnp.stack([used, pos, neg, credited, n_live]).astype(jnp.float32)
        nan = jnp.float32(jnp.nan)
        metrics = dict(metrics)
        metrics.update(
            feedback_events=n_events.astype(jnp.float32), feedback_pos=pos.astype(jnp.float32),
            feedback_neg=neg.astype(jnp.float32), feedback_dropped=(n_events - used).astype(jnp.float32),
            credited_rows=credited, rm_updates=n_live.astype(jnp.float32),
            rm_loss=jnp.where(n_live > 0, jnp.sum(jnp.where(live, losses, 0.0)) / jnp.maximum(n_live, 1), nan),
            r_hat_mean=rh.mean(), r_hat_std=rh.std(), r_hat_score_corr=corr,
            score_mean=sc.mean(), ring_size=ring.size.astype(jnp.float32),
            **{k: totals[i] for i, k in enumerate(TOTAL_NAMES)})
        events = {"present": present, "arrival": it0 + t_idx,
                  "env": b_idx, "value": value[t_idx, b_idx], "about": about[t_idx, b_idx]}
        fs = fs.replace(rm_params=p, rm_opt_state=o, ring=ring, rng=rng, totals=totals)
        return ts, fs, metrics, events

    return FeedbackTrainer(trainer=trainer, init=init, chunk=jax.jit(chunk, donate_argnums=(0, 1)),
                           params=params_for, lag_len=L, max_events=E, apply=apply, chunk_fn=chunk,
                           signals=lambda o, a, t: rule_signals(cols, o, a, t))


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


def default_feedback_config(kind: str):
    """The feedback section of configs/feedback_<kind>.yaml: credit over the channel's delay distribution."""
    from mjx_protamer.human.tamer_loop import FeedbackConfig

    base = FeedbackConfig()
    return dataclasses.replace(base, credit=dataclasses.replace(base.credit, scheme="channel"),
                               teacher=with_channel(base.teacher, kind))


def parse_feedback(spec: str) -> str:
    """'simulated:keyboard' -> 'keyboard' (the kinds the in-jit teacher simulates)."""
    if not spec.startswith("simulated:") or spec.split(":", 1)[1] not in KINDS:
        raise ConfigError(f"--feedback {spec!r}: pretrain takes simulated:keyboard, simulated:prosody or "
                          "simulated:speech (live keyboard feedback is `protamer finetune --feedback keyboard`)")
    return spec.split(":", 1)[1]


def reward_model_bytes(fs: FeedbackState) -> bytes:
    from flax import serialization

    return serialization.msgpack_serialize({
        "params": serialization.to_state_dict(jax.device_get(fs.rm_params)),
        "opt_state": serialization.to_state_dict(jax.device_get(fs.rm_opt_state)),
        "updates": int(fs.totals[4])})


def step_window_note(kind: str, credit, dt: float) -> str | None:
    if credit.scheme == "step_window" and credit.window_steps * dt < 0.2:
        return (f"note: step_window credit covers {credit.window_steps * dt * 1000:.0f} ms before the arrival "
                f"step, less than the simulated {kind} reaction delay; time_window credits the judged steps")
    return None

