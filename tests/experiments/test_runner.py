"""The host runner (`experiments.runner`) on a trivial jitted step: hook order and arguments, checkpoint
cadence, a stop as by a kill and an exact resume, the log rows."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from mjx_protamer.experiments import checkpoints, run_log
from mjx_protamer.experiments.runner import Checkpointer, run_chunks


@jax.jit
def _step(state):
    (count, key), = state  # one part: a counter and a PRNG key (the randomness lives in the state)
    key, sub = jax.random.split(key)
    noise = jax.random.uniform(sub)
    metrics = {"count": count.astype(jnp.float32), "noise": noise, "env_steps": (count + 1) * 10.0,
               "reward_terms": jnp.array([count, 2.0 * count], jnp.float32)}
    return ((count + 1, key),), metrics, {"seen": count}


def _init():
    return ((jnp.int32(0), jax.random.PRNGKey(0)),)


def test_hooks_see_every_chunk_in_order_and_checkpoints_follow_the_cadence(tmp_path):
    seen = []
    ckpt = Checkpointer([tmp_path / "ckpt"], every=2)
    log = run_log.RunLog(tmp_path, tensorboard=False)
    run = run_chunks(_step, _init(), num_chunks=5, steps_per_chunk=10, progress_fn=seen.append, log=log,
                     term_names=("a", "b"), checkpointer=ckpt)
    assert [i.chunk for i in seen] == [1, 2, 3, 4, 5] and all(i.num_chunks == 5 for i in seen)
    assert [int(i.extra["seen"]) for i in seen] == [0, 1, 2, 3, 4]  # host values, in stepping order
    assert isinstance(seen[0].metrics["count"], np.ndarray)
    assert seen[2].row["reward_term/b"] == 4.0 and seen[2].row["chunk"] == 3.0
    assert [r["count"] for r in log.rows] == [0, 1, 2, 3, 4]
    assert checkpoints.available_steps(tmp_path / "ckpt") == [4, 5]  # every 2nd and the last (keeps 2)
    assert run.finished and run.chunks_done == 5 and int(run.state[0][0]) == 5
    assert run.steps_per_s > 0  # chunks 2-5, after the compiling first
    ckpt.close()
    log.close()


def test_stop_and_resume_continue_exactly(tmp_path):
    full = run_chunks(_step, _init(), num_chunks=6, steps_per_chunk=10)
    ckpt = Checkpointer([tmp_path / "ckpt"], every=2)
    log = run_log.RunLog(tmp_path, tensorboard=False)
    stopped = run_chunks(_step, _init(), num_chunks=6, steps_per_chunk=10, max_chunks=3, log=log,
                         checkpointer=ckpt)  # "killed" after chunk 3; the last checkpoint is chunk 2
    assert not stopped.finished and stopped.chunks_done == 3
    log.close()
    ckpt.close()
    ckpt = Checkpointer([tmp_path / "ckpt"], every=2)
    start, state = ckpt.restore(_init())
    assert start == 2
    log = run_log.RunLog(tmp_path, resume_chunk=start, tensorboard=False)
    rest = []
    resumed = run_chunks(_step, state, num_chunks=6, steps_per_chunk=10, start=start, log=log,
                         checkpointer=ckpt, progress_fn=rest.append)
    assert [i.chunk for i in rest] == [3, 4, 5, 6] and resumed.finished
    jax.tree.map(lambda a, b: np.testing.assert_array_equal(np.asarray(a), np.asarray(b)), resumed.state, full.state)
    assert [r["chunk"] for r in log.rows] == [1, 2, 3, 4, 5, 6]  # the row of the lost chunk 3 was rewritten
    noise = [r["noise"] for r in run_log.read_rows(tmp_path / run_log.CSV_NAME)[0]]
    assert len(set(noise)) == 6
    ckpt.close()
    log.close()
