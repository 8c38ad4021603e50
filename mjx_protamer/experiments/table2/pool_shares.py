"""The pooled reward-model score (`run.pooled_corr`) of a table2 run whose conditions were trained on different
processes (`experiments/distributed.py`, `work_split`): each process packs its conditions' reward models and
sampled test states into bytes, the bytes are gathered, and process 0 scores every seed block on the pooled test
states of all the conditions, vmapped over the block's seeds as the process that trained the block would have:
the figures are bit for bit those of one process running that block."""

from __future__ import annotations

import io
import json

import jax
import numpy as np

from mjx_protamer.experiments.table2.run import pooled_corr


def pack_models(reward_models: dict, test_states: dict) -> bytes:
    """Every condition's reward-model parameters (stacked over seeds) and sampled test states, as npz bytes."""
    arrays, index = [], []
    for name, params in reward_models.items():
        leaves = jax.tree.leaves(jax.device_get(params))
        index.append({"condition": name, "leaves": len(leaves), "states": sorted(test_states[name])})
        arrays += [np.asarray(x) for x in leaves] + [np.asarray(test_states[name][k]) for k in index[-1]["states"]]
    buf = io.BytesIO()
    np.savez(buf, *arrays, index=np.frombuffer(json.dumps(index).encode(), np.uint8))
    return buf.getvalue()


def unpack_models(blob: bytes) -> dict[str, tuple[list, dict]]:
    """`pack_models`' bytes as {condition: (reward-model leaves, test states)}."""
    with np.load(io.BytesIO(blob)) as f:
        index = json.loads(bytes(f["index"]))
        arrays = iter(f[f"arr_{i}"] for i in range(len(f.files) - 1))
        out = {}
        for entry in index:
            leaves = [next(arrays) for _ in range(entry["leaves"])]
            out[entry["condition"]] = (leaves, {k: next(arrays) for k in entry["states"]})
    return out


def pool_shares(cfg, ft, shares, blobs: list[bytes], evals: dict) -> None:
    """Add `r_hat_corr_pooled` (and its untrained reference) to `evals[condition][seed]` for every seed, from
    every process's `pack_models` bytes (`blobs`, in the order of `shares`, `work_split.Share`s)."""
    received = {}
    for share, blob in zip(shares, blobs):
        for name, models in unpack_models(blob).items():
            received[(name, share.seeds)] = models
    init = jax.jit(jax.vmap(ft.init))  # the untrained reward models, as train_table2 makes them for its seeds
    for block in dict.fromkeys(s.seeds for s in shares):
        untrained = init(np.asarray(block, np.uint32)).rm_params
        like = jax.tree.structure(untrained)
        reward_models = {c.name: jax.tree.unflatten(like, received[(c.name, block)][0]) for c in cfg.conditions}
        test_states = {c.name: received[(c.name, block)][1] for c in cfg.conditions}
        for name, per_seed in pooled_corr(ft, reward_models, untrained, test_states).items():
            for i, seed in enumerate(block):
                evals[name][seed].update(per_seed[i])
