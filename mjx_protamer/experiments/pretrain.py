"""The host loop of `protamer pretrain`: jitted chunks, and between them logs, progress and checkpoints.

Everything random lives in the TrainState, and a checkpoint holds all of it (learner, env batch, replay,
RNG), so `resume=True` continues from the last checkpoint exactly as if the run had never stopped.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import jax
import yaml

from mjx_protamer.config import ConfigError, read_raw, to_dict
from mjx_protamer.experiments import checkpoints, memory, metrics, run_log
from mjx_protamer.experiments.evaluate import eval_seed, evaluate
from mjx_protamer.experiments.run_loader import CONFIG_NAME


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
    event goes to `feedback.jsonl` (append + fsync, `FeedbackLog`), the reward model to `reward_model.msgpack`
    and the feedback carry to `checkpoints_feedback/` (so `resume` is exact with feedback too).
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
                              f"start a new run there, or give the --out of the run to continue")
        if config_path.is_file() and read_raw(config_path) != saved:
            raise ConfigError(f"--resume: the config differs from the one saved in {config_path}")
    elif existing:
        raise ConfigError(f"{out} already holds a run (checkpoint {existing[-1]}); pass --resume or another --out")

    tc = config.train
    env = make_env(config)
    fb = fb_state = fb_params = fb_log = fb_mngr = None
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
    mngr = checkpoints.manager(ckpt_dir)
    checkpoints.write_atomic(config_path, yaml.safe_dump(saved, sort_keys=False).encode())
    if fb is not None:
        fb_mngr = checkpoints.manager(out / "checkpoints_feedback")
        checkpoints.write_atomic(out / "feedback_config.yaml", yaml.safe_dump(
            {"kind": feedback.kind, "feedback": to_dict(feedback.config), "batched": to_dict(feedback.batched)},
            sort_keys=False).encode())
    state = trainer.init(jax.random.PRNGKey(tc.seed))
    start = 0
    if resume:
        pairs = [(mngr, state)] + ([(fb_mngr, fb_state)] if fb is not None else [])
        step, restored = checkpoints.restore_newest_intact(pairs, lambda line: print(line, file=sys.stderr))
        start = step
        state = restored[0]
        if fb is not None:
            fb_state = restored[1]
    if fb is not None:
        from mjx_protamer.human.queue import FeedbackLog

        fb_log_path = out / "feedback.jsonl"
        _truncate_feedback_log(fb_log_path, (start * tc.chunk_steps) if start else 0)
        fb_log = FeedbackLog(fb_log_path)
        fb_log.note(event="start", kind=feedback.kind, chunk=start)
    log = run_log.RunLog(out, resume_chunk=start)

    steps_per_chunk = tc.chunk_steps * tc.num_envs
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=tc.num_chunks * steps_per_chunk, initial=start * steps_per_chunk, unit="step",
                   dynamic_ncols=True, desc="pretrain")
    t_start = time.perf_counter()
    timed_steps, timed_s = 0, 0.0
    last_return = float("nan")  # the progress bar shows the latest finished episodes' return
    chunk = start
    for chunk in range(start + 1, tc.num_chunks + 1):
        if max_chunks is not None and chunk - start > max_chunks:
            chunk -= 1
            break
        t0 = time.perf_counter()
        if fb is None:
            state, m = trainer.train_chunk(state, human_params)
            m = jax.device_get(m)
        else:
            from mjx_protamer.experiments.feedback_train import log_events

            state, fb_state, m, events = fb.chunk(state, fb_state, fb_params)
            m, events = jax.device_get((m, events))
            log_events(fb_log, events, feedback.kind, feedback.config, feedback.config.dt)
        dt = time.perf_counter() - t0
        if chunk > start + 1 or tc.num_chunks - start == 1:  # the first chunk of a process pays the compile
            timed_steps += steps_per_chunk
            timed_s += dt
        row = {"chunk": float(chunk), **run_log.flatten(m, env.reward_term_names),
               "steps_per_s": steps_per_chunk / dt, "wall_s": time.perf_counter() - t_start}
        log.write(row)
        if chunk % tc.checkpoint_every_chunks == 0 or chunk == tc.num_chunks:
            checkpoints.save(mngr, chunk, state)
            if fb is not None:
                checkpoints.save(fb_mngr, chunk, fb_state)
        if bar is not None:
            bar.update(steps_per_chunk)
            if row["episode_return"] == row["episode_return"]:
                last_return = row["episode_return"]
            post = dict(sps=f"{steps_per_chunk / dt:.0f}", ret=f"{last_return:.1f}",
                        contact=f"{row['contact_rate']:.2f}")
            if fb is not None:
                post.update(fb=f"{row['feedback_total']:.0f}", rhat=f"{row['r_hat_mean']:+.2f}")
            bar.set_postfix(**post)
    if bar is not None:
        bar.close()
    log.close()
    if fb is not None:
        from mjx_protamer.experiments.feedback_train import reward_model_bytes

        fb_log.note(event="end", chunk=chunk, totals=[float(x) for x in jax.device_get(fb_state.totals)])
        fb_log.close()
        checkpoints.write_atomic(out / "reward_model.msgpack", reward_model_bytes(fb_state))
        fb_mngr.close()

    result = {
        "out_dir": str(out),
        "config": str(config_path),
        "checkpoint": str(ckpt_dir / str(mngr.latest_step())) if mngr.latest_step() is not None else None,
        "csv": str(log.csv_path),
        "tensorboard": str(out / "tb"),
        "chunks_done": chunk,
        "finished": chunk == tc.num_chunks,
        "train_wall_s": time.perf_counter() - t_start,
        "steps_per_s": timed_steps / timed_s if timed_s > 0 else float("nan"),
        "state": state,
    }
    if fb is not None:
        result.update(feedback_log=str(out / "feedback.jsonl"), reward_model=str(out / "reward_model.msgpack"),
                      feedback_state=fb_state, feedback_kind=feedback.kind)
        if log.rows:
            last = log.rows[-1]
            result["feedback_summary"] = {k: last[k] for k in (
                "feedback_total", "feedback_pos_total", "feedback_neg_total", "credited_rows_total",
                "rm_updates_total", "r_hat_mean", "r_hat_std", "r_hat_score_corr") if k in last}
    if log.rows:
        result["plot"] = str(run_log.plot_curve(log.rows, out / run_log.PLOT_NAME))
    if final_eval and result["finished"]:
        summary = evaluate(config, env, state.actor_params, tc.eval_episodes, eval_seed(config))
        (out / "eval.json").write_text(json.dumps(summary, indent=2))
        result["eval"] = summary
        result["eval_json"] = str(out / "eval.json")
    mngr.close()
    return result


def report(result: dict) -> str:
    """The end-of-run text: the metrics table and where the outputs are."""
    lines = []
    if "eval" in result:
        ev = result["eval"]
        lines += [f"test episodes: {ev['episodes']} (deterministic actor), mean return {ev['episode_return']:.2f}",
                  metrics.format_table(ev, metrics.PAPER_DDPG), ""]
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


class FeedbackSetup:
    """What `run_pretrain(feedback=...)` needs: the simulated channel, the feedback config, the batch sizing."""

    def __init__(self, kind: str, config, batched=None):
        from mjx_protamer.experiments.feedback_train import KINDS, BatchedFeedbackConfig

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
    checkpoints.write_atomic(path, "".join(json.dumps(r, sort_keys=True) + "\n" for r in keep).encode())
