"""The validation summary: a miss (0) and a wrong sign are told apart; Whisper's stage times are pooled."""

import pytest

from audio_frontend.labelled import Scored
from audio_frontend.report import channel, summarize


def test_summary_separates_misses_from_wrong_signs_and_reports_stages():
    rows = [Scored("a", "pos", 1.0, 0.2, {"encoder_s": 0.05, "decoder_s": 0.02, "features_s": 0.01}),
            Scored("b", "pos", 0.0, 0.2, {"encoder_s": 0.07, "decoder_s": 0.04, "features_s": 0.01}),
            Scored("c", "neg", 1.0, 0.2, {"encoder_s": 0.09, "decoder_s": 0.03, "features_s": 0.03}),
            Scored("d", "neg", -1.0, 0.2, {}),
            Scored("e", "filler", 0.0, 0.1, {})]
    s = summarize(rows, "whisper+vader")
    assert s["sign_accuracy"] == 0.5 and s["miss_rate"] == 0.25 and s["wrong_sign_rate"] == 0.25
    assert s["stages_s"] == pytest.approx({"features_s": 0.01, "encoder_s": 0.07, "decoder_s": 0.03})
    assert channel(s)["wrong_sign_rate"] == 0.25 and channel(s)["stages_s"] == s["stages_s"]
    assert summarize([Scored("p", "pos", 0.5, 0.01, {"valence": 0.5})], "prosody")["stages_s"] is None
