"""`protamer pretrain` (batched DDPG pretraining, the main job) and `protamer eval` (the paper's metrics)."""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time
from pathlib import Path

from mjx_protamer.commands.processes import add_process_flags, processes_of, several
from mjx_protamer.compile_cache import enable as enable_compile_cache


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "pretrain",
        help="train the self-touch policy with batched pure-JAX DDPG",
        description="Batched DDPG pretraining. Writes a checkpoint, a CSV, TensorBoard logs, a training-curve "
        "plot and the test metrics into --out. The built-in default finishes in a few minutes on 2 CPU cores. With "
        "--seeds N: seeds 0..N-1, each such a run in OUT/seed_<k>, on one process or several (protamer launch).",
    )
    p.add_argument("--config", type=Path, default=None,
                   help="YAML config (default: the built-in batched default, configs/pretrain.yaml)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a config value, e.g. --set train.num_envs=64 (repeatable)")
    p.add_argument("--out", type=Path, default=None, help="run directory: new or empty, or with --resume the run to "
                   "continue; locked while the run runs (default: runs/pretrain-<time>)")
    p.add_argument("--backend", choices=("auto", "mjx", "native"), default=None,
                   help="physics backend (the same as --set env.backend=...): native MuJoCo on a CPU, MJX on "
                   "an accelerator; auto (the default) picks by JAX's device")
    p.add_argument("--resume", action="store_true", help="continue the run in --out from its last checkpoint")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--feedback", default=None, metavar="simulated:KIND",
                   help="DeepTAMER with a simulated teacher per env, inside the jitted chunk: simulated:keyboard, "
                   "simulated:prosody or simulated:speech (writes feedback.jsonl and reward_model/ too)")
    p.add_argument("--feedback-config", type=Path, default=None,
                   help="configs/feedback_*.yaml, a run config: its `feedback` section (teacher rule, channel, "
                   "credit, reward model; default: configs/feedback_KIND.yaml's) and `batched` section; its "
                   "`pretrain` section is used only without --config; `session` and `coach` (a live session's) are "
                   "checked, unused. --set feedback.X=... / batched.X=... override it")
    p.add_argument("--seeds", default=None, metavar="N", help="train seeds 0..N-1 one after another, each into "
                   "OUT/seed_<k> (the run `--set train.seed=k --out OUT/seed_<k>` gives), and write their test "
                   "metrics with means and 95%% intervals into OUT/seeds.json and seeds.md; --resume keeps the "
                   "finished seeds")
    add_process_flags(p, "jax.distributed, with --seeds: each process trains a contiguous block of the seeds into "
                      "OUT/seed_<k>; process 0 writes seeds.json/seeds.md. `protamer launch` sets these for local "
                      "processes; --resume continues every process", "scripts/pretrain_slurm.sbatch")
    p.set_defaults(handler=_pretrain)

    e = subparsers.add_parser(
        "eval",
        help="the paper's four metrics of a trained policy (deterministic actor)",
        description="Runs test episodes with the deterministic actor of a checkpoint and reports first_touch_step, "
        "contact_rate, unique_regions and freeze_ratio (means and per-episode lists).",
    )
    e.add_argument("--checkpoint", type=Path, required=True,
                   help="a pretrain run directory, its checkpoints/ directory, or one checkpoint step in it")
    e.add_argument("--episodes", default=10, help="test episodes (default 10)")
    e.add_argument("--seed", default=None, help="test-episode seed, 0..2^32-1 (default: the run's eval seed)")
    e.add_argument("--json", action="store_true", help="print JSON instead of a table")
    e.add_argument("--body-map", default=None, metavar="FILE.png|none",
                   help="self-touch runs: write a body map (the infant coloured by how often each region was "
                   "touched) there (default: RUN/body_map.png; 'none' to skip)")
    e.set_defaults(handler=_eval)


MAX_EPISODES = 10_000  # test episodes of one eval or render: each is a whole rollout held in memory
MAX_SEEDS = 100_000  # --seeds N: trained one after another, so only time bounds it


# `--set` keys of a run's other sections (mjx_protamer/human/feedback_config.py FeedbackRunConfig); the rest are
# the PretrainConfig's. Pretraining uses feedback and batched; session and coach are validated, unused.
RUN_SECTIONS = ("feedback", "batched", "session", "coach")


def _pretrain(args: argparse.Namespace) -> int:
    from mjx_protamer.agents.ddpg.config import PretrainConfig
    from mjx_protamer.config import ConfigError, apply_overrides, from_dict, load_config, to_dict

    if args.resume and args.out is None:
        raise ConfigError("--resume needs --out, the run directory to continue")
    seeds = None
    if args.seeds is not None:
        from mjx_protamer.cli_numbers import number
        from mjx_protamer.experiments.pretrain_seeds import check_seed_overrides

        seeds = number("--seeds", args.seeds, 1, MAX_SEEDS, integer=True)
        check_seed_overrides(args.overrides)
    elif several(args):
        raise ConfigError("several processes train a pretrain run's seeds: give --seeds N (each process trains a "
                          "block of seeds 0..N-1)")
    spec = processes_of(args)
    if args.backend is not None:
        args.overrides = list(args.overrides) + [f"env.backend={args.backend}"]
    run_overrides = [o for o in args.overrides if o.split("=", 1)[0].split(".")[0].strip() in RUN_SECTIONS]
    overrides = [o for o in args.overrides if o not in run_overrides]
    if args.feedback is None and (args.feedback_config is not None or run_overrides):
        raise ConfigError(f"--feedback-config and --set {'.*/'.join(RUN_SECTIONS)}.* need --feedback simulated:KIND")
    feedback = None
    if args.feedback is not None:
        feedback, config = _feedback_setup(args.feedback, args.feedback_config, args.config, overrides, run_overrides)
    elif args.config is None:  # overrides apply on top of the whole built-in default, section by section
        config = from_dict(PretrainConfig, apply_overrides(to_dict(PretrainConfig()), overrides))
    else:
        config = load_config(PretrainConfig, args.config, overrides)
    config.ddpg.check_batched("a pretrain run (batched)", "ddpg.")
    out = args.out or Path("runs") / time.strftime("pretrain-%Y%m%d-%H%M%S")
    if seeds is not None:
        return _pretrain_seeds(config, out, seeds, spec, args.resume, not args.no_progress, feedback)
    from mjx_protamer.outdir import claimed

    # --out is checked, created and locked before JAX starts, and stays locked until the run ends
    with claimed(out, KIND, resume=args.resume, own=("config.yaml",)):
        enable_compile_cache()
        from mjx_protamer.errors import write_failed
        from mjx_protamer.experiments.pretrain import last_good_checkpoint, report, run_pretrain

        try:
            result = run_pretrain(config, out, resume=args.resume, progress=not args.no_progress, feedback=feedback)
        except OSError as e:  # a full disk, no permission: one line, and what --resume continues from
            good = last_good_checkpoint(out)
            if good is None:
                raise write_failed(e, out, "no checkpoint had been saved yet",
                                   "start again with a new or empty --out") from None
            raise write_failed(e, out, f"the last good checkpoint is {good}", f"continue with `protamer pretrain "
                               f"--resume --out {out}` (the same --config and --set)") from None
    print(report(result))
    return 0


KIND = "pretrain"  # what outdir.claim records in a pretrain run's directory


def _pretrain_seeds(config, out: Path, seeds: int, spec, resume: bool, progress: bool, feedback) -> int:
    """`pretrain --seeds N` on this process (one, or one of a jax.distributed job); process 0 prints seeds.md."""
    from mjx_protamer.errors import write_failed
    from mjx_protamer.experiments.pretrain_seeds import run_pretrain_seeds

    enable_compile_cache()
    try:
        summary = run_pretrain_seeds(config, out, seeds, spec, resume=resume, progress=progress, feedback=feedback,
                                     seed_kind=KIND)
    except OSError as e:  # a full disk, no permission: one line, and what --resume keeps
        raise write_failed(e, out, f"the finished seeds are kept in {out}/seed_<k>, an unfinished one has its last "
                           "checkpoint", "continue with the same command and --resume") from None
    if summary is None:  # not process 0: its seeds are in the summary process 0 writes
        return 0
    print(Path(summary["seeds_md"]).read_text())
    for key in ("seeds_json", "seeds_md"):
        print(f"{key:<10} {summary[key]}")
    print(f"wall time  {summary['wall_s']:.0f} s")
    return 0


def _feedback_setup(spec: str, feedback_config: Path | None, pretrain_config: Path | None,
                    overrides: list[str], run_overrides: list[str]):
    """(FeedbackSetup, PretrainConfig) of `--feedback simulated:KIND`, from one run config (FeedbackRunConfig,
    loaded and validated whole): --feedback-config, its feedback section the channel's shipped one
    (configs/feedback_KIND.yaml) when it has none, its pretrain section --config's when given (else the built-in
    default when it has none), `--set` on top (pretraining keys with or without `pretrain.`, the other sections'
    by name), and the channel of the flag."""
    import dataclasses

    from mjx_protamer.agents.ddpg.config import PretrainConfig
    from mjx_protamer.config import apply_overrides, from_dict, read_raw, shipped_config, to_dict
    from mjx_protamer.experiments.feedback_train import parse_feedback, step_window_note
    from mjx_protamer.experiments.pretrain import FeedbackSetup
    from mjx_protamer.human.feedback_config import FeedbackRunConfig
    from mjx_protamer.human.teachers import with_channel

    kind = parse_feedback(spec)
    raw = read_raw(feedback_config)
    own_feedback = "feedback" in raw
    if not own_feedback:  # the channel's shipped teacher, credit and reward model
        raw["feedback"] = read_raw(shipped_config(f"feedback_{kind}.yaml"))["feedback"]
    if pretrain_config is not None:
        raw["pretrain"] = read_raw(pretrain_config)
    elif "pretrain" not in raw:
        raw["pretrain"] = to_dict(PretrainConfig())  # overrides apply on top of the whole default, as without one
    # a pretraining key is named in errors as the run's (`pretrain.train.num_envs`), and may be set so too
    overrides = [o if o.startswith("pretrain.") else f"pretrain.{o}" for o in overrides]
    run = from_dict(FeedbackRunConfig, apply_overrides(raw, overrides + run_overrides))
    file_kind = run.feedback.teacher.channel.kind
    fb = dataclasses.replace(run.feedback, teacher=with_channel(run.feedback.teacher, kind))
    if own_feedback and file_kind != kind:
        print(f"note: the feedback config's channel is {file_kind}; --feedback {spec} simulates {kind}",
              file=sys.stderr)
    note = step_window_note(kind, fb.credit, fb.dt)
    if note:
        print(note, file=sys.stderr)
    return FeedbackSetup(kind, fb, run.batched), run.pretrain


def _eval(args: argparse.Namespace) -> int:
    from mjx_protamer.cli_numbers import number, seed

    args.episodes = number("--episodes", args.episodes, 1, MAX_EPISODES, integer=True)
    args.seed = seed("--seed", args.seed)
    if (args.body_map or "").lower() != "none":
        _prepare_body_map_gl(args.checkpoint)
    enable_compile_cache()
    from mjx_protamer.experiments import metrics
    from mjx_protamer.experiments.evaluate import eval_seed, evaluate, load_run

    # Library chatter on stdout must not corrupt --json (mujoco.mjx's warp notice is already dropped: quiet_mjx).
    with contextlib.redirect_stdout(sys.stderr):
        config, env, state, step = load_run(args.checkpoint)
        seed = eval_seed(config) if args.seed is None else args.seed
        summary = evaluate(config, env, state.actor_params, args.episodes, seed)
    summary["checkpoint_step"] = step
    body_map = _body_map(args, config, summary)
    if body_map is not None:
        summary["body_map"] = str(body_map)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(f"checkpoint step {step}, {summary['episodes']} test episodes, mean return {summary['episode_return']:.2f}")
        print(metrics.format_table(summary, metrics.PAPER_DDPG))
        if body_map is not None:
            print(f"body map: {body_map}")
    return 0


def _prepare_body_map_gl(checkpoint) -> None:
    """Pick the OpenGL backend before JAX starts (a missing checkpoint or OpenGL is reported later)."""
    from mjx_protamer.view.gl import GLUnavailable
    from mjx_protamer.view.scenes import prepare_gl_for

    try:
        prepare_gl_for(checkpoint)
    except (GLUnavailable, FileNotFoundError, OSError, ValueError):  # ValueError: CheckpointError
        pass


def _body_map(args, config, summary):
    """The eval's body map (view.bodymap), or None: a toy run, --body-map none, or no offscreen OpenGL
    (then a note on stderr: the metrics still count)."""
    if config.env_name == "toy" or (args.body_map or "").lower() == "none":
        return None
    from mjx_protamer.experiments.run_loader import resolve_checkpoint
    from mjx_protamer.view.bodymap import write_body_map
    from mjx_protamer.view.gl import GLUnavailable

    path = Path(args.body_map) if args.body_map else resolve_checkpoint(args.checkpoint)[0] / "body_map.png"
    try:
        return write_body_map(summary["region_touch_frequency"], path,
                              f"{summary['episodes']} test episodes, checkpoint step {summary['checkpoint_step']}",
                              config.env)
    except (GLUnavailable, OSError, ImportError) as e:
        print(f"note: no body map: {e}", file=sys.stderr)
        return None
