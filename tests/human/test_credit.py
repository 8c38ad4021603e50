"""Credit weights of the three schemes against hand-computed values; the minimum interval; the step clock."""

import numpy as np
import pytest

from mjx_protamer.human.channels import ChannelConfig, delay_cdf
from mjx_protamer.human.clock import StepClock
from mjx_protamer.human.credit import (CreditAssigner, CreditConfig, StepHistory, silence_reach_s, step_window_weights,
                                       time_window_weight)
from mjx_protamer.human.events import FeedbackEvent


def at(t, value=1.0):
    return FeedbackEvent(t, t, "simulated", value)


def test_step_window_weights_hand_computed():
    w = step_window_weights(15, 0.9)
    assert len(w) == 15
    assert w[0] == 1.0 and w[1] == pytest.approx(0.9) and w[2] == pytest.approx(0.81)
    assert w[14] == pytest.approx(0.2287679245, rel=1e-9)  # 0.9^14


def test_time_window_weight_hand_computed():
    # Feedback at t=3.0 looks back at [-1.0, 2.8]; 3.8 s long.
    assert time_window_weight(0.0, 0.5, 3.0) == pytest.approx(0.5 / 3.8)
    assert time_window_weight(2.5, 3.0, 3.0) == pytest.approx(0.3 / 3.8)  # only [2.5, 2.8]
    assert time_window_weight(2.8, 3.0, 3.0) == 0.0  # inside the 0.2 s minimum delay
    assert time_window_weight(-1.5, -0.5, 3.0) == pytest.approx(0.5 / 3.8)  # only [-1.0, -0.5]
    assert time_window_weight(-3.0, -1.0, 3.0) == 0.0


def test_step_window_credit_lands_on_the_shown_step():
    clock = StepClock(dt=0.005)
    clock.record_chunk(0, 100, t0=100.0)
    ca = CreditAssigner(CreditConfig(scheme="step_window"), clock)
    credit, why = ca.assign(at(100.0 + 0.005 * 50 + 0.001))
    assert why is None and credit.step == 50
    assert credit.steps == tuple(range(50, 35, -1))
    np.testing.assert_allclose(credit.weights, 0.9 ** np.arange(15))


def test_step_window_near_the_start_credits_only_existing_steps():
    clock = StepClock(dt=0.005)
    clock.record_chunk(0, 10, t0=0.0)
    credit, _ = CreditAssigner(CreditConfig(scheme="step_window"), clock).assign(at(0.016))
    assert credit.steps == (3, 2, 1, 0)
    np.testing.assert_allclose(credit.weights, [1.0, 0.9, 0.81, 0.729])


def test_minimum_interval_between_accepted_feedbacks():
    clock = StepClock(dt=1.0)
    clock.record_chunk(0, 100, t0=0.0)
    ca = CreditAssigner(CreditConfig(scheme="step_window", min_interval_steps=5), clock)
    assert ca.assign(at(50.5))[0].step == 50
    credit, why = ca.assign(at(54.5))
    assert credit is None and "within 5 steps" in why
    assert ca.assign(at(55.5))[0].step == 55
    assert ca.dropped == {"within 5 steps of the previous feedback": 1}


def test_time_window_credit_hand_computed():
    clock = StepClock(dt=0.5)
    clock.record_chunk(0, 12, t0=0.0)  # step i spans [0.5 i, 0.5 i + 0.5)
    ca = CreditAssigner(CreditConfig(scheme="time_window", min_interval_steps=0), clock)
    credit, _ = ca.assign(at(3.0))  # window [-1.0, 2.8]
    assert credit.steps == (0, 1, 2, 3, 4, 5)
    np.testing.assert_allclose(credit.weights, [0.5 / 3.8] * 5 + [0.3 / 3.8])
    credit, _ = ca.assign(at(5.0))  # window [1.0, 4.8]: steps 2..8 whole, step 9 for 0.3 s
    assert credit.steps == tuple(range(2, 10))
    np.testing.assert_allclose(credit.weights, [0.5 / 3.8] * 7 + [0.3 / 3.8])
    assert sum(credit.weights) == pytest.approx(1.0)


def test_time_window_at_200hz_covers_760_steps():
    clock = StepClock(dt=0.005, capacity=2048)
    clock.record_chunk(0, 1000, t0=0.0)
    credit, _ = CreditAssigner(CreditConfig(scheme="time_window"), clock).assign(at(4.5))
    assert len(credit.steps) == 760 and credit.steps[0] == 100 and credit.steps[-1] == 859
    assert sum(credit.weights) == pytest.approx(1.0)


def test_step_clock_pause_between_chunks_does_not_stretch_spans():
    clock = StepClock(dt=0.1)
    clock.record_chunk(0, 3, t0=0.0)
    clock.record_chunk(3, 2, t0=10.0)  # a 9.7 s pause
    steps, starts, ends = clock.spans()
    assert steps == [0, 1, 2, 3, 4]
    np.testing.assert_allclose(ends, [0.1, 0.2, 0.3, 10.1, 10.2])
    assert clock.step_at(5.0) == 2 and clock.step_at(-1.0) is None
    with pytest.raises(ValueError):
        clock.record_chunk(4, 1, t0=11.0)


def test_step_history_samples_skip_forgotten_steps():
    hist = StepHistory(capacity=8, obs_size=2, action_size=1)
    hist.record(0, np.arange(24, dtype=np.float32).reshape(12, 2), np.arange(12, dtype=np.float32)[:, None])
    clock = StepClock(dt=1.0)
    clock.record_chunk(0, 12, t0=0.0)
    credit, _ = CreditAssigner(CreditConfig(scheme="step_window"), clock).assign(at(11.5, value=-1.0))
    obs, act, w, h = hist.samples(credit)
    assert act[:, 0].tolist() == [11, 10, 9, 8, 7, 6, 5, 4]  # steps 0..3 were overwritten
    np.testing.assert_allclose(w, 0.9 ** np.arange(8), rtol=1e-6)
    assert (h == -1.0).all()


def test_silent_steps_are_the_remembered_steps_no_credit_read():
    """The host twin of the in-jit silent steps: after an event credits steps 8..11, the other remembered steps
    of 4..11 are rows with target 0 and the silence weight; a forgotten step is skipped, and a step recorded
    again is no longer marked credited."""
    hist = StepHistory(capacity=8, obs_size=1, action_size=1)
    hist.record(0, np.arange(12, dtype=np.float32)[:, None], np.zeros((12, 1), np.float32))
    clock = StepClock(dt=1.0)
    clock.record_chunk(0, 12, t0=0.0)
    credit, _ = CreditAssigner(CreditConfig(scheme="step_window", window_steps=4), clock).assign(at(11.5))
    hist.samples(credit)
    obs, _, w, h = hist.silent_samples(2, 11, 0.03)
    assert obs[:, 0].tolist() == [4, 5, 6, 7]  # steps 2, 3 forgotten (capacity 8), 8..11 credited
    assert (h == 0).all() and np.allclose(w, 0.03)
    hist.record(12, np.full((4, 1), 12.0, np.float32), np.zeros((4, 1), np.float32))  # overwrites 4..7
    assert hist.silent_samples(12, 15, 1.0)[0][:, 0].tolist() == [12.0] * 4
    # every event that could credit a step has arrived this long after it
    keyboard, speech = ChannelConfig("keyboard"), ChannelConfig("speech")
    assert silence_reach_s(CreditConfig(), 0.005, keyboard) == pytest.approx(0.35 + 3.3 * 0.1)
    assert silence_reach_s(CreditConfig(), 0.005, speech) > 1.6 + speech.arrival_offset_s
    assert silence_reach_s(CreditConfig(scheme="step_window"), 0.005) == pytest.approx(0.075)
    assert silence_reach_s(CreditConfig(scheme="time_window"), 0.005) == 4.0


def test_channel_credit_lands_where_the_person_was_looking():
    """A key press 0.35 +- 0.1 s after the judged step: at 200 Hz the credit peaks about 70 steps back,
    each step's weight is the delay's probability mass over the step's span, and the weights sum to ~1."""
    keyboard = ChannelConfig("keyboard")
    clock = StepClock(dt=0.005)
    clock.record_chunk(0, 400, t0=0.0)
    credit, why = CreditAssigner(CreditConfig(min_interval_steps=0), clock, keyboard).assign(at(300 * 0.005))
    assert why is None and credit.step == 300
    w = dict(zip(credit.steps, credit.weights))
    assert sum(w.values()) == pytest.approx(1.0, abs=0.002)
    # step 230 spans [1.150, 1.155): the event at 1.5 s is 0.345..0.350 s after it
    assert w[230] == pytest.approx(delay_cdf(0.350, keyboard) - delay_cdf(0.345, keyboard), rel=1e-9)
    assert w[230] == pytest.approx(0.0199, abs=0.0005)  # Normal pdf at 0.35 (3.99 / s) x 5 ms
    assert max(credit.steps) < 300 - 29  # nothing inside the 0.15 s fastest reaction
    assert 300 - 70 in credit.steps and 300 - 15 not in credit.steps  # the authors' 15-step window is empty
    # a channel credit needs its channel
    with pytest.raises(ValueError, match="channel"):
        CreditAssigner(CreditConfig(), clock)


def test_channel_delay_cdf_hand_computed():
    ch = ChannelConfig("keyboard", delay_mean_s=1.0, delay_std_s=0.5, delay_min_s=0.2)
    assert delay_cdf(0.1, ch) == 0.0  # below the fastest reaction
    assert delay_cdf(1.0, ch) == pytest.approx(0.5)
    assert delay_cdf(1.5, ch) == pytest.approx(0.8413447, rel=1e-6)
    assert delay_cdf(0.2, ch) == pytest.approx(0.0547993, rel=1e-5)  # the mass below 0.2 s sits at 0.2 s
