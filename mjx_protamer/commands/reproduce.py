"""`protamer reproduce table2`: the paper's Table II and Figures 1-2 with simulated teachers; `reproduce rescore`:
the agents of a finished table2 run scored again under another teacher rule; `reproduce live`: whether minutes of
a live session steer the infant, per feedback channel (live/effect.py)."""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from pathlib import Path

from mjx_protamer.commands.processes import add_process_flags, processes_of
from mjx_protamer.live.kinds import LEARNERS


def register(subparsers) -> None:
    from mjx_protamer.live.spec import SPEAKER_SOURCES

    p = subparsers.add_parser(
        "reproduce",
        help="reproduce the paper's experiments with simulated teachers",
        description="Reproduce a result of the paper with simulated teachers.",
    )
    sub = p.add_subparsers(dest="experiment", metavar="EXPERIMENT")
    sub.required = True
    t = sub.add_parser(
        "table2",
        help="Table II and Figures 1-2: DDPG vs DeepTAMER with simulated keyboard, speech and prosody teachers",
        description="Trains DDPG, DTK (simulated keyboard), DTW (simulated speech/Whisper channel) and DTP "
        "(simulated prosody) with the same seeds and the same hidden teacher rule, evaluates each on test "
        "episodes with the deterministic actor and writes table2.md/.json (the paper's numbers beside ours), "
        "figure1_training_reward.png and figure2_unique_regions.png.",
    )
    t.add_argument("--config", type=Path, default=None,
                   help="YAML (default: configs/table2_attention.yaml, shipped with the package: "
                   "habituation, the lateral rule (right hand +1, left -1), asinh reward-model inputs; configs/table2.yaml is the "
                   "earlier head rule without habituation, configs/table2_paper.yaml the paper's single-env "
                   "20-episode setting)")
    t.add_argument("--seeds", default=None, help="run seeds 0..N-1 (default: the config's seeds)")
    t.add_argument("--out", type=Path, default=None, help="output directory: new or empty, or with --resume the run "
                   "to continue; locked while the run runs (default: runs/table2-<time>)")
    t.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a config value, e.g. --set pretrain.train.total_env_steps=32000 (repeatable)")
    t.add_argument("--backend", choices=("auto", "mjx", "native"), default=None,
                   help="physics backend (the same as --set pretrain.env.backend=...); auto picks native MuJoCo "
                   "on a CPU, MJX on an accelerator")
    t.add_argument("--resume", action="store_true",
                   help="continue the run in --out: conditions already finished there are kept, not retrained")
    t.add_argument("--quiet", action="store_true", help="no per-chunk progress lines")
    t.add_argument("--conditions-at-once", default=None, metavar="K",
                   help="conditions trained at the same time in this process, each on a host thread (default 2: on "
                   "a 2-core CPU a second condition fills the cores the first leaves idle, 0.78-0.83 of the time "
                   "one after the other; one at a time on several devices, whose collectives two programs could interleave); every "
                   "condition computes what it would alone")
    d = add_process_flags(t, "jax.distributed: each process trains a share of the conditions and seeds (--split) into "
                          "OUT/process_<k>; process 0 gathers the results and writes the table and figures into OUT. "
                          "`protamer launch` sets these for local processes; --resume continues every process",
                          "scripts/table2_slurm.sbatch")
    d.add_argument("--split", choices=("both", "seeds", "conditions"), default=None,
                   help="how the processes share the work: both (default): the conditions in gcd(N, conditions) "
                   "groups, the seeds in blocks for the rest (2 processes, 4 conditions: 2 conditions each, all "
                   "seeds); seeds: every condition on a block of the seeds; conditions: a group of the conditions on "
                   "all the seeds. A process with all the seeds gives bit for bit one process's results")
    t.set_defaults(handler=_table2)
    r = sub.add_parser(
        "rescore",
        help="test a finished table2 run's agents again and score them under another teacher rule",
        description="Runs the test episodes of every finished condition of a table2 run again (its saved agents, "
        "its test seeds) and scores them with the hidden score of another rule, without training: Table II "
        "of the same policies in the eyes of another teacher, with the teacher-score contrasts against the "
        "baseline. Writes table2.json/.md in --out.",
    )
    r.add_argument("run", type=Path, help="the --out directory of a finished `protamer reproduce table2` run")
    r.add_argument("--config", type=Path, default=None,
                   help="a table2 YAML whose feedback.teacher.rule scores the agents (default: the built-in "
                   "default's lateral rule), e.g. configs/table2_tour_right.yaml")
    r.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a value of --config, e.g. --set 'feedback.teacher.rule=[...]' (repeatable)")
    r.add_argument("--out", type=Path, default=None, help="output directory, new or empty (default: "
                   "RUN/rescore-<time>)")
    r.add_argument("--quiet", action="store_true", help="no per-condition progress lines")
    r.set_defaults(handler=_rescore)
    v = sub.add_parser(
        "live",
        help="live sessions with a simulated teacher vs without feedback, from N checkpoints, per channel",
        description="From each checkpoint: a `protamer finetune` session without feedback and one per channel with "
        "a simulated teacher holding a hidden rule (keyboard: unpaced; prosody and whisper: a simulated person "
        "speaking through the real listener at real-time pace); each final actor on the checkpoint's test "
        "episodes; paired differences with 95% CIs, the drift without feedback, the voice pipeline's delivery. "
        "Writes live_effect.json/.md/.png in --out.",
    )
    src = v.add_mutually_exclusive_group(required=True)
    src.add_argument("--checkpoints", type=Path, nargs="+", help="pretrain runs, one per seed")
    src.add_argument("--pretrain-seeds", help="pretrain the main job for seeds 0..N-1 first, as `protamer pretrain "
                     "--seeds N --out OUT/checkpoints` does (finished seeds are kept)")
    src.add_argument("--merge", type=Path, nargs="+", metavar="RUN",
                     help="pool finished runs of one plan over different checkpoints (their --out directories, e.g. "
                     "groups of checkpoints run on different machines) into one result in --out; the plan is "
                     "theirs")
    v.add_argument("--channels", default="keyboard", help="comma-separated: keyboard, prosody, whisper "
                   "(default keyboard)")
    v.add_argument("--minutes", default=2.0, help="shown time per session (default 2)")
    v.add_argument("--snapshot-minutes", default=0.0, help="also score every session's policy at each multiple of "
                   "this many minutes: the effect minute by minute (live_curve.png; default 0: the end only)")
    v.add_argument("--rule-config", type=Path, default=None, help="a table2 YAML whose hidden rule the teacher holds "
                   "(default: the built-in default's lateral rule)")
    v.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="a session setting for every session, e.g. --set pretrain.ddpg.human_actor_coef=0 (the "
                   "paper's alpha r_env + beta r_hat DDPG)")
    v.add_argument("--speaker", choices=tuple(SPEAKER_SOURCES), default="sentences",
                   help="what the simulated speaker of the prosody and whisper sessions says praise and reproach "
                   "in: sentences (default, about one in 1.4 s) or single words (\"yes\", \"no\": about one a "
                   "second)")
    v.add_argument("--episodes", default=10, help="test episodes per actor (default 10)")
    v.add_argument("--parallel", default=1, help="unpaced sessions at once (default 1)")
    v.add_argument("--learner", choices=LEARNERS, default="ddpg",
                   help="ddpg (default): DDPG + DeepTAMER; coach: Deep COACH from the checkpoint's actor (without "
                   "feedback it does not learn: its no-feedback arm is the start)")
    v.add_argument("--out", type=Path, required=True, help="output directory: new, empty, or one this command wrote "
                   "before (its finished sessions are kept)")
    v.set_defaults(handler=_live)


# What outdir.claim records in each command's --out, and the files that identify a directory written before claims
# existed (a table2 run's are named after its conditions: see _table2)
TABLE2, RESCORE, LIVE = "table2", "rescore", "live-effect"
MAX_SEEDS = 100_000  # --seeds N runs seeds 0..N-1 side by side; the memory estimate decides how many fit


def _table2(args: argparse.Namespace) -> int:
    from mjx_protamer.cli_numbers import number
    from mjx_protamer.compile_cache import enable as _enable_compile_cache
    from mjx_protamer.experiments.table2 import load_table2_config

    from mjx_protamer.experiments.table2 import AT_ONCE

    seeds = None if args.seeds is None else number("--seeds", args.seeds, 1, MAX_SEEDS, integer=True)
    at_once = AT_ONCE if args.conditions_at_once is None else number("--conditions-at-once", args.conditions_at_once,
                                                                     1, 64, integer=True)
    overrides = list(args.overrides) + ([f"pretrain.env.backend={args.backend}"] if args.backend else [])
    cfg = load_table2_config(args.config, overrides, seeds)
    if args.resume and args.out is None:
        from mjx_protamer.config import ConfigError
        raise ConfigError("--resume needs --out: the directory of the table2 run to continue")
    out = args.out or Path("runs") / time.strftime("table2-%Y%m%d-%H%M%S")
    own = ("table2.json",) + tuple(f"condition_{c.name}.json" for c in cfg.conditions)
    from mjx_protamer.outdir import claimed

    spec = processes_of(args)
    if spec is None and args.split is not None:
        from mjx_protamer.config import ConfigError
        raise ConfigError("--split shares the work of several processes; give it with protamer launch, "
                          "--distributed or --coordinator")
    if spec is not None:
        return _table2_processes(args, cfg, spec, own, at_once)
    if args.resume and (out / "processes.json").is_file():
        from mjx_protamer.config import ConfigError
        raise ConfigError(f"--resume: {out} is a run of several processes ({out / 'processes.json'}); continue it "
                          "with the same `protamer launch --processes N` (or --distributed) and --resume")
    with claimed(out, TABLE2, resume=args.resume, own=own):  # checked and locked before JAX starts, until the end
        _enable_compile_cache()
        from mjx_protamer.experiments.table2 import run_table2

        try:
            with contextlib.redirect_stdout(sys.stderr) if args.quiet else contextlib.nullcontext():
                result = run_table2(cfg, out, progress=not args.quiet, resume=args.resume, at_once=at_once)
        except OSError as e:  # a full disk, no permission: one line, and what --resume keeps
            raise _table2_write_failed(e, out, cfg) from None
    _print_table2(result, cfg)
    return 0


def _table2_processes(args: argparse.Namespace, cfg, spec, own, at_once: int) -> int:
    """This process's part of a table2 run on several processes; process 0 prints the table."""
    from mjx_protamer.compile_cache import enable as _enable_compile_cache
    from mjx_protamer.errors import write_failed
    from mjx_protamer.experiments.distributed import run_table2_processes

    _enable_compile_cache()
    try:
        with contextlib.redirect_stdout(sys.stderr) if args.quiet else contextlib.nullcontext():
            result = run_table2_processes(cfg, args.out, spec, progress=not args.quiet, resume=args.resume,
                                          claim_kind=TABLE2, own=own, split=args.split or "both", at_once=at_once)
    except OSError as e:  # a full disk, no permission: one line, and what --resume keeps
        raise write_failed(e, args.out, f"the conditions each process finished are kept in {args.out}/process_<k>",
                           "continue with the same command and --resume") from None
    if result is None:  # not process 0: its seeds are in the table process 0 writes
        return 0
    _print_table2(result, cfg)
    return 0


def _print_table2(result: dict, cfg) -> None:
    """The table, the per-condition body maps (drawn here: a body map renders the infant, which is the view's, and
    the run's library sits below it) and the files written."""
    from mjx_protamer.view.bodymap import write_condition_body_maps

    print(Path(result["table_md"]).read_text())
    write_condition_body_maps(cfg.pretrain, result["region_frequencies"], result["out_dir"])
    for key in ("table_md", "table_json", "figure1", "figure2", "training_csv"):
        print(f"{key:<13} {result[key]}")
    print(f"wall time     {result['wall_s']:.0f} s")


def _table2_write_failed(e: OSError, out: Path, cfg):
    """The one line of a table2 run stopped by a failed write: its checkpoints are the finished conditions."""
    from mjx_protamer.errors import write_failed

    done = [c.name for c in cfg.conditions if (out / f"condition_{c.name}.json").is_file()]
    kept = (f"the conditions finished before it are kept ({', '.join(done)}: {out}/condition_<name>.json and "
            f"their agents)" if done else "no condition had finished yet")
    return write_failed(e, out, kept, f"continue with `protamer reproduce table2 --resume --out {out}` (the same "
                                      "--config, --set and --seeds)")


def _rescore(args: argparse.Namespace) -> int:
    from mjx_protamer.compile_cache import enable as _enable_compile_cache
    from mjx_protamer.config import ConfigError
    from mjx_protamer.experiments.table2 import load_table2_config
    from mjx_protamer.outdir import claimed

    if not (args.run / "config.yaml").is_file():
        raise ConfigError(f"{args.run / 'config.yaml'} is missing: give the --out directory of a table2 run")
    load_table2_config(args.config, args.overrides)  # a bad --config or --set: refused before --out is made
    out = args.out if args.out is not None else args.run / time.strftime("rescore-%Y%m%d-%H%M%S")
    with claimed(out, RESCORE, resumable=False):
        _enable_compile_cache()
        from mjx_protamer.experiments.rescore import rescore_table2

        try:
            with contextlib.redirect_stdout(sys.stderr) if args.quiet else contextlib.nullcontext():
                result = rescore_table2(args.run, args.config, out, args.overrides, progress=not args.quiet)
        except OSError as e:  # a full disk, no permission: one line
            from mjx_protamer.errors import write_failed

            raise write_failed(e, out, f"the run {args.run} is untouched", "rescore it again into a new --out") \
                from None
    print(Path(result["table_md"]).read_text())
    for key in ("table_md", "table_json"):
        print(f"{key:<13} {result[key]}")
    return 0


def _live_merge(args: argparse.Namespace) -> int:
    from mjx_protamer.config import ConfigError
    from mjx_protamer.live.merge import check_runs, merge_live_effects
    from mjx_protamer.outdir import claimed, kind_of

    def differs(value, default) -> bool:
        if isinstance(default, (int, float)):
            try:
                return float(value) != float(default)
            except (TypeError, ValueError):
                return True
        return value != default

    plan_flags = (("--channels", args.channels, "keyboard"), ("--minutes", args.minutes, 2.0),
                  ("--rule-config", args.rule_config, None), ("--set", args.overrides, []),
                  ("--speaker", args.speaker, "sentences"), ("--episodes", args.episodes, 10),
                  ("--parallel", args.parallel, 1), ("--learner", args.learner, "ddpg"),
                  ("--snapshot-minutes", args.snapshot_minutes, 0.0))
    given = [flag for flag, value, default in plan_flags if differs(value, default)]
    if given:
        raise ConfigError(f"--merge pools runs with the plan they ran; leave out {', '.join(given)}")
    out = args.out
    check_runs(args.merge, out)
    # a pooled result written before is replaced; a run with sessions never is (its --out must be new or empty)
    ours = out.is_dir() and kind_of(out) == LIVE and "merged_from" in _read_json(out / "live_effect.json")
    with claimed(out, LIVE, resume=ours):
        try:
            summary = merge_live_effects(args.merge, out, " ".join(sys.argv))
        except OSError as e:  # a full disk, no permission: one line
            from mjx_protamer.errors import write_failed

            raise write_failed(e, out, "the runs it pools are untouched", "run the same command again") from None
    print((out / "live_effect.md").read_text())
    figures = f"{out / 'live_effect.png'}" + (f", {out / 'live_curve.png'}" if "curve" in summary else "")
    print(f"json {out / 'live_effect.json'}\nfigure {figures}")
    return 0


def _read_json(path: Path) -> dict:
    import json

    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _live(args: argparse.Namespace) -> int:
    from mjx_protamer.cli_numbers import number
    from mjx_protamer.config import ConfigError
    from mjx_protamer.live.effect import CHANNELS, Plan, pretrain_checkpoints, run_live_effect
    from mjx_protamer.live.spec import check_config_file
    from mjx_protamer.outdir import claimed, kind_of

    if args.merge:
        return _live_merge(args)
    channels = tuple(c.strip() for c in args.channels.split(",") if c.strip())
    bad = [c for c in channels if c not in CHANNELS]
    if bad or not channels:
        raise ConfigError(f"--channels: {', '.join(bad) or 'none given'}; use keyboard, prosody and/or whisper")
    check_config_file(args.rule_config, "--rule-config")
    if args.speaker != "sentences" and not {"prosody", "whisper"} & set(channels):
        raise ConfigError(f"--speaker {args.speaker}: only the prosody and whisper sessions have a speaker; add one "
                          "of them to --channels or leave --speaker out")
    minutes = number("--minutes", args.minutes, 0.01, 600)
    snapshot_minutes = number("--snapshot-minutes", args.snapshot_minutes, 0.0, 600)
    episodes = number("--episodes", args.episodes, 1, 1000, integer=True)
    parallel = number("--parallel", args.parallel, 1, 64, integer=True)
    seeds = None if args.pretrain_seeds is None else number("--pretrain-seeds", args.pretrain_seeds, 2, 1000, True)
    if seeds is None:
        missing = [c for c in args.checkpoints if not (Path(c) / "config.yaml").is_file()]
        if missing:
            raise ConfigError(f"--checkpoints: {missing[0]} is not a pretrain run directory (no config.yaml)")
    # A directory this command wrote before is continued (its finished sessions are kept); anything else must be
    # new or empty. `own`: what a live-effect directory written before claims existed holds.
    out = args.out
    own = ("live_effect.json", "none_0", "checkpoints/seed_0", "checkpoints/seed0")  # seed0: the layout of older runs
    ours = out.is_dir() and (kind_of(out) == LIVE or (kind_of(out) is None and any((out / f).exists() for f in own)))
    with claimed(out, LIVE, resume=ours, own=own):
        try:
            if seeds is not None:
                from mjx_protamer.compile_cache import enable as enable_compile_cache

                enable_compile_cache()
            checkpoints = pretrain_checkpoints(out, seeds) if seeds is not None else args.checkpoints
            plan = Plan(tuple(Path(c) for c in checkpoints), out, channels, minutes, 250.0, args.rule_config,
                        tuple(args.overrides), episodes, parallel, args.learner, snapshot_minutes, args.speaker)
            summary = run_live_effect(plan)
        except OSError as e:  # a full disk, no permission: one line
            from mjx_protamer.errors import write_failed

            raise write_failed(e, out, "the sessions finished before it are kept (their directories hold DONE)",
                               "run the same command again: it continues") from None
    print((out / "live_effect.md").read_text())
    figures = f"{out / 'live_effect.png'}" + (f", {out / 'live_curve.png'}" if "curve" in summary else "")
    print(f"json {out / 'live_effect.json'}\nfigure {figures}\nwall {summary['wall_s']:.0f} s")
    return 0
