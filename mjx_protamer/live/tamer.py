"""DDPG + DeepTAMER on one live env: jitted DDPG chunks, and between them the person's feedback.

One chunk (`step_chunk`, then the session's sources, then `take_events`, then `extra_updates`):

1. `Trainer.collect_chunk(state, r_hat params)`: `chunk_steps` DDPG iterations of the one env in one jit, with
   `session.updates_per_step` updates each; the reward at sample time is `alpha r_env + beta r_hat(s, a)` and,
   with `ddpg.human_actor_coef`, the actor also climbs r_hat directly (action biasing, agents/ddpg/losses.py).
   The chunk's steps come from the transitions its scan emits, stamped on the step clock at the times they are
   shown.
2. The queue is drained: each event is credited by its time over the channel's delay distribution
   (`human.credit.CreditAssigner`), the credited steps are read from the host history and drawn in proportion
   to their weight; steps whose credit window closed with no event are the teacher's silences (target 0,
   only while it watched with `credit.silence_needs_attention`). The reward model absorbs them in one jitted
   call (live/reward_model.py: the batched path's ring and updates).
3. `extra_updates(n)`: the time the chunk is shown and not computed goes to n more DDPG updates with the new
   r_hat (live/pace.py chooses n; the session record keeps it, so a replay makes the same ones).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from mjx_protamer.human.credit import CreditAssigner, StepHistory, silence_reach_s
from mjx_protamer.human.events import FeedbackEvent
from mjx_protamer.human.feedback_config import FeedbackConfig, SessionConfig
from mjx_protamer.live.learner import Chunk, ChunkLearner
from mjx_protamer.live.reward_model import SessionRewardModel, feedback_rows

REWARD_MODEL_DIR = "reward_model"  # beside checkpoints/: the reward model's state (orbax, checksummed)


class TamerLearner(ChunkLearner):
    """`pretrain`: the session's PretrainConfig (one env, its chunk, its DDPG settings); `use_model`: False for
    a session without feedback (DDPG alone: r_hat is not passed to DDPG, no event is credited)."""

    kind = "ddpg"

    def __init__(self, pretrain, env, feedback: FeedbackConfig, session: SessionConfig, use_model: bool, clock,
                 queue=None, log_path: str | Path | None = None):
        from mjx_protamer.agents.ddpg.train import make_train

        tc, fc = pretrain.train, feedback
        history = max(4096, 2 * tc.chunk_steps + int(silence_reach_s(fc.credit, fc.dt, fc.teacher.channel) / fc.dt) + 64)
        super().__init__(env, fc.dt, tc.chunk_steps, clock, queue, fc.queue_size, log_path, history,
                         fc.credit.silence_needs_attention)
        self.config, self.feedback, self.session = pretrain, fc, session
        self.use_model = use_model
        self.model = SessionRewardModel(fc.reward_model, fc.credit, env.observation_size, env.action_size, fc.seed,
                                        tc.chunk_steps, session.max_events_per_chunk, session.rows_per_event)
        # on the person's clock (`session.updates_per_event`) the chunks make no updates of their own: every update
        # is an extra one that an event bought (live/pace.py)
        self.chunk_updates = session.chunk_updates_per_step
        learn = pretrain if self.chunk_updates == tc.updates_per_step else dataclasses.replace(
            pretrain, train=dataclasses.replace(tc, updates_per_step=self.chunk_updates))
        # praise imitated, reproach avoided (`ddpg.praise_imitation_coef`, `reproach_avoid_coef`): DDPG also reads the
        # reward model's feedback ring, so the person's inputs to it are (r_hat's params, the ring)
        d = pretrain.ddpg
        self.imitate = use_model and (d.praise_imitation_coef > 0 or d.reproach_avoid_coef > 0)
        apply = self.model.apply
        reward_fn = (lambda inputs, obs, action: apply(inputs[0], obs, action)) if self.imitate else apply
        self.trainer = make_train(learn, env, human_reward_fn=reward_fn if use_model else None,
                                  devices=jax.devices()[:1], feedback_rows_fn=feedback_rows if self.imitate else None)
        self.state = self.trainer.init(jax.random.PRNGKey(tc.seed))
        self.history = StepHistory(history, env.observation_size, env.action_size)
        self.assigner = CreditAssigner(fc.credit, self.step_clock, fc.teacher.channel)
        self.silence_reach = silence_reach_s(fc.credit, fc.dt, fc.teacher.channel)
        self.silent_next = 0  # the first step not yet judged silent or credited
        self.credited = 0  # credited rows drawn (rows_per_event per event)
        self.updates = 0  # DDPG updates, the chunks' and the extra ones
        self._credits: list = []  # this drain's (obs, action, value) of each credited event
        self.commit()

    def commit(self) -> None:
        """Put the train state and the reward model on the device as committed arrays. Arrays made outside a jit
        (init, a restored checkpoint) are uncommitted, the chunk's outputs committed, and jit compiles once per
        kind: without this the second chunk would compile the whole chunk again."""
        device = jax.devices()[0]
        self.state = jax.device_put(self.state, device)
        self.model.commit(device)

    def start_from(self, loaded, replay_rows: int) -> None:
        """The pretrained learner on this session's fresh one-env state (env, noise and RNG are the session's):
        networks and optimisers from `loaded`, the anchor at its actor, the critic of r_hat alone on its critic's
        trunk, the replay seeded with its newest
        `replay_rows` transitions (0: empty). Why the replay: DDPG's first updates would otherwise fit the few
        dozen transitions of the first chunk and move the policy within seconds, feedback or not
        (docs/human_feedback.md)."""
        from mjx_protamer.agents.ddpg.replay import newest
        from mjx_protamer.agents.ddpg.train import human_critic_from

        state = self.state.replace(**{k: getattr(loaded, k) for k in (
            "actor_params", "critic_params", "target_actor_params", "target_critic_params",
            "actor_opt_state", "critic_opt_state")})
        if state.human_critic_params is not None:  # the critic of r_hat alone starts on the checkpoint's trunk
            state = state.replace(human_critic_params=human_critic_from(loaded.critic_params),
                                  target_human_critic_params=human_critic_from(loaded.critic_params))
        if state.anchor_params is not None:
            state = state.replace(anchor_params=_copy(loaded.actor_params))
        if replay_rows:
            state = state.replace(replay=newest(loaded.replay, self.state.replay.capacity))
        self.state = state
        self.commit()

    def warm_up(self) -> None:
        """Compile the reward model's update and the extra updates before the first event (a first key press
        must not stall a chunk). Neither changes anything: no rows, and zero updates."""
        if self.use_model:
            jax.block_until_ready(self.model._absorb(_copy(self.model.state), *self._empty_rows()))
        self.state = self.trainer.extra_updates(self.state, self._human_params(), np.int32(0))

    def _empty_rows(self):
        m = self.model
        return (np.zeros((m.max_events, m.rows_per_event, m.obs_size), np.float32),
                np.zeros((m.max_events, m.rows_per_event, m.action_size), np.float32),
                np.zeros((m.max_events, m.rows_per_event), np.float32),
                np.zeros((m.max_events, m.rows_per_event), np.float32), np.int32(0),
                np.zeros((m.max_silent, m.obs_size), np.float32), np.zeros((m.max_silent, m.action_size), np.float32),
                np.zeros((m.max_silent,), np.float32))

    def _human_params(self):
        if not self.use_model:
            return None
        return (self.model.params, self.model.state.ring) if self.imitate else self.model.params

    def step_chunk(self, t0: float) -> Chunk:
        self.state, metrics, steps, extras = self.trainer.collect_chunk(self.state, self._human_params())
        obs, action, terms, regions, metrics = jax.device_get(
            (steps.obs[:, 0], steps.action[:, 0], steps.reward_terms[:, 0], extras.get("region_mask"), metrics))
        self.updates += self.chunk_steps * self.chunk_updates
        t0, times = self._stamp(t0)
        self.history.record(self.first_step, obs, action)
        return self._finish_chunk(Chunk(self.first_step, t0, times, obs, action, terms,
                                        None if regions is None else np.asarray(regions[:, 0]),
                                        {k: float(np.asarray(v).mean()) if np.ndim(v) else float(v)
                                         for k, v in metrics.items()}))

    def _take(self, event: FeedbackEvent):
        credit, why = self.assigner.assign(event)
        if credit is None:
            return None, why, ""
        if not self.use_model:
            return credit, None, _credit_text(credit)
        if len(self._credits) >= self.session.max_events_per_chunk:
            self.history.samples(credit)  # its steps were judged, not watched in silence: never a 0 label
            return None, f"more than session.max_events_per_chunk ({self.session.max_events_per_chunk}) events " \
                         "in one chunk", ""
        obs, act, w, _ = self.history.samples(credit)
        if not len(w):
            return None, "no remembered step inside the credit window", ""
        o, a = self.model.draw(obs, act, w)
        self._credits.append((o, a, float(event.value)))
        self.credited += len(o)
        return credit, None, _credit_text(credit)

    def _after_drain(self, outcomes) -> None:
        """Silences up to the last chunk's time, then the reward model learns from the drain in one call."""
        if not self.use_model:
            return
        silent = self._silent_steps(self.last_chunk.t0 if self.last_chunk is not None else None)
        credits, self._credits = self._credits, []
        self.model.absorb(credits, silent)
        self._release_anchor([value for _, _, value in credits])

    def _release_anchor(self, values: list[float]) -> None:
        """Each event the reward model learned from takes 1/`anchor_release_events` off the anchor's weight, a
        praise `anchor_praise_release` of that (below 0: it gives that much back, the weight staying within
        [0, 1]); with `anchor_praise_hold` a praise also makes the actor of this moment the anchor. Weight and anchor
        live in the train state (saved, restored and replayed with it), not on the host."""
        d = self.config.ddpg
        if not values or self.state.anchor_weight is None:
            return
        if d.anchor_release_events <= 0 and not d.anchor_praise_hold:
            return
        weight = float(self.state.anchor_weight)
        if d.anchor_release_events > 0:
            for v in values:
                weight = min(1.0, max(0.0, weight - (1.0 if v < 0 else d.anchor_praise_release)
                                      / d.anchor_release_events))
        device = jax.devices()[0]
        if d.anchor_praise_hold and any(v > 0 for v in values):
            self.state = self.state.replace(anchor_params=jax.device_put(_copy(self.state.actor_params), device))
        self.state = self.state.replace(anchor_weight=jax.device_put(np.float32(weight), device))

    def _silent_steps(self, now: float | None):
        """(obs, action) of the steps whose credit window had closed by `now` (the drain's chunk's t0, so a
        replay judges the same steps) with no event crediting them; with `credit.silence_needs_attention` only
        the steps the teacher watched from when they were shown until their window closed."""
        empty = (np.zeros((0, self.env.observation_size), np.float32),
                 np.zeros((0, self.env.action_size), np.float32))
        if self.feedback.credit.silence_weight <= 0 or now is None or not len(self.step_clock):
            return empty
        closed = self.step_clock.step_at(now - self.silence_reach)
        if closed is None or closed <= self.silent_next:
            return empty
        watched = None
        if self.attention is not None:
            shown = np.array([self._shown_at(k) for k in range(self.silent_next, closed)])
            known = np.isfinite(shown)
            start = np.where(known, shown, 0.0)
            watched = known & self.attention.watched_throughout(start, start + self.silence_reach)
        obs, act, _, _ = self.history.silent_samples(self.silent_next, closed - 1, 1.0, watched)
        self.silent_next = closed
        return obs, act

    def _shown_at(self, step: int) -> float:
        try:
            return self.step_clock.time_of(step)
        except KeyError:  # older than the clock remembers: not judged watched
            return float("nan")

    def extra_updates(self, n: int) -> int:
        if n > 0:
            self.state = self.trainer.extra_updates(self.state, self._human_params(), np.int32(n))
            jax.block_until_ready(self.state.actor_params)  # the pacer times them
            self.updates += n
        return n

    def predict(self, chunk: Chunk) -> np.ndarray | None:
        return self.model.predict(chunk.obs, chunk.action).reshape(-1) if self.use_model else None

    def actor_params(self) -> dict:
        """The deterministic policy as it stands (what a snapshot keeps)."""
        return self.state.actor_params

    def status(self) -> dict:
        return {"events": self.events, "credited": self.credited, "updates": self.updates,
                "r_hat_updates": self.model.updates if self.use_model else 0}

    def progress(self, pace: dict) -> str:
        s = self.status()
        return f"credited {s['credited']} r_hat updates {s['r_hat_updates']} updates/step {pace['updates_per_step']:.1f}"

    def intro(self, spec) -> list[str]:
        """What the session's terminal says of this learner before the first chunk: what DDPG trains on."""
        lines = []
        if spec.feedback != "none":
            d = self.config.ddpg
            lines.append(
                f"DDPG trains on {d.reward_alpha:g} r_env + {d.reward_beta:g} r_hat"
                + (f", the actor biased by {d.human_actor_coef:g} r_hat" if d.human_actor_coef else "")
                + (f" at its own step size {d.human_actor_lr:g}" if d.human_actor_coef and d.human_actor_lr else "")
                + (f", climbing {d.human_critic_coef:g} x a critic of r_hat alone (gamma {d.human_critic_gamma:g})"
                   if d.human_critic_coef else "")
                + (f", imitating praised actions {d.praise_imitation_coef:g}" if d.praise_imitation_coef else "")
                + (f", avoiding reproached ones {d.reproach_avoid_coef:g}" if d.reproach_avoid_coef else "")
                + (f", anchored {d.anchor_coef:g}" if d.anchor_coef else "")
                + (f" until {d.anchor_release_events} events have taught it" if d.anchor_coef
                   and d.anchor_release_events else "")
                + (f" (a praise counting {d.anchor_praise_release:g})" if d.anchor_coef and d.anchor_release_events
                   and d.anchor_praise_release < 1 else "")
                + (", a praise moving the anchor to the actor it praised" if d.anchor_coef and d.anchor_praise_hold
                   else "")
                + f"; feedback config {spec.config_path or 'the built-in defaults'}")
        if not self.session.explore:
            lines.append("session.explore false: the infant acts with its deterministic actor (no exploration noise)")
        elif self.config.ddpg.noise_follows_hold:
            lines.append("noise_follows_hold: the exploration noise scaled by 1 - the hold's weight (none until the "
                         "person's words let the hold go)")
        return lines

    def trees(self) -> dict:
        """What a save keeps, by directory: the DDPG state (checkpoints/, loadable by `protamer eval` and by
        finetune again) and the reward model (reward_model/)."""
        return {"checkpoints": self.state, REWARD_MODEL_DIR: self.model.state}

    def set_trees(self, trees: dict) -> None:
        self.state, self.model.state = trees["checkpoints"], trees[REWARD_MODEL_DIR]
        self.commit()

    def begin_at(self, step: int) -> None:
        """A later segment (a resume) starts at `step`: no earlier step is remembered, none judged silent."""
        self.first_step = self.silent_next = step

    def _end_note(self) -> dict:
        return {"dropped": self.assigner.dropped}


def _copy(tree):
    """A copy of a tree of arrays whose buffers a jitted call donates (the actor's to every chunk, the reward
    model's state to its update)."""
    return jax.tree.map(lambda x: jnp.array(x, copy=True), tree)


def _credit_text(credit) -> str:
    return f"accepted, credited steps {min(credit.steps)}..{max(credit.steps)} (lands on step {credit.step})"


def session_pretrain(pre, chunk_steps: int, session: SessionConfig, ddpg_overrides: dict, replay_size: int):
    """The checkpoint's PretrainConfig as a session runs it: one env, the session's chunk and updates per step,
    no warm-up, a constant step size (a session is open-ended), the session's DDPG keys
    (feedback_config.SESSION_DDPG_KEYS), and no exploration noise with `session.explore` false."""
    train = dataclasses.replace(pre.train, num_envs=1, chunk_steps=chunk_steps, warmup_env_steps=0,
                                total_env_steps=max(pre.train.total_env_steps, chunk_steps), num_devices=1,
                                updates_per_step=session.updates_per_step)
    ddpg = dataclasses.replace(pre.ddpg, replay_size=replay_size, lr_final_fraction=1.0, **ddpg_overrides)
    if not session.explore:  # the noise's random stream is drawn as before; its value is 0 (agents/ddpg/noise.py)
        ddpg = dataclasses.replace(ddpg, noise=dataclasses.replace(ddpg.noise, kind="none"))
    return dataclasses.replace(pre, train=train, ddpg=ddpg)
