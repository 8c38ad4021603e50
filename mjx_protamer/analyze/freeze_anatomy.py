"""What a frozen test policy is doing: its actions, its servo torques, its touch and its reward model (issue 8).

Reads a finished `protamer reproduce table2 --out DIR` run (config.yaml, test_states_<condition>.npz: every 5th
step of the test episodes, whole episodes in order; reward_models/<condition>/ where the condition learnt one)
and prints one JSON line per seed. The test states are split into still (arm speed below the env's
`freeze_speed`, the freeze metric's own definition) and moving, and for each part it gives:
- `actions_at_wall`: the share of action dimensions with |a| > 0.95 (tanh(1.83); the actor's pre-tanh wall
  `ddpg.actor_preact_free` 2 sits at 0.964);
- `torques_clipped`: the share of the arm actuators' torques (the observation's torque block) at 98% or more
  of their `forcerange` (`envs/body.py` ARM_JOINTS max_torque). A position servo whose target lies past where
  the body blocks the arm pushes at its clip, and then no small change of the action changes the physics;
- `touch_norm`: the L2 norm of the touch features (obs 0:4(k+3));
- `r_hat`: the reward model the condition learnt, on those states (absent where it has no teacher);
- where the run kept its agents (`agents/<condition>/`), what the critic tells the actor there: `q` (Q(s, mu(s))),
  `q_slope` (the norm of dQ/da at a = mu(s)), `actor_slope` (the norm of dQ/d(pre-tanh) = dQ/da (1 - a^2): what
  the deterministic policy gradient moves the actor's output with) and `outward_at_wall` (of the action
  dimensions beyond 0.95, the share whose dQ/da pushes further out), and `q_gain_random` (the best of
  RANDOM_ACTIONS actions drawn uniformly from the box, by the critic, less Q(s, mu(s)), on up to SAMPLE states:
  whether the critic knows a better action than the actor's, far from it).
Also `still_fraction` (the freeze ratio of these samples), `median_still_run_s`, and the share of the still
steps that lie in stops of at least 0.1 s (what a teacher who notices after 0.1 s can see) and 0.5 s (a held
pose), against stop-and-go.

    protamer analyze freeze-anatomy runs/table2 [--condition DTK]
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

WALL = 0.95
CLIP = 0.98
RANDOM_ACTIONS = 256
SAMPLE = 200
STOP_S = (0.1, 0.5)  # the teacher notices a stop after 0.1 s (the rules' sustain 20); 0.5 s is a held pose


def runs_of(mask: np.ndarray):
    """Lengths of the runs of True in a 1-D bool array."""
    padded = np.concatenate([[False], mask, [False]]).astype(np.int8)
    d = np.diff(padded)
    return np.flatnonzero(d == -1) - np.flatnonzero(d == 1)


def obs_layout(env) -> dict[str, np.ndarray]:
    """Indices of the observation's blocks (envs/model.py `observe`): touch, arm speed joints, arm torques."""
    touch = 4 * (env.k + 3)
    qvel0 = touch + len(env.qpos_joints)
    torque0 = qvel0 + len(env.qvel_joints)
    speed = np.array([qvel0 + env.qvel_joints.index(n) for n in env.speed_joints])
    return {"touch": np.arange(touch), "speed": speed,
            "torque": torque0 + np.arange(len(env.torque_actuators))}


def max_torques(env) -> np.ndarray:
    from mjx_protamer.envs import body

    out = []
    for name in env.torque_actuators:
        joint = name.split("_", 1)[1]
        out.append(body.ARM_JOINTS[joint].max_torque)
    return np.asarray(out)


def r_hat_of(run: Path, condition: str, cfg, obs, action):
    """The condition's saved reward models on the states, (seeds, n); None when it learnt none (a condition
    without a teacher saves the untrained model, for `r_hat_corr_untrained`: not what it learnt)."""
    if not any(c.name == condition and c.channel != "none" for c in cfg.conditions):
        return None
    import jax

    from mjx_protamer.experiments.table2 import load_condition_reward_models

    nets, params = load_condition_reward_models(run, cfg, condition, obs.shape[-1], action.shape[-1])
    return np.asarray(jax.jit(jax.vmap(nets.apply))(params, obs, action))


def critic_view(run: Path, condition: str, cfg, obs, action):
    """(Q(s, a) (seeds, n), dQ/da (seeds, n, act), the best Q over RANDOM_ACTIONS uniform actions (seeds, n)) of
    the condition's saved critics at the states' actions; None without saved agents."""
    if not (run / "agents" / condition).is_dir():
        return None
    import jax
    import jax.numpy as jnp

    from mjx_protamer.experiments.table2 import load_condition_agents

    _, critic, params = load_condition_agents(run, cfg, condition, obs.shape[-1], action.shape[-1])
    q_and_grad = jax.vmap(jax.value_and_grad(lambda a, p, o: critic.apply(p, o, a)), in_axes=(0, None, 0))
    q, grad = jax.jit(jax.vmap(q_and_grad))(action, params["critic"], obs)
    # the same random actions for every state and seed (a fixed draw: the script is deterministic)
    others = jax.random.uniform(jax.random.PRNGKey(0), (RANDOM_ACTIONS, action.shape[-1]), minval=-1.0, maxval=1.0)
    best = jax.jit(jax.vmap(lambda p, o: jax.vmap(
        lambda s: critic.apply(p, jnp.broadcast_to(s, (RANDOM_ACTIONS, s.shape[-1])), others).max())(o)))
    return np.asarray(q), np.asarray(grad), np.asarray(best(params["critic"], obs))


def part(mask, action, obs, lay, tmax, r_hat, critic=None):
    if not mask.any():
        return None
    a = action[mask]
    out = {"actions_at_wall": float((np.abs(a) > WALL).mean()),
           "torques_clipped": float((np.abs(obs[mask][:, lay["torque"]]) >= CLIP * tmax).mean()),
           "touch_norm": float(np.linalg.norm(obs[mask][:, lay["touch"]], axis=1).mean())}
    if r_hat is not None:
        out["r_hat"] = float(r_hat[mask].mean())
    if critic is not None:
        q, grad, best = critic[0][mask], critic[1][mask], critic[2][mask]
        out["q"] = float(q.mean())
        out["q_slope"] = float(np.linalg.norm(grad, axis=1).mean())
        out["actor_slope"] = float(np.linalg.norm(grad * (1.0 - a ** 2), axis=1).mean())
        wall = np.abs(a) > WALL
        if wall.any():
            out["outward_at_wall"] = float((np.sign(grad[wall]) == np.sign(a[wall])).mean())
        pick = np.linspace(0, len(q) - 1, min(SAMPLE, len(q))).astype(int)
        out["q_gain_random"] = float((best[pick] - q[pick]).mean())
    return {k: round(v, 3) for k, v in out.items()}


def anatomy(run: Path, condition: str) -> list[dict]:
    """One line a seed of the condition's test states; a run or condition that is not there, or states that do
    not fit the run's env, raise ConfigError."""
    from mjx_protamer.config import ConfigError
    from mjx_protamer.experiments.table2 import STATE_STRIDE, load_finished_condition

    cfg, states = load_finished_condition(run, condition)
    env = cfg.pretrain.env
    obs, action = states["obs"], states["action"]
    lay, tmax = obs_layout(env), max_torques(env)
    if obs.shape[-1] != env.observation_size:
        raise ConfigError(f"{run} holds {obs.shape[-1]}-dim states but its config.yaml's env observes "
                          f"{env.observation_size}: the run's files do not belong together")
    r_hat = r_hat_of(run, condition, cfg, obs, action)
    critic = critic_view(run, condition, cfg, obs, action)
    per_episode = cfg.pretrain.train.episode_length // STATE_STRIDE
    sample_s = STATE_STRIDE * cfg.pretrain.env.physics.timestep
    lines = []
    for i, seed in enumerate(cfg.seeds):
        speed = np.linalg.norm(obs[i][:, lay["speed"]], axis=1)
        still = speed < env.freeze_speed
        runs = np.concatenate([runs_of(ep) for ep in still.reshape(-1, per_episode)])
        rh = None if r_hat is None else r_hat[i]
        cv = None if critic is None else tuple(c[i] for c in critic)
        lines.append({
            "seed": seed, "still_fraction": round(float(still.mean()), 3),
            "median_still_run_s": round(float(np.median(runs)) * sample_s, 3) if len(runs) else None,
            # the freeze's steps by the length of the stop they lie in: a held pose, or stop-and-go
            **{f"still_in_stops_of_{t}s_or_more":
               round(float(runs[runs * sample_s >= t - 1e-9].sum() / max(runs.sum(), 1)), 3) for t in STOP_S},
            "still": part(still, action[i], obs[i], lay, tmax, rh, cv),
            "moving": part(~still, action[i], obs[i], lay, tmax, rh, cv)})
    return lines
