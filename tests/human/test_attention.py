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
    from mjx_protamer.human.queue import FeedbackLog
    from mjx_protamer.live.record import ScriptedQueue

    from toy_session import run_chunk, toy_learner

    gated = ["feedback.credit.silence_weight=0.03", "feedback.credit.silence_needs_attention=true"]
    t_start = 1000.0
    run, cfg, _, clock = toy_learner(gated, clock=VirtualClock(start=t_start), log_path=tmp_path / "fb.jsonl")
    _, outcomes = run_chunk(run, clock, t0=t_start)  # steps 0-99 shown over 1000-1005 s
    drains = [[o.event for o in outcomes]]
    run.queue.put(attention_event(t_start + 1.0, True, "test"))
    run.queue.put(attention_event(t_start + 3.0, False, "test"))
    _, outcomes = run_chunk(run, clock)  # drains both, then judges the steps whose window closed by 1005 s
    drains.append([o.event for o in outcomes])
    assert [o.why for o in outcomes] == ["attention", "attention"]
    run.close()
    reach, dt = run.silence_reach, cfg.feedback.dt
    assert 0.1 < reach < 1.5  # the keyboard channel's delay span
    # silent rows: the steps shown from 1001 s whose window closed before the page hid at 1003 s, each weighing
    # silence_weight events (an event's rows_per_event rows weigh 1 each)
    expected = sum(1 for k in range(100) if t_start + 1.0 <= t_start + k * dt and t_start + k * dt + reach < t_start + 3.0)
    ring = run.model.state.ring
    n = int(ring.size)
    assert 10 < expected < 40 and n == expected and (np.asarray(ring.target[:n]) == 0).all()
    np.testing.assert_allclose(np.asarray(ring.weight[:n]), 0.03 * cfg.session.rows_per_event)
    # exactly the watched steps of the chunk, in order
    shown = [k for k in range(100) if t_start + 1.0 <= t_start + k * dt and t_start + k * dt + reach < t_start + 3.0]
    np.testing.assert_array_equal(np.asarray(ring.obs[:n]), run.history.obs[shown])
    assert run.events == 0  # attention is not feedback
    records = FeedbackLog.records(tmp_path / "fb.jsonl")
    assert [r["value"] for r in records if r.get("source") == "attention"] == [1.0, 0.0]
    # a replay of the session record (the drained events, the chunks' times) gates the same silences
    again, _, _, clock = toy_learner(gated, clock=VirtualClock(start=t_start), queue=ScriptedQueue(drains))
    run_chunk(again, clock, t0=t_start)
    run_chunk(again, clock, t0=t_start + 100 * dt)
    ring2 = again.model.state.ring
    assert int(ring2.size) == n
    np.testing.assert_array_equal(np.asarray(ring2.obs[:n]), np.asarray(ring.obs[:n]))
    np.testing.assert_array_equal(np.asarray(ring2.weight[:n]), np.asarray(ring.weight[:n]))


def test_the_live_loop_credits_an_event_by_the_posterior_as_the_in_jit_path_does():
    """`credit.posterior_temperature` in a live session: the event's rows are drawn by the delay's credit (the
    same host draw whatever the temperature), their weights exp(T v r_hat) under the model before the event,
    renormalised over the event's rows (credit.posterior_weights, the function the in-jit chunk uses)."""
    import jax

    from mjx_protamer.human.credit import posterior_weights

    from toy_session import run_chunk, toy_learner

    runs = []
    for temperature in (0.0, 4.0):
        run, cfg, _, clock = toy_learner([f"feedback.credit.posterior_temperature={temperature}"])
        run_chunk(run, clock, t0=1000.0)  # steps 0-99 shown over 1000-1005 s
        params_before = jax.device_get(run.model.params)  # a host copy: absorbing donates the state
        run.queue.put(FeedbackEvent(1003.0, 1003.0, "keyboard", 1.0, {"key": "+"}))
        outcomes = run.take_events(step=99)
        assert len(outcomes) == 1 and outcomes[0].why is None
        runs.append((run, params_before))
    (prior, params_before), (post, _) = runs
    K = cfg.session.rows_per_event
    r0, r1 = prior.model.state.ring, post.model.state.ring
    assert int(r0.size) == int(r1.size) == K == prior.credited == post.credited
    obs, action = np.asarray(r0.obs[:K]), np.asarray(r0.action[:K])
    np.testing.assert_array_equal(np.asarray(r1.obs[:K]), obs)  # the same rows drawn
    np.testing.assert_array_equal(np.asarray(r0.weight[:K]), np.ones(K))  # the prior: each drawn row weighs 1
    target = np.asarray(r0.target[:K])
    assert (target == 1.0).all() and (np.asarray(r1.target[:K]) == 1.0).all()
    r_hat = np.asarray(prior.model.apply(params_before, obs, action))
    w1 = np.asarray(r1.weight[:K])
    np.testing.assert_allclose(w1, posterior_weights(np, np.ones(K, np.float32), target, r_hat, 4.0), rtol=1e-5)
    assert w1.sum() == pytest.approx(K, rel=1e-5)  # renormalised: the event still weighs one event
    assert np.abs(w1 - 1.0).max() > 1e-3
