"""Deep COACH on one live env: jitted rollout chunks of a Gaussian policy, and between them the corrections.

1. `rollout(params, env_state, key)`: `chunk_steps` steps of one auto-resetting env in one jit; each action is
   sampled from N(mu(s), sigma) and clipped to [-1, 1] for the env; the chunk returns the observations, the
   sampled (unclipped) actions, log pi_old(a|s) and the reward terms. The policy params are an argument: an
   update never recompiles the rollout.
2. The chunk's steps are stamped on the step clock at the times they are shown and remembered by the learner
   (`agents.coach.CoachLearner.record`, with the log-probabilities the importance ratio needs when an older
   window is replayed).
3. Each drained event is mapped to the step shown when it began (`StepClock.step_at(event.t_start)`) and
   `CoachLearner.feedback(value, step)` corrects the window of L steps ending `human_delay_steps` before it
   (docs/human_feedback.md, "Deep COACH live"). COACH learns from corrections alone: no extra updates.
"""

from __future__ import annotations

import functools
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from mjx_protamer.agents.coach import CoachConfig, CoachLearner
from mjx_protamer.agents.coach.networks import log_prob
from mjx_protamer.config import ConfigError
from mjx_protamer.human.events import FeedbackEvent
from mjx_protamer.live.learner import Chunk, ChunkLearner

POLICY_DIR = "coach_policy"  # the policy's parameters (orbax, checksummed) and its progress
OLD_POLICY_FILE = "coach_policy.msgpack"  # the parameters alone, as sessions saved them before checksums
# Deep COACH from a pretrained actor: the initial log std of its Gaussian policy (docs/human_feedback.md)
ACTOR_LOG_STD = -1.0


def _rollout(venv, apply, min_log_std, chunk_steps, params, state, key):
    def step(s, k):
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

    return jax.lax.scan(step, state, jax.random.split(key, chunk_steps))


class CoachSessionLearner(ChunkLearner):
    kind = "coach"

    def __init__(self, coach: CoachConfig, env, dt: float, chunk_steps: int, episode_length: int,
                 min_interval_steps: int, seed: int, clock, queue=None, queue_size: int = 256,
                 log_path: str | Path | None = None):
        from mjx_protamer.envs.wrappers import wrap_for_training

        coach.validate()
        self.coach = coach
        self.learner = CoachLearner(coach, env.observation_size, env.action_size, seed=seed)
        super().__init__(env, dt, chunk_steps, clock, queue, queue_size, log_path, self.learner.history,
                         attention=False)
        self.min_interval_steps = min_interval_steps
        self.venv = wrap_for_training(env, episode_length)
        self.key, k = jax.random.split(jax.random.PRNGKey(seed + 7))
        self.env_state = jax.jit(self.venv.reset)(k[None])
        self._rollout = jax.jit(functools.partial(_rollout, self.venv, self.learner.policy.apply,
                                                  coach.min_log_std, chunk_steps))
        self.corrections = 0
        self.last_step_used: int | None = None
        self.commit()

    def commit(self) -> None:
        """Committed arrays everywhere (see TamerLearner.commit): one compile of rollout and update."""
        device = jax.devices()[0]
        lr = self.learner
        lr.params, lr.opt_state = jax.device_put((lr.params, lr.opt_state), device)
        self.env_state = jax.device_put(self.env_state, device)

    def warm_up(self) -> None:
        lr, c = self.learner, self.coach
        w, L = c.batch_windows, c.window
        batch = (np.zeros((w, L, lr.obs_size), np.float32), np.zeros((w, L, lr.action_size), np.float32),
                 np.zeros((w, L), np.float32), np.zeros((w, L), np.float32), np.zeros((w,), np.float32))
        jax.block_until_ready(lr._update(lr.params, lr.opt_state, *map(jnp.asarray, batch)))

    def step_chunk(self, t0: float) -> Chunk:
        self.key, k = jax.random.split(self.key)
        self.env_state, out = self._rollout(self.learner.params, self.env_state, k)
        out = jax.device_get(out)
        t0, times = self._stamp(t0)
        self.learner.record(self.first_step, out["obs"], out["action"], out["logp"])
        return self._finish_chunk(Chunk(
            self.first_step, t0, times, out["obs"], out["action"], out["reward_terms"], out.get("region_mask"),
            {"step_reward": float(np.mean(out["reward"])), "contact_rate": float(np.mean(out["contact"]))}))

    def _take(self, event: FeedbackEvent):
        s = self.step_clock.step_at(event.t_start)
        why = None
        if s is None:
            why = "before the first remembered step"
        elif self.last_step_used is not None and s - self.last_step_used < self.min_interval_steps:
            why = f"within {self.min_interval_steps} steps of the previous feedback"
        elif event.value == 0.0:
            why = "value 0: no correction"
        elif not self.learner.feedback(float(event.value), s):
            why = "no remembered step in the judged window"
        if why is not None:
            return None, why, ""
        self.corrections += 1
        self.last_step_used = s
        end = s - self.coach.human_delay_steps
        return s, None, (f"accepted, corrects steps {end - self.coach.window + 1}..{end} (the window "
                         f"{self.coach.human_delay_steps} steps before step {s})")

    def extra_updates(self, n: int) -> int:
        return 0  # COACH learns from corrections alone

    def predict(self, chunk: Chunk):
        return None

    def status(self) -> dict:
        # the page shows "credited" for every learner: COACH's are its corrections
        return {"events": self.events, "corrections": self.corrections, "credited": self.corrections,
                "updates": self.learner.updates}

    def progress(self, pace: dict) -> str:
        return f"corrections {self.corrections} coach updates {self.learner.updates}"

    # ----------------------------------------------------------------- starting points and saving

    def start_from_actor(self, actor_params) -> None:
        """The policy's mean becomes a DDPG actor's (same layers: relu hidden, tanh output); the log std stays
        the config's. A session then corrects the pretrained behaviour instead of a random one."""
        mine = dict(self.learner.params["params"])
        theirs = actor_params["params"]
        dense = sorted(k for k in mine if k.startswith("Dense_"))
        shapes = lambda tree: [tuple(tree[k]["kernel"].shape) for k in sorted(k for k in tree if k.startswith("Dense_"))]
        if self.coach.activation != "relu" or shapes(mine) != shapes(theirs):
            raise ConfigError(f"the actor's layers {shapes(theirs)} do not fit the COACH policy's {shapes(mine)} "
                              f"({self.coach.activation}); build it with the actor's hidden sizes and relu")
        for k in dense:
            mine[k] = jax.tree.map(jnp.asarray, theirs[k])
        self.learner.params = {"params": mine}
        self.learner.opt_state = self.learner.optimizer.init(self.learner.params)
        self.commit()

    def actor_params(self) -> dict:
        """The policy's mean as a DDPG actor's parameters (the reverse of `start_from_actor`): the deterministic
        policy a session ends with, tested like an actor."""
        return {"params": {k: v for k, v in self.learner.params["params"].items() if k.startswith("Dense_")}}

    def trees(self) -> dict:
        """What a save keeps: the policy, its optimiser, the env and the random state (coach_policy/)."""
        lr = self.learner
        return {POLICY_DIR: {"params": lr.params, "opt_state": lr.opt_state, "env_state": self.env_state,
                             "key": self.key, "updates": jnp.int32(lr.updates)}}

    def set_trees(self, trees: dict) -> None:
        t, lr = trees[POLICY_DIR], self.learner
        lr.params, lr.opt_state, self.env_state, self.key = t["params"], t["opt_state"], t["env_state"], t["key"]
        lr.updates = int(t["updates"])
        self.commit()

    def begin_at(self, step: int) -> None:
        self.first_step = step

    def load_policy(self, path: Path) -> None:
        """Start from the policy an earlier COACH session saved (its --out, or the coach_policy.msgpack of a
        session saved before checksums), with a fresh optimiser."""
        from mjx_protamer.errors import CheckpointDamaged, CheckpointError
        from mjx_protamer.experiments import old_msgpack

        path = Path(path)
        old = path if path.is_file() else path / OLD_POLICY_FILE
        try:
            if old.is_file() and not (path / POLICY_DIR).is_dir():
                params = old_msgpack.load(old, self.learner.params, "COACH policy")
            else:
                params = self._saved_params(path)
        except CheckpointDamaged as e:
            raise CheckpointDamaged(f"--coach-policy {path}: {e}") from None
        except CheckpointError as e:
            raise ConfigError(f"--coach-policy {path} is not a COACH policy of this shape ({self.coach.activation} "
                              f"layers {tuple(self.coach.hidden)}); was it saved by a session with another "
                              f"--coach-init? ({e})") from None
        self.learner.params = params
        self.learner.opt_state = self.learner.optimizer.init(self.learner.params)
        self.commit()

    def _saved_params(self, path: Path):
        from mjx_protamer.experiments import checkpoints

        like = jax.eval_shape(lambda: self.trees())[POLICY_DIR]
        mngr = checkpoints.manager(path / POLICY_DIR)
        try:
            steps = checkpoints.available_steps(mngr.directory)
            if not steps:
                raise ConfigError(f"--coach-policy {path}: no saved COACH policy there (the --out of an earlier "
                                  "`protamer finetune --learner coach`)")
            return checkpoints.restore(mngr, steps[-1], like)["params"]
        finally:
            mngr.close()

    def _end_note(self) -> dict:
        return {"corrections": self.corrections}
