"""`protamer analyze NAME`: the analyses the docs cite (mjx_protamer/analyze/, whose docstrings say what each
prints). Argument parsing only; each handler imports its analysis, so `protamer --help` stays fast."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "analyze",
        help="analyses of finished runs and recorded sessions that the docs cite",
        description="Analyses of finished runs and recorded sessions that the docs cite; "
        "mjx_protamer/analyze/<name>.py says what each prints.",
    )
    sub = p.add_subparsers(dest="analysis", metavar="ANALYSIS")
    sub.required = True
    for add in (_compare_conditions, _diagnose_reward_labels, _freeze_anatomy, _freeze_through_training,
                _r_hat_on_test_states, _reaction_delay_check):
        add(sub)


def _compare_conditions(sub) -> None:
    c = sub.add_parser(
        "compare-conditions", help="conditions of several table2 runs pooled by name, paired against a reference",
        description="Pools every condition by name over the runs' table2.json (a seed given twice for one name is "
        "an error) and prints JSON: per condition and metric the mean, the 95% half-width and the per-seed "
        "values, and with --reference each condition's difference to it, unpaired and paired over the seeds "
        "both ran.")
    c.add_argument("runs", nargs="+", help="--out directories of finished table2 runs (or rescores); DIR@TAG "
                   "names that run's conditions NAME@TAG")
    c.add_argument("--names", default=None, help="conditions to show, comma-separated, in this order (default: all)")
    c.add_argument("--reference", default=None, help="the condition the others are paired against")
    c.add_argument("--metric", action="append", default=None,
                   help="repeatable (default: teacher_score, r_hat_corr_test, unique_regions, freeze_ratio)")
    c.add_argument("--plot", type=Path, default=None, help="write a PNG of the per-seed values")
    c.set_defaults(handler=_run_compare_conditions)


def _run_compare_conditions(args: argparse.Namespace) -> int:
    from mjx_protamer.analyze import compare_conditions as cc

    metrics = tuple(args.metric or cc.DEFAULT_METRICS)
    try:
        result = cc.compare_runs(args.runs, args.names.split(",") if args.names else None, metrics, args.reference)
    except ValueError as e:
        print(f"protamer analyze compare-conditions: {e}", file=sys.stderr)
        return 2
    if args.plot:
        result["plot"] = str(cc.plot(result, metrics, args.plot))
    print(json.dumps(result, indent=1))
    return 0


def _diagnose_reward_labels(sub) -> None:
    d = sub.add_parser(
        "diagnose-reward-labels", help="what limits the reward model: the states it is fitted on or the labels",
        description="collect: train one seed of a table2 condition as `protamer reproduce table2` does and record "
        "its steps and the teacher's output; fit: fit fresh reward models offline on the recorded runs, with the "
        "teacher's labels or labels an oracle corrected (variants NAME:SILENCE_WEIGHT[:balanced][:em], NAME one "
        "of teacher, exact, no_mistakes, attentive; mjx_protamer/analyze/diagnose_reward_labels.py).")
    steps = d.add_subparsers(dest="step", metavar="STEP")
    steps.required = True
    c = steps.add_parser("collect", help="train one seed and record its steps and the teacher's output")
    c.add_argument("--config", type=Path, default=Path("configs/table2_habituation.yaml"))
    c.add_argument("--condition", default="DTK")
    c.add_argument("--seed", type=int, default=0)
    c.add_argument("--out", type=Path, required=True)
    c.set_defaults(handler=_run_collect)
    f = steps.add_parser("fit", help="refit reward models offline on recorded runs, one JSON line per variant")
    f.add_argument("data", nargs="+", type=Path, help="the .npz of `collect`, one per seed")
    f.add_argument("--variants", default="teacher:0.03:balanced,teacher:0.03,teacher:1,exact:1,no_mistakes:1,"
                                         "attentive:1,attentive:0.03:balanced")
    f.add_argument("--updates", type=int, default=10_000)
    f.add_argument("--learning-rate", type=float, default=1e-3)
    f.add_argument("--hidden", type=int, nargs="+", default=[256, 256])
    f.add_argument("--seed", type=int, default=0)
    f.add_argument("--em-rounds", type=int, default=2, help="variants ending :em: reweight-and-refit rounds")
    f.add_argument("--em-temperature", type=float, default=3.0)
    f.set_defaults(handler=_run_fit)


def _run_collect(args: argparse.Namespace) -> int:
    from mjx_protamer.analyze import diagnose_reward_labels as drl

    drl.collect(args.config, args.condition, args.seed, args.out)
    return 0


def _run_fit(args: argparse.Namespace) -> int:
    from mjx_protamer.analyze import diagnose_reward_labels as drl

    drl.fit(args.data, drl.FitOptions(args.variants, args.updates, args.learning_rate, tuple(args.hidden), args.seed,
                                      args.em_rounds, args.em_temperature))
    return 0


def _finished_run(sub, name: str, help: str, handler) -> None:
    """An analysis of a finished `protamer reproduce table2` run's condition: `RUN [--condition DTK]`."""
    p = sub.add_parser(name, help=help, description=help + " (one JSON line a seed).")
    p.add_argument("run", type=Path, help="the --out directory of a finished table2 run")
    p.add_argument("--condition", default="DTK")
    p.set_defaults(handler=handler)


def _freeze_anatomy(sub) -> None:
    _finished_run(sub, "freeze-anatomy", "what a frozen test policy is doing: its actions, servo torques, touch, "
                  "reward model and critic on its still and moving test states", _run_freeze_anatomy)


def _run_freeze_anatomy(args: argparse.Namespace) -> int:
    from mjx_protamer.analyze.freeze_anatomy import anatomy

    for line in anatomy(args.run, args.condition):
        print(json.dumps(line))
    return 0


def _r_hat_on_test_states(sub) -> None:
    _finished_run(sub, "r-hat-on-test-states", "where a table2 run's reward models err on their own test states",
                  _run_r_hat_on_test_states)


def _run_r_hat_on_test_states(args: argparse.Namespace) -> int:
    from mjx_protamer.analyze.r_hat_on_test_states import r_hat_on_test_states

    for line in r_hat_on_test_states(args.run, args.condition):
        print(json.dumps(line))
    return 0


def _freeze_through_training(sub) -> None:
    t = sub.add_parser(
        "freeze-through-training", help="when the test policy freezes: one seed's DDPG, trained chunk by chunk",
        description="Trains one seed of a table2 config's DDPG chunk by chunk; every --every chunks it prints the "
        "share of slow arm steps (below env.freeze_speed) of the quiet and the noisy envs in that chunk, and of "
        "--episodes test episodes of the deterministic actor at that point.")
    t.add_argument("--config", type=Path, default=Path("configs/table2.yaml"))
    t.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="config override, as for protamer reproduce")
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--every", type=int, default=10, help="chunks between reports")
    t.add_argument("--episodes", type=int, default=4, help="test episodes per report")
    t.set_defaults(handler=_run_freeze_through_training)


def _run_freeze_through_training(args: argparse.Namespace) -> int:
    from mjx_protamer.analyze.freeze_through_training import freeze_through_training

    freeze_through_training(args.config, args.overrides, args.seed, args.every, args.episodes,
                            report=lambda row: print(json.dumps(row), flush=True))
    return 0


def _reaction_delay_check(sub) -> None:
    from mjx_protamer.human.reaction_delay import MIN_GAP_S

    r = sub.add_parser(
        "reaction-delay-check", help="`protamer reaction-delay`'s fit against the truth, on recorded sessions",
        description="Without --person: the sessions' own simulated feedback, whose true delays are known, against "
        "the fit. With --person KIND: --seeds simulated persons a session, reacting to the touches it showed with "
        "the channel KIND's reaction delay, against the fit.")
    r.add_argument("sessions", nargs="+", type=Path)
    r.add_argument("--touch", default="head")
    r.add_argument("--min-gap-s", type=float, default=MIN_GAP_S)
    r.add_argument("--out", type=Path, default=None)
    r.add_argument("--person", choices=("keyboard", "prosody", "speech"), default=None)
    r.add_argument("--seeds", type=int, default=10)
    r.add_argument("--person-gap-s", type=float, default=MIN_GAP_S)
    r.add_argument("--miss", type=float, default=0.15)
    r.add_argument("--unrelated", type=float, default=0.1)
    r.set_defaults(handler=_run_reaction_delay_check)


def _run_reaction_delay_check(args: argparse.Namespace) -> int:
    from mjx_protamer.analyze.reaction_delay_check import report

    # the command line as given, written beside the results it made
    command = "protamer " + " ".join(sys.argv[1:])
    return report(args.sessions, args.touch, args.min_gap_s, args.out, args.person, args.seeds, args.person_gap_s,
                  args.miss, args.unrelated, command)
