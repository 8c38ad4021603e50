"""RMS / webrtc VAD and segmentation: onset, pre-roll, endpoint vs fixed window, bounds."""

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from audio_frontend.vad import RmsDetector, Segmenter, segment_array
from voice_helpers import SR, voice_config


def burst(seconds, amp=0.3, freq=220):
    t = np.arange(int(round(seconds * SR))) / SR
    return (amp * np.sin(2 * np.pi * freq * t)).astype(np.float32)


def silence(seconds, noise_dbfs=None, seed=0):
    n = int(round(seconds * SR))
    if noise_dbfs is None:
        return np.zeros(n, np.float32)
    return np.random.default_rng(seed).normal(0, 10 ** (noise_dbfs / 20), n).astype(np.float32)


def vad(**kw):
    return dataclasses.replace(voice_config().vad, **kw)


def test_one_utterance_with_pre_roll_and_endpoint():
    x = np.concatenate([silence(1.0), burst(1.0), silence(1.0)])
    segs = segment_array(x, vad(), SR, 0.25)
    assert len(segs) == 1
    s = segs[0]
    assert s.t_onset == pytest.approx(1.0)
    assert s.t_start == pytest.approx(1.0 - 0.25)          # pre-roll kept
    assert s.reason == "quiet"
    assert s.t_end == pytest.approx(2.25)                   # one hangover chunk after the speech
    assert s.audio.size == pytest.approx((s.t_end - s.t_start) * SR, abs=1)
    # the audio is the stream's audio at those times
    assert np.array_equal(s.audio, x[int(s.t_start * SR):int(s.t_end * SR)])


def test_fixed_window_as_in_the_paper_records_window_from_onset():
    x = np.concatenate([silence(1.0), burst(0.5), silence(3.0)])
    s, = segment_array(x, vad(segment_mode="fixed", window_s=2.0), SR, 0.25)
    assert s.reason == "window"
    assert s.t_end - s.t_onset == pytest.approx(2.0)
    assert s.duration_s == pytest.approx(2.25)


def test_long_speech_is_cut_at_max_segment():
    x = np.concatenate([silence(0.5), burst(6.0), silence(0.5)])
    segs = segment_array(x, vad(), SR, 0.25)
    assert segs[0].reason == "max_length"
    assert segs[0].duration_s == pytest.approx(3.5)
    assert all(s.duration_s <= 3.5 + 1e-9 for s in segs)


def test_onset_chunks_ignore_a_click_and_min_length_drops_short():
    x = np.concatenate([silence(1.0), burst(0.25), silence(1.5), burst(1.0), silence(1.0)])
    segs = segment_array(x, vad(onset_chunks=2), SR, 0.25)
    assert len(segs) == 1 and segs[0].t_onset == pytest.approx(2.75)
    seg = Segmenter(vad(pre_roll_s=0.0, min_segment_s=0.6), SR, 0.25)
    out = []
    for i in range(0, x.size, SR // 4):
        out += seg.feed(i / SR, x[i:i + SR // 4])
    assert [round(s.t_onset, 2) for s in out] == [2.75]      # 0.25 s click + 0.25 s hangover < 0.6 s
    assert seg.dropped_short == 1


def test_noise_floor_mode_adapts_to_a_noisy_room():
    # noise at -35 dBFS is above an absolute -40 dBFS threshold: everything would be "speech"
    x = np.concatenate([silence(2.0, -35), burst(1.0, 0.3) + silence(1.0, -35, 1), silence(2.0, -35, 2)])
    absolute = segment_array(x, vad(), SR, 0.25)
    assert absolute[0].t_onset == pytest.approx(0.0)
    relative = segment_array(x, vad(threshold_mode="noise_floor", noise_floor_margin_db=10), SR, 0.25)
    assert len(relative) == 1 and relative[0].t_onset == pytest.approx(2.0)


def test_rms_detector_threshold():
    d = RmsDetector(threshold_dbfs=-30)
    assert d.is_speech(np.full(100, 0.1, np.float32), SR)        # -20 dBFS
    assert not d.is_speech(np.full(100, 0.01, np.float32), SR)   # -40 dBFS


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(0.0, 4.0), st.booleans()), min_size=1, max_size=8),
       st.sampled_from(["endpoint", "fixed"]))
def test_segments_are_bounded_ordered_and_inside_the_stream(parts, mode):
    x = np.concatenate([burst(d) if loud else silence(d) for d, loud in parts] + [silence(0.1)])
    cfg = vad(segment_mode=mode)
    segs = segment_array(x, cfg, SR, 0.25)
    total = np.ceil(x.size / (SR / 4)) * 0.25
    prev_end = 0.0
    for s in segs:
        assert cfg.min_segment_s - 1e-9 <= s.duration_s <= cfg.max_segment_s + 1e-9
        assert s.t_start >= prev_end - 1e-9 and s.t_end <= total + 1e-9
        assert s.t_start <= s.t_onset < s.t_end
        prev_end = s.t_end


def test_webrtc_vad_finds_speech_and_ignores_tones_and_clicks(speech):
    pytest.importorskip("webrtcvad")
    x = np.concatenate([silence(1.0, -50), speech["good job"], silence(1.5, -50, 1)])
    segs = segment_array(x, vad(kind="webrtc"), SR, 0.25)
    assert len(segs) == 1 and 0.75 <= segs[0].t_onset <= 1.5
    # non-speech sounds that RMS takes for speech: a hum and clicks
    hum = np.concatenate([silence(1.0), burst(2.0, 0.3, 220), silence(1.0)])
    clicks = np.concatenate([silence(1.0), np.where(np.arange(2 * SR) % 4000 < 40, 0.8, 0.0), silence(1.0)])
    for sig in (hum, clicks):
        assert len(segment_array(sig.astype(np.float32), vad(), SR, 0.25)) == 1
        assert segment_array(sig.astype(np.float32), vad(kind="webrtc"), SR, 0.25) == []


def test_silero_vad_finds_speech_in_noise_and_ignores_hum_clicks_and_noise(speech):
    pytest.importorskip("silero_vad")
    x = np.concatenate([silence(1.0, -35), speech["good job"], silence(1.5, -35, 1)])
    segs = segment_array(x, vad(kind="silero"), SR, 0.25)
    assert len(segs) == 1 and 0.75 <= segs[0].t_onset <= 1.5
    assert len(segment_array(x, vad(), SR, 0.25)) >= 1 and segment_array(x, vad(), SR, 0.25)[0].t_onset < 0.5
    # a room's steady hum at -30 dBFS, clicks and white noise: RMS (-40 dBFS) takes each for speech.
    # (A pure tone switched on out of digital silence does trigger silero at its onset; rooms hum throughout.)
    hum = burst(4.0, 0.045, 220)
    clicks = np.concatenate([silence(1.0), np.where(np.arange(2 * SR) % 4000 < 40, 0.8, 0.0), silence(1.0)])
    for sig in (hum, clicks, silence(3.0, -30)):
        assert len(segment_array(sig.astype(np.float32), vad(), SR, 0.25)) >= 1
        assert segment_array(sig.astype(np.float32), vad(kind="silero"), SR, 0.25) == []


def test_vad_benchmark_counts_misses_and_false_alarms():
    from audio_frontend.vad import Segment
    from audio_frontend.vad_compare import count_errors

    def seg(a, b):
        return Segment(np.zeros(1, np.float32), a, b, a, SR, "quiet")
    truth = [(1.0, 2.0), (4.0, 5.0), (8.0, 9.0)]
    # one segment per utterance but the third is missed; a segment over pure noise is a false alarm
    assert count_errors([seg(0.8, 2.2), seg(3.9, 5.3), seg(6.0, 6.8)], truth) == (1, 1)
    assert count_errors([], truth) == (3, 0)
    from audio_frontend.vad_compare import noise_covered
    # away from speech: 0-0.5, 2.75-3.5, 5.75-7.5, 9.75-10 s = 3.25 s; the 6.0-6.8 segment covers 0.8 s of it
    covered, away = noise_covered([seg(0.8, 2.2), seg(3.9, 5.3), seg(6.0, 6.8)], truth, 10.0)
    assert covered == pytest.approx(0.8, abs=0.02) and away == pytest.approx(3.25, abs=0.02)
