"""`protamer pretrain`: set up a run directory, run its chunks through the host runner, evaluate.

The loop itself (progress bar, CSV/TensorBoard rows, checkpoints, resume) is `experiments.runner`'s, shared
with `reproduce table2`. Everything random lives in the TrainState (and the feedback state), and a
checkpoint holds all of it (learner, env batch, replay, RNG), so `resume=True` continues from the last
checkpoint exactly as if the run had never stopped.

With `train.select_every_chunks > 0` the test episodes run the snapshot that validated best
(agents/ddpg/selection.py): the kept snapshot is a third checkpoint part (`checkpoints_selected/`), so a resumed
run keeps it, every candidate's validation return goes to `selection.json`, and `run_loader.load_run` gives
the kept actor for a finished run.
"""

from __future__ import annotations

import json
from pathlib import Path

import jax
import jax.numpy as jnp
import yaml

from mjx_protamer.atomic import write_atomic
from mjx_protamer.config import ConfigError, check_resume_config, to_dict
from mjx_protamer.experiments import checkpoints, memory, metrics, run_log, runner, saved_reward_model
from mjx_protamer.experiments.evaluate import eval_seed, evaluate
from mjx_protamer.experiments.run_loader import CONFIG_NAME, SELECTED_DIR, read_run_config


def run_pretrain(
    config,
    out_dir: str | Path,
    resume: bool = False,
    progress: bool = True,
    max_chunks: int | None = None,
    human_reward_fn=None,
    human_params=None,
    final_eval: bool = True,
    feedback=None,
) -> dict:
    """Train DDPG from `config` (a PretrainConfig) into `out_dir`; return the outputs and final metrics.

    `max_chunks` stops after that many chunks of this call (as a kill would; used to test resume).
    `feedback`: None, or a `FeedbackSetup` (simulated teachers + DeepTAMER inside the jitted chunk, see
    `experiments.feedback_train`); then the CSV/TensorBoard rows gain feedback counts and r_hat stats, every
    event goes to `feedback.jsonl` (append + fsync, `FeedbackLog`), the reward model to `reward_model/`
    (`saved_reward_model`) and the feedback carry to `checkpoints_feedback/` (so `resume` is exact with feedback
    too).
    """
    from mjx_protamer.agents.ddpg.train import make_train, resolve_devices
    from mjx_protamer.experiments.env_factory import make_env, with_resolved_backend

    config = with_resolved_backend(config)  # printed even without a progress bar: the run depends on it
    out = Path(out_dir)
    ckpt_dir = out / "checkpoints"
    config_path = out / CONFIG_NAME
    saved = to_dict(config)
    existing = checkpoints.available_steps(ckpt_dir)
    if resume:
        if not existing:
            raise ConfigError(f"--resume: {out} holds no checkpoint to continue from; leave out --resume to "
                              f"start a new run (in a new or empty --out), or give the --out of the run to continue")
        if config_path.is_file():  # read as `eval` reads it: a run saved before a knob existed keeps its value
            check_resume_config(config_path, config, lambda path: read_run_config(path.parent))
    elif existing:
        raise ConfigError(f"{out} already holds a run (checkpoint {existing[-1]}); pass --resume or another --out")

    tc = config.train
    env = make_env(config)
    fb = fb_state = fb_params = None
    if feedback is None:
        trainer = make_train(config, env, human_reward_fn=human_reward_fn)
    else:
        from mjx_protamer.experiments.feedback_train import make_feedback_train

        fb = make_feedback_train(config, env, feedback.config, feedback.batched)
        trainer = fb.trainer
        fb_params = fb.params(feedback.kind, feedback.config.credit)
        fb_state = fb.init(tc.seed)
    # Refuse a state that cannot fit before allocating it (or writing anything into `out`).
    like = jax.eval_shape(trainer.init, jax.random.PRNGKey(tc.seed))
    memory.check_fits(like, resolve_devices(tc.num_devices), like.replay, config.ddpg.replay_size,
                      other=None if fb_state is None else fb_state)
    out.mkdir(parents=True, exist_ok=True)
    select = tc.select_every_chunks > 0
    ckpt = runner.Checkpointer([ckpt_dir] + ([out / "checkpoints_feedback"] if fb is not None else [])
                               + ([out / SELECTED_DIR] if select else []), tc.checkpoint_every_chunks)
    write_atomic(config_path, yaml.safe_dump(saved, sort_keys=False).encode())
    if fb is not None:
        write_atomic(out / "feedback_config.yaml", yaml.safe_dump(
            {"kind": feedback.kind, "feedback": to_dict(feedback.config), "batched": to_dict(feedback.batched)},
            sort_keys=False).encode())
    # The runner's state: one part per checkpoint directory.
    parts = (trainer.init(jax.random.PRNGKey(tc.seed)),) + ((fb_state,) if fb is not None else ())
    if select:  # a copy: the chunk donates the TrainState's buffers
        from mjx_protamer.agents.ddpg import selection

        parts += (selection.init(jax.tree.map(jnp.copy, parts[0].actor_params)),)
    start = 0
    if resume:
        start, parts = ckpt.restore(parts)
    progress_fn = None
    if fb is not None:
        from mjx_protamer.experiments.feedback_train import log_events
        from mjx_protamer.human.queue import FeedbackLog

        fb_log_path = out / "feedback.jsonl"
        _truncate_feedback_log(fb_log_path, (start * tc.chunk_steps) if start else 0)
        fb_log = FeedbackLog(fb_log_path)
        fb_log.note(event="start", kind=feedback.kind, chunk=start)

        def step(parts):
            ts, fs, m, events = fb.chunk(*parts, fb_params)
            return (ts, fs), m, events

        def progress_fn(info):
            log_events(fb_log, info.extra, feedback.kind, feedback.config, feedback.config.dt)
    else:
        def step(parts):
            ts, m = trainer.train_chunk(parts[0], human_params)
            return (ts,), m, None
    candidates = []
    if select:
        step, candidates = _with_selection(step, config, env, fb, fb_params, human_reward_fn, human_params, out,
                                           start)
    log = run_log.RunLog(out, resume_chunk=start)
    last_return = [float("nan")]  # the progress bar shows the latest finished episodes' return

    def postfix(info):
        row = info.row
        if row["episode_return"] == row["episode_return"]:
            last_return[0] = row["episode_return"]
        post = dict(sps=f"{row['steps_per_s']:.0f}", ret=f"{last_return[0]:.1f}", contact=f"{row['contact_rate']:.2f}")
        if fb is not None:
            post.update(fb=f"{row['feedback_total']:.0f}", rhat=f"{row['r_hat_mean']:+.2f}")
        return post

    try:
        run = runner.run_chunks(step, parts, tc.num_chunks, tc.chunk_steps * tc.num_envs, start=start,
                                max_chunks=max_chunks, progress_fn=progress_fn, log=log,
                                term_names=env.reward_term_names, checkpointer=ckpt,
                                bar="pretrain" if progress else None, postfix=postfix)
    except BaseException:  # a failed write, a kill: close what is open (quietly: the disk may be full), re-raise
        for closer in (log.close, ckpt.close) + ((fb_log.close,) if fb is not None else ()):
            try:
                closer()
            except Exception:
                pass
        raise
    state, chunk = run.state[0], run.chunks_done
    if fb is not None:
        fb_state = run.state[1]
    kept = run.state[-1] if select else None
    log.close()
    if fb is not None:
        fb_log.note(event="end", chunk=chunk, totals=[float(x) for x in jax.device_get(fb_state.totals)])
        fb_log.close()
        saved_reward_model.save(out, fb_state.rm_params, fb_state.rm_opt_state, int(fb_state.totals[4]))

    result = {
        "out_dir": str(out),
        "config": str(config_path),
        "checkpoint": str(ckpt.latest()) if ckpt.latest() is not None else None,
        "csv": str(log.csv_path),
        "tensorboard": str(out / "tb"),
        "chunks_done": chunk,
        "finished": run.finished,
        "train_wall_s": run.wall_s,
        "steps_per_s": run.steps_per_s,
        "state": state,
    }
    if fb is not None:
        result.update(feedback_log=str(out / "feedback.jsonl"), reward_model=str(out / saved_reward_model.DIR),
                      feedback_state=fb_state, feedback_kind=feedback.kind)
        if log.rows:
            last = log.rows[-1]
            result["feedback_summary"] = {k: last[k] for k in (
                "feedback_total", "feedback_pos_total", "feedback_neg_total", "credited_rows_total",
                "rm_updates_total", "r_hat_mean", "r_hat_std", "r_hat_score_corr") if k in last}
    if log.rows:
        result["plot"] = str(run_log.plot_curve(log.rows, out / run_log.PLOT_NAME))
    if select:
        result["selection"] = {"tested_chunk": int(kept.chunk), "score": float(kept.score),
                               "candidates": candidates}
    if final_eval and result["finished"]:
        summary = evaluate(config, env, state.actor_params if kept is None else kept.actor_params,
                           tc.eval_episodes, eval_seed(config))
        if select:  # the last actor on the same test episodes: what selection changed
            last = evaluate(config, env, state.actor_params, tc.eval_episodes, eval_seed(config))
            summary["selection"] = dict(result["selection"], last_actor={
                k: last[k] for k in ("unique_regions", "freeze_ratio", "contact_rate", "episode_return")})
        write_atomic(out / "eval.json", json.dumps(summary, indent=2).encode())
        result["eval"] = summary
        result["eval_json"] = str(out / "eval.json")
    ckpt.close()
    return result


def last_good_checkpoint(out: str | Path) -> Path | None:
    """The newest checkpoint step of the run in `out` whose every part (checkpoints/, and checkpoints_feedback/
    and checkpoints_selected/ where the run has them) finished its save (has its manifest): where `--resume`
    continues from after a failed write. None when there is none."""
    out = Path(out)
    parts = [out / "checkpoints"] + [out / d for d in ("checkpoints_feedback", SELECTED_DIR) if (out / d).is_dir()]
    steps = set(checkpoints.available_steps(parts[0]))
    for d in parts[1:]:
        steps &= set(checkpoints.available_steps(d))
    for step in sorted(steps, reverse=True):
        if all((d / str(step) / checkpoints.MANIFEST).is_file() for d in parts):
            return parts[0] / str(step)
    return None


def report(result: dict) -> str:
    """The end-of-run text: the metrics table and where the outputs are."""
    lines = []
    if "eval" in result:
        ev = result["eval"]
        lines += [f"test episodes: {ev['episodes']} (deterministic actor), mean return {ev['episode_return']:.2f}",
                  metrics.format_table(ev, metrics.PAPER_DDPG), ""]
    if "selection" in result.get("eval", {}):
        sel = result["eval"]["selection"]
        lines += [f"tested actor: the snapshot after chunk {sel['tested_chunk']} (best validation return "
                  f"{sel['score']:.1f} of {len(sel['candidates'])} candidates, selection.json); the last actor on "
                  f"the same episodes: freeze {sel['last_actor']['freeze_ratio']:.3f}, regions "
                  f"{sel['last_actor']['unique_regions']:.1f}", ""]
    lines.append(f"trained {result['chunks_done']} chunks in {result['train_wall_s']:.1f} s"
                 f" ({result['steps_per_s']:.0f} env steps/s after compile)")
    if "feedback_summary" in result:
        fs = result["feedback_summary"]
        lines.append(f"feedback ({result['feedback_kind']}, simulated): {fs['feedback_total']:.0f} events "
                     f"(+{fs['feedback_pos_total']:.0f} / -{fs['feedback_neg_total']:.0f}), "
                     f"{fs['credited_rows_total']:.0f} credited rows, {fs['rm_updates_total']:.0f} r_hat updates; "
                     f"last chunk r_hat {fs['r_hat_mean']:+.3f} +- {fs['r_hat_std']:.3f}, "
                     f"corr with the hidden score {fs['r_hat_score_corr']:+.2f}")
    for key in ("checkpoint", "config", "csv", "tensorboard", "plot", "eval_json", "feedback_log", "reward_model"):
        if result.get(key):
            lines.append(f"{key:<12} {result[key]}")
    return "\n".join(lines)


def _with_selection(step, config, env, fb, fb_params, human_reward_fn, human_params, out: Path, start: int):
    """`step` with the snapshot selection after it (the state's last part is the kept snapshot), and the list
    of candidates so far (restored from `selection.json` on resume), which it keeps up to date there."""
    from mjx_protamer.experiments.snapshot_selection import SnapshotSelection

    if fb is not None:
        from mjx_protamer.experiments.feedback_train import human_reward

        human_fn = human_reward(fb.apply)
        human_params_of = lambda new: {"params": new[1].rm_params, "gain": fb_params.gain}  # noqa: E731
    else:
        human_fn = human_reward_fn
        human_params_of = lambda new: human_params  # noqa: E731
    path = out / "selection.json"
    candidates = [c for c in json.loads(path.read_text())["candidates"] if c["chunk"] <= start] \
        if start and path.is_file() else []

    def save(candidates):
        write_atomic(path, json.dumps({"candidates": candidates}, indent=2).encode())

    return SnapshotSelection(config, env, human_fn).wrap(step, lambda new: new[0].actor_params, human_params_of,
                                                         start=start, candidates=candidates, on_candidate=save)


class FeedbackSetup:
    """What `run_pretrain(feedback=...)` needs: the simulated channel, the feedback config, the batch sizing."""

    def __init__(self, kind: str, config, batched=None):
        from mjx_protamer.experiments.feedback_train import KINDS
        from mjx_protamer.human.feedback_config import BatchedFeedbackConfig

        if kind not in KINDS:
            raise ConfigError(f"feedback kind {kind!r} is not one of {', '.join(KINDS)}")
        self.kind, self.config, self.batched = kind, config, batched or BatchedFeedbackConfig()




def _truncate_feedback_log(path: Path, last_step: int) -> None:
    """On resume, drop the events logged after the restored checkpoint (they will be given again), atomically."""
    if not path.exists():
        return
    if last_step == 0:
        path.unlink()
        return
    from mjx_protamer.human.queue import FeedbackLog

    keep = [r for r in FeedbackLog.records(path) if r.get("step") is None or r["step"] < last_step]
    write_atomic(path, "".join(json.dumps(r, sort_keys=True) + "\n" for r in keep).encode())
