"""`protamer finetune --replay SESSION --out DIR`: rerun a recorded session headless, bit for bit.

The session's record (human/session_record.py) holds the checkpoint and its hash, the configs and, for
every drain of the feedback queue, the events drained and the step times. The same learner is built
(`feedback._build_run`), runs the same chunks with those step times, and each drain gets the recorded
events (`ScriptedQueue`): the same computations on the same inputs, so the same final parameters.
"""

from __future__ import annotations

from pathlib import Path

from mjx_protamer.commands.feedback import (_build_run, _coach_args_from, _fail, _live_env, _load, _save,
                                           _with_feedback_channel)


def replay(args) -> int:
    """Rerun a recorded session headless (`--replay SESSION --out DIR`): the same checkpoint, configs and
    chunks, and each drain of the queue given the events the session drained then."""
    from mjx_protamer.config import ConfigError
    from mjx_protamer.human.session_record import ScriptedQueue, read_session, tree_sha256
    from mjx_protamer.human.tamer_loop import load_feedback_config

    if args.out is None:
        raise ConfigError("--replay needs --out, a new directory for the rerun")
    try:
        manifest, records = read_session(args.replay)
    except FileNotFoundError as e:
        return _fail(f"--replay: {e}")
    if manifest.get("resumed"):
        return _fail(f"--replay: the session in {args.replay} was resumed (--resume); a replay reruns sessions "
                     f"that ran from their start in one go")
    if args.out.absolute() == args.replay.absolute():
        return _fail("--replay: --out must be a new directory, not the session's own")
    step_dir = Path(manifest["checkpoint_step_dir"])
    if not step_dir.is_dir() or tree_sha256(step_dir) != manifest["checkpoint_sha256"]:
        return _fail(f"--replay: the session started from {step_dir}, which is missing or has changed "
                     f"(SHA-256 differs); a replay needs the very same checkpoint")
    args.learner = manifest["learner"]
    args.checkpoint = step_dir
    _coach_args_from(manifest, args)
    args.fresh_replay = not manifest.get("replay_from_checkpoint", False)  # sessions before 5 Dec.: empty
    args.coach_policy = Path(manifest["coach_policy"]) if manifest["coach_policy"] else None
    args.resume = False
    chunks = [r for r in records if "chunk" in r]
    final = [r["events"] for r in records if r.get("final")]
    drains = [r["events"] for r in chunks] + (final[:1] or [[]])
    from mjx_protamer.commands.train import _enable_compile_cache

    _enable_compile_cache()
    pre, env, loaded, step = _load(args, step_dir)
    if manifest.get("env_backend"):  # sessions recorded before the live env had its own backend ran on the
        pre, env, loaded, step = _live_env(pre, env, loaded, step, manifest["env_backend"])  # checkpoint's
    fb = _with_feedback_channel(load_feedback_config(manifest["config"], manifest["overrides"]).feedback,
                                manifest["feedback"])
    args.out.mkdir(parents=True, exist_ok=True)
    mode = None if manifest["feedback"] == "none" else "queue"
    weights = manifest.get("reward_weights")  # None: recorded before sessions had their own (the checkpoint's)
    run, saved_config = _build_run(args, pre, env, loaded, step, fb, manifest["chunk_steps"], args.out, mode,
                                   queue=ScriptedQueue(drains), weights=tuple(weights) if weights else None)
    print(f"[replay] {manifest['learner']} session of {len(chunks)} chunks, "
          f"{sum(len(d) for d in drains)} events, from {step_dir}", flush=True)
    for r in chunks:
        run.step_chunk(t0=r["t0"])
    run.process_events(step=max(0, run.first_step - 1))
    _save(run, args.out, args.learner, saved_config)
    print(f"[replay] done: step {run.first_step}, {run.events} events; saved in {args.out}", flush=True)
    return 0
