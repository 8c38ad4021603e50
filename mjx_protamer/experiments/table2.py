"""Reproduce the paper's Table II and Figures 1-2 with simulated teachers.

Four conditions with the same seeds and the same hidden teacher rule: DDPG (no feedback), DTK (simulated
keyboard), DTW (simulated speech: the Whisper + sentiment channel, +1/0/-1 through a confusion matrix, long
latency) and DTP (simulated prosody: continuous, noisy). Every condition runs the same compiled program
(`feedback_train.make_feedback_train`): the channel, credit weights and human-reward gain are values, and
DDPG alone is the gain-0, silent-teacher case (its reward is bit for bit DDPG's). DDPG's random stream does
not depend on the feedback path, so for a seed the four conditions start from the same networks, envs and
exploration noise. Each trained policy is evaluated on `eval_episodes` test episodes with the deterministic
actor (the same test seed for every condition).

Outputs in `out`: table2.md and table2.json (the paper's layout, the paper's numbers beside ours),
figure1_training_reward.png (moving average of the training episode return per condition),
figure2_unique_regions.png (box plot of unique regions per test episode), training.csv (every chunk of
every run) and eval_<condition>_seed<k>.json; for `--resume` and the pooled reward-model score, each
condition's reward models (reward_models/<condition>/, orbax) and a sample of its test states
(test_states_<condition>.npz).

How well r_hat learned its teacher is measured twice. `r_hat_corr_test` correlates r_hat with the hidden score
on the condition's own test states; a policy that complies visits states whose score barely varies, so that
figure is mostly noise once feedback has worked. `r_hat_corr_pooled` correlates it on the pooled test states of
every condition of the same seed (the same states for every reward model), which span what the teacher judges.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import platform
import time
import warnings
from pathlib import Path
from typing import Literal

import jax
import jax.numpy as jnp
import numpy as np

from mjx_protamer.agents.ddpg import selection
from mjx_protamer.agents.ddpg.config import PretrainConfig
from mjx_protamer.config import ConfigError, check, check_seed, to_dict
from mjx_protamer.experiments import metrics as M
from mjx_protamer.experiments.evaluate import validation_seed
from mjx_protamer.experiments.feedback_train import BatchedFeedbackConfig, human_reward, make_feedback_train
from mjx_protamer.experiments.run_log import flatten
from mjx_protamer.experiments.runner import run_chunks
from mjx_protamer.experiments.stats import contrast, seed_stats  # noqa: F401  (re-exported: scripts use them)
from mjx_protamer.human.feedback_config import FeedbackConfig

# Paper Table II (means over 10 test episodes).
PAPER = {
    "DDPG": {"first_touch_step": 19.7, "contact_rate": 0.519, "unique_regions": 4.3, "freeze_ratio": 0.180},
    "DTK": {"first_touch_step": 26.1, "contact_rate": 0.763, "unique_regions": 5.3, "freeze_ratio": 0.047},
    "DTW": {"first_touch_step": 23.7, "contact_rate": 0.536, "unique_regions": 3.1, "freeze_ratio": 0.428},
    "DTP": {"first_touch_step": 15.8, "contact_rate": 0.915, "unique_regions": 4.8, "freeze_ratio": 0.258},
}
LABELS = {"first_touch_step": "First touch step ↓", "contact_rate": "Contact rate ↑",
          "unique_regions": "Unique regions ↑", "freeze_ratio": "Freeze ratio ↓"}


@dataclasses.dataclass(frozen=True)
class Condition:
    name: str
    channel: Literal["none", "keyboard", "prosody", "speech"] = "none"
    credit: Literal["channel", "step_window", "time_window"] = "channel"
    beta_scale: float = 1.0  # multiplies ddpg.reward_beta for this condition (a value: no recompile)

    def validate(self) -> None:
        check(bool(self.name), "name", "must not be empty")
        check(self.beta_scale >= 0, "beta_scale", f"must be >= 0, got {self.beta_scale}")


DEFAULT_CONDITIONS = (Condition("DDPG", "none"), Condition("DTK", "keyboard"), Condition("DTW", "speech"),
                      Condition("DTP", "prosody"))


@dataclasses.dataclass(frozen=True)
class Table2Config:
    pretrain: PretrainConfig = dataclasses.field(default_factory=PretrainConfig)
    feedback: FeedbackConfig = dataclasses.field(default_factory=FeedbackConfig)  # rule, model, dt
    batched: BatchedFeedbackConfig = dataclasses.field(default_factory=BatchedFeedbackConfig)
    conditions: tuple[Condition, ...] = DEFAULT_CONDITIONS
    seeds: tuple[int, ...] = (0, 1, 2, 3, 4)  # the issue-8 protocol: 5 seeds, vmapped
    moving_average: int = 10  # chunks in Figure 1's moving average

    def validate(self) -> None:
        check(len(self.conditions) >= 1, "conditions", "needs at least one condition")
        names = [c.name for c in self.conditions]
        check(len(set(names)) == len(names), "conditions", f"names must be unique, got {names}")
        check(len(self.seeds) >= 1, "seeds", "needs at least one seed")
        for i, seed in enumerate(self.seeds):
            check_seed(seed, f"seeds[{i}]")
        check(self.moving_average >= 1, "moving_average", f"must be >= 1, got {self.moving_average}")


def builtin_table2_config() -> Table2Config:
    """What `reproduce table2` runs without --config: configs/table2_attention.yaml (a test holds them equal),
    the setting whose Table II meets issue 8's targets on 5 seeds (docs/results/table2_attention_asinh/).

    Against `Table2Config()`, the base a YAML file's missing keys take: the pretraining default with the
    movement band from 1.5 rad/s and DDPG's step size decayed to 0.1x over the run's second half (the
    baseline's freeze holds on 10 seeds); beta 1; the lateral teacher rule; watched silences as 0 labels
    worth an event; the posterior credit (T = 3); a bounded reward model reading asinh of the touch forces;
    100 replay minibatches a chunk from a 1e5-row buffer. Each change and its measurement: docs/experiments.md.
    """
    from mjx_protamer.human.credit import CreditConfig
    from mjx_protamer.human.reward_model import RewardModelConfig
    from mjx_protamer.human.teachers import LATERAL_RULE, TeacherConfig

    pre = PretrainConfig()
    pre = dataclasses.replace(
        pre, env=dataclasses.replace(pre.env, reward=dataclasses.replace(pre.env.reward, speed_low=1.5)),
        ddpg=dataclasses.replace(pre.ddpg, reward_beta=1.0, lr_final_fraction=0.1, lr_decay_from=0.5))
    feedback = FeedbackConfig(
        credit=CreditConfig(silence_weight=1.0, silence_needs_attention=True, posterior_temperature=3.0),
        reward_model=RewardModelConfig(buffer_size=100_000, bounded=True, asinh_obs=True),
        teacher=TeacherConfig(rule=LATERAL_RULE))
    return Table2Config(pretrain=pre, feedback=feedback,
                        batched=BatchedFeedbackConfig(replay_updates_per_chunk=100))


def load_table2_config(path=None, overrides=None, seeds: int | None = None) -> Table2Config:
    """From a YAML file (its missing keys take `Table2Config()`'s defaults) or, with no file, the built-in
    default (`builtin_table2_config`); `a.b=value` overrides apply to either."""
    from mjx_protamer.config import apply_overrides, from_dict, read_raw

    if path is None:
        raw = apply_overrides(to_dict(builtin_table2_config()), list(overrides or []))
    else:
        raw = read_raw(path, overrides)
    if seeds is not None:
        if seeds < 1:
            raise ConfigError(f"--seeds must be >= 1, got {seeds}")
        raw["seeds"] = list(range(seeds))
    return from_dict(Table2Config, raw)


def run_table2(cfg: Table2Config, out_dir, progress: bool = True, resume: bool = False) -> dict:
    """Every condition's results are written atomically as it finishes (`condition_<name>.json`): a run
    killed at any moment loses at most the condition it was training, and `resume` continues it."""
    t_all = time.perf_counter()
    trained = train_table2(cfg, out_dir, progress, resume)
    return write_table2(cfg, out_dir, trained, time.perf_counter() - t_all)


@dataclasses.dataclass
class Trained:
    """What `train_table2` hands to `write_table2`: every chunk's training row, each condition's test results
    per seed (`evals[name][seed]`) and its training seconds (`wall[name]`). Plain Python: JSON round-trips it
    (`experiments/distributed.py` gathers it from every process)."""
    training: list[dict]
    evals: dict[str, dict[int, dict]]
    wall: dict[str, list[float]]


def train_table2(cfg: Table2Config, out_dir, progress: bool = True, resume: bool = False) -> Trained:
    """Train and test every condition on `cfg.seeds` (vmapped in one program), writing each condition's results
    and agents into `out_dir` as it finishes; the pooled reward-model score at the end. No table or figures:
    `write_table2` makes them."""
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

    memory.check_seeds_fit(memory_per_seed(cfg, env, ft), len(cfg.seeds), resolve_devices(tc.num_devices),
                           f"reproduce table2 ({len(cfg.conditions)} conditions, one at a time)",
                           "lower ddpg.replay_size, train.num_envs or train.eval_episodes")
    saved = yaml.safe_dump(to_dict(cfg), sort_keys=False)
    if resume and (out / "config.yaml").read_text() != saved:
        raise ConfigError(f"--resume: the config differs from the one saved in {out / 'config.yaml'}")
    out.mkdir(parents=True, exist_ok=True)
    write_atomic(out / "config.yaml", saved)
    training: list[dict] = []
    evals: dict[str, dict[int, dict]] = {c.name: {} for c in cfg.conditions}
    wall: dict[str, list[float]] = {c.name: [] for c in cfg.conditions}
    # Seeds run side by side in one program: init, every chunk and the test episodes are vmapped over them.
    seeds = np.asarray(cfg.seeds, np.uint32)  # any seed in 0..2^32-1 (the same keys as int32 below 2^31)
    keys = jax.vmap(jax.random.PRNGKey)(seeds)
    init = jax.jit(jax.vmap(ft.trainer.init))
    init_feedback = jax.jit(jax.vmap(ft.init))
    chunk_fn = jax.jit(jax.vmap(ft.chunk_fn, in_axes=(0, 0, None)), donate_argnums=(0, 1))
    # The tested snapshot (train.select_every_chunks > 0): validation episodes of each seed's own stream
    validate = jax.jit(jax.vmap(selection.make_validate(
        env, tc.episode_length, pre.ddpg.actor_hidden, pre.ddpg.reward_alpha, pre.ddpg.reward_beta,
        human_reward(ft.apply)), in_axes=(0, {"params": 0, "gain": None}, 0)))
    keep = jax.jit(jax.vmap(selection.keep_better, in_axes=(0, 0, 0, None)))
    val_keys = jnp.stack([jax.random.split(jax.random.PRNGKey(validation_seed(dataclasses.replace(
        pre, train=dataclasses.replace(tc, seed=int(s))))), tc.select_episodes) for s in cfg.seeds])
    untrained = init_feedback(seeds).rm_params
    evaluate_seeds = make_seed_evaluator(cfg, env, ft)  # traced once for every condition and actor
    reward_models: dict[str, object] = {}
    test_states: dict[str, dict] = {}
    for cond in cfg.conditions:
        if done[cond.name].is_file():  # finished before an interruption (resume)
            reward_models[cond.name], test_states[cond.name] = load_condition_models(out, cond.name, untrained)
            kept = json.loads(done[cond.name].read_text())
            training += kept["training"]
            evals[cond.name] = {int(k): v for k, v in kept["evals"].items()}
            wall[cond.name].append(kept["train_wall_s"])
            if progress:
                print(f"[{cond.name}] kept from {done[cond.name]}", flush=True)
            continue
        kind = None if cond.channel == "none" else cond.channel
        credit = dataclasses.replace(cfg.feedback.credit, scheme=cond.credit)
        t0 = time.perf_counter()
        fp = ft.params(kind, credit)
        fp = fp._replace(gain=fp.gain * cond.beta_scale)

        chunks_run, validations = [0], []

        def step(state):  # called within this iteration: fp, cond and t0 are this condition's
            ts, fs, m, _ = chunk_fn(*state[:2], fp)
            kept = state[2]
            chunks_run[0] += 1
            if selection.is_candidate(chunks_run[0], tc.num_chunks, tc.select_every_chunks, tc.select_from):
                score, speed = validate(ts.actor_params, {"params": fs.rm_params, "gain": fp.gain}, val_keys)
                kept = keep(jax.vmap(selection.init)(ts.actor_params) if kept is None else kept, ts.actor_params, score,
                            chunks_run[0])
                validations.append({"chunk": chunks_run[0], "score": np.asarray(score).tolist(), "freeze_ratio":
                                    np.mean(np.asarray(speed) < pre.env.freeze_speed, axis=(1, 2)).tolist()})
            return (ts, fs, kept), m, None

        def progress_fn(info):
            rows = [{"condition": cond.name, "seed": int(seed), "chunk": info.chunk,
                     **flatten(jax.tree.map(lambda x, i=i: x[i], info.metrics), env.reward_term_names)}
                    for i, seed in enumerate(cfg.seeds)]
            training.extend(rows)
            if progress and (info.chunk % max(1, tc.num_chunks // 5) == 0 or info.chunk == tc.num_chunks):
                print(f"[{cond.name}, {len(seeds)} seeds] chunk {info.chunk}/{tc.num_chunks} return "
                      f"{np.nanmean([r['episode_return'] for r in rows]):.1f} contact "
                      f"{np.mean([r['contact_rate'] for r in rows]):.2f} feedback "
                      f"{np.mean([r['feedback_total'] for r in rows]):.0f} r_hat corr "
                      f"{np.mean([r['r_hat_score_corr'] for r in rows]):+.2f} "
                      f"({time.perf_counter() - t0:.0f} s)", flush=True)

        ts, fs, kept = run_chunks(step, (init(keys), init_feedback(seeds), None), tc.num_chunks,
                                  tc.chunk_steps * tc.num_envs * len(seeds), progress_fn=progress_fn).state
        train_s = time.perf_counter() - t0
        tested = ts.actor_params if kept is None else kept.actor_params
        results, test_states[cond.name] = evaluate_seeds(tested, fs.rm_params, untrained)
        # With selection, the last actor meets the same test episodes too: what selection changed is then a
        # paired difference on one training run, not a comparison across runs
        last_results = None if kept is None else evaluate_seeds(ts.actor_params, fs.rm_params, untrained)[0]
        reward_models[cond.name] = fs.rm_params
        _save_condition_models(out, cond.name, fs.rm_params, test_states[cond.name],
                               {"actor": tested, "critic": ts.critic_params})
        kept_chunk = None if kept is None else np.asarray(kept.chunk)
        for i, seed in enumerate(cfg.seeds):
            ev = results[i]
            if kept is not None:  # which snapshot was tested, and what each candidate validated at
                ev["selection"] = {"tested_chunk": int(kept_chunk[i]), "candidates": [
                    {"chunk": v["chunk"], "score": v["score"][i], "freeze_ratio": v["freeze_ratio"][i]}
                    for v in validations], "last_actor": {k: last_results[i][k] for k in SELECTION_METRICS}}
            last = [r for r in training if r["condition"] == cond.name and r["seed"] == seed][-1]
            ev["feedback"] = {k: last[k] for k in ("feedback_total", "feedback_pos_total", "feedback_neg_total",
                                                   "credited_rows_total", "rm_updates_total", "r_hat_score_corr")}
            ev["train_wall_s"] = train_s
            evals[cond.name][seed] = ev
            write_atomic(out / f"eval_{cond.name}_seed{seed}.json", json.dumps(ev, indent=2))
        wall[cond.name].append(train_s)
        write_atomic(done[cond.name], json.dumps({
            "training": [r for r in training if r["condition"] == cond.name], "train_wall_s": train_s,
            "evals": {str(k): v for k, v in evals[cond.name].items()}}))
    pooled = pooled_corr(ft, reward_models, untrained, test_states)
    for name, per_seed in pooled.items():
        for i, seed in enumerate(cfg.seeds):
            evals[name][seed].update(per_seed[i])
            write_atomic(out / f"eval_{name}_seed{seed}.json", json.dumps(evals[name][seed], indent=2))
    return Trained(training, evals, wall)


def write_table2(cfg: Table2Config, out_dir, trained: Trained, total_s: float, extra: dict | None = None) -> dict:
    """table2.json / table2.md (with `extra`'s keys added to the summary), the figures, training.csv and the body
    maps of a trained run into `out_dir`; the paths, the wall time and the summary."""
    from mjx_protamer.atomic import write_atomic

    out, pre = Path(out_dir), cfg.pretrain
    training, evals = trained.training, trained.evals
    _write_training_csv(training, out / "training.csv")
    summary = {**summarize(cfg, evals, trained.wall, total_s), **(extra or {})}
    write_atomic(out / "table2.json", json.dumps(summary, indent=2))
    write_atomic(out / "table2.md", format_markdown(summary))
    fig1 = plot_training(training, cfg, out / "figure1_training_reward.png")
    fig2 = plot_regions(summary, out / "figure2_unique_regions.png")
    from mjx_protamer.view.bodymap import write_condition_body_maps  # body_map_<condition>.png
    write_condition_body_maps(pre, evals, out)
    return {"out_dir": str(out), "table_md": str(out / "table2.md"), "table_json": str(out / "table2.json"),
            "figure1": str(fig1), "figure2": str(fig2), "training_csv": str(out / "training.csv"),
            "wall_s": total_s, "summary": summary}


def memory_per_seed(cfg: Table2Config, env, ft) -> dict[str, int]:
    """Bytes one seed of a table2 run holds at its peak, by part, from abstract shapes (`jax.eval_shape`: nothing
    is allocated): the learner's state with its replay and the feedback state of the condition training now
    (conditions run one after another), the kept snapshot (train.select_every_chunks), the test episodes' signals
    and env states, and what the run keeps of every condition until the end (reward models, sampled test
    states)."""
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
    return {"learner state and replay": tree_bytes(learner), "feedback state": tree_bytes(feedback),
            "kept snapshot": tree_bytes(learner.actor_params) if tc.select_every_chunks > 0 else 0,
            "test episodes": test,
            "kept per condition": len(cfg.conditions) * (tree_bytes(feedback.rm_params) + sampled)}


def _corr(x: np.ndarray, y: np.ndarray) -> float | None:
    """Pearson correlation; None where either side is constant (no variation to track)."""
    x, y = x - x.mean(), y - y.mean()
    den = float(np.sqrt(np.sum(x * x) * np.sum(y * y)))
    return float(np.sum(x * y) / den) if den > 1e-12 else None


# What `run_table2` also reports of the last actor when it tests a selected snapshot
SELECTION_METRICS = ("unique_regions", "freeze_ratio", "contact_rate", "teacher_score")

STATE_STRIDE = 5  # every 5th test step (25 ms) is kept for the pooled score: neighbours are near copies


def _save_condition_models(out: Path, name: str, rm_params, states: dict, agents: dict) -> None:
    """The condition's reward models, its agents (each seed's actor and critic, `agents/<name>/`: what the
    test episodes ran, for rendering, fine-tuning or diagnosis, e.g. scripts/freeze_anatomy.py) and its
    sampled test states."""
    import io

    from mjx_protamer.atomic import write_atomic
    from mjx_protamer.experiments import checkpoints

    for path, tree in ((out / "reward_models" / name, rm_params), (out / "agents" / name, agents)):
        checkpoints.save_model(path, jax.device_get(tree))
    buf = io.BytesIO()
    np.savez_compressed(buf, **states)
    write_atomic(out / f"test_states_{name}.npz", buf.getvalue())


def load_finished_condition(out: Path, name: str) -> tuple["Table2Config", dict]:
    """(config, sampled test states) of a finished condition of a table2 run, for the diagnostics in scripts/."""
    states = _read_test_states(out, name, "give the --out directory of a finished table2 run and a condition it "
                                          "ran (--condition)")
    return load_table2_config(out / "config.yaml"), states


def _read_test_states(out: Path, name: str, fix: str) -> dict:
    """The test states `run_table2` sampled for a condition; a missing file is a ConfigError ending in `fix`."""
    path = out / f"test_states_{name}.npz"
    if not path.is_file():
        raise ConfigError(f"{path} is missing: {fix}")
    with np.load(path) as f:
        return {k: f[k] for k in f.files}


def finished_condition_cli(description: str, argv=None):
    """The command line of the diagnostics in scripts/ (`RUN_DIR [--condition DTK]`): (args, config, test
    states); a run or condition that is not there exits with a one-line error."""
    import argparse

    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("run", type=Path, help="the --out directory of a finished table2 run")
    ap.add_argument("--condition", default="DTK")
    args = ap.parse_args(argv)
    try:
        return (args, *load_finished_condition(args.run, args.condition))
    except ConfigError as e:
        raise SystemExit(f"error: {e}") from None


def load_condition_reward_models(out: Path, cfg: "Table2Config", name: str, obs_size: int, act_size: int):
    """(nets, params) of a finished condition's reward models, stacked over the run's seeds."""
    from mjx_protamer.experiments import checkpoints
    from mjx_protamer.human.reward_model import reward_nets

    nets = reward_nets(cfg.feedback.reward_model)
    keys = jax.random.split(jax.random.PRNGKey(0), len(cfg.seeds))
    like = jax.vmap(lambda k: nets.net.init(k, jnp.zeros((1, obs_size)), jnp.zeros((1, act_size))))(keys)
    return nets, checkpoints.restore(checkpoints.manager(out / "reward_models" / name), 0, like)


def load_condition_agents(out: Path, cfg: "Table2Config", name: str, obs_size: int, act_size: int):
    """(actor, critic, params) of a finished condition: the flax modules and {"actor", "critic"} params
    stacked over the run's seeds, as `run_table2` saved them."""
    from mjx_protamer.agents.ddpg.networks import Actor, Critic
    from mjx_protamer.experiments import checkpoints

    path = out / "agents" / name
    if not path.is_dir():
        raise ConfigError(f"{path} is missing: give the --out directory of a table2 run that finished condition "
                          f"{name} (runs before this version did not keep their agents)")
    dc = cfg.pretrain.ddpg
    actor, critic = Actor(action_size=act_size, hidden=tuple(dc.actor_hidden)), Critic(hidden=tuple(dc.critic_hidden))

    def init(key):
        ka, kc = jax.random.split(key)
        return {"actor": actor.init(ka, jnp.zeros((obs_size,))),
                "critic": critic.init(kc, jnp.zeros((obs_size,)), jnp.zeros((act_size,)))}

    like = jax.vmap(init)(jax.random.split(jax.random.PRNGKey(0), len(cfg.seeds)))
    return actor, critic, checkpoints.restore(checkpoints.manager(path), 0, like)


def load_condition_models(out: Path, name: str, like) -> tuple[object, dict]:
    """(reward-model params stacked over seeds, sampled test states) of a finished condition (`like`: params of
    the same shape, e.g. untrained ones)."""
    from mjx_protamer.experiments import checkpoints

    states = _read_test_states(out, name, "--resume cannot use this run (an older version?); start again with "
                                          "another --out")
    return checkpoints.restore(checkpoints.manager(out / "reward_models" / name), 0, like), states


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
        out[name] = [{"r_hat_corr_pooled": _corr(r_hat[i], score[i]),
                      "r_hat_corr_pooled_untrained": _corr(r_hat0[i], score[i])} for i in range(len(obs))]
    return out


def make_seed_evaluator(cfg: Table2Config, env, ft):
    """`evaluate(actor_params, rm_params, untrained_params) -> (per-seed results, sample)`: test episodes of
    every seed's deterministic actor (vmapped over seeds): the four metrics, the teacher's mean hidden score
    on them (`teacher_score`), and how r_hat tracks that score on these held-out states, beside an untrained
    reward model of the same seed (`r_hat_corr_test`, `r_hat_corr_untrained`). Also every STATE_STRIDE-th
    test state with its score, per seed (seeds, n, ...), for `pooled_corr`.

    One evaluator serves a whole run: its jitted rollout is traced once, then every condition's tested and
    last actors reuse it (the parameter shapes are the same)."""
    from mjx_protamer.agents.ddpg.evaluate import make_rollout
    from mjx_protamer.experiments.evaluate import eval_seed
    from mjx_protamer.human.teachers import rule_scores

    pre = cfg.pretrain
    rollout = make_rollout(env, pre.train.episode_length, pre.ddpg.actor_hidden)
    episodes = pre.train.eval_episodes
    keys = jnp.stack([jax.random.split(jax.random.PRNGKey(eval_seed(dataclasses.replace(
        pre, train=dataclasses.replace(pre.train, seed=int(s))))), episodes) for s in cfg.seeds])
    teacher = cfg.feedback.teacher

    def run(actor_params, rm_params, untrained_params, keys):
        sig = rollout(actor_params, keys)
        score = jax.vmap(lambda o, a, t, r: rule_scores(teacher, ft.signals(o, a, t, r)))(
            sig["obs"], sig["action"], sig["reward_terms"], sig["region_mask"])
        r_hat = ft.apply(rm_params, sig["obs"], sig["action"])
        r_hat0 = ft.apply(untrained_params, sig["obs"], sig["action"])
        keep = ("reward", "self_contact", "region_mask", "arm_speed")
        sample = {"obs": sig["obs"][:, ::STATE_STRIDE], "action": sig["action"][:, ::STATE_STRIDE],
                  "score": score[:, ::STATE_STRIDE]}
        sample = jax.tree.map(lambda x: x.reshape(-1, *x.shape[2:]), sample)  # (episodes * steps, ...)
        return {k: sig[k] for k in keep}, score, r_hat, r_hat0, sample

    run_seeds = jax.jit(jax.vmap(run))

    def evaluate(actor_params, rm_params, untrained_params) -> tuple[list[dict], dict]:
        sig, score, r_hat, r_hat0, sample = jax.device_get(run_seeds(actor_params, rm_params, untrained_params,
                                                                     keys))
        out = []
        for i in range(len(cfg.seeds)):
            ev = M.summarize(sig["self_contact"][i], sig["region_mask"][i], sig["arm_speed"][i],
                             freeze_threshold=pre.env.freeze_speed)
            returns = np.sum(sig["reward"][i], axis=1)
            ev["episode_return"] = float(returns.mean())
            ev["per_episode"]["episode_return"] = [float(r) for r in returns]
            ev["teacher_score"] = float(score[i].mean())
            ev["per_episode"]["teacher_score"] = [float(x) for x in score[i].mean(axis=1)]
            ev["r_hat_corr_test"] = _corr(np.ravel(r_hat[i]), np.ravel(score[i]))
            ev["r_hat_corr_untrained"] = _corr(np.ravel(r_hat0[i]), np.ravel(score[i]))
            out.append(ev)
        return out, sample

    return evaluate


def _write_training_csv(rows: list[dict], path: Path) -> None:
    keys: list[str] = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)


def summarize(cfg: Table2Config, evals: dict, wall: dict, total_s: float) -> dict:
    """table2.json's content: per condition and metric the seed statistics, the contrasts against the baseline,
    and the run's setting (`evals[name][seed]`: one seed's test results; `wall[name]`: training seconds)."""
    conds = {}
    for c in cfg.conditions:
        per_seed = evals[c.name]
        entry: dict = {"channel": c.channel, "credit": c.credit if c.channel != "none" else None,
                       "beta": cfg.pretrain.ddpg.reward_beta * c.beta_scale if c.channel != "none" else 0.0,
                       "paper": PAPER.get(c.name)}
        for name in M.METRIC_NAMES + ("teacher_score",):
            entry[name] = seed_stats([per_seed[s][name] for s in cfg.seeds])
            entry[name]["seed_means"] = entry[name]["seed_values"]
            entry[name]["per_episode"] = [v for s in cfg.seeds for v in per_seed[s]["per_episode"][name]]
        for name in ("r_hat_corr_test", "r_hat_corr_untrained", "r_hat_corr_pooled", "r_hat_corr_pooled_untrained",
                     "episode_return"):
            entry[name] = seed_stats([per_seed[s][name] for s in cfg.seeds])
        entry["feedback"] = {k: float(np.mean([per_seed[s]["feedback"][k] for s in cfg.seeds]))
                             for k in per_seed[cfg.seeds[0]]["feedback"]}
        entry["train_wall_s"] = float(np.sum(wall[c.name]))
        if "selection" in per_seed[cfg.seeds[0]]:
            sel = [per_seed[s]["selection"] for s in cfg.seeds]
            entry["selection"] = {
                "tested_chunks": [x["tested_chunk"] for x in sel],
                "last_actor": {k: seed_stats([x["last_actor"][k] for x in sel]) for k in SELECTION_METRICS},
                "tested_minus_last": {k: seed_stats([per_seed[s][k] - x["last_actor"][k]
                                                     for s, x in zip(cfg.seeds, sel)]) for k in SELECTION_METRICS}}
        conds[c.name] = entry
    tc = cfg.pretrain.train
    baseline = next((c.name for c in cfg.conditions if c.channel == "none"), None)
    versus = {c.name: contrast(conds[baseline]["teacher_score"]["seed_values"],
                               conds[c.name]["teacher_score"]["seed_values"])
              for c in cfg.conditions if baseline is not None and c.channel != "none"}
    return {
        "conditions": conds,
        "teacher_score_vs_baseline": {"baseline": baseline, "conditions": versus} if versus else None,
        "seeds": list(cfg.seeds),
        "env": cfg.pretrain.env_name,
        "reward": reward_preset_name(cfg.pretrain),
        "num_envs": tc.num_envs,
        "env_steps_per_run": tc.iterations * tc.num_envs,
        "eval_episodes_per_seed": tc.eval_episodes,
        "wall_s": total_s,
        "machine": f"{platform.machine()}, {jax.local_device_count()} x {jax.local_devices()[0].platform}, "
                   f"{__import__('os').cpu_count()} CPU cores visible",
    }


def _fmt(stat: dict, digits: int = 3) -> str:
    if stat["mean"] is None:
        return "n/a"
    ci = f" ± {stat['ci95']:.{digits}f}" if stat.get("ci95") is not None else ""
    return f"{stat['mean']:.{digits}f}{ci}"


def reward_preset_name(pre) -> str:
    """The self-touch reward's preset ('infant', 'paper') and any fields changed from it, e.g. 'infant (speed_low
    1.5)', against the preset it differs from least; the env name for another env."""
    if pre.env_name != "self_touch":
        return pre.env_name
    reward = pre.env.reward

    def changed(name):
        base = type(reward).preset(name)
        return [f"{f.name} {getattr(reward, f.name)}" for f in dataclasses.fields(reward)
                if getattr(reward, f.name) != getattr(base, f.name)]

    name = min(type(reward).PRESETS, key=lambda n: len(changed(n)))
    diff = changed(name)
    return f"{name} ({', '.join(diff)})" if diff else name


def format_markdown(summary: dict) -> str:
    conds = summary["conditions"]
    names = list(conds)
    n = len(summary["seeds"])
    head = "| Metric | " + " | ".join(f"{c} ours | {c} paper" for c in names) + " |"
    sep = "|---|" + "---|---|" * len(names)
    lines = [f"Table II analogue: mean over {n} seed(s) {summary['seeds']} of each seed's mean over "
             f"{summary['eval_episodes_per_seed']} test episodes (deterministic actor), ± the 95% confidence "
             f"half-width (Student t over seeds); {summary['env']} env, reward preset {summary.get('reward')}, "
             f"{summary['num_envs']} envs x {summary['env_steps_per_run']} env steps per run; wall time "
             f"{summary['wall_s']:.0f} s.", "", head, sep]
    for metric in M.METRIC_NAMES:
        cells = []
        for c in names:
            paper = conds[c]["paper"]
            cells.append(f"{_fmt(conds[c][metric])} | " + (f"{paper[metric]:.3f}" if paper else "-"))
        lines.append(f"| {LABELS[metric]} | " + " | ".join(cells) + " |")
    lines += ["", "| Teacher and reward model | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for key, label in (("teacher_score", "teacher_score (hidden rule, test episodes) ↑"),
                       ("r_hat_corr_test", "r_hat_corr_test (held-out test states)"),
                       ("r_hat_corr_untrained", "r_hat_corr_untrained (same states)"),
                       ("r_hat_corr_pooled", "r_hat_corr_pooled (every condition's test states)"),
                       ("r_hat_corr_pooled_untrained", "r_hat_corr_pooled_untrained (same states)"),
                       ("episode_return", "test return (intrinsic)")):
        lines.append(f"| {label} | " + " | ".join(_fmt(conds[c][key], 1 if key == "episode_return" else 3)
                                                  for c in names) + " |")
    for key, label in (("feedback_total", "events given (per seed)"), ("credited_rows_total", "credited rows"),
                       ("rm_updates_total", "r_hat updates")):
        lines.append(f"| {label} | " + " | ".join(f"{conds[c]['feedback'][key]:.0f}" for c in names) + " |")
    versus = summary.get("teacher_score_vs_baseline")
    if versus:
        lines += ["", f"| teacher_score against {versus['baseline']} | difference of means | sum of the ci95 | "
                      "beyond it | per-seed differences (paired mean ± ci95) |", "|---|---|---|---|---|"]
        for c, v in versus["conditions"].items():
            if v["difference"] is None:
                lines.append(f"| {c} | n/a | n/a | n/a | n/a |")
                continue
            seeds = ", ".join("n/a" if d is None else f"{d:.2f}" for d in v["paired"]["seed_values"])
            lines.append(f"| {c} | {v['difference']:.3f} | {v['ci95_sum']:.3f} | "
                         f"{'yes' if v['beyond_ci95_sum'] else 'no'} | {_fmt(v['paired'])} ({seeds}) |")
    selected = [c for c in names if "selection" in conds[c]]
    if selected:
        lines += ["", "The tested actor is the best snapshot on validation episodes (train.select_every_chunks); the "
                      "last actor on the same test episodes:", "",
                  "| Condition | tested chunk per seed | " + " | ".join(f"{k}: last actor | tested - last (paired)"
                                                                      for k in SELECTION_METRICS) + " |",
                  "|---|---|" + "---|---|" * len(SELECTION_METRICS)]
        for c in selected:
            sel = conds[c]["selection"]
            lines.append(f"| {c} | {', '.join(str(k) for k in sel['tested_chunks'])} | " + " | ".join(
                f"{_fmt(sel['last_actor'][k])} | {_fmt(sel['tested_minus_last'][k])}" for k in SELECTION_METRICS) + " |")
    lines += ["", "Per-seed means (seeds in order):", ""]
    for metric in M.METRIC_NAMES + ("teacher_score", "r_hat_corr_test", "r_hat_corr_pooled"):
        vals = "; ".join(f"{c} " + ", ".join("n/a" if v is None else f"{v:.3g}" for v in conds[c][metric]["seed_values"])
                         for c in names)
        lines.append(f"- {metric}: {vals}")
    return "\n".join(lines) + "\n"


def _moving(x: np.ndarray, k: int) -> np.ndarray:
    """Moving average that skips NaN (chunks without a finished episode)."""
    out = np.full_like(x, np.nan, dtype=float)
    for i in range(len(x)):
        w = x[max(0, i - k + 1): i + 1]
        w = w[~np.isnan(w)]
        if w.size:
            out[i] = w.mean()
    return out


def plot_training(rows: list[dict], cfg: Table2Config, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4))
    panels = (("episode_return", "training episode return (intrinsic reward)"),
              ("sampled_reward", "reward DDPG trains on per step (α r_env + β r̂)"))
    for ax, (key, label) in zip(axes, panels):
        for c in cfg.conditions:
            curves = []
            for seed in cfg.seeds:
                r = [x for x in rows if x["condition"] == c.name and x["seed"] == seed]
                curves.append(_moving(np.array([x.get(key, np.nan) for x in r], float), cfg.moving_average))
                steps = np.array([x["env_steps"] for x in r])
            curves = np.array(curves)
            with warnings.catch_warnings():  # chunks where no seed finished an episode stay NaN
                warnings.simplefilter("ignore", RuntimeWarning)
                mean = np.nanmean(curves, axis=0)
            line, = ax.plot(steps, mean, label=c.name, lw=2)
            for curve in curves if len(cfg.seeds) > 1 else ():  # every seed, thin: bimodal runs stay visible
                ax.plot(steps, curve, color=line.get_color(), lw=0.6, alpha=0.5)
        ax.set_xlabel("env steps (all envs)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        ax.legend()
    fig.suptitle(f"Figure 1 analogue: moving average ({cfg.moving_average} chunks) over "
                 f"{len(cfg.seeds)} seed(s); thick: mean, thin: each seed")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_regions(summary: dict, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(summary["conditions"])
    data = [summary["conditions"][n]["unique_regions"]["per_episode"] for n in names]
    fig, ax = plt.subplots(figsize=(6, 4.4))
    # the box spans test episodes; its outliers are single episodes, drawn unlike the seed means' circles
    ax.boxplot(data, showmeans=True, flierprops=dict(marker="+", markeredgecolor="grey", markersize=6))
    ax.plot([], [], "^", color="green", label="mean of episodes")
    ax.plot([], [], "+", color="grey", label="single episodes (box outliers)")
    ax.set_xticks(range(1, len(names) + 1), names)
    for i, n in enumerate(names, start=1):
        seed_means = summary["conditions"][n]["unique_regions"]["seed_values"]
        jitter = np.linspace(-0.12, 0.12, len(seed_means)) if len(seed_means) > 1 else np.zeros(1)
        ax.scatter(i + jitter, seed_means, marker="o", facecolors="none", edgecolors="black", zorder=3,
                   label="seed means" if i == 1 else None)
        paper = summary["conditions"][n]["paper"]
        if paper:
            ax.plot(i, paper["unique_regions"], marker="x", color="red", ms=9,
                    label="paper mean" if i == 1 else None)
    ax.set_ylabel("unique regions per test episode")
    ax.set_ylim(-0.3, 8.3)
    ax.grid(alpha=0.3, axis="y")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.08), ncol=4, fontsize=7.5, frameon=False)  # off the data
    ax.set_title(f"Figure 2 analogue ({sum(len(d) for d in data) // len(names)} test episodes per condition)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
