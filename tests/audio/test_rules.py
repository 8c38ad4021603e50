"""The linguistic rule layer and the front-end config."""

import pytest

from audio_frontend.rules import RuleLayer, words_of
from mjx_protamer.config import ConfigError
from voice_helpers import voice_config


@pytest.fixture
def rules():
    return RuleLayer.from_config(voice_config().sentiment)


def never(text):
    raise AssertionError(f"the classifier must not be called for {text!r}")


@pytest.mark.parametrize("text,value", [("Yes.", 1), ("Good job!", 1), ("no", -1), ("BAD!", -1),
                                        ("uh, yes", 1), ("No, no, no.", -1), ("well done", 1)])
def test_keywords_decide_without_the_classifier(rules, text, value):
    d = rules.decide(text, never)
    assert (d.value, d.rule) == (value, "keyword")


@pytest.mark.parametrize("text,rule", [("Hmm.", "filler"), ("uh, um... hmm", "filler"), ("", "empty"),
                                       ("[BLANK_AUDIO]", "empty"), ("(music)", "empty")])
def test_fillers_and_empty_give_zero(rules, text, rule):
    d = rules.decide(text, never)
    assert (d.value, d.rule) == (0, rule)


def test_other_sentences_go_to_the_classifier(rules):
    seen = []

    def classify(text):
        seen.append(text)
        return ("NEGATIVE", 0.9) if "not" in text else ("POSITIVE", 0.8)
    assert rules.decide("That was not nice", classify).value == -1
    d = rules.decide("Hmm, you touched your hand", classify)
    assert (d.value, d.rule, d.label) == (1, "classifier", "POSITIVE")
    assert seen == ["that was not nice", "you touched your hand"]   # fillers removed before classifying
    assert rules.decide("yes and no I think", classify).rule == "classifier"   # keywords of both signs
    assert rules.decide("that is not bad", classify).rule == "classifier"      # a negator turns keywords around
    # a classifier that says neither (VADER below its threshold) gives no feedback
    d = rules.decide("something else", lambda t: ("NEUTRAL", 0.01))
    assert (d.value, d.rule, d.label) == (0, "classifier", "NEUTRAL")
    with pytest.raises(ValueError, match="neither positive"):
        rules.decide("something else", lambda t: ("MIXED", 1.0))


@pytest.mark.parametrize("text,value", [("No, wrong way", -1), ("stop it now", -1), ("yes, that was great", 1),
                                        ("well done, keep going", 1)])
def test_keywords_of_one_sign_in_a_sentence_decide(rules, text, value):
    d = rules.decide(text, never)
    assert (d.value, d.rule) == (value, "keyword_vote")


def test_without_a_classifier_undecided_text_is_neutral(rules):
    d = rules.decide("touch your hand", None)
    assert (d.value, d.rule) == (0, "no_classifier")


def test_words_normalisation():
    assert words_of("Good job!! [BLANK_AUDIO] It's OK.") == ["good", "job", "it's", "ok"]


def test_config_yaml_matches_defaults_and_keeps_yes_no_as_strings():
    from audio_frontend.config import DEFAULT_CONFIG_PATH, load_voice_config
    assert DEFAULT_CONFIG_PATH.is_file()
    cfg = load_voice_config()
    assert cfg == voice_config()
    assert "yes" in cfg.sentiment.affirmative and "no" in cfg.sentiment.negative
    assert cfg.audio.chunk_s == 0.25 and (cfg.vad.min_segment_s, cfg.vad.max_segment_s) == (0.4, 3.5)


def test_config_validation_names_the_field():
    with pytest.raises(ConfigError, match="vad.min_segment_s"):
        voice_config("vad.min_segment_s=5.0")
    with pytest.raises(ConfigError, match="sentiment.negative.*both"):
        voice_config("sentiment.negative=['yes']")
    with pytest.raises(ConfigError, match="prosody.tau"):
        voice_config("prosody.tau=0")
    with pytest.raises(ConfigError, match="vad.kind"):
        voice_config("vad.kind=energy")
