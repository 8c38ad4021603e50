"""Deep COACH on the host: jitted rollout chunks of ONE env, and between them the feedback queue.

The same shape as `tamer_loop.TamerRun`, with `CoachLearner` in place of DDPG + DeepTAMER:

1. `rollout(params, env_state, key)`: `chunk_steps` steps of one (auto-resetting) env in one jit; each
   action is sampled from the Gaussian policy N(mu(s), sigma) and clipped to [-1, 1] for the env; the
   chunk returns the observations, the sampled (unclipped) actions, log pi_old(a|s) and the reward terms.
   The policy params are an argument: a COACH update never recompiles the rollout.
2. The chunk's steps are stamped on the `StepClock` at their presentation times (as in TamerRun) and
   remembered by the learner (`CoachLearner.record`, with the log-probabilities the importance ratio
   needs when an older window is replayed).
3. The queue is drained (each event logged), each event is mapped to the step shown when it began
   (`StepClock.step_at(event.t_start)`), and `CoachLearner.feedback(value, step)` turns it into a
   correction of the window of L steps ending `human_delay_steps` before that step (see
   docs/human_feedback.md, "How a scalar becomes a correction").
"""

from __future__ import annotations

import dataclasses
import functools
import time
from pathlib import Path
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

from mjx_protamer.agents.coach import CoachConfig, CoachLearner
from mjx_protamer.agents.coach.networks import log_prob
from mjx_protamer.config import ConfigError
from mjx_protamer.human.attention import describe, is_attention
from mjx_protamer.human.clock import StepClock, VirtualClock
from mjx_protamer.human.queue import FeedbackLog, FeedbackQueue
from mjx_protamer.human.teachers import HostTeacher, TeacherConfig, env_signal_columns, rule_signals, with_channel
from mjx_protamer.human.touches import TouchWatcher


@dataclasses.dataclass(frozen=True)
class CoachRunConfig:
    coach: CoachConfig = dataclasses.field(default_factory=CoachConfig)
    chunk_steps: int = 50
    episode_length: int = 1000
    dt: float = 0.005  # presentation period of one step (s)
    queue_size: int = 256
    min_interval_steps: int = 5  # events closer than this (in steps) to the previous one are not used
    seed: int = 0


def _rollout(venv, apply, min_log_std, chunk_steps, params, state, key):
    def step(carry, k):
        s = carry
        mean, log_std = apply(params, s.obs)
        log_std = jnp.maximum(log_std, min_log_std)
        a = mean + jnp.exp(log_std) * jax.random.normal(k, mean.shape)
        lp = log_prob(mean, log_std, a, min_log_std)
        ns = venv.step(s, jnp.clip(a, -1.0, 1.0))
        out = {"obs": s.obs[0], "action": a[0], "logp": lp[0], "reward": ns.reward[0],
               "reward_terms": ns.metrics["reward_terms"][0],
               "contact": jnp.asarray(ns.metrics.get("self_contact", jnp.zeros((1,))), jnp.float32).reshape(-1)[0]}
        if getattr(venv, "region_names", ()):  # what a teacher rule's region signals read
            out["region_mask"] = ns.metrics["region_mask"][0]
        return ns, out

    state, out = jax.lax.scan(step, state, jax.random.split(key, chunk_steps))
    return state, out


class CoachRun:
    """Deep COACH on one env, fed by a FeedbackQueue. `feedback`: None (no teacher: events come from
    outside, e.g. the keyboard thread or the voice listener, on the wall clock) or "simulated:<kind>"
    (a host simulated teacher on a virtual clock feeds the queue)."""

    def __init__(self, config: CoachRunConfig, env, feedback: str | None = None, queue: FeedbackQueue | None = None,
                 log_path: str | Path | None = None, clock: Callable[[], float] | None = None,
                 teacher: TeacherConfig | None = None):
        from mjx_protamer.envs.wrappers import wrap_for_training

        config.coach.validate()
        self.config = config
        self.env = env
        self.learner = CoachLearner(config.coach, env.observation_size, env.action_size, seed=config.seed)
        self.venv = wrap_for_training(env, config.episode_length)
        self.key = jax.random.PRNGKey(config.seed + 7)
        self.key, k = jax.random.split(self.key)
        self.env_state = jax.jit(self.venv.reset)(k[None])
        self._commit()
        self._rollout = jax.jit(functools.partial(_rollout, self.venv, self.learner.policy.apply,
                                                  config.coach.min_log_std, config.chunk_steps))
        self.simulated = feedback is not None and feedback.startswith("simulated")
        self.clock = clock or (VirtualClock(start=time.time()) if self.simulated else time.time)
        self.queue = queue or FeedbackQueue(config.queue_size, clock=self.clock)
        self.log = FeedbackLog(log_path) if log_path is not None else None
        self.step_clock = StepClock(config.dt, capacity=self.learner.history)
        self.teacher = None
        if self.simulated:
            tcfg = teacher or TeacherConfig()
            kind = feedback.split(":", 1)[1] if ":" in feedback else tcfg.channel.kind
            self.teacher = HostTeacher(with_channel(tcfg, kind), config.dt, seed=config.seed)
            self.teacher_cols = env_signal_columns(tcfg.signals, env)
        self.first_step = 0
        self.events = 0
        self.corrections = 0
        self.last_step_used: int | None = None
        self.outcomes: list[tuple] = []  # (event, step or None, reason or None) of the last drain
        self.last_chunk: dict | None = None  # the steps of the last chunk (step_chunk), as TamerRun
        self.touches = TouchWatcher(env)

    def _commit(self) -> None:
        """Committed arrays everywhere (see TamerRun.commit_state): one compile of rollout and update."""
        device = jax.devices()[0]
        lr = self.learner
        lr.params, lr.opt_state = jax.device_put((lr.params, lr.opt_state), device)
        self.env_state = jax.device_put(self.env_state, device)

    @property
    def params(self):
        return self.learner.params

    def step_chunk(self, t0: float | None = None) -> dict:
        cfg = self.config
        self.key, k = jax.random.split(self.key)
        self.env_state, out = self._rollout(self.learner.params, self.env_state, k)
        out = jax.device_get(out)
        n, first = cfg.chunk_steps, self.first_step
        t0 = self.clock() if t0 is None else t0
        if len(self.step_clock):
            t0 = max(t0, self.step_clock.time_of(self.step_clock.last_step) + cfg.dt)
        times = self.step_clock.record_chunk(first, n, t0, cfg.dt)
        if isinstance(self.clock, VirtualClock):
            self.clock.set(t0 + n * cfg.dt)
        self.learner.record(first, out["obs"], out["action"], out["logp"])
        self.last_chunk = {"first_step": first, "t0": t0, "obs": out["obs"], "action": out["action"],
                           "touches": self.touches.changes(first, out["obs"], out["action"], out["reward_terms"],
                                                           out.get("region_mask"))}
        if self.teacher is not None:
            sig = rule_signals(self.teacher_cols, out["obs"], out["action"], out["reward_terms"],
                               out.get("region_mask"), xp=np)
            self.teacher.observe(first, times, sig)
            self.teacher.emit_due(self.queue, self.clock())
        self.process_events(step=first + n - 1)
        self.first_step += n
        return {"step_reward": float(np.mean(out["reward"])), "contact_rate": float(np.mean(out["contact"])),
                "feedback_events": len(self.outcomes), "feedback_total": self.events,
                "corrections": self.corrections, "coach_updates": self.learner.updates,
                "coach_loss": self.learner.last_loss, "actions": out["action"], "obs": out["obs"]}

    def process_events(self, step: int) -> list:
        """Drain and log the queue; each event corrects the window before the step it began at."""
        self.outcomes = []
        for event in self.queue.drain(self.log, step=step):
            if is_attention(event):  # the live page's watching state: COACH learns from corrections only
                self.outcomes.append((event, None, describe(event, used=False)))
                continue
            self.events += 1
            s = self.step_clock.step_at(event.t_start)
            why = None
            if s is None:
                why = "before the first remembered step"
            elif self.last_step_used is not None and s - self.last_step_used < self.config.min_interval_steps:
                why = f"within {self.config.min_interval_steps} steps of the previous feedback"
            elif event.value == 0.0:
                why = "value 0: no correction"
            elif not self.learner.feedback(float(event.value), s):
                why = "no remembered step in the judged window"
            if why is None:
                self.corrections += 1
                self.last_step_used = s
            elif self.log is not None:
                self.log.note(event="not used", reason=why, t_start=event.t_start, value=event.value)
            self.outcomes.append((event, s if why is None else None, why))
        return self.outcomes

    def save_policy(self, path: str | Path) -> None:
        from flax import serialization

        Path(path).write_bytes(serialization.to_bytes(jax.device_get(self.learner.params)))

    def load_policy(self, path: str | Path) -> None:
        from flax import serialization

        def shapes(tree):
            return jax.tree.structure(tree), [np.shape(x) for x in jax.tree.leaves(tree)]

        try:
            params = serialization.from_bytes(self.learner.params, Path(path).read_bytes())
            fits = shapes(params) == shapes(self.learner.params)
        except (ValueError, KeyError, TypeError):
            fits = False
        if not fits:
            raise ConfigError(f"{path} is not a COACH policy of this shape ({self.config.coach.activation} layers "
                              f"{tuple(self.config.coach.hidden)}); was it saved by a session with another "
                              f"--coach-init?")
        self.learner.params = params
        self.learner.opt_state = self.learner.optimizer.init(self.learner.params)
        self._commit()

    def start_from_actor(self, actor_params) -> None:
        """The policy's mean becomes a DDPG actor's (same layers: relu hidden, tanh output); the log std stays
        the config's. A fine-tuning session then corrects the pretrained behaviour instead of a random one."""
        mine = dict(self.learner.params["params"])
        theirs = actor_params["params"]
        dense = sorted(k for k in mine if k.startswith("Dense_"))
        shapes = lambda tree: [tuple(tree[k]["kernel"].shape) for k in sorted(k for k in tree if k.startswith("Dense_"))]
        if self.config.coach.activation != "relu" or shapes(mine) != shapes(theirs):
            raise ConfigError(f"the actor's layers {shapes(theirs)} do not fit the COACH policy's {shapes(mine)} "
                              f"({self.config.coach.activation}); build it with the actor's hidden sizes and relu")
        for k in dense:
            mine[k] = jax.tree.map(jnp.asarray, theirs[k])
        self.learner.params = {"params": mine}
        self.learner.opt_state = self.learner.optimizer.init(self.learner.params)
        self._commit()

    def close(self) -> None:
        if self.log is not None:
            self.log.note(event="end", queue=self.queue.stats(), corrections=self.corrections)
            self.log.close()
