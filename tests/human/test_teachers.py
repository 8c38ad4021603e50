"""Simulated teachers: scoring rule, giving model, channels; batched (jit) and host (real queue) variants."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_protamer.config import ConfigError, from_dict
from mjx_protamer.human.clock import VirtualClock
from mjx_protamer.human.queue import FeedbackQueue
from mjx_protamer.human.teachers import (ChannelConfig, Clause, HostTeacher, TeacherConfig,
                                         batched_teacher, batched_teacher_init, rule_signals, signal_columns,
                                         with_channel)

DT = 0.01
RULE = (Clause("region", 1.0, above=0.0), Clause("movement", -1.0, below=-0.25, sustain=5))
EXACT = TeacherConfig(rule=RULE, threshold=0.5, give_rate=1.0, min_gap_steps=0, flip_prob=0.0,
                      silence_fraction=0.0, channel=ChannelConfig("keyboard", delay_std_s=0.0))


def run(config, signals, seed=0, arrival=True):
    state = batched_teacher_init(config, signals.shape[1], DT)
    _, out = jax.jit(lambda s, x, k: batched_teacher(config, DT, s, x, k, arrival=arrival))(
        state, jnp.asarray(signals), jax.random.PRNGKey(seed))
    return {k: np.asarray(v) for k, v in out.items()}


def test_rule_scores_new_regions_and_sustained_freezing():
    sig = np.zeros((40, 2, 2), np.float32)
    sig[3, 0, 0] = 0.3  # env 0: a new region at step 3
    sig[10:20, 1, 1] = -0.5  # env 1: frozen for 10 steps: the clause fires from the 5th (step 14)
    out = run(EXACT, sig, arrival=False)
    assert np.flatnonzero(out["valid"][:, 0]).tolist() == [3] and out["value"][3, 0] == 1.0
    assert np.flatnonzero(out["valid"][:, 1]).tolist() == list(range(14, 20))
    assert (out["value"][14:20, 1] == -1.0).all()


def test_the_score_is_what_holds_now_and_feedback_waits_until_all_of_it_is_noticed():
    """The score counts a clause while it holds (a function of the step); the teacher gives feedback only when
    every clause that holds has held for its `sustain`: a touch that slows is not approved for the touch while
    the freeze is not yet noticed, and neither is disapproved once both are (score 0)."""
    rule = (Clause("obs:0", 1.0, above=0.5, sustain=3), Clause("obs:1", -1.0, above=0.5, sustain=5))
    cfg = dataclasses.replace(EXACT, rule=rule)
    sig = np.zeros((30, 1, 2), np.float32)
    sig[0:20, 0, 0] = 1.0  # touching from step 0 to 19
    sig[10:30, 0, 1] = 1.0  # slow from step 10 on
    out = run(cfg, sig, arrival=False)
    assert out["score"][:, 0].tolist() == [1.0] * 10 + [0.0] * 10 + [-1.0] * 10
    given = np.flatnonzero(out["valid"][:, 0]).tolist()
    # the touch noticed at step 2; from 10 the slowing is not yet noticed (score 0 anyway), from 14 it is and
    # both cancel; from 20 the slowing alone, noticed since 14
    assert given == list(range(2, 10)) + list(range(20, 30))
    assert (out["value"][2:10, 0] == 1).all() and (out["value"][20:30, 0] == -1).all()


def test_the_teacher_gives_only_while_it_watches_and_says_when_it_does():
    """`watching` (the attention signal a learner may gate its silences with) is false exactly in the silent
    mode, in which no feedback is given."""
    cfg = dataclasses.replace(EXACT, silence_fraction=0.5, silence_mean_s=0.1)
    sig = np.zeros((400, 4, 2), np.float32)
    sig[:, :, 0] = 1.0  # always something to praise
    out = run(cfg, sig, arrival=False)
    assert 0.3 < out["watching"].mean() < 0.7
    assert out["valid"][~out["watching"]].sum() == 0 and (out["valid"] == out["watching"]).all()
    out = run(cfg, sig)  # on arrival: feedback still comes (from earlier judgements) while the teacher looks away
    assert out["valid"][~out["watching"]].sum() > 0


def test_keyboard_feedback_arrives_after_the_reaction_delay():
    sig = np.zeros((80, 3, 2), np.float32)
    sig[[5, 30], :, 0] = 1.0
    out = run(EXACT, sig)
    for b in range(3):  # delay exactly 0.35 s = 35 steps, no utterance, no latency
        assert np.flatnonzero(out["valid"][:, b]).tolist() == [40, 65]
        assert out["about"][40, b] == 5 and out["about"][65, b] == 30


def test_give_rate_min_gap_flips_and_silence():
    sig = np.zeros((2000, 4, 2), np.float32)
    sig[:, :, 0] = 1.0  # approval-worthy at every step
    cfg = dataclasses.replace(EXACT, give_rate=0.5, min_gap_steps=10, flip_prob=0.2)
    out = run(cfg, sig, arrival=False)
    for b in range(4):
        given = np.flatnonzero(out["valid"][:, b])
        assert np.diff(given).min() >= 10
    # gaps are 10 + Geometric(0.5) - 1 -> mean 11 steps
    assert 2000 / 11 * 0.85 < out["valid"].sum() / 4 < 2000 / 11 * 1.15
    assert abs((out["value"][out["valid"]] < 0).mean() - 0.2) < 0.05
    silent = run(dataclasses.replace(cfg, silence_fraction=0.5, silence_mean_s=0.2), sig, arrival=False)
    assert 0.35 < silent["valid"].sum() / out["valid"].sum() < 0.65


def test_speech_confusion_and_prosody_noise():
    sig = np.zeros((3000, 4, 2), np.float32)
    sig[:, :, 0] = 1.0
    speech = run(with_channel(dataclasses.replace(EXACT, min_gap_steps=0), "speech"), sig, arrival=False)
    v = speech["value"][speech["valid"]]  # the measured Whisper + VADER rates for an intended +1 (channels.py)
    assert abs((v == 1).mean() - 72 / 84) < 0.03 and abs((v == 0).mean() - 12 / 84) < 0.03
    assert abs((v == -1).mean() - 0 / 84) < 0.01
    prosody = run(with_channel(EXACT, "prosody"), sig, arrival=False)
    v = prosody["value"][prosody["valid"]]
    assert len(np.unique(v)) > 100 and 0.5 < v.mean() < 0.9 and (np.abs(v) <= 1).all()
    assert abs((v < 0).mean() - 0.030) < 0.012  # the offline prosody scorer's measured sign errors


def test_speech_arrives_later_than_keyboard():
    sig = np.zeros((400, 2, 2), np.float32)
    sig[10, :, 0] = 1.0
    speech = run(with_channel(EXACT, "speech"), sig)
    (t,) = np.flatnonzero(speech["valid"][:, 0])
    assert t == 10 + round((0.8 + 0.865 + 0.528) / DT)


def test_host_teacher_feeds_the_real_queue_on_a_virtual_clock():
    clock = VirtualClock(start=1000.0)
    q = FeedbackQueue(maxsize=16, clock=clock)
    teacher = HostTeacher(EXACT, DT, seed=0)
    sig = np.zeros((50, 2), np.float32)
    sig[[4, 20], 0] = 1.0
    times = 1000.0 + DT * np.arange(50)
    assert teacher.observe(0, times, sig) == 2
    clock.set(times[-1] + DT)
    assert teacher.emit_due(q, clock()) == 1  # step 4 + 0.35 s is due, step 20 + 0.35 s is not yet
    clock.advance(0.2)
    assert teacher.emit_due(q, clock()) == 1
    events = q.drain()
    assert [e.details["about_step"] for e in events] == [4, 20]
    assert [e.t_start for e in events] == pytest.approx([1000.04 + 0.35, 1000.2 + 0.35])
    assert all(e.value == 1.0 and e.source == "simulated" for e in events)


def test_rule_signals_read_terms_obs_actions_and_regions_alike_in_numpy_and_jax():
    """One extraction for every path: the host (numpy) and jit (jax.numpy) give the same columns."""
    regions = ("hip", "head", "left_upper_arm")
    cols = signal_columns(("b", "obs:1", "action:0", "obs_norm:0:2", "region:head", "regions_touched"), ("a", "b"),
                          2, 1, regions)
    terms = np.array([[1.0, 2.0], [3.0, 4.0]], np.float32)
    obs, action = np.array([[3.0, 7.0], [0, 8.0]], np.float32), np.array([[9.0], [10.0]], np.float32)
    mask = np.array([[0, 1, 1], [1, 0, 0]], np.float32)
    expected = [[2, 7, 9, np.hypot(3, 7), 1, 2], [4, 8, 10, 8, 0, 1]]
    host = rule_signals(cols, obs, action, terms, mask, xp=np)
    in_jit = jax.jit(lambda *a: rule_signals(cols, *a))(obs, action, terms, mask)
    np.testing.assert_allclose(host, expected, rtol=1e-6)
    np.testing.assert_array_equal(host, np.asarray(in_jit))
    assert host.dtype == np.float32
    with pytest.raises(ValueError, match="region mask"):  # a path that reads regions must supply them
        rule_signals(cols, obs, action, terms, None, xp=np)


def test_signal_errors_name_the_field_and_what_is_allowed():
    regions = ("hip", "head")
    for names, region_names, match in (
            (("nope",), regions, "'nope' is not a reward term"),
            (("obs:x",), regions, "'obs:x' is not a reward term"),
            (("obs_norm:1",), regions, "obs_norm:a:b"),
            (("region:foot",), regions, "'region:foot' names no body region; allowed: region:hip, region:head"),
            (("region:head",), (), "this env has none"),
            (("regions_touched",), (), "this env has none")):
        with pytest.raises(ConfigError, match="feedback.teacher.rule") as err:
            signal_columns(names, ("a",), 2, 1, region_names)
        assert match in str(err.value) and "\n" not in str(err.value)


def test_teacher_config_from_yaml_dict():
    cfg = from_dict(TeacherConfig, {"rule": [{"signal": "region", "value": 1.0, "above": 0.0}],
                                    "channel": {"kind": "speech"}})
    assert cfg.rule[0] == Clause("region", 1.0, above=0.0) and cfg.channel.get("latency_s") == 0.528
    with pytest.raises(ConfigError, match="confusion"):
        from_dict(TeacherConfig, {"channel": {"confusion": [1, 0, 0, 0, 1, 0, 0, 0, 0.5]}})


def test_channel_presets_are_the_measured_voice_pipelines():
    """The simulated voice channels carry what docs/results/voice_channels.json measured: utterance length and
    latency medians, the speech confusion rates, the prosody sign accuracy."""
    import json
    import math
    from pathlib import Path

    from mjx_protamer.human.channels import MEASURED_IN, PRESETS

    m = json.loads((Path(__file__).resolve().parents[2] / MEASURED_IN).read_text())["channels"]
    for kind, scorer in (("prosody", "prosody"), ("speech", "whisper+vader")):
        assert PRESETS[kind]["duration_s"] == pytest.approx(m[scorer]["utterance_s"]["median"], abs=0.005)
        assert PRESETS[kind]["latency_s"] == pytest.approx(m[scorer]["event_latency_s"]["median"], abs=0.005)
    rates = m["whisper+vader"]["outcome_rates"]
    conf = PRESETS["speech"]["confusion"]
    for row, label in ((0, "pos"), (2, "neg")):
        assert conf[3 * row:3 * row + 3] == pytest.approx([rates[label]["+1"], rates[label]["0"], rates[label]["-1"]])
    flip = 1 - m["prosody"]["sign_accuracy"]
    assert 0.5 * (1 + math.erf(-2.0 / PRESETS["prosody"]["noise_std"] / math.sqrt(2))) == pytest.approx(flip, abs=0.002)
