"""The linguistic rule layer (paper V-B.4): keywords decide, fillers are neutral, else the classifier.

Pure Python; the classifier is any callable `text -> (label, score)`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Callable

_BRACKETS = re.compile(r"[\[\(\*][^\]\)\*]*[\]\)\*]")   # Whisper's [BLANK_AUDIO], (music), *cough*
_WORD = re.compile(r"[a-z0-9']+")
# Words that turn the keyword after them around ("not good", "never wrong"); "no" is a keyword itself.
NEGATORS = frozenset({"not", "never", "nothing", "nobody", "neither", "nor", "without", "hardly", "barely"})
# How many words after a negator it reaches: "not good", "not very good", "did not do that right".
NEGATION_SCOPE = 3
# An utterance that opens with one of these forbids what the learner did ("don't do that", "do not touch").
PROHIBITIVE_OPENINGS = (("don't",), ("dont",), ("do", "not"))


def words_of(text: str) -> list[str]:
    text = _BRACKETS.sub(" ", text.lower())
    return [w.strip("'") for w in _WORD.findall(text) if w.strip("'")]


def collapse_repeats(words: list[str]) -> list[str]:
    """One copy of a phrase said several times in a row ("good job good job good" -> "good job").

    Whisper loops on a segment with little silence after it and stops mid-copy at its token limit;
    a trailing partial copy of the repeated phrase is dropped with the repeats. A repeated keyword
    ("no no no") keeps its value."""
    w = list(words)
    changed = True
    while changed:
        changed = False
        for n in range(1, len(w) // 2 + 1):
            i = 0
            while i + 2 * n <= len(w):
                if w[i:i + n] == w[i + n:i + 2 * n]:
                    j = i + n
                    while w[j:j + n] == w[i:i + n]:
                        del w[j:j + n]
                    tail = w[j:]
                    if tail and len(tail) < n and w[i:i + len(tail)] == tail:
                        del w[j:]
                    changed = True
                i += 1
    return w


def is_negator(word: str) -> bool:
    return word in NEGATORS or word.endswith("n't")


@dataclass(frozen=True)
class RuleDecision:
    value: float          # +1, -1 or 0
    # "keyword", "keyword_vote", "negated_negative", "prohibitive", "filler", "empty", "low_confidence",
    # "classifier", "no_classifier", "alternative", "filler_like"
    rule: str
    words: tuple[str, ...]
    label: str | None = None
    score: float | None = None
    alternative: str | None = None   # rule "alternative": the beam hypothesis whose keywords decided
    # the filler gate's evidence when it was asked: (most likely filler, its mean token log-probability)
    filler: tuple[str, float] | None = None
    # rule "filler_like": the value the words would have given
    gated_value: float | None = None


# The rules by which keywords alone decide: what an alternative hypothesis may decide by.
KEYWORD_RULES = frozenset({"keyword", "keyword_vote", "prohibitive"})


# A classifier that can say "neither" (VADER below its threshold) gives no feedback for that text.
NEUTRAL_LABEL = "NEUTRAL"


class RuleLayer:
    def __init__(self, affirmative, negative, fillers, positive_labels=("POSITIVE",), negative_labels=("NEGATIVE",),
                 discourse_markers=(), min_avg_logprob: float | None = None,
                 alternative_margin: float | None = None, filler_gate=None):
        """`filler_gate`: a `FillerGateConfig` (enabled, margin, candidates, max_words) or None (off)."""
        self.affirmative = {" ".join(words_of(k)) for k in affirmative}
        self.negative = {" ".join(words_of(k)) for k in negative}
        self.fillers = {" ".join(words_of(k)) for k in fillers}
        self.discourse_markers = {" ".join(words_of(k)) for k in discourse_markers}
        self.positive_labels = {lab.lower() for lab in positive_labels}
        self.negative_labels = {lab.lower() for lab in negative_labels}
        self.min_avg_logprob = min_avg_logprob
        self.alternative_margin = alternative_margin
        self.filler_gate = filler_gate if filler_gate is not None and filler_gate.enabled else None
        self._phrases = sorted([(tuple(k.split()), 1.0) for k in self.affirmative if k]
                               + [(tuple(k.split()), -1.0) for k in self.negative if k], key=lambda t: -len(t[0]))

    @classmethod
    def from_config(cls, cfg, asr_cfg=None) -> "RuleLayer":
        """`cfg`: the `sentiment` section; `asr_cfg` (optional): the `asr` section, for the confidence gate."""
        return cls(cfg.affirmative, cfg.negative, cfg.fillers, cfg.positive_labels, cfg.negative_labels,
                   cfg.discourse_markers, getattr(asr_cfg, "min_avg_logprob", None), cfg.alternative_margin,
                   cfg.filler_gate)

    def keyword_value(self, content: list[str]) -> float | None:
        phrase = " ".join(content)
        if phrase in self.affirmative:
            return 1.0
        if phrase in self.negative:
            return -1.0
        # the same keyword repeated ("no no no", "yes yes") is still a single keyword
        if len(set(content)) == 1:
            return self.keyword_value(content[:1]) if len(content) > 1 else None
        return None

    def keyword_hits(self, content: list[str]) -> list[tuple[int, float]]:
        """(position, value) of each keyword in a sentence, longest phrase first, after negation:
        an affirmative keyword a negator reaches counts as negative ("not right"), a negative one it
        reaches counts 0 ("not bad": mild and easily misheard, so no feedback rather than praise)."""
        hits, i = [], 0
        while i < len(content):
            for phrase, value in self._phrases:
                if tuple(content[i:i + len(phrase)]) == phrase:
                    break
            else:
                i += 1
                continue
            if any(is_negator(w) for w in content[max(0, i - NEGATION_SCOPE):i]):
                value = -1.0 if value > 0 else 0.0
            hits.append((i, value))
            i += len(phrase)
        return hits

    def vote_value(self, content: list[str]) -> tuple[float, str] | None:
        """Keywords of one polarity (after negation) decide ("no, wrong way", "stop it now", "that is not
        right"); only negated negatives give 0; keywords of both polarities decide nothing."""
        values = {v for _, v in self.keyword_hits(content)}
        if not values:
            return None
        signed = values - {0.0}
        if not signed:
            return 0.0, "negated_negative"
        if len(signed) == 1:
            return signed.pop(), "keyword_vote"
        return None

    def label_value(self, label: str) -> float:
        lab = label.lower()
        if lab == NEUTRAL_LABEL.lower():
            return 0.0
        if lab in self.positive_labels:
            return 1.0
        if lab in self.negative_labels:
            return -1.0
        raise ValueError(f"sentiment label {label!r} is neither positive {sorted(self.positive_labels)} nor "
                         f"negative {sorted(self.negative_labels)} nor {NEUTRAL_LABEL}; "
                         f"set sentiment.positive_labels / negative_labels")

    def decide(self, transcript: str, classify: Callable[[str], tuple[str, float]] | None,
               avg_logprob: float | None = None,
               alternatives: tuple[tuple[str, float | None], ...] = (),
               filler_logprob: Callable[[tuple[str, ...]], tuple[str, float]] | None = None) -> RuleDecision:
        """`avg_logprob`: the recogniser's mean token log-probability, when it gives one; below
        `min_avg_logprob` the transcript is too unsure to give feedback. `alternatives`: the recogniser's
        other hypotheses `(text, avg_logprob)`; when the transcript has words but nothing decides (the
        classifier says neutral), the first of them within `alternative_margin` of `avg_logprob` whose
        keywords decide gives the value (rule "alternative"). A keyword the recogniser found nearly as
        likely is kept; the classifier is never asked about an alternative. `filler_logprob(candidates)`:
        the recogniser's (filler, mean token log-probability) of the most likely filler as the whole
        transcript; a signed decision on a short transcript is dropped when that filler is within the
        filler gate's margin of `avg_logprob` (rule "filler_like")."""
        d = self._decide_words(transcript, classify, avg_logprob, alternatives)
        return self._gate(d, avg_logprob, filler_logprob)

    def _gate(self, d: RuleDecision, avg_logprob: float | None, filler_logprob) -> RuleDecision:
        """The filler gate: a sign is kept only if no hesitation filler is nearly as likely a transcript."""
        g = self.filler_gate
        if (g is None or d.value == 0 or filler_logprob is None or avg_logprob is None
                or (g.max_words is not None and len(d.words) > g.max_words)):
            return d
        word, lp = filler_logprob(tuple(g.candidates))
        if lp >= avg_logprob - g.margin:
            return RuleDecision(0.0, "filler_like", d.words, d.label, d.score, d.alternative, (word, float(lp)),
                                gated_value=d.value)
        return RuleDecision(d.value, d.rule, d.words, d.label, d.score, d.alternative, (word, float(lp)))

    def _decide_words(self, transcript: str, classify, avg_logprob: float | None,
                      alternatives: tuple[tuple[str, float | None], ...]) -> RuleDecision:
        d = self._decide(transcript, classify, avg_logprob)
        if (d.value != 0 or d.rule != "classifier" or self.alternative_margin is None or avg_logprob is None):
            return d
        for text, logprob in alternatives:
            if logprob is None or avg_logprob - logprob > self.alternative_margin:
                continue
            a = self._decide(text, None, logprob)   # the confidence gate holds for alternatives too
            if a.value != 0 and a.rule in KEYWORD_RULES:
                return RuleDecision(a.value, "alternative", d.words, d.label, float(logprob), alternative=text)
        return d

    def _decide(self, transcript: str, classify, avg_logprob: float | None = None) -> RuleDecision:
        words = collapse_repeats(words_of(transcript))
        if not words:
            return RuleDecision(0.0, "empty", ())
        content = [w for w in words if w not in self.fillers]
        if not content:
            return RuleDecision(0.0, "filler", tuple(words))
        if self.min_avg_logprob is not None and avg_logprob is not None and avg_logprob < self.min_avg_logprob:
            return RuleDecision(0.0, "low_confidence", tuple(words), score=float(avg_logprob))
        kv = self.keyword_value(content)
        if kv is not None:
            return RuleDecision(kv, "keyword", tuple(words))
        if content[0] in self.discourse_markers:   # "okay, let us see": the rest says what it means
            content = content[1:]
        vote = self.vote_value(content)
        if vote is not None:
            return RuleDecision(vote[0], vote[1], tuple(words))
        if any(tuple(content[:len(p)]) == p for p in PROHIBITIVE_OPENINGS):
            return RuleDecision(-1.0, "prohibitive", tuple(words))
        if classify is None:   # keyword-only mode: what the rules cannot decide gives no feedback
            return RuleDecision(0.0, "no_classifier", tuple(words))
        label, score = classify(" ".join(content))
        return RuleDecision(self.label_value(label), "classifier", tuple(words), label=label, score=float(score))
