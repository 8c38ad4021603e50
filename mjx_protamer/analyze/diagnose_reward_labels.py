"""What limits the reward model: the states it is fitted on, or the labels the teacher gives (issue 8).

Two steps, both on the production code paths:

  collect: train one seed of a table2 condition (DTK by default) exactly as `protamer reproduce table2` does,
           and record every chunk's steps (obs, action) and the teacher's output (value, valid, score, about)
           from the chunk's trace (`feedback_train.ChunkTrace`, read through the runner's progress callback);
           then the test episodes' states with their hidden score (`table2.make_seed_evaluator`).
           protamer analyze diagnose-reward-labels collect --config configs/table2_habituation.yaml \
               --seed 0 --out runs/labels_seed0.npz
  fit:     fit fresh reward models offline on the recorded run's credited and silent rows
           (`batched.draw_credited_steps`, the silent-step rule of `batched.draw_silent_steps`, and
           `batched.reward_model_updates`), with the teacher's labels or with labels an oracle corrected, and
           print r_hat's correlation with the hidden score on the test states and on the last 10 chunks'
           training states, one JSON line per variant.
           protamer analyze diagnose-reward-labels fit runs/labels_seed{0,1,2,3,4}.npz

Variants (`--variants`, comma-separated NAME:SILENCE_WEIGHT[:balanced][:em]):
  teacher      the teacher's labels: each event's value on its credited steps, 0 on silent steps
  exact        the same steps, labelled with their hidden score (the states' ceiling)
  no_mistakes  the teacher's labels without the events whose sign the teacher flipped (`flip_prob`)
  attentive    the teacher's labels, the silent steps limited to those whose hidden score is 0 (an oracle
               that knows when silence meant "nothing to say" rather than "not watching")
  ...:em        after the fit, each event's credited rows are reweighted by how well the model agrees with
               the event (weight x exp(T v r_hat), renormalised per event: the posterior over which of its
               steps the event was about, an EM step) and the model is refitted, `--em-rounds` times at
               temperature `--em-temperature`
Also printed: how many reproaches were flipped praise, and where the silent steps with score +1 lie.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import optax


@dataclasses.dataclass(frozen=True)
class FitOptions:
    """How `fit` refits the reward models (the CLI's defaults are the docs' runs)."""

    variants: str
    updates: int
    learning_rate: float
    hidden: tuple[int, ...]
    seed: int
    em_rounds: int
    em_temperature: float


VARIANTS = ("teacher", "exact", "no_mistakes", "attentive")


def collect(config: Path, condition: str, seed: int, out: Path) -> None:
    """Trains one seed of the config's `condition` and saves its steps, the teacher's output and the test states
    to `out` (.npz); a condition without feedback raises ConfigError."""
    from mjx_protamer.config import ConfigError
    from mjx_protamer.experiments.env_factory import make_env, with_resolved_backend
    from mjx_protamer.experiments.feedback_train import make_feedback_train
    from mjx_protamer.experiments.runner import run_chunks
    from mjx_protamer.experiments.table2 import load_table2_config, make_seed_evaluator

    cfg = load_table2_config(config)
    cfg = dataclasses.replace(cfg, seeds=(seed,), pretrain=with_resolved_backend(cfg.pretrain, announce=True))
    pre = cfg.pretrain
    env = make_env(pre)
    ft = make_feedback_train(pre, env, cfg.feedback, cfg.batched)
    matches = [c for c in cfg.conditions if c.name == condition]
    if not matches or matches[0].channel == "none":
        raise ConfigError(f"--condition {condition!r} must name a feedback condition of {config}")
    cond = matches[0]
    fp = ft.params(cond.channel, dataclasses.replace(cfg.feedback.credit, scheme=cond.credit))
    fp = fp._replace(gain=fp.gain * cond.beta_scale)
    ts = jax.jit(ft.trainer.init)(jax.random.PRNGKey(seed))
    fs = jax.jit(ft.init)(jnp.int32(seed))
    untrained = jax.tree.map(np.array, fs.rm_params)  # fs is donated to the chunk
    n = pre.train.num_chunks
    rec = {k: [] for k in ("obs", "action", "value", "valid", "score", "about")}

    def step(state):
        ts, fs, metrics, _, trace = ft.collect_chunk(*state, fp)
        return (ts, fs), metrics, trace

    def record(info) -> None:  # the chunk's trace: the steps the teacher judged and what it said
        trace = info.extra
        rec["obs"].append(trace.obs)
        rec["action"].append(trace.action)
        for k in ("value", "valid", "score", "about"):
            rec[k].append(trace.teacher[k])
        if info.chunk % 10 == 1 or info.chunk == n:
            print(f"chunk {info.chunk}/{n} r_hat corr {float(info.metrics['r_hat_score_corr']):+.2f} "
                  f"({info.wall_s:.0f} s)", flush=True)

    ts, fs = run_chunks(step, (ts, fs), n, pre.train.chunk_steps * pre.train.num_envs, progress_fn=record).state
    one = lambda t: jax.tree.map(lambda x: x[None], t)
    res, sample = make_seed_evaluator(cfg, env, ft)(one(ts.actor_params), one(fs.rm_params), one(untrained))
    print(json.dumps({k: res[0][k] for k in ("unique_regions", "freeze_ratio", "teacher_score", "r_hat_corr_test")}))
    np.savez_compressed(out, **{k: np.stack(v) for k, v in rec.items()},
                        **{"test_" + k: np.asarray(v[0]) for k, v in sample.items()},
                        lag_w=np.asarray(fp.lag_w), silence_w=float(fp.silence_w),
                        rows_per_event=cfg.batched.rows_per_event,
                        silence_rows_per_chunk=cfg.batched.silence_rows_per_chunk,
                        chunk_steps=pre.train.chunk_steps)
    print(f"saved {out}")


def fit(data: list[Path], opts: FitOptions) -> None:
    """Every recorded run (one per seed), then each variant's mean over them, 95% CI and per-seed values; a
    variant of another name raises ConfigError."""
    from mjx_protamer.config import ConfigError
    from mjx_protamer.experiments.table2 import seed_stats

    for spec in opts.variants.split(","):
        if spec.split(":")[0] not in VARIANTS:
            raise ConfigError(f"variant {spec.split(':')[0]!r}: use {', '.join(VARIANTS)}")
    per_run = [fit_one(opts, path) for path in data]
    for name in per_run[0]:
        for metric in ("r_hat_corr_test", "r_hat_corr_late_training"):
            stats = seed_stats([run[name][metric] for run in per_run])
            print(json.dumps({"variant": name, "metric": metric, "mean": round(stats["mean"], 3),
                              "ci95": None if stats["ci95"] is None else round(stats["ci95"], 3),
                              "per_seed": [round(v, 3) for v in stats["seed_values"]]}), flush=True)


def fit_one(opts, path) -> dict:
    from mjx_protamer.human.batched import draw_credited_steps
    from mjx_protamer.human.reward_model import RewardMLP, reward_fn

    d = np.load(path)
    print(f"== {path}", flush=True)
    flat = lambda x: x.reshape(-1, *x.shape[2:])  # (chunks, T, B, ...) -> (steps, B, ...)
    obs, act = flat(d["obs"]), flat(d["action"])
    value, valid, score, about = flat(d["value"]), flat(d["valid"]), flat(d["score"]), flat(d["about"]).astype(int)
    TT, B, O = obs.shape
    A = act.shape[-1]
    K = int(d["rows_per_event"])
    lag_w = np.asarray(d["lag_w"])

    # the credited rows of every event, as in the chunk (K lags drawn by credit weight)
    E = int(valid.sum())
    rel, b_idx, ok, target, _ = map(np.asarray, draw_credited_steps(
        jnp.asarray(value), jnp.asarray(valid), jnp.asarray(lag_w), jax.random.PRNGKey(opts.seed), E, K))
    ok = ok & (rel >= 0)
    rel = np.clip(rel, 0, None)
    ev_t, ev_b = np.nonzero(valid)  # the order draw_credited_steps takes events in
    mistake = value[ev_t, ev_b] != score[np.clip(about[ev_t, ev_b], 0, TT - 1), ev_b]

    # the silent steps: no arrival at any lag with credit weight (batched.draw_silent_steps)
    first = int(np.argmax(lag_w > 0))
    last = len(lag_w) - 1 - int(np.argmax((lag_w > 0)[::-1]))
    arrivals = np.concatenate([np.zeros((1, B), np.int64), np.cumsum(valid, 0)])
    p = np.arange(TT - last)
    silent = (arrivals[p + last + 1] - arrivals[p + first]) == 0
    n_silent = int(silent.sum())
    S = int(d["silence_rows_per_chunk"]) * (TT // int(d["chunk_steps"]))
    pick = np.random.default_rng(opts.seed).choice(np.flatnonzero(silent.ravel()), S)
    s_t, s_b = p[pick // B], pick % B

    # where the silent steps with score +1 lie: the length of the +1 stretch around them
    runs = np.zeros((TT, B), int)
    for b in range(B):
        edges = np.flatnonzero(np.diff(np.concatenate([[0], (score[:, b] == 1).astype(int), [0]])))
        for start, stop in zip(edges[::2], edges[1::2]):
            runs[start:stop, b] = stop - start
    silent_pos = silent & (score[p] == 1)
    run_of_silent = runs[p][silent_pos]
    neg = value[ev_t, ev_b] < 0
    print(json.dumps({
        "steps": TT * B, "events": E, "praise": int((~neg).sum()), "reproach": int(neg.sum()),
        "reproach_that_was_flipped_praise": int((neg & mistake).sum()),
        "praise_that_was_flipped_reproach": int((~neg & mistake).sum()),
        "credited_rows_with_the_events_value_as_score": float(
            (score[rel, b_idx[:, None]] == target)[ok].mean()),
        "silent_steps": n_silent, "silent_steps_score_share": {
            str(v): float((score[p][silent] == v).mean()) for v in (-1, 0, 1)},
        "silent_plus1_steps_stretch_length_quartiles": [float(x) for x in np.percentile(run_of_silent, [25, 50, 75])],
        "silent_plus1_steps_in_stretches_under_20_steps": float((run_of_silent < 20).mean()),
    }), flush=True)

    hidden = tuple(opts.hidden)
    apply = reward_fn(hidden, True)
    net = RewardMLP(hidden, True)
    test = (d["test_obs"], d["test_action"], d["test_score"])
    late = (obs[-1000:].reshape(-1, O), act[-1000:].reshape(-1, A), score[-1000:].reshape(-1))
    ev_obs, ev_act = obs[rel, b_idx[:, None]].reshape(-1, O), act[rel, b_idx[:, None]].reshape(-1, A)
    ev_score = score[rel, b_idx[:, None]].reshape(-1)
    si_obs, si_act, si_score = obs[s_t, s_b], act[s_t, s_b], score[s_t, s_b]

    def corr(params, data):
        r = np.asarray(jax.jit(apply)(params, data[0], data[1]))
        r, s = r - r.mean(), data[2] - data[2].mean()
        return float(np.sum(r * s) / np.sqrt(np.sum(r * r) * np.sum(s * s)))

    def group_means(params, data):
        r = np.asarray(jax.jit(apply)(params, data[0], data[1]))
        return {str(v): round(float(r[data[2] == v].mean()), 3) for v in (-1, 0, 1) if np.any(data[2] == v)}

    results = {}
    for spec in opts.variants.split(","):
        name, w_silence, *rest = spec.split(":")
        w_ev = (ok & ~mistake[:, None]) if name == "no_mistakes" else ok
        w_si = np.full(len(s_t), float(w_silence) * K * n_silent / S, np.float32)
        if name == "attentive":
            w_si = w_si * (si_score == 0)
        h_ev = ev_score if name == "exact" else target.reshape(-1)
        h_si = si_score if name == "exact" else np.zeros(len(s_t))
        balance = 10.0 if "balanced" in rest else None
        w_ev = w_ev.astype(np.float32)
        for em_round in range(1 + (opts.em_rounds if "em" in rest else 0)):
            if em_round:
                agree = opts.em_temperature * target * np.asarray(jax.jit(apply)(params, ev_obs, ev_act)).reshape(E, K)
                post = np.exp(agree - agree.max(1, keepdims=True)) * w_ev
                w_ev = post / np.maximum(post.sum(1, keepdims=True), 1e-12) * w_ev.sum(1, keepdims=True)
            params = fit_rows(opts, net, apply, O, A, balance, (ev_obs, si_obs), (ev_act, si_act),
                              (w_ev.reshape(-1), w_si), (h_ev, h_si))
        results[spec] = {"r_hat_corr_test": corr(params, test), "r_hat_corr_late_training": corr(params, late)}
        print(json.dumps({"variant": spec, **{k: round(v, 3) for k, v in results[spec].items()},
                          "test_r_hat_by_score": group_means(params, test)}), flush=True)
    return results


def fit_rows(opts: FitOptions, net, apply, O, A, balance, *columns):
    """A fresh bounded model fitted on the rows (obs, action, weight, target), each given as parts to join."""
    from mjx_protamer.human.batched import FeedbackRing, reward_model_updates

    rows = [np.concatenate(parts).astype(np.float32) for parts in columns]
    keep = rows[2] > 0
    o, a, w, h = (jnp.asarray(r[keep]) for r in rows)
    ring = FeedbackRing(o, a, w, h, jnp.int32(0), jnp.int32(len(w)))
    params = net.init(jax.random.PRNGKey(opts.seed), jnp.zeros((1, O)), jnp.zeros((1, A)))
    opt = optax.adam(opts.learning_rate)
    opt_state = opt.init(params)
    block = jax.jit(lambda pr, st, k: reward_model_updates(
        apply, opt, pr, st, ring, (o[:1], a[:1], w[:1], h[:1]), k, 0, 1000, 64, 1, balance)[:2])
    for i in range(opts.updates // 1000):
        params, opt_state = block(params, opt_state, jax.random.PRNGKey(1000 + i))
    return params
