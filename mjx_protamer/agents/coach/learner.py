"""The Deep COACH learner on the host: act, remember steps, turn feedback into windows, update.

How a scalar feedback becomes a correction
------------------------------------------
COACH reads feedback as the advantage of what the agent has just been doing under its current policy, so
one scalar per event is enough: a key press +1 / -1 / 0, a prosody valence in [-1, 1], a Whisper label.
The window of the last L steps before the judged step gets the update f * e_lambda, and
grad log N(a | mu, sigma) = (a - mu) / sigma^2 for the mean: a positive f moves the mean towards the
actions actually taken (the exploration noise that was sampled), a negative f away from them, and
|f| (e.g. the strength of a prosodic valence) scales the step; 0 changes nothing but the entropy term.
The direction of the correction thus comes from the agent's own recent exploration, its sign and size
from the human. Events reach the learner through the same queue as for DeepTAMER; the event's step is
`StepClock.step_at(event.t_start)`, and the judged window ends `human_delay_steps` before it.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import optax

from mjx_protamer.agents.coach.config import CoachConfig
from mjx_protamer.agents.coach.losses import coach_loss
from mjx_protamer.agents.coach.networks import GaussianPolicy, log_prob
from mjx_protamer.agents.coach.replay import WindowReplay


class CoachLearner:
    def __init__(self, config: CoachConfig, obs_size: int, action_size: int, seed: int = 0, history: int = 4096):
        self.config = config
        self.obs_size, self.action_size = obs_size, action_size
        self.policy = GaussianPolicy(action_size, tuple(config.hidden), config.init_log_std, config.activation)
        self.params = self.policy.init(jax.random.PRNGKey(seed), jnp.zeros((1, obs_size)))
        self.optimizer = optax.adam(config.learning_rate)
        self.opt_state = self.optimizer.init(self.params)
        self.replay = WindowReplay(config.replay_size, config.window, obs_size, action_size)
        self.rng = np.random.default_rng(seed)
        self.key = jax.random.PRNGKey(seed + 1)
        # history of recorded steps by global step: obs, action, log pi_old(a|s)
        self.history = history
        self._obs = np.zeros((history, obs_size), np.float32)
        self._act = np.zeros((history, action_size), np.float32)
        self._logp = np.zeros((history,), np.float32)
        self._step = np.full((history,), -1, np.int64)
        self.updates = 0
        self.last_loss = float("nan")
        self._act_fn = jax.jit(functools.partial(_sample, self.policy.apply, config.min_log_std))
        self._update = jax.jit(functools.partial(_update, self.policy.apply, self.optimizer, config))

    def act(self, obs) -> tuple[np.ndarray, np.ndarray]:
        """Sample actions for a batch of observations (B, O): (actions, log pi(a|s))."""
        self.key, k = jax.random.split(self.key)
        a, lp = self._act_fn(self.params, jnp.asarray(obs, jnp.float32), k)
        return np.asarray(a), np.asarray(lp)

    def mean_action(self, obs) -> np.ndarray:
        return np.asarray(self.policy.apply(self.params, jnp.asarray(obs, jnp.float32))[0])

    def record(self, first_step: int, obs, action, logp) -> None:
        """Remember steps first_step.. with the log-probability under the policy that sampled them."""
        n = len(obs)
        idx = (first_step + np.arange(n)) % self.history
        self._obs[idx], self._act[idx], self._logp[idx] = obs, action, logp
        self._step[idx] = first_step + np.arange(n)

    def window(self, step: int):
        """The L steps ending at `step` (oldest first) with a mask for steps not remembered."""
        steps = step - np.arange(self.config.window - 1, -1, -1)
        idx = steps % self.history
        mask = (self._step[idx] == steps).astype(np.float32)
        return self._obs[idx], self._act[idx], self._logp[idx], mask

    def feedback(self, value: float, step: int) -> bool:
        """Feedback arriving at `step` judges the window ending at step - human_delay_steps."""
        end = step - self.config.human_delay_steps
        obs, act, logp, mask = self.window(end)
        if mask.sum() == 0:
            return False
        newest = self.replay.add(obs, act, logp, mask, value)
        for _ in range(self.config.updates_per_feedback):
            batch = self.replay.batch(self.rng, self.config.batch_windows, newest)
            self.params, self.opt_state, loss = self._update(self.params, self.opt_state, *map(jnp.asarray, batch))
            self.updates += 1
            self.last_loss = float(loss)
        return True


def _sample(apply, min_log_std, params, obs, key):
    mean, log_std = apply(params, obs)
    log_std = jnp.maximum(log_std, min_log_std)
    action = mean + jnp.exp(log_std) * jax.random.normal(key, mean.shape)
    return action, log_prob(mean, log_std, action, min_log_std)


def _update(apply, optimizer, config: CoachConfig, params, opt_state, obs, action, logp_old, mask, feedback):
    (loss, _), grads = jax.value_and_grad(coach_loss, has_aux=True)(
        params, apply, obs, action, logp_old, mask, feedback, config.trace_decay, config.entropy_coef,
        config.min_log_std)
    updates, opt_state = optimizer.update(grads, opt_state, params)
    return optax.apply_updates(params, updates), opt_state, loss
