"""The environment benchmark behind `protamer bench env`: MJX env, MJX physics, native C, NumPy twin.

One run measures, on this machine:
- MJX full env steps/s (physics + touch observation + reward + regions + auto-reset), through
  `wrap_for_training(SelfTouchEnv(), 1000)` stepped under `lax.scan` chunks with pre-drawn uniform
  random actions, at each batch size; compile time (first call) reported separately, steps/s the
  median of `--repeats` timed chunks;
- MJX physics-only steps/s: vmapped `mjx.step` under the same scan, same model, at batch 256;
- native full env steps/s (`NativeSelfTouchEnv`: native MuJoCo through one `jax.pure_callback` per
  vectorised step, touch sensing on the host in the same call, reward and observation in JAX), the same
  wrapped chunk at each batch size, and its compile;
- native physics-only steps/s through `mujoco.batch` (the native env's engine: state rows in, step, the
  outputs the env reads copied out, touch sensing left out) at batch 256, beside `mujoco.rollout`, and
  the same with the host's touch sensing (`native_batch_physics_and_sensing_steps_per_s`);
- the alternative to the callback: a Python loop that steps the native physics on the host and calls a
  jitted post-physics step (sensing, reward, wrappers) per vectorised step (`native_host_loop_steps_per_s`);
- native MuJoCo physics-only steps/s: `mujoco.rollout.rollout` on all cores (one MjData per thread);
- the NumPy twin's steps/s (native physics + NumPy sensing/reward, one env, Python loop);
- contact fidelity: self-contact rate and region frequencies of the same held-random-target rollouts
  (native C, NumPy twin) under the fast settings and under `PhysicsConfig.reference()` (MuJoCo's own
  solver settings, all contacts, friction on skin), so a reader sees the cheap settings keep the contacts
  the task needs.

Timings are wall-clock on a shared machine: other processes' load shows up in them (`machine.loadavg`).
"""

from __future__ import annotations

import argparse
import copy
from pathlib import Path
import dataclasses
import os
import statistics
import time

import numpy as np

BATCH_SIZES = (1, 64, 256, 1024)
PHYSICS_BATCH = 256


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--batch-sizes", default=",".join(map(str, BATCH_SIZES)),
                        help="comma-separated MJX batch sizes (default: 1,64,256,1024)")
    parser.add_argument("--steps", type=int, default=200, help="env steps per timed scan chunk (default 200)")
    parser.add_argument("--repeats", type=int, default=3, help="timed chunks per measurement; median (default 3)")
    parser.add_argument("--twin-steps", type=int, default=2000, help="NumPy twin steps timed (default 2000)")
    parser.add_argument("--fidelity-episodes", type=int, default=10,
                        help="held-random-target episodes per setting for the contact-fidelity figure (default 10)")
    parser.add_argument("--fidelity-steps", type=int, default=500, help="steps per fidelity episode (default 500)")
    parser.add_argument("--figure", default=None, help="write the contact-fidelity bar chart to this PNG")
    parser.add_argument("--quick", action="store_true",
                        help="a fast smoke run: batch sizes 1,64, 20 steps, 1 repeat, short twin and fidelity runs")


def parse_positive_ints(text, flag: str) -> list[int]:
    """A comma-separated list of positive integers given to `flag` (or a list of them); a ConfigError (one line
    from the CLI) otherwise."""
    from mjx_protamer.config import ConfigError

    try:
        values = [int(b) for b in text] if isinstance(text, (list, tuple)) else \
            [int(b) for b in str(text).split(",") if b.strip()]
    except ValueError:
        values = []
    if not values or any(b < 1 for b in values):
        raise ConfigError(f"{flag} must be comma-separated positive integers, got {text!r}")
    return values


def _timed(fn, repeats: int) -> tuple[float, list[float]]:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), times


# --- MJX ---------------------------------------------------------------------------------------------
def _env_sweep(backend: str, env, sizes, steps: int, repeats: int) -> dict:
    """`<backend>_env_steps_per_s` and `<backend>_env_compile_s`, keyed by batch size."""
    out: dict = {f"{backend}_env_steps_per_s": {}, f"{backend}_env_compile_s": {}}
    for b in sizes:
        r = _bench_env(env, b, steps, repeats)
        out[f"{backend}_env_steps_per_s"][str(b)] = r["steps_per_s"]
        out[f"{backend}_env_compile_s"][str(b)] = r["compile_s"]
    return out


def _bench_env(env, batch: int, steps: int, repeats: int, seed: int = 0) -> dict:
    import jax

    from mjx_protamer.envs.wrappers import wrap_for_training

    wrapped = wrap_for_training(env, 1000)

    def chunk(state, actions):
        def body(s, a):
            s = wrapped.step(s, a)
            return s, s.reward
        state, rewards = jax.lax.scan(body, state, actions)
        return state, rewards.sum()

    rng = jax.random.PRNGKey(seed)
    state = jax.jit(wrapped.reset)(jax.random.split(rng, batch))
    actions = jax.random.uniform(jax.random.PRNGKey(seed + 1), (steps, batch, env.action_size), minval=-1.0,
                                 maxval=1.0)
    jax.block_until_ready(state)
    t = time.perf_counter()
    compiled = jax.jit(chunk, donate_argnums=0).lower(state, actions).compile()
    compile_s = time.perf_counter() - t
    state, r = compiled(state, actions)  # warm-up
    jax.block_until_ready(r)
    holder = [state]

    def run():
        holder[0], r = compiled(holder[0], actions)
        jax.block_until_ready(r)

    med, times = _timed(run, repeats)
    return {"steps_per_s": batch * steps / med, "compile_s": compile_s, "chunk_s": times}


def _bench_mjx_physics(env, batch: int, steps: int, repeats: int, seed: int = 0) -> dict:
    import jax
    import jax.numpy as jnp
    from mjx_protamer.quiet_mjx import mjx

    model = env.model
    lo = jnp.asarray(model.ctrl_lo, jnp.float32)
    hi = jnp.asarray(model.ctrl_hi, jnp.float32)
    step = jax.vmap(mjx.step, in_axes=(None, 0))

    def chunk(d, actions):
        def body(d, a):
            d = step(env.mjx_model, d.replace(ctrl=lo + 0.5 * (a + 1.0) * (hi - lo)))
            return d, None
        d, _ = jax.lax.scan(body, d, actions)
        return d

    d = jax.tree.map(lambda x: jnp.broadcast_to(x, (batch,) + x.shape), env.init_data)
    actions = jax.random.uniform(jax.random.PRNGKey(seed + 2), (steps, batch, env.action_size), minval=-1.0,
                                 maxval=1.0)
    t = time.perf_counter()
    compiled = jax.jit(chunk).lower(d, actions).compile()
    compile_s = time.perf_counter() - t
    d = compiled(d, actions)
    jax.block_until_ready(d.qpos)
    holder = [d]

    def run():
        holder[0] = compiled(holder[0], actions)
        jax.block_until_ready(holder[0].qpos)

    med, times = _timed(run, repeats)
    return {"steps_per_s": batch * steps / med, "compile_s": compile_s, "chunk_s": times}


# --- native C and the NumPy twin -----------------------------------------------------------------------
def _bench_native_batch_physics(native_env, batch: int, steps: int, repeats: int, seed: int = 0,
                                sense: bool = True) -> dict:
    """`NativePhysics.step` alone (mujoco.batch, the outputs the env reads copied out), host loop; with
    `sense=False` without the host's touch sensing (zeros in its place): the physics alone."""
    from mjx_protamer.envs.sensing import N_EXTENDED, N_REGIONS

    physics = native_env.physics
    if not sense:
        physics = copy.copy(physics)
        physics._batches = {}
        physics._sense = lambda b: (np.zeros((b.nsim, physics.touch_size)), np.zeros((b.nsim, N_REGIONS + N_EXTENDED)))
    bits = np.tile(np.asarray(native_env.init_data.state), (batch, 1))
    actions = np.random.default_rng(seed).uniform(-1, 1, (steps, batch, native_env.action_size)).astype(np.float32)
    holder = [bits]

    def run():
        for a in actions:
            holder[0] = physics.step(holder[0], a)[0]

    run()  # warm-up (the batch for this size is made once)
    med, times = _timed(run, repeats)
    return {"steps_per_s": batch * steps / med, "chunk_s": times, "nthread": physics.nthread}


def _bench_native_host_loop(native_env, batch: int, steps: int, repeats: int, seed: int = 0) -> dict:
    """The alternative to the in-jit callback: per vectorised step, native physics on the host, then one
    jitted call for the rest of the env step (sensing, reward, observation, auto-reset)."""
    import jax
    import jax.numpy as jnp

    from mjx_protamer.envs.native_env import unpack
    from mjx_protamer.envs.wrappers import wrap_for_training

    class _Prestepped(type(native_env)):
        """The physics already ran on the host: the step takes the stepped data as it is."""

        def __init__(self, base):
            self.__dict__.update(base.__dict__)

        def _physics_step(self, d, action):
            return d, jnp.bool_(False)

    wrapped = wrap_for_training(_Prestepped(native_env), 1000)
    physics = native_env.physics
    state = jax.jit(wrapped.reset)(jax.random.split(jax.random.PRNGKey(seed), batch))
    post = jax.jit(lambda s, d, a: wrapped.step(s.replace(data=d), a), donate_argnums=0)
    actions = np.random.default_rng(seed).uniform(-1, 1, (steps, batch, native_env.action_size)).astype(np.float32)
    holder = [state]

    def run():
        s = holder[0]
        for a in actions:
            bits, packed, _ = physics.step(np.asarray(s.data.state), a)
            s = post(s, unpack(physics, bits, packed), a)
        jax.block_until_ready(s.reward)
        holder[0] = s

    t = time.perf_counter()
    run()  # compile + warm-up
    compile_s = time.perf_counter() - t
    med, times = _timed(run, repeats)
    return {"steps_per_s": batch * steps / med, "chunk_s": times, "first_run_s": compile_s}


def _bench_native_physics(model, batch: int, steps: int, repeats: int, nthread: int, seed: int = 0) -> dict:
    import mujoco
    from mujoco import rollout

    m = model.mj_model
    d = mujoco.MjData(m)
    d.qpos[:] = model.init_qpos
    d.qvel[:] = model.init_qvel
    d.qacc_warmstart[:] = model.init_warmstart
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state0 = np.empty(mujoco.mj_stateSize(m, spec))
    mujoco.mj_getState(m, d, state0, spec)
    rng = np.random.default_rng(seed)
    a = rng.uniform(-1, 1, (batch, steps, m.nu))
    ctrl = model.ctrl_lo + 0.5 * (a + 1.0) * (model.ctrl_hi - model.ctrl_lo)
    initial = np.tile(state0, (batch, 1))
    datas = [mujoco.MjData(m) for _ in range(nthread)]
    out_state = np.empty((batch, steps, state0.size))

    def run():
        rollout.rollout(m, datas, initial, ctrl, state=out_state, persistent_pool=True)

    run()  # warm-up (thread pool)
    med, times = _timed(run, repeats)
    rollout.shutdown_persistent_pool()
    return {"steps_per_s": batch * steps / med, "chunk_s": times, "nthread": nthread, "batch": batch}


def _bench_twin(config, steps: int, seed: int = 0) -> dict:
    from mjx_protamer.envs.twin import SelfTouchTwinEnv

    env = SelfTouchTwinEnv(config)
    env.reset(seed=seed)
    actions = np.random.default_rng(seed).uniform(-1, 1, (steps, env.action_size)).astype(np.float32)
    t = time.perf_counter()
    for a in actions:
        env.step(a)
    return {"steps_per_s": steps / (time.perf_counter() - t)}


def contact_fidelity(episodes: int, steps: int, hold: int = 50, seed: int = 0) -> dict:
    """Self-contact rate and per-region frequencies of held-random-target rollouts, fast vs reference.

    Both settings run the same episodes (same reset seeds, same targets held `hold` steps) on native C
    through the NumPy twin. Region frequency: fraction of steps on which that region was touched.
    """
    from mjx_protamer.envs import body
    from mjx_protamer.envs.config import EnvConfig, PhysicsConfig
    from mjx_protamer.envs.twin import SelfTouchTwinEnv

    ref = body.PhysicsConfig.reference()
    ref_fields = {f.name: getattr(ref, f.name) for f in dataclasses.fields(PhysicsConfig)}
    settings = {"fast": EnvConfig(), "reference": EnvConfig(physics=PhysicsConfig(**ref_fields))}
    out = {}
    for name, cfg in settings.items():
        env = SelfTouchTwinEnv(cfg)
        rng = np.random.default_rng(seed)
        contact, regions, extended, t0 = [], [], [], time.perf_counter()
        for ep in range(episodes):
            env.reset(seed=seed + ep)
            for i in range(steps):
                if i % hold == 0:
                    a = rng.uniform(-1, 1, env.action_size).astype(np.float32)
                _, _, _, _, info = env.step(a)
                contact.append(info["self_contact"])
                regions.append(info["region_mask"])
                extended.append(info["extended_region_mask"])
        regions, extended = np.array(regions), np.array(extended)
        out[name] = {
            "self_contact_rate": float(np.mean(contact)),
            "region_frequency": dict(zip(body.REGIONS, map(float, regions.mean(axis=0)))),
            "extended_region_frequency": dict(zip(body.EXTENDED_REGIONS, map(float, extended.mean(axis=0)))),
            "steps": episodes * steps,
            "steps_per_s": episodes * steps / (time.perf_counter() - t0),
        }
    out["settings"] = {"fast": dataclasses.asdict(settings["fast"].physics), "reference": ref_fields,
                       "hold_steps": hold}
    return out


def plot_fidelity(fidelity: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = ["self_contact"] + list(fidelity["fast"]["region_frequency"])
    x = np.arange(len(names))
    fig, ax = plt.subplots(figsize=(10, 4))
    for off, key in ((-0.2, "fast"), (0.2, "reference")):
        f = fidelity[key]
        vals = [f["self_contact_rate"]] + list(f["region_frequency"].values())
        ax.bar(x + off, vals, width=0.4, label=f"{key} settings (native C)")
    ax.set_xticks(x, names, rotation=30, ha="right")
    ax.set_ylabel("fraction of steps")
    ax.set_title("Self-contact under held random targets: fast vs reference physics settings")
    ax.legend()
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


# --- the run ---------------------------------------------------------------------------------------------
def run_env_benchmark(args) -> dict:
    """Run every measurement once; returns the JSON-able report (see the module docstring)."""
    import mujoco

    from mjx_protamer.envs.self_touch import SelfTouchEnv
    from mjx_protamer.experiments.machine import describe

    quick = bool(getattr(args, "quick", False))
    sizes = parse_positive_ints(getattr(args, "batch_sizes", BATCH_SIZES), "--batch-sizes")
    steps = int(getattr(args, "steps", 200))
    repeats = int(getattr(args, "repeats", 3))
    twin_steps = int(getattr(args, "twin_steps", 2000))
    fid_eps, fid_steps = int(getattr(args, "fidelity_episodes", 10)), int(getattr(args, "fidelity_steps", 500))
    if quick:
        sizes, steps, repeats, twin_steps, fid_eps, fid_steps = [1, 64], 20, 1, 200, 1, 100
    if steps < 1 or repeats < 1:
        raise ValueError(f"--steps and --repeats must be >= 1, got {steps}, {repeats}")
    physics_batch = PHYSICS_BATCH if not quick else max(sizes)

    loadavg_start = os.getloadavg()
    env = SelfTouchEnv()
    report: dict = _env_sweep("mjx", env, sizes, steps, repeats)
    phys = _bench_mjx_physics(env, physics_batch, steps, repeats)
    report["mjx_physics_steps_per_s"] = phys["steps_per_s"]
    report["mjx_physics_compile_s"] = phys["compile_s"]
    report["mjx_physics_batch_size"] = physics_batch

    nthread = os.cpu_count() or 1
    native = _bench_native_physics(env.model, max(physics_batch, 4 * nthread), steps, repeats, nthread)
    native_1 = _bench_native_physics(env.model, max(physics_batch, 4 * nthread), steps, repeats, 1)
    report["native_physics_steps_per_s"] = native["steps_per_s"]
    report["native_physics_threads"] = nthread
    report["native_physics_steps_per_s_1thread"] = native_1["steps_per_s"]
    report["numpy_twin_steps_per_s"] = _bench_twin(env.config, twin_steps)["steps_per_s"]
    env_at = report["mjx_env_steps_per_s"].get(str(physics_batch))

    from mjx_protamer.envs.native_env import NativeSelfTouchEnv

    native_env = NativeSelfTouchEnv(env.config)
    report.update(_env_sweep("native", native_env, sizes, steps, repeats))
    batch_phys = _bench_native_batch_physics(native_env, physics_batch, steps, repeats, sense=False)
    report["native_batch_physics_steps_per_s"] = batch_phys["steps_per_s"]
    report["native_batch_physics_and_sensing_steps_per_s"] = _bench_native_batch_physics(
        native_env, physics_batch, steps, repeats)["steps_per_s"]
    report["native_batch_physics_threads"] = batch_phys["nthread"]
    report["native_host_loop_steps_per_s"] = _bench_native_host_loop(native_env, physics_batch, steps,
                                                                     repeats)["steps_per_s"]
    native_at = report["native_env_steps_per_s"].get(str(physics_batch))
    report["ratio_native_env_vs_mjx_env"] = (native_at / env_at) if (native_at and env_at) else None
    report["ratio_native_env_vs_native_physics"] = (native_at / batch_phys["steps_per_s"]) if native_at else None
    report["ratio_callback_vs_host_loop"] = (native_at / report["native_host_loop_steps_per_s"]) if native_at else None

    report["ratio_mjx256_vs_native"] = (env_at / report["native_physics_steps_per_s"]) if env_at else None
    report["ratio_mjx256_vs_numpy_twin"] = (env_at / report["numpy_twin_steps_per_s"]) if env_at else None
    report["ratio_mjx256_vs_reference_env_460"] = (env_at / 460.0) if env_at else None
    report["obs_reward_overhead_fraction"] = (1.0 - env_at / report["mjx_physics_steps_per_s"]) if env_at else None
    report["contact_fidelity"] = contact_fidelity(fid_eps, fid_steps)
    figure = getattr(args, "figure", None)
    if figure:
        # A figure that cannot be written must not throw away the measurements: report it instead.
        try:
            plot_fidelity(report["contact_fidelity"], figure)
            report["contact_fidelity_figure"] = figure
        except OSError as e:
            report["contact_fidelity_figure_error"] = f"could not write {figure}: {e}"
    report["settings"] = {"steps_per_chunk": steps, "repeats": repeats, "twin_steps": twin_steps, "quick": quick,
                          "physics": dataclasses.asdict(env.config.physics)}
    report["machine"] = dict(describe(), mujoco_version=mujoco.__version__, loadavg_start=loadavg_start,
                             loadavg_end=os.getloadavg())
    return report


def main(argv=None) -> int:
    import json

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_arguments(parser)
    print(json.dumps(run_env_benchmark(parser.parse_args(argv)), indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
