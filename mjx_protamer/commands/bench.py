"""`protamer bench env|train|live|voice [--json]`: speed benchmarks that print their figures.

Each benchmark lives with what it measures (experiments/bench_env.py, experiments/bench_train.py,
audio_frontend/bench.py); this module only wires them to the command line and prints the result.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import sys

# name -> (module, function that returns the JSON-able result)
BENCHMARKS = {
    "env": ("mjx_protamer.experiments.bench_env", "run_env_benchmark",
            "MJX and native-physics env steps/s at several batch sizes vs MJX physics, native MuJoCo and the twin"),
    "train": ("mjx_protamer.experiments.bench_train", "run_train_benchmark",
              "DDPG training steps/s (single env, batched; MJX and native) with the single-env roofline, vs SB3"),
    "live": ("mjx_protamer.experiments.bench_live", "run_live_benchmark",
             "a paced live session with the web view and the Whisper listener (the simulated speaker): real-time "
             "factor, updates per shown step, view frames/s, listener latency"),
    "tracking": ("mjx_protamer.experiments.tracking", "run_tracking_benchmark",
                 "position-servo tracking error on held random targets (free space and blocked)"),
    "voice": ("audio_frontend.bench", "run_voice_benchmark",
              "latency from end of utterance to feedback event, prosody and Whisper"),
    "vad": ("audio_frontend.vad_compare", "run_vad_benchmark",
            "misses and false alarms of the rms, webrtc and silero VADs on synthesised sessions with noise"),
}


def _print_table(result: dict, prefix: str = "") -> None:
    for key, value in result.items():
        if isinstance(value, dict):
            _print_table(value, prefix + key + ".")
        else:
            print(f"{prefix + key:48s} {value}")


def _run(args: argparse.Namespace) -> int:
    module, func, _ = BENCHMARKS[args.benchmark]
    # Libraries print notices on stdout (mujoco.mjx: "Failed to import warp"); keep stdout for the result.
    with contextlib.redirect_stdout(sys.stderr):
        result = getattr(importlib.import_module(module), func)(args)
    if args.json:
        print(json.dumps(result, indent=2, sort_keys=True))
    else:
        _print_table(result)
    return 0


def register(sub) -> None:
    parser = sub.add_parser("bench", help="speed benchmarks (printed as a table or JSON)")
    benches = parser.add_subparsers(dest="benchmark", metavar="BENCHMARK")
    benches.required = True
    for name, (module, _, help_text) in BENCHMARKS.items():
        p = benches.add_parser(name, help=help_text)
        p.add_argument("--json", action="store_true", help="print one JSON object")
        # Argument definitions are light (no JAX/torch at import) in each benchmark module.
        importlib.import_module(module).add_arguments(p)
        p.set_defaults(handler=_run)
