"""The linguistic rule layer and the front-end config."""

import pytest

from audio_frontend.rules import RuleLayer, collapse_repeats, words_of
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
        return ("NEGATIVE", 0.9) if "hate" in text else ("POSITIVE", 0.8)
    assert rules.decide("I hate that", classify).value == -1
    d = rules.decide("Hmm, you touched your hand", classify)
    assert (d.value, d.rule, d.label) == (1, "classifier", "POSITIVE")
    assert seen == ["i hate that", "you touched your hand"]   # fillers removed before classifying
    assert rules.decide("yes and no I think", classify).rule == "classifier"   # keywords of both signs
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
    with pytest.raises(ConfigError, match="sentiment.discourse_markers.*not keywords"):
        voice_config("sentiment.discourse_markers=['well']")
    with pytest.raises(ConfigError, match="asr.window_s"):
        voice_config("asr.window_s=0.5")
    with pytest.raises(ConfigError, match="asr.min_avg_logprob"):
        voice_config("asr.min_avg_logprob=0.5")
    with pytest.raises(ConfigError, match="asr.num_hypotheses.*beam_size"):
        voice_config("asr.beam_size=2", "asr.num_hypotheses=3")
    with pytest.raises(ConfigError, match="asr.pad"):
        voice_config("asr.pad=noise")
    with pytest.raises(ConfigError, match="sentiment.alternative_margin"):
        voice_config("sentiment.alternative_margin=-0.5")


@pytest.mark.parametrize("text,value,rule", [
    ("That is not right.", -1, "keyword_vote"),            # a negated affirmative is reproach
    ("You did not do that right.", -1, "keyword_vote"),    # three words after the negator are in its scope
    ("That was not good at all.", -1, "keyword_vote"),     # the phrase "not good" itself
    ("I don't think that's good.", -1, "keyword_vote"),
    ("Not bad.", 0, "negated_negative"),                   # mild and easily misheard: no feedback, not praise
    ("Not really bad.", 0, "negated_negative"),            # what Whisper made of "that is really bad"
    ("Don't stop.", 0, "negated_negative"),
    ("Don't worry, you are doing good.", 1, "keyword_vote"),   # "good" is out of the negator's reach
    ("No, that's not right.", -1, "keyword_vote"),
])
def test_negation_turns_the_keywords_it_reaches(rules, text, value, rule):
    d = rules.decide(text, never)
    assert (d.value, d.rule) == (value, rule), d


@pytest.mark.parametrize("text", ["Don't do that!", "Do not touch it.", "don't, uh, do it"])
def test_an_utterance_that_opens_with_dont_forbids(rules, text):
    d = rules.decide(text, never)
    assert (d.value, d.rule) == (-1, "prohibitive"), d


def test_an_opening_discourse_marker_is_not_praise(rules):
    seen = []

    def classify(text):
        seen.append(text)
        return "NEUTRAL", 0.0
    # "okay" alone is a keyword; opening a sentence it is a discourse marker, left out of what is classified
    assert rules.decide("Okay.", never).value == 1
    d = rules.decide("Okay, let us see.", classify)
    assert (d.value, d.rule) == (0, "classifier") and seen == ["let us see"]
    assert rules.decide("Right, now the other hand.", classify).value == 0 and seen[-1] == "now the other hand"
    assert rules.decide("That's right!", never).value == 1   # not at the start: the keyword counts
    assert rules.decide("Okay, good job.", never).value == 1


@pytest.mark.parametrize("words,kept", [
    ("you did it you did it you did it you", "you did it"),   # Whisper looping, cut mid-copy at its token limit
    ("uh uh uh uh uh", "uh"),
    ("no no no", "no"),
    ("stop it out stop it out stop it out stop", "stop it out"),
    ("good job", "good job"),
    ("that is what it is", "that is what it is"),              # a word said twice apart is no repeat
])
def test_collapse_repeats(words, kept):
    assert " ".join(collapse_repeats(words.split())) == kept


def test_a_looping_transcript_is_decided_on_one_copy(rules):
    seen = []

    def classify(text):
        seen.append(text)
        return "POSITIVE", 0.9
    d = rules.decide("You did it... You did it... You did it... You", classify)
    assert d.value == 1 and seen == ["you did it"]
    assert rules.decide("uh uh uh uh uh uh uh uh", never).rule == "filler"


def test_low_confidence_transcripts_give_no_feedback():
    gated = RuleLayer.from_config(voice_config().sentiment, voice_config("asr.min_avg_logprob=-1.0").asr)
    d = gated.decide("That was all I really want to do.", never, avg_logprob=-1.3)
    assert (d.value, d.rule, d.score) == (0, "low_confidence", -1.3)
    assert gated.decide("Good job.", never, avg_logprob=-0.4).value == 1
    assert gated.decide("Good job.", never, avg_logprob=None).value == 1   # a backend without scores: no gate
    assert gated.decide("Um...", never, avg_logprob=-3.0).rule == "filler"
    # off by default
    assert RuleLayer.from_config(voice_config().sentiment, voice_config().asr).decide(
        "Good job.", never, avg_logprob=-5.0).value == 1


def neutral(text):
    return "NEUTRAL", 0.0


def test_a_keyword_among_the_other_hypotheses_decides_a_transcript_without_sentiment(rules):
    """Whisper heard "But move." best and "Bad move." nearly as likely (the dev voices' most common miss):
    the keyword of an alternative within alternative_margin (1.0) of the best decides."""
    alts = (("But move!", -1.09), ("Bad move.", -1.25), ("Good move.", -1.3))
    d = rules.decide("But move.", neutral, -0.65, alts)
    assert (d.value, d.rule, d.alternative, d.score) == (-1, "alternative", "Bad move.", -1.25)
    assert d.words == ("but", "move")                     # what was heard best stays the transcript
    # beyond the margin: no feedback
    d = rules.decide("But move.", neutral, -0.1, alts)
    assert (d.value, d.rule, d.alternative) == (0, "classifier", None)
    # off, or a backend without scores
    off = RuleLayer.from_config(voice_config("sentiment.alternative_margin=null").sentiment)
    assert off.decide("But move.", neutral, -0.65, alts).rule == "classifier"
    assert rules.decide("But move.", neutral, None, alts).rule == "classifier"
    assert rules.decide("But move.", neutral, -0.65, (("Bad move.", None),)).rule == "classifier"


def test_alternatives_never_override_what_the_best_transcript_decides(rules):
    alts = (("No.", -0.5), ("Good job.", -0.5))
    # a keyword, a filler, an empty transcript, a classifier's sign and a negated negative stand
    assert rules.decide("Yes.", never, -0.4, alts).value == 1
    assert (rules.decide("Um...", never, -0.4, alts).rule, rules.decide("", never, -0.4, alts).rule) == (
        "filler", "empty")
    assert rules.decide("I love it", lambda t: ("POSITIVE", 0.9), -0.4, alts).value == 1
    assert rules.decide("Not really bad.", never, -0.4, alts).rule == "negated_negative"
    # too unsure to give feedback is not a reason to take another guess
    gated = RuleLayer.from_config(voice_config().sentiment, voice_config("asr.min_avg_logprob=-1.0").asr)
    assert gated.decide("But move.", neutral, -1.3, (("Bad move.", -1.4),)).rule == "low_confidence"
    # and the gate holds for the alternatives: a sure best transcript does not vouch for an unsure keyword
    assert gated.decide("But move.", neutral, -0.9, (("Bad move.", -1.2),)).rule == "classifier"
    assert gated.decide("But move.", neutral, -0.9, (("Bad move.", -0.95),)).rule == "alternative"


def test_only_the_keywords_of_an_alternative_count_never_the_classifier(rules):
    """A classifier reads sentiment into misheard words ("you did it" heard as "You'll be dead."): an
    alternative the rules cannot decide by keywords is passed over, and so is one that decides 0."""
    seen = []

    def classify(text):
        seen.append(text)
        return ("NEGATIVE", 0.7) if "dead" in text else ("NEUTRAL", 0.0)
    alts = (("You'll be dead.", -1.26), ("Not bad.", -1.3), ("Uh, no.", -1.4), ("Don't do that.", -1.5))
    d = rules.decide("You'll be deep.", classify, -1.07, alts)
    assert (d.value, d.rule, d.alternative) == (-1, "alternative", "Uh, no.")
    assert seen == ["you'll be deep"]                    # the classifier saw the best transcript only
    d = rules.decide("You'll be deep.", classify, -1.07, alts[:2])
    assert (d.value, d.rule) == (0, "classifier")


class FillerScores:
    """A recogniser's filler evidence: (filler, mean token log-probability), counting the calls."""

    def __init__(self, word="mm", logprob=-1.5):
        self.answer, self.calls = (word, logprob), []

    def __call__(self, candidates):
        self.calls.append(candidates)
        return self.answer


def test_the_filler_gate_drops_a_sign_when_a_filler_is_nearly_as_likely(rules):
    """Whisper wrote "Yeah." for a filler: when the decoder finds a hesitation filler as the whole
    transcript within filler_gate.margin (1.0) of the best transcript's mean log-probability, the word
    is not trusted (rule filler_like, value 0); further below, the sign stands."""
    near = FillerScores("er", -1.9)
    d = rules.decide("Yeah.", never, -1.1, (), near)
    assert (d.value, d.rule, d.gated_value, d.filler) == (0, "filler_like", 1, ("er", -1.9))
    assert near.calls == [("mm", "hmm", "hm", "uh", "um", "er")]      # the configured candidates
    far = FillerScores("mm", -2.2)
    d = rules.decide("Yeah.", never, -1.1, (), far)
    assert (d.value, d.rule, d.gated_value, d.filler) == (1, "keyword", None, ("mm", -2.2))
    # any signed decision: the classifier's, a keyword vote, an alternative's keyword
    assert rules.decide("Thank you.", lambda t: ("POSITIVE", 0.4), -1.0, (), FillerScores("hm", -1.5)).rule == \
        "filler_like"
    d = rules.decide("But move.", neutral, -0.65, (("Bad move.", -1.25),), FillerScores("mm", -1.0))
    assert (d.value, d.rule, d.gated_value) == (0, "filler_like", -1)


def test_the_filler_gate_is_asked_only_about_short_signed_transcripts(rules):
    """No feedback already (fillers, neutral sentences), more than filler_gate.max_words (3) words, no
    scores from the backend, or the gate off: the recogniser is not asked (the forced decode costs time)."""
    asked = FillerScores("mm", 0.0)
    assert rules.decide("Um...", never, -1.0, (), asked).rule == "filler"
    assert rules.decide("Look at the hand.", neutral, -1.0, (), asked).value == 0
    assert rules.decide("Yes, that was great.", never, -1.0, (), asked).value == 1     # 4 words
    assert rules.decide("Yes.", never, None, (), asked).value == 1                    # no avg_logprob
    assert asked.calls == []
    assert rules.decide("Yes.", never, -1.0, (), None).value == 1                     # no filler scores
    off = RuleLayer.from_config(voice_config("sentiment.filler_gate.enabled=false").sentiment)
    assert off.decide("Yeah.", never, -1.1, (), asked).value == 1 and asked.calls == []
    wide = RuleLayer.from_config(voice_config("sentiment.filler_gate.max_words=null").sentiment)
    assert wide.decide("Yes, that was great.", never, -1.0, (), asked).rule == "filler_like"


def test_the_filler_gate_config_is_checked():
    with pytest.raises(ConfigError,
                       match=r"sentiment\.filler_gate\.candidates.*\['yeah'\] are not in sentiment\.fillers"):
        voice_config("sentiment.filler_gate.candidates=[mm, yeah]")
    with pytest.raises(ConfigError, match=r"sentiment\.filler_gate\.margin"):
        voice_config("sentiment.filler_gate.margin=-1")
    with pytest.raises(ConfigError, match=r"sentiment\.filler_gate\.max_words"):
        voice_config("sentiment.filler_gate.max_words=0")
