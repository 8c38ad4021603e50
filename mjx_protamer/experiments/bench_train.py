"""`protamer bench train`: end-to-end DDPG training throughput (env steps + updates), pure JAX vs SB3.

Three measurements, in one process, each the median of `--repeats` timed runs after an untimed warm-up
(the JAX warm-up pays the compile):

- `steps_per_s`: pure-JAX DDPG with the paper's single-env hyper-parameters (1 env, one update of batch 64
  per env step, 400-300 networks, OU noise), env + updates, one jitted chunk of `--steps` steps per run;
- `sb3_steps_per_s`: Stable-Baselines3 DDPG with the same hyper-parameters (400-300, Adam 1e-3, gamma
  0.99, tau 0.001, batch 64, replay 1e5, train_freq 1, gradient_steps 1, OU theta 0.15 sigma 0.6 dt 1) on
  the NumPy/Gymnasium twin of the env (`mjx_protamer.envs.twin`; `--env toy` uses the toy env's twin).
  SB3's critic takes the action at its input layer, not the second: the cost differs by a few hundred MACs;
- `batched256_steps_per_s`: pure JAX with `--batched-envs` (256) envs and one update per vectorised step.

Those three use the backend `auto` picks for their number of envs (on a CPU: MJX for one env, native
MuJoCo for a batch; MJX on an accelerator; `backend_single`, `backend_batched`). Side by side, for
each of `--backends` (self_touch only): `single_env_steps_per_s` and `batched_steps_per_s` keyed by backend,
and `ratio_batched_native_vs_mjx`.

The single-env roofline, measured in the same run: one update of the paper's networks costs
`update_flops` (the matmuls of target actor + target critic forward, critic forward and backward, actor
and critic forward and backward for the actor loss; counted from the layer sizes), which at this machine's
`matmul_flops_per_s` (a jitted 1024^3 float32 matmul, the best JAX does here) takes
`update_flops / matmul_flops_per_s`; one env step takes `1 / single_env_env_steps_per_s` (the env alone at
batch 1, the chunk's backend). `single_env_roofline_steps_per_s` is one over their sum, and
`single_env_fraction_of_roofline = steps_per_s / single_env_roofline_steps_per_s` (issue 11's definition,
the one its 0.8 target is stated in).

Beside it, the same roofline from the update's own matmuls (`update_dot_shapes`: the dots autodiff runs,
at batch 64, `update_dot_flops` in all; 4 A + 6 C less the input-layer gradients nobody needs, 15% below
`update_flops`), timed as a chain in one jitted scan (`update_matmul_s`, the rate
`matmul_update_shapes_flops_per_s`): `single_env_roofline_update_shapes_steps_per_s` and
`single_env_fraction_of_roofline_update_shapes`. Whether the small matmuls run slower than the big one is
then a measurement, not an assumption.

`ratio_vs_sb3 = steps_per_s / sb3_steps_per_s`.

`batched_trainer` (issue 40; `--skip-roofline` leaves it out): the batched trainer of `--roofline-config` (the
main job by default) after its warm-up, with 1 seed and with 5 seeds vmapped in one program (`--roofline-seeds`),
against its roofline: the chunk's updates at their own matmuls' time plus its env steps, both measured in the
same run; the env timed alone on random actions (`fraction_of_roofline`) and as the trainer's own chunk without
updates from the trained state (`fraction_of_roofline_trained_worlds`: a trained infant touches itself, and touch
sensing costs what its contacts cost). `run_train_s_projected` is the whole run's training time at this pace.

`machine`: JAX's backend, the device kind (which GPU, if any), cores and load (experiments/machine.py).
"""

from __future__ import annotations

import argparse
import statistics
import time


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--env", choices=("self_touch", "toy"), default="self_touch",
                        help="env to train on (self_touch: MJX env vs its NumPy twin)")
    parser.add_argument("--steps", type=int, default=1000, help="env steps per timed single-env JAX run")
    parser.add_argument("--sb3-steps", type=int, default=500, help="env steps per timed SB3 run")
    parser.add_argument("--batched-envs", type=int, default=256)
    parser.add_argument("--batched-iterations", type=int, default=20,
                        help="vectorised steps per timed batched run")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--skip-sb3", action="store_true", help="do not run Stable-Baselines3")
    parser.add_argument("--roofline-config", default=None,
                        help="the batched run whose trainer is put against its roofline (default: the main job, "
                        "configs/pretrain.yaml)")
    parser.add_argument("--roofline-set", action="append", default=[], metavar="KEY=VALUE",
                        help="override a value of --roofline-config (repeatable)")
    parser.add_argument("--roofline-seeds", default="1,5",
                        help="seed counts to time the batched trainer at, vmapped in one program (default 1,5)")
    parser.add_argument("--roofline-chunks", type=int, default=3, help="timed chunks per repeat (default 3)")
    parser.add_argument("--skip-roofline", action="store_true", help="do not time the batched trainer")
    parser.add_argument("--backends", default="mjx,native",
                        help="physics backends to train on side by side (self_touch; default mjx,native; '' for none)")


def _config(env_name: str, num_envs: int, chunk_steps: int, backend: str = "auto"):
    from mjx_protamer.agents.ddpg.config import PretrainConfig
    from mjx_protamer.config import load_config

    return load_config(PretrainConfig, None, [
        f"env_name={env_name}", f"train.num_envs={num_envs}", f"train.chunk_steps={chunk_steps}",
        f"train.total_env_steps={num_envs * chunk_steps * 4}", f"train.warmup_env_steps={max(64, num_envs)}",
        "train.updates_per_step=1", "train.num_devices=1", f"env.backend={backend}",
    ] + (["train.episode_length=25"] if env_name == "toy" else []))


def _parse_backends(text: str) -> list[str]:
    names = [b.strip() for b in str(text).split(",") if b.strip()]
    bad = [b for b in names if b not in ("mjx", "native")]
    if bad:
        raise ValueError(f"--backends must name mjx and/or native (comma-separated), got {text!r}")
    return names


def update_flops(obs_size: int, action_size: int, actor_hidden, critic_hidden, batch: int) -> float:
    """Matmul FLOPs of one DDPG update (networks.py's shapes; the critic takes the action at layer 2).

    Forward MACs per sample: A (actor), C (critic). The update runs the target actor and critic forward
    (A + C), the critic forward and backward (3 C: a backward pass costs two forwards), and the actor loss
    through actor and critic forward and backward (3 (A + C)): 4 A + 7 C MACs, 2 FLOPs each.
    """
    widths = [obs_size, *actor_hidden, action_size]
    a = sum(i * o for i, o in zip(widths[:-1], widths[1:]))
    c = obs_size * critic_hidden[0]
    prev = critic_hidden[0] + action_size
    for width in critic_hidden[1:]:
        c += prev * width
        prev = width
    c += prev * 1
    return 2.0 * batch * (4 * a + 7 * c)


def update_dot_shapes(obs_size: int, action_size: int, actor_hidden, critic_hidden, batch: int) -> list:
    """The (m, k, n) of every matmul `lhs (m, k) @ rhs (k, n)` in one DDPG update, as autodiff runs them.

    Targets: target actor and target critic forward on next_obs. Critic loss: critic forward, then per
    layer the weight gradient (in, batch) @ (batch, out) and the input gradient (batch, out) @ (out, in),
    except at the first layer, whose input (the observation) needs none. Actor loss: actor and critic
    forward; back through the critic's input gradients only (its weights are not trained there), then the
    actor's weight and input gradients (none for its first layer's input).
    """
    a_layers = list(zip([obs_size, *actor_hidden], [*actor_hidden, action_size]))
    c_widths_in = [obs_size, critic_hidden[0] + action_size, *critic_hidden[1:]]
    c_layers = list(zip(c_widths_in, [*critic_hidden, 1]))

    def forward(layers):
        return [(batch, i, o) for i, o in layers]

    def input_grads(layers):
        return [(batch, o, i) for i, o in layers[1:]]

    def weight_grads(layers):
        return [(i, batch, o) for i, o in layers]

    return (forward(a_layers) + forward(c_layers)
            + forward(c_layers) + weight_grads(c_layers) + input_grads(c_layers)
            + forward(a_layers) + forward(c_layers) + input_grads(c_layers)
            + weight_grads(a_layers) + input_grads(a_layers))


def measure_dot_chain_seconds(shapes, steps: int = 500, repeats: int = 5) -> float:
    """Seconds for one pass over `shapes` (a matmul each, float32, jitted, `steps` passes in a `lax.scan`;
    median of `repeats`). Each left operand gets the loop's scalar carry added so XLA cannot hoist the
    matmul out of the loop; that small pass is counted in, so the time is if anything high."""
    import jax
    import jax.numpy as jnp

    keys = jax.random.split(jax.random.PRNGKey(0), 2 * len(shapes))
    mats = [(jax.random.normal(keys[2 * i], (m, k), jnp.float32),
             0.01 * jax.random.normal(keys[2 * i + 1], (k, n), jnp.float32)) for i, (m, k, n) in enumerate(shapes)]

    def body(carry, _):
        total = jnp.zeros((), jnp.float32)
        for lhs, rhs in mats:
            total = total + ((lhs + carry) @ rhs)[0, 0]
        return carry + 1e-9 * total, None

    run = jax.jit(lambda c: jax.lax.scan(body, c, None, length=steps)[0])
    c0 = jnp.zeros((), jnp.float32)
    jax.block_until_ready(run(c0))
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(run(c0))
        times.append(time.perf_counter() - t)
    return statistics.median(times) / steps


def measure_matmul_flops(n: int = 1024, repeats: int = 5) -> float:
    """FLOP/s of a jitted n x n x n float32 matmul on JAX's default device (median of `repeats`)."""
    import jax
    import jax.numpy as jnp

    x = jax.random.normal(jax.random.PRNGKey(0), (n, n), jnp.float32)
    y = jax.random.normal(jax.random.PRNGKey(1), (n, n), jnp.float32)
    mm = jax.jit(lambda a, b: a @ b)
    jax.block_until_ready(mm(x, y))
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(mm(x, y))
        times.append(time.perf_counter() - t)
    return 2.0 * n**3 / statistics.median(times)


def _time_jax(env, config, repeats: int) -> dict:
    import jax

    from mjx_protamer.agents.ddpg.train import make_train

    trainer = make_train(config, env)
    t0 = time.perf_counter()
    state = trainer.init(jax.random.PRNGKey(0))
    state, m = trainer.train_chunk(state, None)  # compile + warm-up (fills the replay past the warm-up)
    jax.block_until_ready(m)
    compile_s = time.perf_counter() - t0
    steps = config.train.chunk_steps * config.train.num_envs
    rates = []
    for _ in range(repeats):
        t = time.perf_counter()
        state, m = trainer.train_chunk(state, None)
        jax.block_until_ready(m)
        rates.append(steps / (time.perf_counter() - t))
    return {"median": statistics.median(rates), "runs": rates, "compile_s": compile_s}


def _warm_chunks(config) -> int:
    """Chunks that take a trainer past its warm-up (random actions, no updates), plus one for the compile."""
    iterations = config.train.warmup_iterations
    return -(-iterations // config.train.chunk_steps) + 1


def _chunk_runner(config, seeds: int, env):
    """(init state, step): the jitted chunk of `config`'s trainer, alone (1 seed: what `pretrain` runs) or with
    `seeds` vmapped in one program (what `reproduce table2` runs)."""
    import jax
    import numpy as np

    from mjx_protamer.agents.ddpg.train import make_train

    trainer = make_train(config, env)
    if seeds == 1:
        return trainer.init, lambda s: trainer.train_chunk(s, None)
    init = jax.jit(jax.vmap(trainer.init))
    keys = jax.vmap(jax.random.PRNGKey)(np.arange(seeds, dtype=np.uint32))
    return (lambda _: init(keys)), jax.jit(jax.vmap(lambda s: trainer.chunk_body(s, None)[:2]), donate_argnums=0)


def _time_chunks(step, state, chunks: int, repeats: int):
    import jax

    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        for _ in range(chunks):
            state, metrics = step(state)
        jax.block_until_ready(metrics)
        times.append((time.perf_counter() - t) / chunks)
    return state, times


def time_batched_trainer(config, env, seeds: int, chunks: int, repeats: int) -> dict:
    """Seconds per chunk of the batched trainer of `config` after its warm-up, `seeds` vmapped in one program,
    median of `repeats` runs of `chunks` chunks; then the same chunks from the same state with no updates (the
    env stepping the worlds the trained policy visits, acting and replay writes: `no_update_chunk_s`). The
    physics backend is the one the run would use."""
    import dataclasses

    import jax

    init, step = _chunk_runner(config, seeds, env)
    t0 = time.perf_counter()
    state = init(jax.random.PRNGKey(0))
    for _ in range(_warm_chunks(config)):
        state, metrics = step(state)
    jax.block_until_ready(metrics)
    warm_s = time.perf_counter() - t0
    state, times = _time_chunks(step, state, chunks, repeats)
    # The env's cost depends on what the policy does (touch sensing runs only for worlds in contact, and a trained
    # infant touches itself most of the time), so it is timed on the trainer's own worlds, not on random actions.
    idle = dataclasses.replace(config, train=dataclasses.replace(config.train, updates_per_step=0))
    _, step0 = _chunk_runner(idle, seeds, env)
    state, _ = step0(state)  # compile
    jax.block_until_ready(state)
    state, times0 = _time_chunks(step0, state, chunks, repeats)
    out = {"chunk_s": statistics.median(times), "chunk_s_runs": times, "warm_up_and_compile_s": warm_s,
           "no_update_chunk_s": statistics.median(times0), "no_update_chunk_s_runs": times0}
    if seeds > 1:  # vmapped seeds are what `reproduce table2` trains, two conditions at a time
        pair = _time_two_at_once(step, state, chunks, repeats)
        out.update(two_at_once_chunk_s=statistics.median(pair), two_at_once_chunk_s_runs=pair)
    return out


def _time_two_at_once(step, state, chunks: int, repeats: int) -> list[float]:
    """Seconds per chunk when two copies of the trainer's program run at once on host threads
    (`side_by_side`, as `reproduce table2` trains two conditions): the pair's wall time over both its chunks."""
    import jax
    import jax.numpy as jnp

    from mjx_protamer.experiments.side_by_side import run_side_by_side

    states = [state, jax.tree.map(jnp.copy, state)]
    times = []

    def job(k):
        def run(between_chunks):
            between_chunks()  # compiled already: the second program need not wait for a first chunk
            s, metrics = states[k], None
            for _ in range(chunks):
                s, metrics = step(s)
            jax.block_until_ready(metrics)
            states[k] = s
        return run

    for _ in range(repeats):
        t = time.perf_counter()
        run_side_by_side([job(0), job(1)], at_once=2)
        times.append((time.perf_counter() - t) / (2 * chunks))
    return times


def batched_roofline(config, seed_counts, chunks: int, repeats: int) -> dict:
    """The batched trainer against its roofline (issue 40): a chunk's updates at the time their own matmuls take
    (`update_dot_shapes` at the run's networks and batch, chained in one jitted scan, measured now) plus its env
    steps. The env's time is given two ways, both measured now: at the rate the env alone steps the same batch
    with random actions (`bench env`'s protocol: `roofline_chunk_s`, `fraction_of_roofline`), and as the same
    trainer's chunk without updates from the trained state (the worlds the policy visits, with acting and replay
    writes: `roofline_trained_worlds_chunk_s`, `fraction_of_roofline_trained_worlds`). The fraction is roofline
    time over measured time: 1.0 would mean nothing but the update's arithmetic and the env costs anything.
    With vmapped seeds also per chunk of two copies of the program at once (`..._two_at_once`): how `reproduce
    table2` trains, two conditions at a time, since one program leaves part of the cores idle.
    Keyed by the number of vmapped seeds."""
    from mjx_protamer.experiments.bench_env import _bench_env
    from mjx_protamer.experiments.env_factory import make_env

    tc, dc = config.train, config.ddpg
    env = make_env(config)
    shapes = update_dot_shapes(env.observation_size, env.action_size, dc.actor_hidden, dc.critic_hidden,
                               dc.batch_size)
    dot_s = measure_dot_chain_seconds(shapes, repeats=repeats)
    out = {"config": {"num_envs": tc.num_envs, "updates_per_step": tc.updates_per_step,
                      "chunk_steps": tc.chunk_steps, "batch_size": dc.batch_size, "iterations": tc.iterations,
                      "backend": getattr(getattr(config, "env", None), "backend", None)},
           "update_matmul_s": dot_s, "seeds": {}}
    for seeds in seed_counts:
        worlds = tc.num_envs * seeds
        env_rate = _bench_env(env, worlds, tc.chunk_steps, repeats)["steps_per_s"]
        timed = time_batched_trainer(config, env, seeds, chunks, repeats)
        updates = tc.chunk_steps * tc.updates_per_step * seeds
        update_s, env_s = updates * dot_s, tc.chunk_steps * worlds / env_rate
        roofline_s, trained_s = update_s + env_s, update_s + timed["no_update_chunk_s"]
        out["seeds"][str(seeds)] = dict(
            timed, env_steps_per_s_alone=env_rate, roofline_chunk_s=roofline_s, roofline_update_s=update_s,
            roofline_env_s=env_s, fraction_of_roofline=roofline_s / timed["chunk_s"],
            roofline_trained_worlds_chunk_s=trained_s,
            fraction_of_roofline_trained_worlds=trained_s / timed["chunk_s"],
            update_share_beyond_matmuls_s=timed["chunk_s"] - trained_s,
            updates_per_s=updates / timed["chunk_s"], env_steps_per_s=tc.chunk_steps * worlds / timed["chunk_s"],
            run_train_s_projected=tc.num_chunks * timed["chunk_s"], run_train_s_at_roofline=tc.num_chunks * roofline_s)
        if "two_at_once_chunk_s" in timed:
            out["seeds"][str(seeds)].update(
                fraction_of_roofline_two_at_once=roofline_s / timed["two_at_once_chunk_s"],
                fraction_of_roofline_trained_worlds_two_at_once=trained_s / timed["two_at_once_chunk_s"])
    return out


def _make_twin(config):
    """The NumPy/Gymnasium twin of the env the JAX side trains on (same env config)."""
    if config.env_name == "toy":
        from mjx_protamer.envs.toy_twin import PointReachGym

        return PointReachGym(config.toy, episode_length=config.train.episode_length)
    from mjx_protamer.envs.twin import SelfTouchTwinEnv

    return SelfTouchTwinEnv(config.env)  # truncates at env.episode_length itself


def _time_sb3(config, steps: int, repeats: int) -> dict:
    import numpy as np
    import torch
    from stable_baselines3 import DDPG
    from stable_baselines3.common.noise import OrnsteinUhlenbeckActionNoise

    env = _make_twin(config)
    act = env.action_space.shape[0]
    noise = OrnsteinUhlenbeckActionNoise(mean=np.zeros(act), sigma=0.6 * np.ones(act), theta=0.15, dt=1.0)
    model = DDPG(
        "MlpPolicy", env, learning_rate=1e-3, buffer_size=100_000, learning_starts=64, batch_size=64,
        tau=0.001, gamma=0.99, train_freq=1, gradient_steps=1, action_noise=noise,
        policy_kwargs={"net_arch": {"pi": [400, 300], "qf": [400, 300]}}, device="cpu", seed=0, verbose=0,
    )
    model.learn(total_timesteps=64 + 100)  # past learning_starts, warm
    rates = []
    for _ in range(repeats):
        t = time.perf_counter()
        model.learn(total_timesteps=steps, reset_num_timesteps=False)
        rates.append(steps / (time.perf_counter() - t))
    return {"median": statistics.median(rates), "runs": rates, "torch_threads": torch.get_num_threads(),
            "env": f"{type(env).__module__}.{type(env).__name__}"}


def _roofline_run(args: argparse.Namespace):
    """(config, seed counts) of the batched-trainer section, validated."""
    from mjx_protamer.agents.ddpg.config import PretrainConfig
    from mjx_protamer.config import load_config, shipped_config
    from mjx_protamer.experiments.bench_env import parse_positive_ints
    from mjx_protamer.experiments.env_factory import with_resolved_backend

    counts = parse_positive_ints(args.roofline_seeds, "--roofline-seeds")
    path = args.roofline_config or shipped_config("pretrain.yaml")
    return with_resolved_backend(load_config(PretrainConfig, path, args.roofline_set), announce=False), counts


def run_train_benchmark(args: argparse.Namespace) -> dict:
    from mjx_protamer.experiments.bench_env import _bench_env
    from mjx_protamer.experiments.env_factory import make_env, resolve_backend
    from mjx_protamer.experiments.machine import describe

    trainer_run = None if getattr(args, "skip_roofline", False) else _roofline_run(args)  # bad input: before any work
    single = _config(args.env, 1, args.steps)
    env = make_env(single)
    jax_single = _time_jax(env, single, args.repeats)
    batched = _config(args.env, args.batched_envs, args.batched_iterations)
    jax_batched = _time_jax(make_env(batched), batched, args.repeats)
    self_touch = args.env == "self_touch"
    chosen_single = resolve_backend("auto", 1) if self_touch else None
    chosen_batched = resolve_backend("auto", args.batched_envs) if self_touch else None
    result = {
        "env": args.env,
        "backend_single": chosen_single,
        "backend_batched": chosen_batched,
        "steps_per_s": jax_single["median"],
        "batched256_steps_per_s": jax_batched["median"],
        "batched_envs": args.batched_envs,
        "jax_single_runs": jax_single["runs"],
        "jax_batched_runs": jax_batched["runs"],
        "jax_single_compile_s": jax_single["compile_s"],
        "jax_batched_compile_s": jax_batched["compile_s"],
        "updates_per_env_step_single": 1,
        "updates_per_vectorised_step_batched": 1,
        "repeats": args.repeats,
        "machine": describe(),
    }

    # The single-env roofline: matmul peak and one env step, measured now, on this machine.
    flops = update_flops(env.observation_size, env.action_size, single.ddpg.actor_hidden,
                         single.ddpg.critic_hidden, single.ddpg.batch_size)
    peak = measure_matmul_flops()
    env_rate = _bench_env(env, 1, 200, args.repeats)["steps_per_s"]
    roofline = 1.0 / (flops / peak + 1.0 / env_rate)
    result.update(update_flops=flops, matmul_flops_per_s=peak, single_env_env_steps_per_s=env_rate,
                  single_env_roofline_steps_per_s=roofline,
                  single_env_fraction_of_roofline=jax_single["median"] / roofline)
    shapes = update_dot_shapes(env.observation_size, env.action_size, single.ddpg.actor_hidden,
                               single.ddpg.critic_hidden, single.ddpg.batch_size)
    dot_flops = float(sum(2 * m * k * n for m, k, n in shapes))
    dot_s = measure_dot_chain_seconds(shapes, repeats=args.repeats)
    roofline_shapes = 1.0 / (dot_s + 1.0 / env_rate)
    result.update(update_dot_flops=dot_flops, update_matmul_s=dot_s, matmul_update_shapes_flops_per_s=dot_flops / dot_s,
                  single_env_roofline_update_shapes_steps_per_s=roofline_shapes,
                  single_env_fraction_of_roofline_update_shapes=jax_single["median"] / roofline_shapes)

    if self_touch:
        result.update(single_env_steps_per_s={chosen_single: jax_single["median"]},
                      batched_steps_per_s={chosen_batched: jax_batched["median"]})
        for backend in _parse_backends(getattr(args, "backends", "mjx,native")):
            for key, n, k in (("single_env_steps_per_s", 1, args.steps),
                              ("batched_steps_per_s", args.batched_envs, args.batched_iterations)):
                if backend not in result[key]:
                    cfg = _config(args.env, n, k, backend)
                    result[key][backend] = _time_jax(make_env(cfg), cfg, args.repeats)["median"]
        rates = result["batched_steps_per_s"]
        result["ratio_batched_native_vs_mjx"] = (rates["native"] / rates["mjx"]
                                                 if {"native", "mjx"} <= rates.keys() else None)
    if trainer_run is not None:
        result["batched_trainer"] = batched_roofline(*trainer_run, args.roofline_chunks, args.repeats)
    if not args.skip_sb3:
        sb3 = _time_sb3(single, args.sb3_steps, args.repeats)
        result.update(sb3_steps_per_s=sb3["median"], sb3_runs=sb3["runs"], sb3_torch_threads=sb3["torch_threads"],
                      sb3_env=sb3["env"], ratio_vs_sb3=jax_single["median"] / sb3["median"])
    else:
        result.update(sb3_steps_per_s=None, ratio_vs_sb3=None)
    return result


def main(argv: list[str] | None = None) -> int:  # `python -m mjx_protamer.experiments.bench_train` until wired
    import json

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_arguments(parser)
    print(json.dumps(run_train_benchmark(parser.parse_args(argv)), indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
