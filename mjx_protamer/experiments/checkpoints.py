"""Orbax checkpoints of a whole TrainState (learner, env batch, replay, RNG): named leaves, a checksum, atomic.

Leaves are saved under their path in the tree (`actor_params/params/Dense_0/kernel`, `replay/obs`, ...), not
by position, so a checkpoint restores each array into the field it came from or refuses: reordering or
renaming fields can never put the actor into the target actor silently.

Beside the arrays, each step directory holds `manifest.json`: every leaf's path, shape and dtype and a
SHA-256 over the leaves' names and bytes. It is written atomically after orbax has finished the step, so a
step without it is an unfinished save. `restore` checks the manifest against the structure it restores into
(a checkpoint of another config is refused and says which leaf differs), then every file's size and SHA-256
before orbax opens any of them, then the checksum of what it read (a damaged checkpoint is refused with "use
the previous one"). Checking the files first matters: when orbax meets one unreadable array it abandons its
reads of the others, and tensorstore's threads print their failures to stderr after the error was reported.
`newest_intact` is what `--resume` uses.

Orbax writes each step into a temporary directory and renames it when complete, so a run killed while saving
leaves the previous checkpoint intact. Saving is synchronous: the train step donates its input buffers, so
the next chunk must not start before the save ends.
"""

from __future__ import annotations

import errno
import gc
import hashlib
import json
import shutil
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import orbax.checkpoint as ocp

from mjx_protamer.atomic import write_atomic
from mjx_protamer.errors import CheckpointDamaged, CheckpointError

MANIFEST = "manifest.json"
FORMAT = 3  # 1: leaves by flat index, no manifest (before checksums); 2: no per-file checksums


def manager(directory: str | Path, max_to_keep: int = 2) -> ocp.CheckpointManager:
    options = ocp.CheckpointManagerOptions(max_to_keep=max_to_keep, enable_async_checkpointing=False)
    return ocp.CheckpointManager(Path(directory).absolute(), options=options)


def _key_name(key) -> str:
    for attr in ("name", "key", "idx"):
        if hasattr(key, attr):
            return str(getattr(key, attr))
    return str(key)


def named_leaves(tree) -> dict[str, object]:
    """{'a/b/c': leaf} for every leaf of the tree, named by its path."""
    flat, _ = jax.tree_util.tree_flatten_with_path(tree)
    return {"/".join(_key_name(k) for k in path): leaf for path, leaf in flat}


def _nested(named: dict[str, object]) -> dict:
    """The named leaves as nested dicts (orbax's natural tree), without zero-size arrays (orbax refuses them;
    mjx.Data has some, e.g. `act`: they are rebuilt as zeros on restore)."""
    out: dict = {}
    for name, leaf in named.items():
        if leaf.size == 0:
            continue
        node = out
        *parents, last = name.split("/")
        for p in parents:
            node = node.setdefault(p, {})
        node[last] = leaf
    return out


def _lookup(nested: dict, name: str):
    node = nested
    for p in name.split("/"):
        node = node[p]
    return node


def _digest(named_arrays: dict[str, np.ndarray]) -> str:
    h = hashlib.sha256()
    for name in sorted(named_arrays):
        a = np.ascontiguousarray(named_arrays[name])
        h.update(f"{name}:{a.dtype.str}:{a.shape}\n".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _describe(named: dict) -> dict:
    return {name: {"shape": list(x.shape), "dtype": np.dtype(x.dtype).name} for name, x in named.items()}


def step_dir(mngr: ocp.CheckpointManager, step: int) -> Path:
    return Path(mngr.directory) / str(step)


def _file_sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _file_digests(directory: Path) -> dict[str, dict]:
    """{relative path: {size, sha256}} of every file orbax wrote into the step directory."""
    return {p.relative_to(directory).as_posix(): {"size": p.stat().st_size, "sha256": _file_sha256(p)}
            for p in sorted(directory.rglob("*")) if p.is_file() and p.name != MANIFEST}


def _check_files(manifest: dict, directory: Path) -> None:
    """Refuse a missing, truncated or altered file before orbax reads any (see the module docstring)."""
    for rel, want in manifest.get("files", {}).items():
        path = directory / rel
        if not path.is_file():
            raise CheckpointDamaged(f"its file {rel} is missing")
        size = path.stat().st_size
        if size != want["size"]:
            raise CheckpointDamaged(f"its file {rel} has {size} bytes, {want['size']} when saved (truncated?)")
        if _file_sha256(path) != want["sha256"]:
            raise CheckpointDamaged(f"its file {rel} does not match its SHA-256 checksum")


def save(mngr: ocp.CheckpointManager, step: int, state) -> None:
    """Save `state` as `step` (arrays by orbax, then the manifest). A write that fails (a full disk, no
    permission) raises OSError naming the path; orbax's and tensorstore's own errors for it (e.g.
    RESOURCE_EXHAUSTED) are turned into one, so callers report every failed save the same way."""
    named = named_leaves(state)
    try:
        mngr.save(step, args=ocp.args.StandardSave(_nested(named)))
        mngr.wait_until_finished()
    except OSError:
        raise
    except Exception as e:  # orbax/tensorstore wrap the file system's errors in their own types
        first = str(e).strip().splitlines()[0][:200] if str(e).strip() else type(e).__name__
        raise OSError(errno.EIO, f"the checkpoint could not be written ({first})", str(step_dir(mngr, step))) from e
    host = {name: np.asarray(jax.device_get(x)) for name, x in named.items()}
    manifest = {"format": FORMAT, "step": int(step), "leaves": _describe(host), "sha256": _digest(host),
                "files": _file_digests(step_dir(mngr, step))}
    write_atomic(step_dir(mngr, step) / MANIFEST, json.dumps(manifest, indent=1))


def save_model(directory: str | Path, tree) -> None:
    """Save a model that is written once, at the end of a run (a reward model, a condition's agents), as step 0
    of `directory`, replacing what an unfinished earlier attempt left there (a kill, a full disk)."""
    directory = Path(directory)
    if (directory / "0").exists():
        shutil.rmtree(directory / "0")
    mngr = manager(directory, max_to_keep=1)
    try:
        save(mngr, 0, tree)
    finally:
        mngr.close()


def load_model(directory: str | Path, like):
    """The model `save_model` wrote into `directory`, checked as `restore` checks a step."""
    mngr = manager(directory)
    try:
        return restore(mngr, 0, like)
    finally:
        mngr.close()


def _read_manifest(directory: Path) -> dict:
    path = directory / MANIFEST
    if not path.is_file():
        raise CheckpointDamaged(f"no {MANIFEST} (an unfinished save, or a checkpoint written before checksums)")
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
        leaves, digest = manifest["leaves"], manifest["sha256"]
        files = manifest.get("files", {})  # absent in format 2
        if not isinstance(leaves, dict) or not isinstance(digest, str) or not isinstance(files, dict):
            raise TypeError
        for want in files.values():
            int(want["size"]), str(want["sha256"])
    except (ValueError, KeyError, TypeError, UnicodeDecodeError):
        raise CheckpointDamaged(f"its {MANIFEST} is unreadable") from None
    return manifest


def _check_structure(manifest: dict, like_named: dict, directory: Path) -> None:
    saved, here = manifest["leaves"], _describe(like_named)
    missing, extra = sorted(set(here) - set(saved)), sorted(set(saved) - set(here))
    if missing or extra:
        what = (f"lacks {missing[0]}" if missing else f"has {extra[0]}, which this config does not")
        more = len(missing) + len(extra) - 1
        raise CheckpointError(f"checkpoint {directory} does not fit this config: it {what}"
                              + (f" (and {more} other leaf differences)" if more else "")
                              + "; load it with the config.yaml of the run that wrote it")
    for name in sorted(here):
        if saved[name] != here[name]:
            raise CheckpointError(
                f"checkpoint {directory} does not fit this config: {name} is {tuple(saved[name]['shape'])} "
                f"{saved[name]['dtype']} there but {tuple(here[name]['shape'])} {here[name]['dtype']} here "
                f"(a different num_envs, observation size or network?); use the run's own config.yaml")


def available_steps(directory: str | Path) -> list[int]:
    directory = Path(directory)
    if not directory.is_dir():
        return []
    return sorted(int(p.name) for p in directory.iterdir() if p.is_dir() and p.name.isdigit())


def _previous_hint(mngr: ocp.CheckpointManager, step: int) -> str:
    earlier = [s for s in available_steps(mngr.directory) if s < step]
    if not earlier:
        return "no earlier checkpoint is left: train again, or restore this one from a backup"
    return f"use the previous one ({step_dir(mngr, earlier[-1])})"


def restore(mngr: ocp.CheckpointManager, step: int, like):
    """Restore into the structure, shapes and shardings of `like` (a state or its eval_shape), each leaf by
    its path; CheckpointError when the checkpoint does not fit `like`, CheckpointDamaged when its files are
    missing, unfinished or corrupt."""
    directory = step_dir(mngr, step)
    if not directory.is_dir():
        steps = available_steps(mngr.directory)
        have = f"the steps there: {', '.join(map(str, steps))}" if steps else "it holds no checkpoint"
        raise CheckpointError(f"checkpoint step {step} does not exist in {mngr.directory}; {have}")
    like_named = named_leaves(like)
    try:
        manifest = _read_manifest(directory)
    except CheckpointDamaged as e:
        raise CheckpointDamaged(f"checkpoint {directory} is damaged: {e}; {_previous_hint(mngr, step)}") from None
    _check_structure(manifest, like_named, directory)
    try:
        _check_files(manifest, directory)
    except CheckpointDamaged as e:
        raise CheckpointDamaged(f"checkpoint {directory} is damaged: {e}; {_previous_hint(mngr, step)}") from None
    abstract = _nested({name: _abstract(x) for name, x in like_named.items()})
    failure = None
    try:
        restored = mngr.restore(step, args=ocp.args.StandardRestore(abstract))
    except Exception as e:  # orbax/tensorstore raise many types for missing or truncated files
        failure = str(e).strip().splitlines()[0].split(". See full")[0][:160] if str(e).strip() else type(e).__name__
    if failure is not None:
        _collect_orphaned_reads()
        raise CheckpointDamaged(f"checkpoint {directory} is damaged: its arrays cannot be read ({failure}); "
                                f"{_previous_hint(mngr, step)}")
    out = {name: (_lookup(restored, name) if x.size > 0 else _empty(x)) for name, x in like_named.items()}
    host = {name: np.asarray(jax.device_get(x)) for name, x in out.items()}
    if _digest(host) != manifest["sha256"]:
        raise CheckpointDamaged(f"checkpoint {directory} is damaged: its arrays do not match their SHA-256 "
                                f"checksum; {_previous_hint(mngr, step)}")
    treedef = jax.tree.structure(like)
    return jax.tree.unflatten(treedef, [out[name] for name in like_named])


def _from_abandoned_read(report) -> bool:
    """Whether an unraisable-exception report comes from orbax's abandoned reads: their coroutines, a frame of
    orbax in the traceback, or tensorstore completing a read in flight after orbax closed its event loop
    (`call_soon_threadsafe` -> 'Event loop is closed', reported from tensorstore's thread with no object)."""
    code = getattr(report.object, "cr_code", None)
    if code is not None and "orbax" in code.co_filename:
        return True
    frames = []
    tb = report.exc_traceback
    while tb is not None:
        frames.append(tb.tb_frame.f_code)
        tb = tb.tb_next
    if any("orbax" in f.co_filename for f in frames):
        return True
    return (report.object is None and isinstance(report.exc_value, RuntimeError)
            and str(report.exc_value) == "Event loop is closed"
            and any(f.co_name == "call_soon_threadsafe" for f in frames))


def _collect_orphaned_reads() -> None:
    """When one array fails to read, orbax abandons the reads of the others as coroutines that are never
    awaited, and tensorstore may still complete some; each would print an 'Exception ignored in: ...' block
    (hundreds for a TrainState), now or whenever the garbage collector or tensorstore's thread gets to them.
    From the first damaged checkpoint on, those reports (and only those) are dropped; the coroutines
    collectable now are finalised at once."""
    current = sys.unraisablehook
    if not getattr(current, "drops_orbax_orphans", False):
        def hook(report, _previous=current):
            if not _from_abandoned_read(report):
                _previous(report)

        hook.drops_orbax_orphans = True
        sys.unraisablehook = hook
    gc.collect()


def set_aside(mngr: ocp.CheckpointManager, step: int) -> Path:
    """Move a damaged step out of the manager's directory (into `<dir>_damaged/`), keeping its files for
    inspection, so that later saves of the same step number do not collide with it."""
    src = step_dir(mngr, step)
    dest_root = Path(str(mngr.directory).rstrip("/") + "_damaged")
    dest_root.mkdir(parents=True, exist_ok=True)
    dest = dest_root / f"{step}-{time.strftime('%Y%m%d-%H%M%S')}"
    shutil.move(str(src), str(dest))
    mngr.reload()
    return dest


def _empty(x):
    array = jnp.zeros(x.shape, x.dtype)
    sharding = getattr(x, "sharding", None)
    return jax.device_put(array, sharding) if sharding is not None else array


def _abstract(x):
    # A `like` without a placement (an eval_shape) restores onto this process's first device rather than onto the
    # device the checkpoint names: a run saved by process k of a jax.distributed job names the job's global device
    # (cpu:2048 for process 1), which a one-process `eval` or `finetune` of that run does not have.
    sharding = getattr(x, "sharding", None)
    if sharding is None:
        sharding = jax.sharding.SingleDeviceSharding(jax.local_devices()[0])
    return jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=sharding)


def restore_newest_intact(pairs: list, report) -> tuple[int | None, list]:
    """(step, restored states) at the newest step where every (manager, like) pair restores intact, for
    `--resume`. Steps that are damaged or incomplete (one manager lacks them: a kill between two saves) are
    reported through `report(line)` and set aside. (None, []) when there was no checkpoint at all;
    CheckpointDamaged when there were some but none is intact. A checkpoint that does not fit (CheckpointError)
    is not skipped: every older one would not fit either."""
    steps = sorted(set().union(*(available_steps(m.directory) for m, _ in pairs)), reverse=True)
    for step in steps:
        try:
            for m, _ in pairs:
                if not step_dir(m, step).is_dir():
                    raise CheckpointDamaged(f"checkpoint {step_dir(m, step)} is missing (a kill between two saves)")
            states = [restore(m, step, like) for m, like in pairs]
        except CheckpointDamaged as e:
            moved = [set_aside(m, step) for m, _ in pairs if step_dir(m, step).is_dir()]
            report(f"--resume: skipping step {step}: {str(e).split('; use the previous')[0]}"
                   + (f" (moved to {moved[0].parent})" if moved else ""))
            continue
        if step != steps[0]:
            report(f"--resume: resuming from step {step}, the newest intact checkpoint")
        return step, states
    if steps:
        raise CheckpointDamaged(f"no intact checkpoint in {pairs[0][0].directory} (the damaged ones were moved "
                                f"beside it); start the run again without --resume")
    return None, []
