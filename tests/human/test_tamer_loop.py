"""DDPG + DeepTAMER of a live session (live/tamer.py) through the real queue on the toy env.

A simulated keyboard teacher (live/sources.py) who wants the point to move up (+1 when action[1] > 0.2, -1 when
< -0.2) - something the env's reward does not ask for - watches each chunk and feeds the real FeedbackQueue on
a virtual clock; the learner credits the events on its step clock and its reward model (the batched path's ring
and updates) absorbs them with the silences, and its params enter every DDPG chunk.

The end-to-end test (slow): against DDPG alone with the same seeds, the deterministic actor's mean vertical
action on test episodes must rise by at least 0.15.
"""

import jax
import numpy as np
import pytest

from mjx_protamer.config import ConfigError
from mjx_protamer.human.queue import FeedbackLog
from mjx_protamer.live.sources import SimulatedTeacher

from toy_session import run_chunk, toy_learner

RULE = ["feedback.credit.min_interval_steps=2", "feedback.teacher.min_gap_steps=2", "feedback.teacher.give_rate=0.5",
        "feedback.teacher.rule=[{signal: 'action:1', value: 1.0, above: 0.2}, "
        "{signal: 'action:1', value: -1.0, below: -0.2}]"]


def teacher_for(learner, cfg, env, clock):
    return SimulatedTeacher(learner.queue, cfg.feedback.teacher, cfg.feedback.dt, cfg.feedback.seed, env, clock)


def test_loop_smoke_events_flow_from_teacher_to_reward_model(tmp_path):
    learner, cfg, env, clock = toy_learner(RULE + ["feedback.credit.silence_weight=0.03"],
                                           log_path=tmp_path / "fb.jsonl", warmup_env_steps=100)
    teacher = teacher_for(learner, cfg, env, clock)
    learner.warm_up()  # compiles; changes nothing
    assert learner.model.updates == 0 and int(learner.model.state.ring.size) == 0 and learner.updates == 0
    probe = np.zeros((1, env.observation_size)), np.array([[0.0, 1.0]])
    before = learner.model.predict(*probe)
    used, extra = 0, 0
    for i in range(4):
        _, outcomes = run_chunk(learner, clock, [teacher], extra=10 * i)
        used += sum(o.why is None for o in outcomes)
        extra += 10 * i
    learner.close()
    rows = cfg.session.rows_per_event
    assert learner.events > 10 and used > 5 and learner.credited == rows * used
    assert learner.model.updates >= used  # one minibatch step per credited event at least, then the replay
    assert learner.status() == {"events": learner.events, "credited": learner.credited, "updates": 400 + extra,
                                "r_hat_updates": learner.model.updates}
    stats = learner.queue.stats()
    assert stats["overflow"] == 0 and stats["rejected"] == 0
    logged = FeedbackLog.read(tmp_path / "fb.jsonl")
    assert len(logged) == learner.events and all(e.source == "simulated" for e in logged)
    # every event judged a step the learner showed earlier
    assert all(e.details["about_step"] < learner.first_step for e in logged)
    assert not np.allclose(before, learner.model.predict(*probe))
    # the ring: each credited event's rows_per_event rows weigh 1 with its +-1 label; the 0 rows are the steps
    # the teacher watched in silence, judged once their window closed, each weighing silence_weight events
    ring = learner.model.state.ring
    n = int(ring.size)
    weight, target = np.asarray(ring.weight[:n]), np.asarray(ring.target[:n])
    zero = target == 0
    assert zero.any() and np.allclose(weight[zero], 0.03 * rows)
    assert (~zero).sum() == learner.credited and np.all(weight[~zero] == 1.0) and np.all(np.abs(target[~zero]) == 1)
    assert learner.silent_next <= learner.first_step - learner.silence_reach / cfg.feedback.dt + 1


def test_an_event_dropped_for_the_chunks_capacity_still_keeps_its_steps_from_being_silences():
    """`session.max_events_per_chunk`: a drain's surplus events are not learnt from, but the steps they judged
    were not watched in silence (the batched path counts every arrival against silence, draw_silent_steps), so
    none of them becomes a 0 label: fewer silent rows than when that event was never given."""
    from mjx_protamer.human.events import FeedbackEvent

    silent, used = {}, {}
    for with_b in (False, True):
        learner, cfg, _, clock = toy_learner(["feedback.credit.silence_weight=0.03", "session.max_events_per_chunk=1"])
        run_chunk(learner, clock, t0=1000.0)  # steps 0-99 shown over 1000-1005 s
        learner.queue.put(FeedbackEvent(1002.0, 1002.0, "keyboard", 1.0, {"key": "+"}))
        if with_b:  # 40 steps later, in the same drain: over the capacity
            learner.queue.put(FeedbackEvent(1004.0, 1004.0, "keyboard", -1.0, {"key": "-"}))
        run_chunk(learner, clock)
        run_chunk(learner, clock)  # every window of the first chunk has closed
        ring = learner.model.state.ring
        target = np.asarray(ring.target[:int(ring.size)])
        silent[with_b], used[with_b] = int((target == 0).sum()), int((target != 0).sum())
    assert used[False] == used[True] == cfg.session.rows_per_event  # the dropped event taught nothing
    assert (target != -1).all()
    assert 0 < silent[True] < silent[False] - 5, silent


def test_a_session_refuses_silences_gated_by_an_attention_signal_its_teacher_lacks(tmp_path):
    from mjx_protamer.live.spec import SessionSpec

    gated = ["feedback.credit.silence_needs_attention=true"]
    with pytest.raises(ConfigError, match="silence_needs_attention"):
        SessionSpec.create(learner="ddpg", feedback="simulated:keyboard", out=tmp_path / "s", checkpoint=None,
                           config=None, overrides=gated)
    # the live page reports attention: there it is allowed
    SessionSpec.create(learner="ddpg", feedback="keyboard", view="web", out=tmp_path / "s", checkpoint=None,
                       config=None, overrides=gated)


def test_deep_coach_is_configured_from_the_coach_section_and_the_command_line(tmp_path):
    """`--set coach.KEY=V` reaches a COACH session's learner (validated by the one loader); --coach-delay-s sets
    the judged window's delay in steps, and --coach-init actor the actor's network shape on top."""
    from mjx_protamer.agents.ddpg.config import PretrainConfig
    from mjx_protamer.live.build import coach_config
    from mjx_protamer.live.coach import ACTOR_LOG_STD
    from mjx_protamer.live.spec import SessionSpec

    pre = PretrainConfig()
    spec = SessionSpec.create(learner="coach", feedback="keyboard", out=tmp_path / "s", checkpoint=None, config=None,
                              overrides=["coach.learning_rate=0.001", "coach.window=6"], coach_delay_s=0.2)
    cfg = coach_config(spec, pre)
    assert (cfg.learning_rate, cfg.window, cfg.human_delay_steps) == (0.001, 6, 40)  # 0.2 s at 200 Hz
    assert cfg.hidden == tuple(pre.ddpg.actor_hidden) and cfg.activation == "relu" and cfg.init_log_std == ACTOR_LOG_STD
    scratch = SessionSpec.create(learner="coach", feedback="keyboard", out=tmp_path / "s", checkpoint=None,
                                 config=None, coach_init="scratch", coach_log_std=-1.5)
    cfg = coach_config(scratch, pre)
    assert cfg.hidden == (64, 64) and cfg.activation == "tanh" and cfg.init_log_std == -1.5
    with pytest.raises(ConfigError, match="coach.trace_decay"):
        SessionSpec.create(learner="coach", feedback="keyboard", out=tmp_path / "s", checkpoint=None, config=None,
                           overrides=["coach.trace_decay=0"])


@pytest.mark.slow
def test_tamer_with_simulated_keyboard_teacher_moves_behaviour_its_way():
    from mjx_protamer.agents.ddpg.evaluate import make_rollout

    overrides = RULE + ["pretrain.ddpg.actor_hidden=[64,64]", "pretrain.ddpg.critic_hidden=[64,64]",
                        "pretrain.ddpg.reward_beta=1.0", "pretrain.ddpg.replay_size=20000", "pretrain.ddpg.tau=0.005",
                        "feedback.reward_model.hidden=[64,64]"]
    vertical = {}
    for use_model in (False, True):
        learner, cfg, env, clock = toy_learner(overrides, use_model=use_model, warmup_env_steps=200)
        sources = [teacher_for(learner, cfg, env, clock)] if use_model else []
        for _ in range(30):  # 3000 steps shown, 2 updates each (an unpaced session's)
            run_chunk(learner, clock, sources, extra=100)
        rollout = make_rollout(env, 50, cfg.pretrain.ddpg.actor_hidden, keep=("action",))
        out = rollout(learner.state.actor_params, jax.random.split(jax.random.PRNGKey(123), 16))
        vertical[use_model] = float(np.asarray(out["action"])[..., 1].mean())
        if use_model:
            assert learner.events > 100
    print(f"mean vertical action: DDPG {vertical[False]:+.3f}, DDPG+DeepTAMER {vertical[True]:+.3f}")
    assert vertical[True] > vertical[False] + 0.15


def test_the_anchor_lets_go_as_the_person_teaches_and_holds_a_session_nobody_speaks_to():
    """`ddpg.anchor_release_events`: each event the reward model learns from takes 1/N off the anchor's weight
    (in the train state, so a save and a replay keep it), a praise `anchor_praise_release` of that; without
    feedback it stays 1. A new weight is a new
    value of a traced input, not a new compile of the chunk."""
    anchored = RULE + ["pretrain.ddpg.anchor_coef=0.5", "pretrain.ddpg.anchor_release_events=40"]
    learner, cfg, env, clock = toy_learner(anchored, warmup_env_steps=100)
    teacher = teacher_for(learner, cfg, env, clock)
    assert float(learner.state.anchor_weight) == 1.0
    used, weights = 0, []
    for _ in range(3):
        _, outcomes = run_chunk(learner, clock, [teacher], extra=5)
        used += sum(o.why is None for o in outcomes)
        weights.append(float(learner.state.anchor_weight))
        assert weights[-1] == pytest.approx(max(0.0, 1.0 - used / 40), abs=1e-6)
    assert used > 40 and weights[-1] == 0.0 and weights[0] > 0.0  # it fell event by event, then to 0
    assert learner.trainer.collect_chunk._cache_size() == 1 and learner.trainer.extra_updates._cache_size() == 1

    # `ddpg.anchor_praise_release` 0: a praise keeps the anchor ("keep doing this"); only reproach lets it go
    learner, cfg, env, clock = toy_learner(anchored + ["pretrain.ddpg.anchor_praise_release=0"],
                                           warmup_env_steps=100)
    teacher = teacher_for(learner, cfg, env, clock)
    signs = []
    for _ in range(2):
        _, outcomes = run_chunk(learner, clock, [teacher], extra=5)
        signs += [o.event.value > 0 for o in outcomes if o.why is None]
        assert float(learner.state.anchor_weight) == pytest.approx(max(0.0, 1.0 - signs.count(False) / 40), abs=1e-6)
    assert signs.count(True) > 5 and signs.count(False) > 0, signs

    # `ddpg.anchor_praise_hold`: a praise makes the actor of that moment the anchor; with `anchor_praise_release`
    # -1 it gives 1/N of weight back as a reproach takes 1/N. The drain runs before the extra updates, so right
    # after a drain with a praise, anchor == actor.
    learner, cfg, env, clock = toy_learner(anchored + ["pretrain.ddpg.anchor_praise_hold=true",
                                                       "pretrain.ddpg.anchor_praise_release=-1"], warmup_env_steps=100)
    teacher = teacher_for(learner, cfg, env, clock)
    checkpoint_actor = jax.tree.map(np.array, learner.state.anchor_params)
    weight, held = 1.0, 0
    for _ in range(3):
        _, outcomes = run_chunk(learner, clock, [teacher])
        values = [o.event.value for o in outcomes if o.why is None]
        for v in values:
            weight = min(1.0, max(0.0, weight + (1 / 40 if v >= 0 else -1 / 40)))
        assert float(learner.state.anchor_weight) == pytest.approx(weight, abs=1e-6)
        anchor, actor = (jax.tree.leaves(jax.tree.map(np.array, p)) for p in
                         (learner.state.anchor_params, learner.state.actor_params))
        if any(v > 0 for v in values):
            held += 1
            assert all(np.array_equal(a, b) for a, b in zip(anchor, actor))
        learner.extra_updates(5)  # the actor moves on; the anchor stays where the praise put it
        assert all(np.array_equal(a, b) for a, b in zip(anchor, jax.tree.leaves(
            jax.tree.map(np.array, learner.state.anchor_params))))
    assert held >= 2 and not all(np.array_equal(a, b) for a, b in zip(
        jax.tree.leaves(checkpoint_actor), jax.tree.leaves(jax.tree.map(np.array, learner.state.anchor_params))))
    assert learner.trainer.collect_chunk._cache_size() == 1 and learner.trainer.extra_updates._cache_size() == 1
    with pytest.raises(ConfigError, match="anchor_praise_hold"):
        toy_learner(RULE + ["pretrain.ddpg.anchor_praise_hold=true"], warmup_env_steps=100)

    silent, _, _, silent_clock = toy_learner(anchored, use_model=False, warmup_env_steps=100)
    for _ in range(2):
        run_chunk(silent, silent_clock, extra=5)
    assert float(silent.state.anchor_weight) == 1.0


def test_on_the_persons_clock_a_chunk_makes_no_updates_of_its_own():
    """`session.updates_per_event`: the chunk steps the env and fills the replay but does not learn; the updates the
    person's events buy come after the drain (live/pace.py settles how many)."""
    learner, _, _, clock = toy_learner(RULE + ["session.updates_per_event=20"], warmup_env_steps=0)
    before = jax.tree.map(np.array, learner.state.actor_params)
    run_chunk(learner, clock)
    run_chunk(learner, clock)
    assert learner.updates == 0
    jax.tree.map(np.testing.assert_array_equal, jax.tree.map(np.array, learner.state.actor_params), before)
    run_chunk(learner, clock, extra=20)
    assert learner.updates == 20
    changed = jax.tree.map(lambda a, b: not np.array_equal(np.array(a), b), learner.state.actor_params, before)
    assert any(jax.tree.leaves(changed))


def test_praise_imitation_and_reproach_avoidance_move_the_actor_as_the_person_said():
    """`ddpg.praise_imitation_coef` and `reproach_avoid_coef`: DDPG draws rows of the feedback ring the person
    praised (or reproached; in proportion to weight x |value|, never a silence) and pulls the actor toward their
    actions (or pushes it away). The person's other
    routes to the policy are off here (no action biasing, r_hat out of the critic), so what moves the actor up is
    the imitation: the teacher praises up (action[1] > 0.2) and reproaches down."""
    from mjx_protamer.human.batched import ring_add, ring_init
    from mjx_protamer.live.reward_model import feedback_rows

    ring = ring_init(8, 1, 1)
    _, _, w = feedback_rows((None, ring), jax.random.PRNGKey(0), 16, 1.0)
    assert float(w.sum()) == 0.0  # nothing praised yet: no pull
    rows = np.arange(6, dtype=np.float32)[:, None]
    ring = ring_add(ring, rows, rows, np.array([1, 1, 1, 1, 0.03, 1], np.float32),
                    np.array([-1, 1, 0.5, -1, 0, 0], np.float32))
    obs, action, w = feedback_rows((None, ring), jax.random.PRNGKey(1), 3000, 1.0)
    picked = np.asarray(obs)[:, 0]
    assert set(np.unique(picked)) == {1.0, 2.0} and np.all(np.asarray(action)[:, 0] == picked)
    assert float(np.mean(picked == 1.0)) == pytest.approx(2 / 3, abs=0.03) and np.all(np.asarray(w) == 1.0)
    obs, _, w = feedback_rows((None, ring), jax.random.PRNGKey(2), 3000, -1.0)  # reproach: rows 0 and 3 alike
    picked = np.asarray(obs)[:, 0]
    assert set(np.unique(picked)) == {0.0, 3.0} and float(np.mean(picked == 0.0)) == pytest.approx(0.5, abs=0.03)

    # the teacher praises down (action[1] < -0.2), where this env's own reward does not lead
    down = RULE[:3] + ["feedback.teacher.rule=[{signal: 'action:1', value: -1.0, above: 0.2}, "
                       "{signal: 'action:1', value: 1.0, below: -0.2}]",
                       "pretrain.ddpg.human_actor_coef=0", "pretrain.ddpg.reward_beta=0"]
    vertical = {}
    for name, knob in (("none", []), ("imitate", ["pretrain.ddpg.praise_imitation_coef=50"]),
                       ("avoid", ["pretrain.ddpg.reproach_avoid_coef=50"])):
        learner, cfg, env, clock = toy_learner(down + knob, warmup_env_steps=100)
        teacher = teacher_for(learner, cfg, env, clock)
        for _ in range(2):
            run_chunk(learner, clock, [teacher])
        learner.extra_updates(300)
        ring = learner.model.state.ring
        target, obs = np.asarray(ring.target[:int(ring.size)]), np.asarray(ring.obs[:int(ring.size)])
        assert (target > 0).sum() > 100 and (target < 0).sum() > 100
        vertical[name] = float(np.mean(np.asarray(learner.trainer.act(learner.state.actor_params, obs))[:, 1]))
    # the env's reward alone takes the actor up; imitating the praise keeps it down with the praised actions, and
    # pushing away from the reproached (up) actions holds it back
    assert vertical["imitate"] < -0.1 and vertical["none"] > vertical["imitate"] + 0.5, vertical
    assert vertical["none"] > vertical["avoid"] + 0.3, vertical


def test_without_exploration_the_person_watches_the_deterministic_actor():
    """`session.explore` false: the infant on screen acts as the actor the session hands over (no noise added);
    with the checkpoint's noise (the default) the first shown action differs from it."""
    first = {}
    for explore in (True, False):
        learner, _, _, clock = toy_learner([f"session.explore={str(explore).lower()}",
                                            "pretrain.ddpg.noise.sigma=0.3"])
        params = jax.tree.map(np.array, learner.state.actor_params)  # the chunk's first step acts before any update
        chunk, _ = run_chunk(learner, clock)
        first[explore] = float(np.abs(chunk.action[0] - np.asarray(learner.trainer.act(params, chunk.obs[0]))).max())
    assert first[False] == 0.0 and first[True] > 0.01, first


def test_with_noise_following_the_hold_the_infant_explores_as_far_as_the_words_let_the_hold_go():
    """`ddpg.noise_follows_hold`: the shown action is the deterministic actor's plus (1 - the hold's weight) x the
    noise a session without the option adds (the same seed draws the same noise): none while nobody has spoken
    (weight 1), three quarters of it at weight 0.25. It needs an anchor whose weight the events move."""
    anchored = ["pretrain.ddpg.noise.sigma=0.3", "pretrain.ddpg.anchor_coef=0.5",
                "pretrain.ddpg.anchor_release_events=4"]
    added = {}
    for follows, weight in ((False, 1.0), (True, 1.0), (True, 0.25)):
        learner, _, _, clock = toy_learner(anchored + [f"pretrain.ddpg.noise_follows_hold={str(follows).lower()}"])
        learner.state = learner.state.replace(anchor_weight=jax.device_put(np.float32(weight), jax.devices()[0]))
        params = jax.tree.map(np.array, learner.state.actor_params)  # the chunk's first step acts before any update
        chunk, _ = run_chunk(learner, clock)
        added[follows, weight] = chunk.action[0] - np.asarray(learner.trainer.act(params, chunk.obs[0]))
        assert np.abs(chunk.action[0]).max() < 1.0  # not clipped: the noise is all there is between the two
    noise = added[False, 1.0]
    assert np.abs(noise).max() > 0.01
    assert np.all(added[True, 1.0] == 0.0)
    np.testing.assert_allclose(added[True, 0.25], 0.75 * noise, atol=1e-5)
    with pytest.raises(ConfigError, match="noise_follows_hold"):
        toy_learner(["pretrain.ddpg.noise_follows_hold=true", "pretrain.ddpg.anchor_coef=0.5"])
