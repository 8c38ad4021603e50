"""Evaluate a policy on test episodes (deterministic actor): the one evaluator of `protamer eval`, pretrain's
test episodes, table2's conditions and the live-effect report. Loading a saved run is `run_loader.load_run`.

`make_evaluator` is pure JAX and vmaps over seeds (table2 runs every seed's actor at once); `summarize` turns
its output into the results' JSON on the host. Whole-number counts (the paper's metrics, body-map counts)
are computed inside the jit; sums of floats (returns, the teacher's mean score, r_hat's correlation) are taken
on the host from the per-step values, in float32 as NumPy sums them, so the numbers do not depend on how XLA
orders a reduction.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from mjx_protamer.experiments import metrics
# Re-exported: callers that load a run for evaluation import these from here.
from mjx_protamer.experiments.run_loader import CONFIG_NAME, load_run, resolve_checkpoint  # noqa: F401
from mjx_protamer.experiments.stats import pearson


def make_evaluator(config, env, teacher=None, reward_model_apply=None, state_stride: int = 0):
    """evaluate(actor_params, keys (E, 2), reward_models={}) -> dict of device arrays, vmappable:
    - `counts`: `metrics.episode_counts` of every episode (the paper's metrics, body-map counts);
    - `reward` (E, T): the env reward of every step (the episode return);
    - with a `teacher` (TeacherConfig): `score` (E, T), its hidden score of every step;
    - per named reward model (`reward_models[name]` params for `reward_model_apply`): `r_hat/<name>` (E, T);
    - with `state_stride` > 0 and a teacher: `states`, every `state_stride`-th step's obs, action and score,
      flattened over episodes (E * ceil(T / stride), ...).
    `config` is the run's PretrainConfig (episode length, actor layers, freeze threshold)."""
    from mjx_protamer.agents.ddpg.evaluate import METRIC_SIGNALS, make_rollout

    keep = METRIC_SIGNALS
    if teacher is not None:
        from mjx_protamer.human.teachers import env_signal_columns, rule_scores, rule_signals

        cols = env_signal_columns(teacher.signals, env)
    if teacher is not None or reward_model_apply is not None:
        keep += ("obs", "action", "reward_terms")
    rollout = make_rollout(env, config.train.episode_length, config.ddpg.actor_hidden, keep=keep)
    threshold = config.env.freeze_speed  # rad/s; the toy env scales its speed so that 1 "rad/s" is 0.1 a step

    def evaluate(actor_params, keys, reward_models=None) -> dict:
        sig = rollout(actor_params, keys)
        out = {"counts": metrics.episode_counts(sig["self_contact"], sig["region_mask"], sig["arm_speed"],
                                                threshold, xp=jnp),
               "reward": sig["reward"]}
        if teacher is not None:
            out["score"] = jax.vmap(lambda o, a, t, r: rule_scores(teacher, rule_signals(cols, o, a, t, r)))(
                sig["obs"], sig["action"], sig["reward_terms"], sig["region_mask"])
            if state_stride > 0:
                states = {"obs": sig["obs"][:, ::state_stride], "action": sig["action"][:, ::state_stride],
                          "score": out["score"][:, ::state_stride]}
                out["states"] = jax.tree.map(lambda x: x.reshape(-1, *x.shape[2:]), states)
        for name, params in (reward_models or {}).items():
            out[f"r_hat/{name}"] = reward_model_apply(params, sig["obs"], sig["action"])
        return out

    return evaluate


def summarize(evaluation: dict, steps: int) -> dict:
    """The results' JSON of one seed's `make_evaluator` output (host arrays): the four metrics (means and
    per-episode lists), `region_touch_frequency`, the mean return; with a teacher `teacher_score`; per reward
    model `r_hat_corr_<name>`, r_hat's correlation with the hidden score on these test states."""
    summary = metrics.from_counts(evaluation["counts"], steps)
    returns = np.sum(evaluation["reward"], axis=1)
    summary["episode_return"] = float(returns.mean())
    summary["per_episode"]["episode_return"] = [float(r) for r in returns]
    if "score" in evaluation:
        score = evaluation["score"]
        summary["teacher_score"] = float(score.mean())
        summary["per_episode"]["teacher_score"] = [float(x) for x in score.mean(axis=1)]
        for key in evaluation:
            if key.startswith("r_hat/"):
                summary[f"r_hat_corr_{key[len('r_hat/'):]}"] = pearson(np.ravel(evaluation[key]), np.ravel(score))
    return summary


def evaluate(config, env, actor_params, episodes: int, seed: int) -> dict:
    """The four metrics (means and per-episode lists) and the mean return over `episodes` test episodes."""
    keys = jax.random.split(jax.random.PRNGKey(seed), episodes)
    return summarize(jax.device_get(jax.jit(make_evaluator(config, env))(actor_params, keys)),
                     config.train.episode_length)


def eval_seed(config) -> int:
    """Test episodes use their own seed stream, apart from training's."""
    return config.train.seed + 10_000


def validation_seed(config) -> int:
    """Validation episodes (choosing the test snapshot, agents/ddpg/selection.py) use a third stream."""
    return config.train.seed + 20_000
