"""The filler gate's acoustic evidence: is a sound one open vowel with no consonant (Praat)?"""

import numpy as np
import pytest

from voice_helpers import SR, need_synth, voice_config

pytestmark = pytest.mark.audio


def test_loudness_dip_is_the_closure_between_two_louder_stretches():
    from audio_frontend.filler_acoustics import loudness_dip_db

    assert loudness_dip_db(np.array([40, 60, 70, 68, 55, 30.0])) == 0.0       # one rise and fall
    assert loudness_dip_db(np.array([40, 70, 50, 66, 40.0])) == 16.0          # a closure: 66 - 50
    assert loudness_dip_db(np.array([70.0, 69.0])) == 0.0


@pytest.fixture(scope="module")
def said():
    need_synth()
    pytest.importorskip("parselmouth")
    from audio_frontend.synth import synthesize, with_silence

    def say(text, style, voice):
        return with_silence(synthesize(text, style, voice=voice), 0.25, 0.25)
    return say


@pytest.mark.parametrize("voice", ["en-gb-scotland", "en-gb-scotland+f1", "en-us"])
def test_a_filler_vowel_is_open_and_every_keyword_has_a_consonant(said, voice):
    """espeak's Scottish "er" glides from [e] to [ɐ] (Whisper hears "Yeah.") but has no consonant: it is
    one open vowel by the gate's thresholds, as are "er" and "uh" elsewhere; one-word keywords said in
    the same voice, in the tones the test set uses, are not (a glide, nasal or stop in each)."""
    from audio_frontend.filler_acoustics import vowel_shape

    g = voice_config().sentiment.filler_gate
    for text, style in (("er", "filler"), ("er", "neutral"), ("uh", "filler")):
        s = vowel_shape(said(text, style, voice), SR)
        assert s.is_open_vowel(g.vowel_max_dip_db, g.vowel_min_f1_hz), (text, style, s)
    for text, style in (("yeah", "positive"), ("yeah", "neutral"), ("yes", "neutral"), ("no", "angry"),
                        ("no", "positive"), ("bad", "positive"), ("bad", "angry"), ("good", "positive")):
        s = vowel_shape(said(text, style, voice), SR)
        assert not s.is_open_vowel(g.vowel_max_dip_db, g.vowel_min_f1_hz), (text, style, s)


def test_silence_and_a_click_are_not_a_vowel():
    pytest.importorskip("parselmouth")
    from audio_frontend.filler_acoustics import vowel_shape

    s = vowel_shape(np.zeros(SR // 2, np.float32), SR)
    assert not s.is_open_vowel(1.0, 400.0) and np.isnan(s.f1_min_hz)
    assert not vowel_shape(np.zeros(100, np.float32), SR).is_open_vowel(1.0, 400.0)
    assert not vowel_shape(np.full(SR, np.nan, np.float32), SR).is_open_vowel(1.0, 400.0)
