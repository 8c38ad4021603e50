"""What a table2 run keeps of every finished condition, and how scripts and `--resume` read it back: each seed's
agents (`agents/<condition>/`) and reward models (`reward_models/<condition>/`, orbax checkpoints) and a sample
of its test states (`test_states_<condition>.npz`)."""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from mjx_protamer.config import ConfigError
from mjx_protamer.experiments.table2.config import Table2Config, load_table2_config


def save_condition_models(out: Path, name: str, rm_params, states: dict, agents: dict) -> None:
    """The condition's reward models, its agents (each seed's actor and critic, `agents/<name>/`: what the
    test episodes ran, for rendering, fine-tuning or diagnosis, e.g. `protamer analyze freeze-anatomy`) and its
    sampled test states."""
    import io

    from mjx_protamer.atomic import write_atomic
    from mjx_protamer.experiments import checkpoints

    for path, tree in ((out / "reward_models" / name, rm_params), (out / "agents" / name, agents)):
        checkpoints.save_model(path, jax.device_get(tree))
    buf = io.BytesIO()
    np.savez_compressed(buf, **states)
    write_atomic(out / f"test_states_{name}.npz", buf.getvalue())


def load_finished_condition(out: Path, name: str) -> tuple[Table2Config, dict]:
    """(config, sampled test states) of a finished condition of a table2 run, for the diagnostics of `protamer analyze`."""
    states = _read_test_states(out, name, "give the --out directory of a finished table2 run and a condition it "
                                          "ran (--condition)")
    return load_table2_config(out / "config.yaml"), states


def _read_test_states(out: Path, name: str, fix: str) -> dict:
    """The test states `run_table2` sampled for a condition; a missing file is a ConfigError ending in `fix`."""
    path = out / f"test_states_{name}.npz"
    if not path.is_file():
        raise ConfigError(f"{path} is missing: {fix}")
    with np.load(path) as f:
        return {k: f[k] for k in f.files}


def load_condition_reward_models(out: Path, cfg: Table2Config, name: str, obs_size: int, act_size: int):
    """(nets, params) of a finished condition's reward models, stacked over the run's seeds."""
    from mjx_protamer.experiments import checkpoints
    from mjx_protamer.human.reward_model import reward_nets

    nets = reward_nets(cfg.feedback.reward_model)
    keys = jax.random.split(jax.random.PRNGKey(0), len(cfg.seeds))
    like = jax.vmap(lambda k: nets.net.init(k, jnp.zeros((1, obs_size)), jnp.zeros((1, act_size))))(keys)
    return nets, checkpoints.restore(checkpoints.manager(out / "reward_models" / name), 0, like)


def load_condition_agents(out: Path, cfg: Table2Config, name: str, obs_size: int, act_size: int):
    """(actor, critic, params) of a finished condition: the flax modules and {"actor", "critic"} params
    stacked over the run's seeds, as `run_table2` saved them."""
    from mjx_protamer.agents.ddpg.networks import Actor, Critic
    from mjx_protamer.experiments import checkpoints

    path = out / "agents" / name
    if not path.is_dir():
        raise ConfigError(f"{path} is missing: give the --out directory of a table2 run that finished condition "
                          f"{name} (runs before this version did not keep their agents)")
    dc = cfg.pretrain.ddpg
    actor, critic = Actor(action_size=act_size, hidden=tuple(dc.actor_hidden)), Critic(hidden=tuple(dc.critic_hidden))

    def init(key):
        ka, kc = jax.random.split(key)
        return {"actor": actor.init(ka, jnp.zeros((obs_size,))),
                "critic": critic.init(kc, jnp.zeros((obs_size,)), jnp.zeros((act_size,)))}

    like = jax.vmap(init)(jax.random.split(jax.random.PRNGKey(0), len(cfg.seeds)))
    return actor, critic, checkpoints.restore(checkpoints.manager(path), 0, like)


def load_condition_models(out: Path, name: str, like) -> tuple[object, dict]:
    """(reward-model params stacked over seeds, sampled test states) of a finished condition (`like`: params of
    the same shape, e.g. untrained ones)."""
    from mjx_protamer.experiments import checkpoints

    states = _read_test_states(out, name, "--resume cannot use this run (an older version?); start again with "
                                          "another --out")
    return checkpoints.restore(checkpoints.manager(out / "reward_models" / name), 0, like), states


