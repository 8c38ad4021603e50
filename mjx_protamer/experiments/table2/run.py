"""Train and test every condition of Table II: `train_table2` (the conditions one after another, each on every
seed at once) and `run_table2` (that, then the table, figures and body maps of `artifacts.write_table2`).

Every condition runs the same compiled program (`feedback_train.make_feedback_train`): the channel, credit
weights and human-reward gain are values, and DDPG alone is the gain-0, silent-teacher case (its reward is bit
for bit DDPG's). DDPG's random stream does not depend on the feedback path, so for a seed the four conditions
start from the same networks, envs and exploration noise. Each trained policy is evaluated on `eval_episodes`
test episodes with the deterministic actor (the same test seed for every condition).

How well r_hat learned its teacher is measured twice. `r_hat_corr_test` correlates r_hat with the hidden score
on the condition's own test states; a policy that complies visits states whose score barely varies, so that
figure is mostly noise once feedback has worked. `r_hat_corr_pooled` correlates it on the pooled test states of
every condition of the same seed (the same states for every reward model), which span what the teacher judges.
"""
from __future__ import annotations

import dataclasses
import json
import threading
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from mjx_protamer.config import ConfigError, check_resume_config, to_dict
from mjx_protamer.experiments.feedback_train import human_reward, make_feedback_train
from mjx_protamer.experiments.run_log import flatten
from mjx_protamer.experiments.runner import run_chunks
from mjx_protamer.experiments.side_by_side import run_side_by_side
from mjx_protamer.experiments.snapshot_selection import SnapshotSelection
from mjx_protamer.experiments.stats import pearson
from mjx_protamer.experiments.table2.artifacts import write_table2
from mjx_protamer.experiments.table2.config import Table2Config
from mjx_protamer.experiments.table2.models import load_condition_models, save_condition_models
from mjx_protamer.experiments.table2.report import SELECTION_METRICS

STATE_STRIDE = 5  # every 5th test step (25 ms) is kept for the pooled score: neighbours are near copies
# Conditions trained at the same time, each on a host thread (experiments/side_by_side.py: on the 2-core CPU a
# second condition's chunks fill the cores the first leaves idle; the pair takes 0.78-0.83 of its sequential time)
AT_ONCE = 2


def run_table2(cfg: Table2Config, out_dir, progress: bool = True, resume: bool = False,
               at_once: int = AT_ONCE) -> dict:
    """Every condition's results are written atomically as it finishes (`condition_<name>.json`): a run
    killed at any moment loses at most the conditions it was training (`at_once` of them), and `resume`
    continues it."""
    t_all = time.perf_counter()
    trained = train_table2(cfg, out_dir, progress, resume, at_once=at_once)
    return write_table2(cfg, out_dir, trained, time.perf_counter() - t_all,
                        {"conditions_at_once": trained.at_once})


@dataclasses.dataclass
class Trained:
    """What `train_table2` hands to `write_table2`: every chunk's training row, each condition's test results
    per seed (`evals[name][seed]`) and its training seconds (`wall[name]`). Plain Python: JSON round-trips it
    (`experiments/distributed.py` gathers it from every process)."""
    training: list[dict]
    evals: dict[str, dict[int, dict]]
    wall: dict[str, list[float]]
    at_once: int = 1  # conditions that trained at a time (at most those left to train)


def train_table2(cfg: Table2Config, out_dir, progress: bool = True, resume: bool = False, pooled=None,
                 at_once: int = AT_ONCE) -> Trained:
    """Train and test every condition on `cfg.seeds` (vmapped in one program), `at_once` conditions at a time
    (`side_by_side`: each computes what it would alone), writing each condition's results and agents into
    `out_dir` as it finishes; the pooled reward-model score at the end (`pooled`: what computes it,
    `pooled_corr`'s signature; a run whose conditions are split across processes pools them elsewhere). No table
    or figures: `write_table2` makes them. A condition's `train_wall_s` is its own wall time, shared with the
    conditions beside it."""
    from mjx_protamer.atomic import write_atomic
    from mjx_protamer.experiments.env_factory import make_env, with_resolved_backend

    cfg = dataclasses.replace(cfg, pretrain=with_resolved_backend(cfg.pretrain, announce=progress))
    out = Path(out_dir)
    import yaml

    done = {c.name: out / f"condition_{c.name}.json" for c in cfg.conditions}
    if resume:
        if not (out / "config.yaml").is_file():
            raise ConfigError(f"--resume: {out} holds no table2 run to continue; leave out --resume to start one there")
    elif any(p.is_file() for p in done.values()):
        raise ConfigError(f"{out} already holds a table2 run; pass --resume to continue it, or another --out")
    pre = cfg.pretrain
    tc = pre.train
    env = make_env(pre)
    ft = make_feedback_train(pre, env, cfg.feedback, cfg.batched)
    # Every seed's state side by side, and what the run keeps of every condition: refused before allocating
    from mjx_protamer.agents.ddpg.train import resolve_devices
    from mjx_protamer.experiments import memory

    devices = resolve_devices(tc.num_devices)
    left = [c for c in cfg.conditions if not (resume and done[c.name].is_file())]
    # Several devices: each chunk is a shard_map with collectives, and two programs issuing theirs from two threads
    # could wait on each other across the devices; one condition at a time there
    at_once = max(1, min(at_once, len(left), 1 if len(devices) > 1 else len(left)))
    memory.check_seeds_fit(memory_per_seed(cfg, env, ft, at_once), len(cfg.seeds), devices,
                           f"reproduce table2 ({len(cfg.conditions)} conditions, {at_once} at a time)",
                           "lower ddpg.replay_size, train.num_envs or train.eval_episodes, or train fewer "
                           "conditions at once (--conditions-at-once 1)")
    if resume:
        check_resume_config(out / "config.yaml", cfg)
    out.mkdir(parents=True, exist_ok=True)
    write_atomic(out / "config.yaml", yaml.safe_dump(to_dict(cfg), sort_keys=False))
    evals: dict[str, dict[int, dict]] = {c.name: {} for c in cfg.conditions}
    wall: dict[str, list[float]] = {c.name: [] for c in cfg.conditions}
    # Seeds run side by side in one program: init, every chunk and the test episodes are vmapped over them.
    seeds = np.asarray(cfg.seeds, np.uint32)  # any seed in 0..2^32-1 (the same keys as int32 below 2^31)
    keys = jax.vmap(jax.random.PRNGKey)(seeds)
    init = jax.jit(jax.vmap(ft.trainer.init))
    init_feedback = jax.jit(jax.vmap(ft.init))
    chunk_fn = jax.jit(jax.vmap(ft.chunk_fn, in_axes=(0, 0, None)), donate_argnums=(0, 1))
    # The tested snapshot (train.select_every_chunks > 0): validation episodes of each seed's own stream
    selecting = SnapshotSelection(pre, env, human_reward(ft.apply), seeds=cfg.seeds,
                                  human_params_axes={"params": 0, "gain": None})
    untrained = init_feedback(seeds).rm_params
    evaluate_seeds = make_seed_evaluator(cfg, env, ft)  # traced once for every condition and actor
    reward_models: dict[str, object] = {}
    test_states: dict[str, dict] = {}
    rows: dict[str, list[dict]] = {c.name: [] for c in cfg.conditions}  # training rows, joined in order at the end
    saving = threading.Lock()

    def train_condition(cond, between_chunks) -> None:
        """Train, test and save one condition on every seed; `between_chunks` (side_by_side) may stop it."""
        kind = None if cond.channel == "none" else cond.channel
        credit = dataclasses.replace(cfg.feedback.credit, scheme=cond.credit)
        t0 = time.perf_counter()
        fp = ft.params(kind, credit)
        fp = fp._replace(gain=fp.gain * cond.beta_scale)

        def train_step(state):
            ts, fs, m, _ = chunk_fn(*state, fp)
            return (ts, fs), m, None

        step, validations = selecting.wrap(train_step, lambda new: new[0].actor_params,
                                           lambda new, fp=fp: {"params": new[1].rm_params, "gain": fp.gain})

        def progress_fn(info):
            new_rows = [{"condition": cond.name, "seed": int(seed), "chunk": info.chunk,
                         **flatten(jax.tree.map(lambda x, i=i: x[i], info.metrics), env.reward_term_names)}
                        for i, seed in enumerate(cfg.seeds)]
            rows[cond.name].extend(new_rows)
            if progress and (info.chunk % max(1, tc.num_chunks // 5) == 0 or info.chunk == tc.num_chunks):
                print(f"[{cond.name}, {len(seeds)} seeds] chunk {info.chunk}/{tc.num_chunks} return "
                      f"{np.nanmean([r['episode_return'] for r in new_rows]):.1f} contact "
                      f"{np.mean([r['contact_rate'] for r in new_rows]):.2f} feedback "
                      f"{np.mean([r['feedback_total'] for r in new_rows]):.0f} r_hat corr "
                      f"{np.mean([r['r_hat_score_corr'] for r in new_rows]):+.2f} "
                      f"({time.perf_counter() - t0:.0f} s)", flush=True)
            between_chunks()

        ts, fs, kept = run_chunks(step, (init(keys), init_feedback(seeds), None), tc.num_chunks,
                                  tc.chunk_steps * tc.num_envs * len(seeds), progress_fn=progress_fn).state
        train_s = time.perf_counter() - t0
        tested = ts.actor_params if kept is None else kept.actor_params
        results, test_states[cond.name] = evaluate_seeds(tested, fs.rm_params, untrained)
        # With selection, the last actor meets the same test episodes too: what selection changed is then a
        # paired difference on one training run, not a comparison across runs
        last_results = None if kept is None else evaluate_seeds(ts.actor_params, fs.rm_params, untrained)[0]
        reward_models[cond.name] = fs.rm_params
        with saving:  # one orbax save at a time
            save_condition_models(out, cond.name, fs.rm_params, test_states[cond.name],
                                   {"actor": tested, "critic": ts.critic_params})
        kept_chunk = None if kept is None else np.asarray(kept.chunk)
        for i, seed in enumerate(cfg.seeds):
            ev = results[i]
            if kept is not None:  # which snapshot was tested, and what each candidate validated at
                ev["selection"] = {"tested_chunk": int(kept_chunk[i]), "candidates": [
                    {"chunk": v["chunk"], "score": v["score"][i], "freeze_ratio": v["freeze_ratio"][i]}
                    for v in validations], "last_actor": {k: last_results[i][k] for k in SELECTION_METRICS}}
            last = [r for r in rows[cond.name] if r["seed"] == seed][-1]
            ev["feedback"] = {k: last[k] for k in ("feedback_total", "feedback_pos_total", "feedback_neg_total",
                                                   "credited_rows_total", "rm_updates_total", "r_hat_score_corr")}
            ev["train_wall_s"] = train_s
            evals[cond.name][seed] = ev
            write_atomic(out / f"eval_{cond.name}_seed{seed}.json", json.dumps(ev, indent=2))
        wall[cond.name].append(train_s)
        write_atomic(done[cond.name], json.dumps({
            "training": rows[cond.name], "train_wall_s": train_s,
            "evals": {str(k): v for k, v in evals[cond.name].items()}}))

    todo = []
    for cond in cfg.conditions:
        if done[cond.name].is_file():  # finished before an interruption (resume)
            reward_models[cond.name], test_states[cond.name] = load_condition_models(out, cond.name, untrained)
            kept = json.loads(done[cond.name].read_text())
            rows[cond.name] = kept["training"]
            evals[cond.name] = {int(k): v for k, v in kept["evals"].items()}
            wall[cond.name].append(kept["train_wall_s"])
            if progress:
                print(f"[{cond.name}] kept from {done[cond.name]}", flush=True)
        else:
            todo.append(lambda between_chunks, cond=cond: train_condition(cond, between_chunks))
    run_side_by_side(todo, at_once)
    training = [r for c in cfg.conditions for r in rows[c.name]]
    test_states = {c.name: test_states[c.name] for c in cfg.conditions}  # the conditions' order, whoever finished first
    for name, per_seed in (pooled or pooled_corr)(ft, reward_models, untrained, test_states).items():
        for i, seed in enumerate(cfg.seeds):
            evals[name][seed].update(per_seed[i])
            write_atomic(out / f"eval_{name}_seed{seed}.json", json.dumps(evals[name][seed], indent=2))
    return Trained(training, evals, wall, at_once)


def memory_per_seed(cfg: Table2Config, env, ft, at_once: int = 1) -> dict[str, int]:
    """Bytes one seed of a table2 run holds at its peak, by part, from abstract shapes (`jax.eval_shape`: nothing
    is allocated): the learner's state with its replay and the feedback state of each of the `at_once`
    conditions training now, their kept snapshots (train.select_every_chunks) and test episodes' signals and env
    states, and what the run keeps of every condition until the end (reward models, sampled test states)."""
    from mjx_protamer.experiments.memory import tree_bytes

    pre = cfg.pretrain
    tc = pre.train
    key = jax.random.PRNGKey(0)
    learner = jax.eval_shape(ft.trainer.init, key)
    feedback = jax.eval_shape(ft.init, jnp.uint32(0))
    episodes, steps = tc.eval_episodes, tc.episode_length
    floats = env.observation_size + env.action_size + len(env.reward_term_names) + 8 + 3  # a step's signals
    test = episodes * (steps * (floats + 3) * 4 + tree_bytes(jax.eval_shape(env.reset, key)))
    sampled = episodes * (-(-steps // STATE_STRIDE)) * (env.observation_size + env.action_size + 1) * 4
    return {"learner state and replay": at_once * tree_bytes(learner), "feedback state": at_once * tree_bytes(feedback),
            "kept snapshot": at_once * tree_bytes(learner.actor_params) if tc.select_every_chunks > 0 else 0,
            "test episodes": at_once * test,
            "kept per condition": len(cfg.conditions) * (tree_bytes(feedback.rm_params) + sampled)}


def pooled_corr(ft, reward_models: dict, untrained_params, test_states: dict) -> dict[str, list[dict]]:
    """Per condition and seed, r_hat's correlation with the hidden score on the pooled test states of every
    condition of that seed (`r_hat_corr_pooled`), beside the untrained reward model's
    (`r_hat_corr_pooled_untrained`)."""
    names = list(test_states)
    obs = np.concatenate([test_states[n]["obs"] for n in names], axis=1)  # (seeds, states, obs)
    action = np.concatenate([test_states[n]["action"] for n in names], axis=1)
    score = np.concatenate([test_states[n]["score"] for n in names], axis=1)
    apply = jax.jit(jax.vmap(ft.apply))
    r_hat0 = np.asarray(apply(untrained_params, obs, action))
    out = {}
    for name in names:
        r_hat = np.asarray(apply(reward_models[name], obs, action))
        out[name] = [{"r_hat_corr_pooled": pearson(r_hat[i], score[i]),
                      "r_hat_corr_pooled_untrained": pearson(r_hat0[i], score[i])} for i in range(len(obs))]
    return out


def make_seed_evaluator(cfg: Table2Config, env, ft):
    """`evaluate(actor_params, rm_params, untrained_params) -> (per-seed results, sample)`: test episodes of
    every seed's deterministic actor (vmapped over seeds): the four metrics, the teacher's mean hidden score
    on them (`teacher_score`), and how r_hat tracks that score on these held-out states, beside an untrained
    reward model of the same seed (`r_hat_corr_test`, `r_hat_corr_untrained`). Also every STATE_STRIDE-th
    test state with its score, per seed (seeds, n, ...), for `pooled_corr`.

    One evaluator serves a whole run: its jitted rollout is traced once, then every condition's tested and
    last actors reuse it (the parameter shapes are the same)."""
    from mjx_protamer.experiments.evaluate import eval_seed, make_evaluator, summarize

    pre = cfg.pretrain
    episodes = pre.train.eval_episodes
    keys = jnp.stack([jax.random.split(jax.random.PRNGKey(eval_seed(dataclasses.replace(
        pre, train=dataclasses.replace(pre.train, seed=int(s))))), episodes) for s in cfg.seeds])
    run = make_evaluator(pre, env, cfg.feedback.teacher, ft.apply, state_stride=STATE_STRIDE)
    run_seeds = jax.jit(jax.vmap(lambda actor, rm, untrained, k: run(actor, k, {"test": rm, "untrained": untrained})))

    def evaluate(actor_params, rm_params, untrained_params) -> tuple[list[dict], dict]:
        ev = jax.device_get(run_seeds(actor_params, rm_params, untrained_params, keys))
        per_seed = [summarize(jax.tree.map(lambda x, i=i: x[i], ev), pre.train.episode_length)
                    for i in range(len(cfg.seeds))]
        return per_seed, ev["states"]

    return evaluate

