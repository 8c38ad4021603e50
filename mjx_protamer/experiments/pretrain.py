"""The host loop of `protamer pretrain`: jitted chunks, and between them logs, progress and checkpoints.

Everything random lives in the TrainState, and a checkpoint holds all of it (learner, env batch, replay,
RNG), so `resume=True` continues from the last checkpoint exactly as if the run had never stopped.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import jax
import yaml

from mjx_protamer.config import ConfigError, to_dict
from mjx_protamer.experiments import checkpoints, metrics, run_log
from mjx_protamer.experiments.evaluate import CONFIG_NAME, eval_seed, evaluate


def run_pretrain(
    config,
    out_dir: str | Path,
    resume: bool = False,
    progress: bool = True,
    max_chunks: int | None = None,
    human_reward_fn=None,
    human_params=None,
    final_eval: bool = True,
) -> dict:
    """Train DDPG from `config` (a PretrainConfig) into `out_dir`; return the outputs and final metrics.

    `max_chunks` stops after that many chunks of this call (as a kill would; used to test resume).
    """
    from mjx_protamer.agents.ddpg.train import make_train
    from mjx_protamer.experiments.env_factory import make_env

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ckpt_dir = out / "checkpoints"
    config_path = out / CONFIG_NAME
    saved = to_dict(config)
    mngr = checkpoints.manager(ckpt_dir)
    latest = mngr.latest_step()
    if resume:
        if config_path.is_file() and yaml.safe_load(config_path.read_text()) != saved:
            raise ConfigError(f"--resume: the config differs from the one saved in {config_path}")
    elif latest is not None:
        raise ConfigError(f"{out} already holds a run (checkpoint {latest}); pass --resume or another --out")
    config_path.write_text(yaml.safe_dump(saved, sort_keys=False))

    tc = config.train
    env = make_env(config)
    trainer = make_train(config, env, human_reward_fn=human_reward_fn)
    state = trainer.init(jax.random.PRNGKey(tc.seed))
    start = 0
    if resume and latest is not None:
        state = checkpoints.restore(mngr, latest, state)
        start = latest
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
        state, m = trainer.train_chunk(state, human_params)
        m = jax.device_get(m)
        dt = time.perf_counter() - t0
        if chunk > start + 1 or tc.num_chunks - start == 1:  # the first chunk of a process pays the compile
            timed_steps += steps_per_chunk
            timed_s += dt
        row = {"chunk": float(chunk), **run_log.flatten(m, env.reward_term_names),
               "steps_per_s": steps_per_chunk / dt, "wall_s": time.perf_counter() - t_start}
        log.write(row)
        if chunk % tc.checkpoint_every_chunks == 0 or chunk == tc.num_chunks:
            checkpoints.save(mngr, chunk, state)
        if bar is not None:
            bar.update(steps_per_chunk)
            if row["episode_return"] == row["episode_return"]:
                last_return = row["episode_return"]
            bar.set_postfix(sps=f"{steps_per_chunk / dt:.0f}", ret=f"{last_return:.1f}",
                            contact=f"{row['contact_rate']:.2f}")
    if bar is not None:
        bar.close()
    log.close()

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
    for key in ("checkpoint", "config", "csv", "tensorboard", "plot", "eval_json"):
        if result.get(key):
            lines.append(f"{key:<12} {result[key]}")
    return "\n".join(lines)
