"""`protamer pretrain --seeds N`: the run for seeds 0..N-1, each into `OUT/seed_<k>`, on one process or several.

Each `OUT/seed_<k>` is an ordinary pretrain run directory, bit for bit what `protamer pretrain --set
train.seed=k --out OUT/seed_<k>` writes (the same config, checkpoints and test metrics), so `eval`, `render` and
`finetune --checkpoint OUT/seed_<k>` take it as it is. OUT gets `seeds.json` (each seed's test metrics, their
means with 95% intervals, which process trained each seed and how long it took) and `seeds.md`.

A process trains its seeds one after another, each with `run_pretrain`: a seed's run is then the one-seed
program of the plain command, so its results are the same whatever the number of seeds or processes. Vmapping
the seeds in one program would give other results (another program layout) and buys little on a CPU: `protamer
bench train` measured the main job's trainer at 0.64 of its roofline for one seed against 0.56 for 5 seeds
vmapped.

On several processes (`experiments/distributed.py`), each trains a contiguous block of the seeds
(`work_split.seed_blocks`) into its own `OUT/seed_<k>`, after process 0 has claimed OUT; the per-seed summaries
go to process 0 through the job's collective (hosts need not share a file system), and process 0 writes the
summary. `processes.json` records the blocks; `--resume` keeps every finished seed (its test metrics written),
continues an unfinished one from its last checkpoint, starts the others, and refuses another split of the seeds
(another --processes or --seeds).

Host I/O only: the training is `experiments.pretrain`'s.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import time
from pathlib import Path

from mjx_protamer.atomic import write_atomic
from mjx_protamer.config import ConfigError
from mjx_protamer.errors import DistributedError
from mjx_protamer.experiments import distributed
from mjx_protamer.experiments.stats import seed_stats
from mjx_protamer.experiments.work_split import seed_blocks

SEEDS_KIND = "pretrain-seeds"  # what outdir.claim records in OUT
SUMMARY_JSON, SUMMARY_MD = "seeds.json", "seeds.md"
# The paper's test metrics and the test return, as `evaluate` reports them; the arrows: which way is better
METRICS = {"first_touch_step": "↓", "contact_rate": "↑", "unique_regions": "↑", "freeze_ratio": "↓",
           "episode_return": "↑"}


def seed_dir(out: str | Path, seed: int) -> Path:
    return Path(out) / f"seed_{seed}"


def seed_config(config, seed: int):
    """The run config of one seed: `config` with `train.seed` set, as `--set train.seed=<seed>` gives."""
    return dataclasses.replace(config, train=dataclasses.replace(config.train, seed=seed))


def run_pretrain_seeds(config, out: str | Path, seeds: int, spec=None, resume: bool = False, progress: bool = True,
                       feedback=None, seed_kind: str = "pretrain") -> dict | None:
    """Seeds 0..`seeds`-1 of the pretrain `config` (a PretrainConfig; `feedback` as `run_pretrain` takes it) into
    `out`/seed_<k>, each directory claimed as a `seed_kind` run (what `protamer pretrain` claims its --out as).
    `spec`: None for one process, or the `distributed.Processes` job this process joins and trains its block of
    the seeds in. Process 0 returns the summary (`seeds.json`'s content, and the paths written), the others None.
    `progress`: each seed's progress bar (a line per seed is printed anyway). Raises ConfigError / OutputDirError /
    DistributedError with one line."""
    t_all = time.perf_counter()
    out = Path(out)
    every = tuple(range(seeds))
    if spec is not None and spec.count is not None:
        seed_blocks(every, spec.count)  # refused before joining: too many processes for the seeds
    index, count = (0, 1) if spec is None else distributed.join(spec)
    blocks = seed_blocks(every, count)
    layout = {"count": count, "seed_blocks": [list(b) for b in blocks]}
    check = lambda: distributed.check_layout(out / distributed.LAYOUT, layout, resume, lambda before: before,  # noqa: E731
                                             lambda before: _refusal(out, before))
    with distributed.claimed_by_process_0(out, index, SEEDS_KIND, resume, (SUMMARY_JSON,), check):
        if count > 1:
            print(f"process {index}/{count}: seeds {list(blocks[index])} into {out}/seed_<k>", flush=True)
        mine = [_train_seed(config, out, k, index, resume, progress, feedback, seed_kind) for k in blocks[index]]
        runs = mine if spec is None else [run for share in distributed.hand_to_process_0("pretrain", mine)
                                          for run in share]
        if index != 0:
            print(f"process {index}/{count}: its seeds handed to process 0", flush=True)
            return None
        return write_summary(out, runs, layout, time.perf_counter() - t_all)


def _refusal(out: Path, before: dict) -> str:
    return (f"--resume: {out} was run on {before['count']} process(es) with seeds {before['seed_blocks']}; continue "
            "it with the same --processes and --seeds")


def _train_seed(config, out: Path, seed: int, index: int, resume: bool, progress: bool, feedback,
                seed_kind: str) -> dict:
    """One seed's run in `out`/seed_<k> (kept where a resumed run finished it, continued where it has a checkpoint),
    and its summary for seeds.json."""
    from mjx_protamer.experiments import checkpoints
    from mjx_protamer.outdir import claimed

    where = seed_dir(out, seed)
    cfg = seed_config(config, seed)
    # alone: orbax and the compile cache see a one-process run (distributed.alone)
    with claimed(where, seed_kind, resume=resume and where.is_dir()), \
            distributed.alone() if distributed.joined() else contextlib.nullcontext():
        if resume and (where / "eval.json").is_file():
            _check_kept_config(where, cfg)
            print(f"[seed {seed}] kept from {where} (finished)", flush=True)
            return _summary(seed, index, json.loads((where / "eval.json").read_text()), None, None)
        from mjx_protamer.experiments.pretrain import run_pretrain

        t0 = time.perf_counter()
        print(f"[seed {seed}] training into {where}", flush=True)
        result = run_pretrain(cfg, where, resume=resume and bool(checkpoints.available_steps(where / "checkpoints")),
                              progress=progress, feedback=feedback)
        return _summary(seed, index, result["eval"], time.perf_counter() - t0, result["train_wall_s"])


def _check_kept_config(where: Path, cfg) -> None:
    """A finished seed is kept only for the config it was trained with (as `--resume` continues a run)."""
    from mjx_protamer.config import check_resume_config
    from mjx_protamer.experiments.env_factory import with_resolved_backend
    from mjx_protamer.experiments.run_loader import CONFIG_NAME, read_run_config

    check_resume_config(where / CONFIG_NAME, with_resolved_backend(cfg, announce=False),
                        lambda path: read_run_config(path.parent))


def _summary(seed: int, process: int, ev: dict, wall_s: float | None, train_wall_s: float | None) -> dict:
    """What seeds.json says of a seed (JSON-able: it travels to process 0). `wall_s`: the seed's whole run here
    (set-up, compile, training, test episodes), `train_wall_s` its chunk loop (the runner's: the first chunk
    pays the compile); both None for a seed kept from before."""
    return {"seed": seed, "dir": seed_dir(".", seed).name, "process": process, "kept": wall_s is None,
            "wall_s": wall_s, "train_wall_s": train_wall_s, "test": {m: ev.get(m) for m in METRICS},
            "episodes": ev.get("episodes")}


def write_summary(out: Path, runs: list[dict], layout: dict, wall_s: float) -> dict:
    """seeds.json and seeds.md in `out` from every seed's summary (in seed order); the summary."""
    seeds = [r["seed"] for r in runs]
    expected = [s for block in layout["seed_blocks"] for s in block]
    if seeds != expected:
        raise DistributedError(f"the processes handed back seeds {seeds}, not {expected}")
    summary = {
        "seeds": seeds,
        "metrics": {m: seed_stats([r["test"][m] for r in runs]) for m in METRICS},
        "per_seed": runs,
        "processes": layout,
        "wall_s": wall_s,
    }
    write_atomic(out / SUMMARY_JSON, json.dumps(summary, indent=2))
    write_atomic(out / SUMMARY_MD, seeds_table(summary))
    return {**summary, "out_dir": str(out), "seeds_json": str(out / SUMMARY_JSON), "seeds_md": str(out / SUMMARY_MD)}


def _cell(x, digits: int) -> str:
    return "–" if x is None else f"{x:.{digits}f}"


def seeds_table(summary: dict) -> str:
    """seeds.md: a row a seed (which process trained it, in how many seconds), then the means with 95% intervals."""
    digits = {"first_touch_step": 1, "contact_rate": 3, "unique_regions": 1, "freeze_ratio": 3, "episode_return": 2}
    head = "| seed | process | " + " | ".join(f"{m} {arrow}" for m, arrow in METRICS.items()) + " | wall s |"
    lines = [f"# pretrain, {len(summary['seeds'])} seeds (test episodes of each seed's deterministic actor)", "",
             head, "|" + "---|" * (len(METRICS) + 3)]
    for r in summary["per_seed"]:
        wall = "kept" if r["kept"] else f"{r['wall_s']:.0f}"
        lines.append(f"| {r['seed']} | {r['process']} | "
                     + " | ".join(_cell(r["test"][m], digits[m]) for m in METRICS) + f" | {wall} |")
    means = []
    for m in METRICS:
        st = summary["metrics"][m]
        means.append(_cell(st["mean"], digits[m]) + ("" if st["ci95"] is None else f" ± {_cell(st['ci95'], digits[m])}"))
    lines.append("| mean ± 95% CI | | " + " | ".join(means) + " | |")
    return "\n".join(lines) + "\n"


def check_seed_overrides(overrides: list[str]) -> None:
    """`--seeds N` sets every seed itself: a `--set train.seed=` with it is refused."""
    for o in overrides:
        if o.split("=", 1)[0].strip() in ("train.seed", "pretrain.train.seed"):
            raise ConfigError(f"--seeds N trains seeds 0..N-1 (train.seed of each); leave out --set {o}")

