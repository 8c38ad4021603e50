"""`protamer finetune --feedback keyboard --checkpoint PATH`: one env, live, learning from your keys.

Loads the actor and critic of a pretrain run, runs ONE env in short jitted chunks (`--chunk-ms` of
simulated time, 250 ms by default) paced to real time, and between chunks drains the keyboard queue,
credits each accepted event to the steps shown before it and updates the DeepTAMER reward model, whose
params enter the next chunk. Each chunk prints a status line (step, contact, reward, events); each key
press is confirmed at once. On exit (q, end of --seconds, or Ctrl-C) it saves the checkpoint, the reward
model and the feedback log into --out.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "finetune",
        help="fine-tune a pretrained policy live with human feedback (keyboard)",
        description="Runs one env live from a pretrain checkpoint with DDPG + DeepTAMER; press + / - / 0 to "
        "give feedback, q to stop. Saves the checkpoint, reward model and feedback log on exit or Ctrl-C.",
    )
    p.add_argument("--feedback", choices=["keyboard", "simulated:keyboard", "simulated:prosody", "simulated:speech"],
                   default="keyboard", help="where feedback comes from (simulated:* for a dry run without a human)")
    p.add_argument("--checkpoint", type=Path, required=True, help="a pretrain run directory or checkpoint in it")
    p.add_argument("--config", type=Path, default=None, help="feedback YAML (configs/feedback_keyboard.yaml); "
                   "its pretrain section is replaced by the checkpoint's")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a feedback config value, e.g. --set feedback.credit.scheme=time_window")
    p.add_argument("--out", type=Path, default=None, help="output directory (default: runs/finetune-<time>)")
    p.add_argument("--chunk-ms", type=float, default=250.0, help="simulated time per jitted chunk (ms)")
    p.add_argument("--seconds", type=float, default=0.0, help="stop after this long (0: until q or Ctrl-C)")
    p.set_defaults(handler=_finetune)


def _finetune(args: argparse.Namespace) -> int:
    import dataclasses

    import jax

    from mjx_protamer.config import ConfigError, to_dict
    from mjx_protamer.experiments import checkpoints
    from mjx_protamer.experiments.evaluate import load_run
    from mjx_protamer.human.keyboard import KeyboardFeedback
    from mjx_protamer.human.tamer_loop import FeedbackRunConfig, TamerRun, load_feedback_config

    if args.chunk_ms <= 0:
        raise ConfigError("--chunk-ms must be > 0")
    pre, env, loaded, step = load_run(args.checkpoint)
    fb = load_feedback_config(args.config, args.overrides).feedback
    chunk_steps = max(1, round(args.chunk_ms / 1000.0 / fb.dt))
    train = dataclasses.replace(pre.train, num_envs=1, chunk_steps=chunk_steps, warmup_env_steps=0,
                                total_env_steps=max(pre.train.total_env_steps, chunk_steps), num_devices=1)
    ddpg = dataclasses.replace(pre.ddpg, replay_size=max(pre.ddpg.batch_size, 20_000, chunk_steps))
    config = FeedbackRunConfig(pretrain=dataclasses.replace(pre, train=train, ddpg=ddpg),
                               feedback=dataclasses.replace(fb, watch_env=0))
    out = args.out or Path("runs") / time.strftime("finetune-%Y%m%d-%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    run = TamerRun(config, env, feedback=None if args.feedback == "none" else args.feedback,
                   log_path=out / "feedback.jsonl")
    # The pretrained learner, on a fresh single-env state (env batch, noise and replay are new).
    run.state = run.state.replace(**{k: getattr(loaded, k) for k in (
        "actor_params", "critic_params", "target_actor_params", "target_critic_params",
        "actor_opt_state", "critic_opt_state")})
    keys = None
    if args.feedback == "keyboard":
        keys = KeyboardFeedback(run.queue).start()
    print(f"[finetune] from {args.checkpoint} (step {step}); chunks of {chunk_steps} steps "
          f"({chunk_steps * fb.dt * 1000:.0f} ms); output {out}")
    t_end = time.time() + args.seconds if args.seconds > 0 else float("inf")
    try:
        while time.time() < t_end and not (keys and keys.stop_requested.is_set()):
            t0 = time.time()
            m = run.step_chunk(t0=t0 if args.feedback == "keyboard" else None)
            print(f"[step {run.first_step:>7}] contact {float(m['contact_rate']):.2f} "
                  f"reward {float(m['step_reward']):+.3f} events {run.events} "
                  f"credited {run.credited} r_hat updates {run.model.updates}", flush=True)
            if args.feedback == "keyboard":  # show the chunk at real-time pace
                time.sleep(max(0.0, t0 + chunk_steps * fb.dt - time.time()))
    except KeyboardInterrupt:
        print("\n[finetune] interrupted: saving")
    finally:
        if keys is not None:
            keys.stop()
        run.process_events(step=run.first_step - 1)  # whatever arrived last
        mngr = checkpoints.manager(out / "checkpoints")
        checkpoints.save(mngr, run.first_step, jax.device_get(run.state))
        run.model.save(out / "reward_model.msgpack")
        import yaml

        (out / "config.yaml").write_text(yaml.safe_dump(to_dict(config.pretrain), sort_keys=False))
        (out / "feedback_config.yaml").write_text(yaml.safe_dump(to_dict(config.feedback), sort_keys=False))
        run.close()
        print(f"[finetune] saved checkpoint, reward model and feedback log in {out}: {run.queue.stats()}")
    return 0
