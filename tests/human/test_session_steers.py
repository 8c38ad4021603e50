"""A short live session with the shipped learner steers the toy infant its teacher's way, on 5 seeds.

The session is built as `protamer finetune` builds it (live/spec.py with the shipped configs/feedback_keyboard.yaml,
live/build.py on the shared toy checkpoint) and run as live/loop.py runs it, unpaced: one chunk, the simulated
keyboard teacher's look at it (a hidden rule the toy's reward does not ask for: the second action up, +1 above
0.2, -1 below -0.2), the drain, the spare-time updates. Against a session without feedback from the same
checkpoint and seed, the final actors' teacher score on the checkpoint's test episodes must rise by more than
the two arms' 95% intervals together, over 5 session seeds.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

RULE = "feedback.teacher.rule=[{signal: 'action:1', value: 1.0, above: 0.2}, {signal: 'action:1', value: -1.0, below: -0.2}]"
SEEDS = 5
CHUNKS = 30  # 30 chunks of 25 steps at 20 Hz: 37.5 s shown


def _session(toy_run: Path, feedback: str, seed: int):
    from mjx_protamer.human.clock import VirtualClock
    from mjx_protamer.live.build import build_learner, load_checkpoint
    from mjx_protamer.live.pace import UpdatePacer
    from mjx_protamer.live.sources import SimulatedTeacher
    from mjx_protamer.live.spec import SessionSpec

    spec = SessionSpec.create(learner="ddpg", feedback=feedback, out=toy_run / "unused", checkpoint=toy_run,
                              config=None, overrides=[RULE, "feedback.dt=0.05", f"feedback.seed={seed}",
                                                      "feedback.teacher.min_gap_steps=4",
                                                      "feedback.credit.min_interval_steps=2"],
                              chunk_ms=1250.0, pace=False)
    loaded = load_checkpoint(toy_run, report=lambda line: None)
    clock = VirtualClock(start=1000.0)
    learner = build_learner(spec, loaded, clock)
    fc, sc = spec.config.feedback, spec.config.session
    teacher = ([SimulatedTeacher(learner.queue, fc.teacher, fc.dt, fc.seed, loaded.env, clock)]
               if feedback != "none" else [])
    pacer = UpdatePacer(learner.chunk_steps, fc.dt, sc.updates_per_step, sc.max_updates_per_step,
                        sc.spare_fraction, sc.unpaced_updates_per_step, paced=False)
    for _ in range(CHUNKS):
        chunk = learner.step_chunk(clock())
        clock.set(chunk.t0 + learner.chunk_steps * learner.dt)
        for t in teacher:
            t.observe(chunk)
        learner.take_events(chunk.first_step + learner.chunk_steps - 1)
        learner.extra_updates(pacer.next())
    return learner, loaded, spec


def _teacher_score(loaded, spec, actor_params) -> float:
    import jax

    from mjx_protamer.experiments.evaluate import eval_seed, make_evaluator, summarize

    evaluate = make_evaluator(loaded.pre, loaded.env, spec.config.feedback.teacher)
    ev = evaluate(actor_params, jax.random.split(jax.random.PRNGKey(eval_seed(loaded.pre)), 8))
    return summarize(jax.device_get(ev), loaded.pre.train.episode_length)["teacher_score"]


def test_a_short_keyboard_session_moves_the_teacher_score_beyond_the_intervals(toy_run):
    from mjx_protamer.experiments.stats import contrast

    scores = {"none": [], "simulated:keyboard": []}
    events = []
    for seed in range(SEEDS):
        for feedback in scores:
            learner, loaded, spec = _session(Path(toy_run), feedback, seed)
            scores[feedback].append(_teacher_score(loaded, spec, learner.state.actor_params))
            if feedback != "none":
                events.append(learner.events)
    c = contrast(scores["none"], scores["simulated:keyboard"])
    print(f"teacher score without feedback {np.round(scores['none'], 2)}, with {np.round(scores['simulated:keyboard'], 2)}"
          f"; events {events}; paired {c['paired']['mean']:+.3f} +- {c['paired']['ci95']:.3f}")
    assert min(events) >= 10
    assert c["beyond_ci95_sum"] and c["paired_beyond_zero"], c
