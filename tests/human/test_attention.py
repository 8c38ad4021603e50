"""A live teacher's attention: the timeline the page's visibility builds, and the silences it lets teach."""

import numpy as np
import pytest

from mjx_protamer.human.attention import AttentionTimeline, attention_event
from mjx_protamer.human.clock import VirtualClock
from mjx_protamer.human.events import FeedbackEvent, InvalidFeedback, validate_event


def test_a_step_counts_as_watched_only_if_the_teacher_watched_from_its_showing_to_its_window_end():
    tl = AttentionTimeline()
    assert not tl.watched_throughout(np.array([5.0]), np.array([6.0])).any()  # nothing heard: not watched
    # recorded out of order, as two producers may deliver them
    for t, on in ((20.0, True), (10.0, True), (12.0, False), (25.0, False)):
        tl.record(attention_event(t, on, "test"))
    start = np.array([9.0, 10.0, 10.5, 11.0, 13.0, 20.0, 24.0, 24.5])
    end = start + 1.0
    # 9 starts unwatched; 10-11 watched to its end; 11-12 ends as the page hides (not watched); 20-21 watched;
    # 24-25 ends exactly when it stops
    assert tl.watched_throughout(start, end).tolist() == [False, True, True, False, False, True, False, False]


def test_an_attention_event_is_one_or_zero():
    validate_event(attention_event(100.0, True, "test"), now=100.0)
    with pytest.raises(InvalidFeedback, match="attention event"):
        validate_event(FeedbackEvent(100.0, 100.0, "attention", 0.5), now=100.0)


def test_the_live_loop_learns_from_the_silences_its_page_watched_and_records_the_attention(tmp_path):
    from mjx_protamer.envs.toy import PointReachEnv
    from mjx_protamer.human.queue import FeedbackLog
    from mjx_protamer.human.tamer_loop import TamerRun, load_feedback_config

    from mjx_protamer.human.session_record import ScriptedQueue

    cfg = load_feedback_config(None, [
        "pretrain.env_name=toy", "pretrain.ddpg.actor_hidden=[16]", "pretrain.ddpg.critic_hidden=[16,16]",
        "pretrain.train.num_envs=1", "pretrain.train.episode_length=50", "pretrain.train.warmup_env_steps=0",
        "pretrain.train.chunk_steps=100", "pretrain.train.total_env_steps=400", "feedback.dt=0.05",
        "feedback.reward_model.hidden=[16]", "feedback.credit.silence_weight=0.03",
        "feedback.credit.silence_needs_attention=true"])
    t_start = 1000.0
    run = TamerRun(cfg, PointReachEnv(cfg.pretrain.toy), feedback="queue", clock=VirtualClock(start=t_start),
                   log_path=tmp_path / "fb.jsonl")
    run.step_chunk(t0=t_start)  # steps 0-99 shown over 1000-1005 s
    drains = [[o[0] for o in run.outcomes]]
    run.queue.put(attention_event(t_start + 1.0, True, "test"))
    run.queue.put(attention_event(t_start + 3.0, False, "test"))
    run.step_chunk()  # drains both, then judges the steps whose window closed by 1005 s
    drains.append([o[0] for o in run.outcomes])
    run.close()
    reach, dt = run.silence_reach, cfg.feedback.dt
    assert 0.1 < reach < 1.5  # the keyboard channel's delay span
    # silent rows: the steps shown from 1001 s whose window closed before the page hid at 1003 s
    expected = sum(1 for k in range(100) if t_start + 1.0 <= t_start + k * dt and t_start + k * dt + reach < t_start + 3.0)
    buf = run.model.buffer
    assert 10 < expected < 40 and buf.size == expected and (buf.target[:buf.size] == 0).all()
    assert run.events == 0  # attention is not feedback
    records = FeedbackLog.records(tmp_path / "fb.jsonl")
    assert [r["value"] for r in records if r.get("source") == "attention"] == [1.0, 0.0]
    # a replay of the session record (the drained events, the chunks' times) gates the same silences
    again = TamerRun(cfg, PointReachEnv(cfg.pretrain.toy), feedback="queue", queue=ScriptedQueue(drains),
                     clock=VirtualClock(start=t_start))
    again.step_chunk(t0=t_start)
    again.step_chunk(t0=t_start + 100 * dt)
    assert again.model.buffer.size == buf.size
    np.testing.assert_array_equal(again.model.buffer.obs[:buf.size], buf.obs[:buf.size])


def test_the_host_loop_credits_an_event_by_the_posterior_as_the_in_jit_path_does():
    """`credit.posterior_temperature` in the live loop: the event's rows are those of the delay's credit, their
    weights that credit times exp(T v r_hat) under the model before the event, renormalised
    (credit.posterior_weights, the function the in-jit chunk uses)."""
    from mjx_protamer.envs.toy import PointReachEnv
    from mjx_protamer.human.credit import posterior_weights
    from mjx_protamer.human.tamer_loop import TamerRun, load_feedback_config

    base = ["pretrain.env_name=toy", "pretrain.ddpg.actor_hidden=[16]", "pretrain.ddpg.critic_hidden=[16,16]",
            "pretrain.train.num_envs=1", "pretrain.train.episode_length=50", "pretrain.train.warmup_env_steps=0",
            "pretrain.train.chunk_steps=100", "pretrain.train.total_env_steps=400", "feedback.dt=0.05",
            "feedback.reward_model.hidden=[16]"]
    runs = []
    for temperature in (0.0, 4.0):
        cfg = load_feedback_config(None, base + [f"feedback.credit.posterior_temperature={temperature}"])
        run = TamerRun(cfg, PointReachEnv(cfg.pretrain.toy), feedback="queue", clock=VirtualClock(start=1000.0))
        run.step_chunk(t0=1000.0)
        params_before = run.model.params
        run.queue.put(FeedbackEvent(1003.0, 1003.0, "keyboard", 1.0, {"key": "+"}))
        assert len(run.process_events(step=99)) == 1
        runs.append((run, params_before))
    (prior, params_before), (post, _) = runs
    n = prior.model.buffer.size
    assert n == post.model.buffer.size > 5
    b0, b1 = prior.model.buffer, post.model.buffer
    np.testing.assert_array_equal(b0.obs[:n], b1.obs[:n])
    r_hat = np.asarray(prior.model.apply(params_before, b0.obs[:n], b0.action[:n]))
    np.testing.assert_allclose(b1.weight[:n], posterior_weights(np, b0.weight[:n], b0.target[:n], r_hat, 4.0),
                               rtol=1e-5)
    assert np.abs(b1.weight[:n] - b0.weight[:n]).max() > 1e-3
