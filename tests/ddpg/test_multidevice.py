"""Data parallelism over 2 forced host devices, in a subprocess (XLA_FLAGS must precede the JAX import)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

SCRIPT = textwrap.dedent(
    """
    import json, sys
    import jax, numpy as np
    sys.path.insert(0, sys.argv[1] + "/tests/ddpg")
    from ddpg_helpers import tiny_config
    from mjx_protamer.agents.ddpg.train import make_train
    from mjx_protamer.envs.toy import PointReachEnv

    config = tiny_config(num_devices=2)
    trainer = make_train(config, PointReachEnv())
    state = trainer.init(jax.random.PRNGKey(0))
    for _ in range(config.train.num_chunks):
        state, m = trainer.train_chunk(state, None)
    ptr0 = int(state.replay.ptr)
    state, m, steps, _ = trainer.collect_chunk(state, None)  # the emitted transitions, split over devices by env
    T = config.train.chunk_steps
    rows = (ptr0 + np.arange(T)[:, None] * 2 + np.arange(2)) % 500  # each device's own replay (500 rows)
    emitted_match = all(np.array_equal(np.asarray(r.data)[rows], np.asarray(e.data))
                        for r, e in zip(state.replay.data.obs.addressable_shards, steps.obs.addressable_shards))
    kernel = state.critic_params["params"]["Dense_1"]["kernel"]
    replicas = [np.asarray(s.data) for s in kernel.addressable_shards]
    obs_shards = [np.asarray(s.data) for s in state.env_state.obs.addressable_shards]
    print(json.dumps({
        "devices": len(jax.devices()),
        "trainer_devices": trainer.num_devices,
        "replicas_equal": all(np.array_equal(replicas[0], r) for r in replicas),
        "replica_count": len(replicas),
        "replay_local_rows": [s.data.shape[0] for s in state.replay.data.obs.addressable_shards],
        "env_local": [o.shape[0] for o in obs_shards],
        "envs_differ": not np.allclose(obs_shards[0], obs_shards[1]),
        "replay_size": int(state.replay.size),
        "emitted_shape": list(steps.obs.shape),
        "emitted_local": [list(x.data.shape) for x in steps.obs.addressable_shards],
        "emitted_match": emitted_match,
        "critic_loss": float(m["critic_loss"]),
        "env_steps": int(m["env_steps"]),
    }))
    """
)


def test_two_device_data_parallel_training():
    root = Path(__file__).resolve().parents[2]
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", JAX_PLATFORMS="cpu")
    proc = subprocess.run([sys.executable, "-c", SCRIPT, str(root)], env=env, capture_output=True, text=True,
                          timeout=300, cwd=root)
    assert proc.returncode == 0, proc.stderr[-3000:]
    r = json.loads(proc.stdout.strip().splitlines()[-1])
    assert r["devices"] == 2 and r["trainer_devices"] == 2
    assert r["replica_count"] == 2 and r["replicas_equal"], "gradients must be averaged: replicas identical"
    assert r["replay_local_rows"] == [500, 500] and r["env_local"] == [2, 2]
    assert r["envs_differ"]
    assert r["replay_size"] == 150 * 2  # per device: 100 + 50 (collect_chunk) iterations x 2 local envs
    assert r["env_steps"] == 600 and r["critic_loss"] == r["critic_loss"]  # finite, not NaN
    assert r["emitted_shape"] == [50, 4, 6] and r["emitted_local"] == [[50, 2, 6]] * 2
    assert r["emitted_match"], "each device emits the transitions it stored, in stepping order"
