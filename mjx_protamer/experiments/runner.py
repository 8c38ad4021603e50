"""The one host loop of training runs: jitted chunks, and between them progress, logs, checkpoints and hooks.

Used by `protamer pretrain` (with or without simulated feedback) and by every condition of `protamer
reproduce table2`. Brax's shape: the caller owns the jitted chunk (`step(state) -> (state, metrics, extra)`,
all device values) and receives each chunk's results on the host through `progress_fn(ChunkInfo)`. Between
two chunks, in this order:

1. the metrics and `extra` (e.g. a chunk's feedback events) come to the host;
2. `progress_fn(info)` runs (the caller's hook: event logs, table rows, progress lines);
3. the chunk's row goes to the RunLog (CSV and TensorBoard), when one is given;
4. the Checkpointer saves every `every` chunks and after the last, when one is given;
5. the progress bar advances, when one is asked for.

Everything random lives in the state, so a run resumed from a checkpoint (`Checkpointer.restore`, then
`run_chunks(start=the restored chunk)`) continues exactly as if it had never stopped. The first chunk a
process runs pays the compile; it is left out of the steps/s figure.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path
from typing import Any, Callable

import jax

from mjx_protamer.experiments import checkpoints, run_log


@dataclasses.dataclass
class ChunkInfo:
    """What `progress_fn` and the bar's `postfix` see after each chunk (host values)."""
    chunk: int  # 1-based index of the chunk just run
    num_chunks: int
    metrics: dict  # the chunk's metrics (leading seed axis when the step is vmapped over seeds)
    extra: Any  # the step's third output
    seconds: float  # this chunk's wall time
    wall_s: float  # since the loop started
    row: dict | None  # the RunLog row (scalar metrics flattened, steps_per_s, wall_s); None without a log


@dataclasses.dataclass
class RunResult:
    state: Any
    chunks_done: int  # the last chunk run (or restored, when none ran)
    finished: bool  # reached num_chunks
    wall_s: float
    steps_per_s: float  # env steps per second after the first (compiling) chunk; NaN with too few chunks


class Checkpointer:
    """Orbax checkpoints (`checkpoints.py`) of a state made of parts, one directory each (the DDPG TrainState,
    and with feedback the feedback state): every part is saved at the same chunk, and a resume takes the newest
    chunk where every part is intact."""

    def __init__(self, directories: list[Path], every: int):
        self.directories = [Path(d) for d in directories]
        self.managers = [checkpoints.manager(d) for d in self.directories]
        self.every = every

    def restore(self, like: tuple) -> tuple[int, tuple]:
        step, restored = checkpoints.restore_newest_intact(list(zip(self.managers, like)),
                                                           lambda line: print(line, file=sys.stderr))
        return step, tuple(restored)

    def save(self, chunk: int, parts: tuple) -> None:
        for mngr, part in zip(self.managers, parts):
            checkpoints.save(mngr, chunk, part)

    def latest(self) -> Path | None:
        """The newest step directory of the first part, as the directory was given (relative stays relative)."""
        step = self.managers[0].latest_step()
        return None if step is None else self.directories[0] / str(step)

    def close(self) -> None:
        for mngr in self.managers:
            mngr.close()


def run_chunks(
    step: Callable[[Any], tuple[Any, Any, Any]],
    state,
    num_chunks: int,
    steps_per_chunk: int,
    *,
    start: int = 0,
    max_chunks: int | None = None,
    progress_fn: Callable[[ChunkInfo], None] | None = None,
    log: run_log.RunLog | None = None,
    term_names: tuple[str, ...] = (),
    checkpointer: Checkpointer | None = None,
    bar: str | None = None,
    postfix: Callable[[ChunkInfo], dict] | None = None,
) -> RunResult:
    """Run chunks `start + 1 .. num_chunks` (at most `max_chunks` of them: a stop as by a kill, for tests).

    `step(state) -> (state, metrics, extra)`; with a checkpointer the state is a tuple with one part per
    checkpoint directory; `bar` the progress bar's label (None: no bar); `term_names` name the columns of the
    `reward_terms` vector in the log row."""
    bar_obj = None
    if bar is not None:
        from tqdm import tqdm

        bar_obj = tqdm(total=num_chunks * steps_per_chunk, initial=start * steps_per_chunk, unit="step",
                       dynamic_ncols=True, desc=bar)
    t_start = time.perf_counter()
    timed_steps, timed_s = 0, 0.0
    chunk = start
    last = num_chunks if max_chunks is None else min(num_chunks, start + max_chunks)
    try:
        for chunk in range(start + 1, last + 1):
            t0 = time.perf_counter()
            state, metrics, extra = step(state)
            metrics, extra = jax.device_get((metrics, extra))
            seconds = time.perf_counter() - t0
            if chunk > start + 1 or num_chunks - start == 1:  # the first chunk of a process pays the compile
                timed_steps += steps_per_chunk
                timed_s += seconds
            wall = time.perf_counter() - t_start
            row = None
            if log is not None:
                row = {"chunk": float(chunk), **run_log.flatten(metrics, term_names),
                       "steps_per_s": steps_per_chunk / seconds, "wall_s": wall}
            info = ChunkInfo(chunk, num_chunks, metrics, extra, seconds, wall, row)
            if progress_fn is not None:
                progress_fn(info)
            if log is not None:
                log.write(row)
            if checkpointer is not None and (chunk % checkpointer.every == 0 or chunk == num_chunks):
                checkpointer.save(chunk, state)
            if bar_obj is not None:
                bar_obj.update(steps_per_chunk)
                if postfix is not None:
                    bar_obj.set_postfix(**postfix(info))
    finally:
        if bar_obj is not None:
            bar_obj.close()
    return RunResult(state=state, chunks_done=chunk, finished=chunk == num_chunks,
                     wall_s=time.perf_counter() - t_start,
                     steps_per_s=timed_steps / timed_s if timed_s > 0 else float("nan"))
