"""A live session's learner on the toy env without the session around it (shared by the tests here).

`toy_learner` builds `live.tamer.TamerLearner` as `live/build.py` does for a checkpoint (the session's
PretrainConfig via `session_pretrain`: one env, no warm-up), but from scratch; `run_chunk` is one iteration of
`live/loop.py`: the chunk, the virtual clock moved to its end, the sources' look at it, the drain, spare updates.
"""

from __future__ import annotations

import dataclasses

from mjx_protamer.envs.toy import PointReachEnv
from mjx_protamer.human.clock import VirtualClock
from mjx_protamer.human.feedback_config import load_feedback_config
from mjx_protamer.live.tamer import TamerLearner, session_pretrain

# tiny nets, one 100-step chunk at 20 Hz (5 s shown)
TOY = ["pretrain.env_name=toy", "pretrain.ddpg.actor_hidden=[16]", "pretrain.ddpg.critic_hidden=[16,16]",
       "pretrain.train.episode_length=50", "pretrain.train.chunk_steps=100", "feedback.dt=0.05",
       "feedback.reward_model.hidden=[16]"]


def toy_learner(overrides=(), use_model: bool = True, clock=None, queue=None, log_path=None, warmup_env_steps=0):
    """(learner, config, env, clock) for the toy env with TOY + `overrides` (a clock: a VirtualClock at 1000 s
    unless given). `warmup_env_steps` > 0: random actions first, for a learner that starts from scratch."""
    cfg = load_feedback_config(None, [*TOY, *overrides])
    env = PointReachEnv(cfg.pretrain.toy)
    pre = session_pretrain(cfg.pretrain, cfg.pretrain.train.chunk_steps, cfg.session, {},
                           cfg.pretrain.ddpg.replay_size)
    if warmup_env_steps:
        pre = dataclasses.replace(pre, train=dataclasses.replace(pre.train, warmup_env_steps=warmup_env_steps))
    clock = clock if clock is not None else VirtualClock(start=1000.0)
    learner = TamerLearner(pre, env, cfg.feedback, cfg.session, use_model=use_model, clock=clock, queue=queue,
                           log_path=log_path)
    return learner, cfg, env, clock


def run_chunk(learner, clock, sources=(), extra: int = 0, t0: float | None = None):
    """One iteration of live/loop.py's loop: (chunk, outcomes of its drain)."""
    chunk = learner.step_chunk(clock() if t0 is None else t0)
    if isinstance(clock, VirtualClock):
        clock.set(chunk.t0 + learner.chunk_steps * learner.dt)
    for s in sources:
        s.observe(chunk)
    outcomes = learner.take_events(chunk.first_step + learner.chunk_steps - 1)
    learner.extra_updates(extra)
    return chunk, outcomes
