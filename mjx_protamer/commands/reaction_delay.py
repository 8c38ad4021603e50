"""`protamer reaction-delay SESSION`: a person's reaction delay, measured from a recorded finetune session,
as the channel values credit should use. No JAX (human/reaction_delay.py holds the model)."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "reaction-delay",
        help="measure a person's reaction delay from a recorded finetune session",
        description="Fits the delay from the onsets of a touch (as the session showed them) to the onsets of the "
        "feedback that reacted to them, in a `protamer finetune` session where the person gave feedback each "
        "time they saw that touch begin (docs/human_feedback.md, 'Measuring your reaction delay'). Prints the "
        "delay's mean, spread and fastest reactions, and the --set values that make credit use them.",
    )
    p.add_argument("session", type=Path, help="the --out directory of a `protamer finetune` session (self-touch)")
    p.add_argument("--touch", default=None,
                   help="the touch the person reacted to: a body region (hip, lower_body, upper_body, head, "
                   "left/right_upper_arm, left/right_lower_arm) or left_hand / right_hand (default: the session's "
                   "--calibrate touch, else head: the pretrained infant's hands rest on its body most of the time, "
                   "so a hand's touch seldom begins; a hand arriving at the head does, every few seconds)")
    p.add_argument("--sign", choices=("+", "-", "any"), default="any",
                   help="count only praise (+), only reproach (-) or any nonzero feedback (default)")
    p.add_argument("--window-s", type=float, nargs=2, default=None, metavar=("LO", "HI"),
                   help="shortest and longest delay that can be a reaction (default 0.1 2.5)")
    p.add_argument("--min-gap-s", type=float, default=None,
                   help="a touch begins after at least this long without it (default 0.1: chatter is one touch)")
    p.add_argument("--json", type=Path, default=None, help="write the fit, per feedback, to this JSON file")
    p.add_argument("--plot", type=Path, default=None, help="write a PNG of the delays and the fitted distribution")
    p.set_defaults(handler=_reaction_delay)


def _reaction_delay(args: argparse.Namespace) -> int:
    from mjx_protamer.live.reaction_delay import measure

    return measure(args.session, args.touch, args.sign, args.window_s, args.min_gap_s, args.json, args.plot)
