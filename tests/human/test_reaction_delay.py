"""Measuring a person's reaction delay from a recorded session (human/reaction_delay.py, touches.py,
`protamer reaction-delay`): the fit recovers known delays from feedback that misses touches and reacts to
other things, our simulated teacher used as the person, and the command reads a recorded session."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from mjx_protamer.cli import main
from mjx_protamer.human import reaction_delay as rd
from mjx_protamer.human.events import FeedbackEvent
from mjx_protamer.live.record import FORMAT, MANIFEST, SessionRecorder, write_json_atomic
from mjx_protamer.human.touches import TouchChanges, shown_touches, touch_onsets


def _person(mean, std, seconds=120.0, rate=1.0, hit=0.85, unrelated=0.1, seed=0):
    """Touch onsets (at least 0.3 s apart), the feedback onsets of a person who reacts to 85% of them with
    delay max(0.15, Normal(mean, std)) and gives 10% more feedback at random times, and the delays drawn."""
    rng = np.random.default_rng(seed)
    onsets = np.cumsum(0.3 + rng.exponential(1 / rate, size=int(seconds * rate * 2)))
    onsets = onsets[onsets < seconds]
    reacted = rng.random(len(onsets)) < hit
    delays = np.maximum(0.15, rng.normal(mean, std, reacted.sum()))
    other = rng.uniform(0, seconds, int(unrelated * reacted.sum()))
    return onsets, np.concatenate([onsets[reacted] + delays, other]), delays


@pytest.mark.parametrize("mean,std,tol", [(0.35, 0.1, 0.02), (0.8, 0.25, 0.08)])  # the keyboard's, speech's presets
def test_fit_recovers_a_known_delay_from_missed_touches_and_unrelated_feedback(mean, std, tol):
    """Ten persons each, onsets every 1.3 s on average: the fitted mean and spread against the delays each
    person drew (speech's wide, slow delay spans two onsets at times, hence its wider tolerance)."""
    errors, std_errors = [], []
    for seed in range(10):
        onsets, responses, delays = _person(mean, std, seed=seed)
        fit = rd.fit_reaction_delay(onsets, responses, 120.0)
        errors.append(fit.mean_s - delays.mean())
        std_errors.append(fit.std_s - delays.std())
        assert fit.n_feedback == len(responses) and fit.n_onsets == len(onsets)
        assert fit.min_s < mean - std  # the fast tail, not the mean
        assert fit.outside_window < 0.025
    assert np.median(np.abs(errors)) < tol / 2 and np.max(np.abs(errors)) < tol, errors
    assert np.median(np.abs(std_errors)) < tol / 2 and np.max(np.abs(std_errors)) < tol, std_errors
    assert fit.channel_overrides()[0] == f"feedback.teacher.channel.delay_mean_s={fit.mean_s:.3f}"


def test_feedback_at_random_times_is_not_fitted_as_a_delay():
    """30 sessions of 100 feedback events at random times: each has onsets in its windows, and the fit says
    they do not look like reactions instead of returning a delay; the same onsets with a person's feedback fit."""
    fitted = 0
    for seed in range(30):
        onsets, reactions, _ = _person(0.35, 0.1, seed=seed)
        try:
            rd.fit_reaction_delay(onsets, np.random.default_rng(100 + seed).uniform(0, 120, 100), 120.0)
            fitted += 1
        except rd.NotEnoughReactions as e:
            assert "look like reactions" in str(e)
        assert rd.fit_reaction_delay(onsets, reactions, 120.0).reacted > 0.8
    assert fitted == 0


def test_too_few_reactions_and_a_bad_window_are_errors():
    onsets = np.arange(0.0, 60.0, 2.0)
    with pytest.raises(rd.NotEnoughReactions, match="only 3 of 3 feedback events"):
        rd.fit_reaction_delay(onsets, onsets[:3] + 0.4, 60.0)
    ten = rd.fit_reaction_delay(onsets, onsets[:10] + 0.4 + 0.01 * np.arange(10), 60.0)  # exactly enough
    assert ten.reactions > 9.99 and abs(ten.mean_s - 0.445) < 0.01
    for window in ((1.0, 0.5), (0.1, math.inf)):
        with pytest.raises(ValueError, match="0 <= lo < hi < inf"):
            rd.fit_reaction_delay(onsets, onsets + 0.4, 60.0, window=window)
    narrow = rd.fit_reaction_delay(onsets, onsets + 0.05 + 0.01 * np.sin(onsets), 60.0, window=(0.0, 0.1))
    assert abs(narrow.mean_s - 0.05) < 0.01


def test_touch_changes_across_chunks_become_intervals_and_debounced_onsets():
    changes = TouchChanges(("right_hand", "head"))
    # right hand: on at steps 12-14, off 15-16 (a 2-step gap: chatter), on 17-22, off 23-..; head never
    flags = np.zeros((30, 2), bool)
    flags[12:15, 0] = flags[17:23, 0] = True
    records = []
    for i, first in enumerate((0, 10, 20)):  # chunks of 10 steps shown from t0 = 100, 100.05, 100.1 (dt 0.005)
        records.append({"chunk": i, "first_step": first, "t0": 100.0 + first * 0.005,
                        "touches": changes.update(first, flags[first:first + 10])})
    assert records[0]["touches"] == {}
    assert records[1]["touches"] == {"right_hand": [[12, 1], [15, 0], [17, 1]]}
    assert records[2]["touches"] == {"right_hand": [[23, 0]]}
    iv, shown = shown_touches(records, 0.005, 10)
    assert list(iv) == ["right_hand"] and shown == pytest.approx(0.1)  # chunk 0 was computed, never shown
    assert np.allclose([i[:2] for i in iv["right_hand"]], [(100.06, 100.075), (100.085, 100.115)])
    assert np.allclose(touch_onsets(iv["right_hand"], 0.3), [100.06])  # the 10 ms gap is one touch
    assert np.allclose(touch_onsets(iv["right_hand"], 0.005), [100.06, 100.085])


def test_unshown_chunks_resumes_and_pauses_are_not_shown_time_nor_onsets():
    """Each session process records chunks from index 0, and its chunk 0 runs before the view and the
    feedback sources start: not shown, its touches not seen to begin. A resume (index 0 again, whether its
    steps jump back to an autosave or continue after a clean stop) closes the touches open before it; its
    pause is not shown time; a clock that goes backwards is refused."""
    dt, n = 0.01, 10
    records = [{"chunk": 0, "first_step": 0, "t0": 0.0, "touches": {"head": [[2, 1]]}},  # on before anyone watched
               {"chunk": 1, "first_step": 10, "t0": 0.1, "touches": {"head": [[13, 0], [16, 1]]}},
               {"chunk": 2, "first_step": 20, "t0": 0.2, "touches": {}},  # head still on at the stop
               # a clean stop and --resume 60 s later: the steps continue, the new process starts at index 0 and
               # its TouchChanges from 'no touch' (head on again at once, unseen), then a chunk with an onset
               {"chunk": 0, "first_step": 30, "t0": 60.3, "touches": {"head": [[30, 1], [32, 0]]}},
               {"chunk": 1, "first_step": 40, "t0": 60.4, "touches": {"head": [[45, 1], [47, 0]]}}]
    iv, shown = shown_touches(records, dt, n)
    assert shown == pytest.approx(0.3)  # chunks 1, 2 and the resumed 1: not the unshown chunks 0, not the pause
    assert [(round(a, 3), round(b, 3), began) for a, b, began in iv["head"]] == [
        (0.02, 0.13, False), (0.16, 0.3, True), (60.3, 60.32, False), (60.45, 60.47, True)]
    assert np.allclose(touch_onsets(iv["head"], 0.02), [0.16, 60.45])
    with pytest.raises(ValueError, match="clock goes backwards"):
        shown_touches(records + [{"chunk": 0, "first_step": 50, "t0": 5.0, "touches": {}}], dt, n)


def test_our_simulated_teacher_as_the_person_gives_back_its_channel_delay():
    """The keyboard teacher, asked to praise the right hand as soon as it touches (sustain 1, always gives,
    at most once a second, no mistakes, no silences), watching a hand that touches at random: the fit
    recovers the channel's reaction delay (0.35 +- 0.1 s) from the events' onsets alone."""
    from mjx_protamer.human.teachers import Clause, HostTeacher, TeacherConfig

    dt, n = 0.005, 24000  # 2 minutes shown
    rng = np.random.default_rng(3)
    touching = np.zeros(n, np.float32)
    t = 200
    while t < n:
        length = int(rng.integers(20, 160))  # touches of 0.1-0.8 s
        touching[t:t + length] = 1.0
        t += length + int(rng.integers(100, 500))  # 0.5-2.5 s apart
    teacher = HostTeacher(TeacherConfig(rule=(Clause("right", 1.0, above=0.5, sustain=1),), give_rate=1.0,
                                        min_gap_steps=200, flip_prob=0.0, silence_fraction=0.0), dt, seed=0)
    chunk = 2000
    for first in range(0, n, chunk):
        teacher.observe(first, 10.0 + dt * np.arange(first, first + chunk), touching[first:first + chunk, None])
    given: list[FeedbackEvent] = []
    teacher.emit_due(type("Collect", (), {"put": lambda self, e: given.append(e) or True})(), math.inf)
    responses = [e.t_start for e in given]
    on = np.flatnonzero(np.diff(np.concatenate([[0.0], touching])) > 0)  # the teacher's judged steps (sustain 1)
    fit = rd.fit_reaction_delay(10.0 + dt * on, responses, n * dt)
    assert fit.n_feedback >= 0.9 * len(on)
    assert abs(fit.mean_s - 0.35) < 0.03 and abs(fit.std_s - 0.1) < 0.03, fit
    assert fit.reacted > 0.9


def _recorder(path, manifest: dict) -> SessionRecorder:
    """A session record's writer in `path`, its manifest written first (as live/session.py does)."""
    write_json_atomic(path / MANIFEST, {**manifest, "record_format": FORMAT})
    return SessionRecorder(path)


def _record_session(path, onsets_steps, feedback_times, dt=0.005, chunk=50, steps=24000, t0=1000.0):
    """A recorded session on disk, as `protamer finetune` writes it: the manifest and one line per chunk
    with its touches and the feedback drained then."""
    path.mkdir()
    changes = TouchChanges(("left_hand", "right_hand"))
    flags = np.zeros((steps, 2), bool)
    for s in onsets_steps:
        flags[s:s + 40, 1] = True
    rec = _recorder(path, {"version": 2, "feedback": "keyboard", "chunk_steps": chunk,
                           "feedback_config": {"dt": dt, "teacher": {"channel": {"kind": "keyboard"}}}})
    feedback = sorted(feedback_times)
    for i, first in enumerate(range(0, steps, chunk)):
        start = t0 + first * dt
        due = [t for t in feedback if t < start + chunk * dt]
        feedback = feedback[len(due):]
        rec.chunk(i, first, start, [FeedbackEvent(t, t, "keyboard", 1.0, {"key": "+"}) for t in due],
                  touches=changes.update(first, flags[first:first + chunk]))
    rec.close()


def test_the_command_measures_a_recorded_session_and_writes_json_and_a_plot(tmp_path, capsys):
    rng = np.random.default_rng(4)
    onsets = np.arange(400, 23000, 300) + rng.integers(0, 100, size=len(np.arange(400, 23000, 300)))
    delays = np.maximum(0.15, rng.normal(0.45, 0.12, len(onsets)))
    _record_session(tmp_path / "s", onsets, list(1000.0 + onsets * 0.005 + delays))
    code = main(["reaction-delay", str(tmp_path / "s"), "--touch", "right_hand", "--json", str(tmp_path / "fit.json"),
                 "--plot", str(tmp_path / "fit.png")])
    out = capsys.readouterr().out
    assert code == 0, out
    fit = json.loads((tmp_path / "fit.json").read_text())
    assert abs(fit["mean_s"] - delays.mean()) < 0.01 and abs(fit["std_s"] - delays.std()) < 0.02
    assert fit["n_onsets"] == len(onsets) and fit["touch"] == "right_hand"
    assert "--set feedback.teacher.channel.delay_mean_s=" in out
    assert (tmp_path / "fit.png").stat().st_size > 10_000
    assert not list(tmp_path.glob(".*tmp*"))
    assert main(["reaction-delay", str(tmp_path / "s"), "--touch", "right_hand", "--plot", str(tmp_path)]) == 2
    assert "cannot write the output" in capsys.readouterr().err


def test_the_command_explains_what_is_missing(tmp_path, capsys):
    assert main(["reaction-delay", str(tmp_path / "nothing")]) == 2
    assert "is not a recorded finetune session" in capsys.readouterr().err
    _record_session(tmp_path / "s", [400, 1000], [1002.4, 1005.4])
    assert main(["reaction-delay", str(tmp_path / "s"), "--touch", "head"]) == 2
    assert "never happened" in capsys.readouterr().err
    assert main(["reaction-delay", str(tmp_path / "s"), "--touch", "nose"]) == 2
    assert "--touch 'nose': not a touch; use one of hip" in capsys.readouterr().err
    assert main(["reaction-delay", str(tmp_path / "s"), "--touch", "right_hand"]) == 2
    err = capsys.readouterr().err
    assert "only 2 of 2 feedback events" in err and "Give feedback each time right_hand starts touching" in err
    assert main(["reaction-delay", str(tmp_path / "s"), "--touch", "right_hand", "--window-s", "1", "0.5"]) == 2
    assert "--window-s needs 0 <= LO < HI < inf" in capsys.readouterr().err
    bad = tmp_path / "bad"
    bad.mkdir()
    _recorder(bad, {}).close()  # a manifest without the feedback config
    assert main(["reaction-delay", str(bad)]) == 2
    assert "cannot read the session record (KeyError" in capsys.readouterr().err
    empty = tmp_path / "loading"
    empty.mkdir()
    _recorder(empty, {"feedback": "keyboard", "chunk_steps": 10, "feedback_config": {"dt": 0.01}}).close()
    assert main(["reaction-delay", str(empty)]) == 2
    assert "showed no chunk (stopped while loading)" in capsys.readouterr().err
    toy = tmp_path / "toy"
    toy.mkdir()
    rec = _recorder(toy, {"feedback": "keyboard", "chunk_steps": 10, "feedback_config": {"dt": 0.01}})
    for i in range(3):
        rec.chunk(i, 10 * i, 0.1 * i, [], touches={})  # an env without regions records no touches
    rec.close()
    assert main(["reaction-delay", str(toy)]) == 2
    assert "recorded no touches" in capsys.readouterr().err
