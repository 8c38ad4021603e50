"""The one place a session's learner is chosen and built: a new session, a resume and a replay all come here.

`load_checkpoint(spec, path, backend)` loads the pretrain run a session starts from, with the live env in place
of the checkpoint's (one world, on the backend that steps it fastest here, or the one a recorded session used).
`build_learner(spec, loaded, ...)` builds DDPG + DeepTAMER or Deep COACH on it. A resumed session (and a replay,
at each resume it records) builds a new learner for a new *segment*: its host-side random streams fold in the
segment's number, so the replay rebuilds exactly what the resumed process built.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from mjx_protamer.live.kinds import LEARNER_KINDS
from mjx_protamer.live.spec import SessionSpec


@dataclasses.dataclass
class Loaded:
    """A pretrain checkpoint as a session uses it."""

    pre: object  # PretrainConfig, with the live env's backend
    env: object
    state: object  # the checkpoint's TrainState
    step: int
    run_dir: Path
    identity: dict  # the checkpoint's step directory and SHA-256 (session.json)


def load_checkpoint(path: Path, backend: str | None = None, report=print) -> Loaded:
    """Load a pretrain run (or a finetune output) as a session's starting point; CheckpointError when it cannot."""
    from mjx_protamer.errors import CheckpointError
    from mjx_protamer.experiments.env_factory import live_config, make_live_env
    from mjx_protamer.experiments.run_loader import load_run, resolve_checkpoint
    from mjx_protamer.live.record import tree_sha256

    try:
        pre, env, state, step = load_run(path)
    except CheckpointError:
        raise
    except (FileNotFoundError, ValueError, KeyError) as e:
        raise CheckpointError(f"{path} cannot be loaded: {type(e).__name__}: {e}") from None
    except Exception as e:  # orbax / tensorstore errors of a truncated or foreign checkpoint
        from mjx_protamer.config import ConfigError

        if isinstance(e, ConfigError):
            raise
        raise CheckpointError(f"{path} cannot be restored (corrupt, incomplete, or from another version of the "
                              f"config): {type(e).__name__}: {e}") from None
    if pre.env_name == "self_touch":
        how = "recorded by the session" if backend else "the fastest for one world here"
        if not (live_config(pre, backend).env.backend == pre.env.backend == getattr(env, "backend", None)):
            env, pre = make_live_env(pre, backend)
        report(f"[finetune] physics backend: {pre.env.backend} ({how})")
    run_dir, ckpt_dir, _ = resolve_checkpoint(path)
    step_dir = next(p for p in ckpt_dir.iterdir() if p.is_dir() and p.name.isdigit() and int(p.name) == step)
    identity = {"checkpoint": str(run_dir.absolute()), "checkpoint_step_dir": str(step_dir.absolute()),
                "checkpoint_step": int(step), "checkpoint_sha256": tree_sha256(step_dir),
                "checkpoint_config_sha256": tree_sha256(run_dir / "config.yaml"),
                "env_backend": pre.env.backend if pre.env_name == "self_touch" else None}
    return Loaded(pre, env, state, int(step), run_dir, identity)


def replay_size(spec: SessionSpec, pre) -> int:
    return max(pre.ddpg.batch_size, spec.config.session.replay_from_checkpoint, spec.chunk_steps)


def coach_config(spec: SessionSpec, pre):
    """Deep COACH's config for a session: the feedback config's `coach` section (`--set coach.KEY=V`), with the
    judged window's delay from `--coach-delay-s`, and, from the checkpoint's actor (`--coach-init actor`), the
    actor's widths and relu with the log std that starts it near the actor's behaviour (`--coach-log-std`
    overrides it)."""
    from mjx_protamer.live.coach import ACTOR_LOG_STD

    delay = round(spec.coach_delay_s / spec.config.feedback.dt)
    coach = dataclasses.replace(spec.config.coach, human_delay_steps=delay)
    if spec.coach_init == "actor":
        coach = dataclasses.replace(coach, hidden=tuple(pre.ddpg.actor_hidden), activation="relu",
                                    init_log_std=ACTOR_LOG_STD)
    if spec.coach_log_std is not None:
        coach = dataclasses.replace(coach, init_log_std=float(spec.coach_log_std))
    coach.validate()
    return coach


def build_learner(spec: SessionSpec, loaded: Loaded, clock, queue=None, log_path: Path | None = None,
                  segment: int = 0):
    """The session's learner on `loaded`, in its starting state (a new session's: the checkpoint's networks;
    a later segment's state is restored or adopted by the caller). `queue`: None for the session's own
    FeedbackQueue (a replay passes its ScriptedQueue)."""
    fc, sc = spec.config.feedback, spec.config.session
    seed = fc.seed + 7919 * segment  # host streams of a later segment (a resume) differ, reproducibly
    if spec.learner == "coach":
        from mjx_protamer.live.coach import CoachSessionLearner

        pre = loaded.pre
        from_actor = spec.coach_init == "actor"
        coach = coach_config(spec, pre)
        learner = CoachSessionLearner(coach, loaded.env, fc.dt, spec.chunk_steps, pre.train.episode_length,
                                      fc.credit.min_interval_steps, seed, clock, queue, fc.queue_size, log_path)
        if segment == 0:
            if spec.coach_policy is not None:
                learner.load_policy(Path(spec.coach_policy))
            elif from_actor:
                learner.start_from_actor(loaded.state.actor_params)
        return learner
    from mjx_protamer.live.tamer import TamerLearner, session_pretrain

    pre = session_pretrain(loaded.pre, spec.chunk_steps, sc, spec.ddpg_overrides(), replay_size(spec, loaded.pre))
    fc = dataclasses.replace(fc, seed=seed, watch_env=0)
    learner = TamerLearner(pre, loaded.env, fc, sc, use_model=spec.feedback != "none", clock=clock, queue=queue,
                           log_path=log_path)
    if segment == 0:
        learner.start_from(loaded.state, 0 if spec.fresh_replay else sc.replay_from_checkpoint)
    return learner


def adopt(learner, previous) -> None:
    """A later segment's learner takes the state an earlier segment's reached (a replay at a resume): what the
    resumed process restored from that save."""
    learner.set_trees(previous.trees())
    learner.begin_at(previous.first_step)


def final_actor(session: Path, learner: str):
    """The deterministic policy a finished session ended with: DDPG's actor, or the mean of COACH's Gaussian
    policy (the actor's layers, `live/coach.py`)."""
    from mjx_protamer.experiments.run_loader import load_run
    from mjx_protamer.live.record import read_manifest

    if LEARNER_KINDS[learner].pretrain_run:  # its save is a pretrain run
        return load_run(session)[2].actor_params
    manifest = read_manifest(session)
    spec = SessionSpec.from_manifest(manifest, session)
    coach = build_learner(spec, load_checkpoint(Path(manifest["checkpoint_step_dir"]), report=lambda line: None),
                          clock=lambda: 0.0)
    coach.load_policy(session)
    return coach.actor_params()
