"""The linguistic rule layer (paper V-B.4): keywords decide, fillers are neutral, else the classifier.

Pure Python; the classifier is any callable `text -> (label, score)`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Callable

_BRACKETS = re.compile(r"[\[\(\*][^\]\)\*]*[\]\)\*]")   # Whisper's [BLANK_AUDIO], (music), *cough*
_WORD = re.compile(r"[a-z0-9']+")
# Words that can turn a keyword around ("not good", "never wrong"): a sentence with one goes to the
# classifier, which reads negation, instead of the keyword vote.
NEGATORS = frozenset({"not", "never", "nothing", "nobody", "neither", "nor", "without", "hardly", "barely"})


def words_of(text: str) -> list[str]:
    text = _BRACKETS.sub(" ", text.lower())
    return [w.strip("'") for w in _WORD.findall(text) if w.strip("'")]


@dataclass(frozen=True)
class RuleDecision:
    value: float          # +1, -1 or 0
    rule: str             # "keyword", "keyword_vote", "filler", "empty", "classifier", "no_classifier"
    words: tuple[str, ...]
    label: str | None = None
    score: float | None = None


# A classifier that can say "neither" (VADER below its threshold) gives no feedback for that text.
NEUTRAL_LABEL = "NEUTRAL"


class RuleLayer:
    def __init__(self, affirmative, negative, fillers, positive_labels=("POSITIVE",), negative_labels=("NEGATIVE",)):
        self.affirmative = {" ".join(words_of(k)) for k in affirmative}
        self.negative = {" ".join(words_of(k)) for k in negative}
        self.fillers = {" ".join(words_of(k)) for k in fillers}
        self.positive_labels = {lab.lower() for lab in positive_labels}
        self.negative_labels = {lab.lower() for lab in negative_labels}

    @classmethod
    def from_config(cls, cfg) -> "RuleLayer":
        return cls(cfg.affirmative, cfg.negative, cfg.fillers, cfg.positive_labels, cfg.negative_labels)

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

    def vote_value(self, content: list[str]) -> float | None:
        """Keywords of one polarity only, and no negator: that polarity ("no, wrong way", "stop it now")."""
        if any(w in NEGATORS or w.endswith("n't") for w in content):
            return None
        text = " " + " ".join(content) + " "
        pos = any(f" {k} " in text for k in self.affirmative)
        neg = any(f" {k} " in text for k in self.negative)
        if pos != neg:
            return 1.0 if pos else -1.0
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

    def decide(self, transcript: str, classify: Callable[[str], tuple[str, float]] | None) -> RuleDecision:
        words = words_of(transcript)
        if not words:
            return RuleDecision(0.0, "empty", ())
        content = [w for w in words if w not in self.fillers]
        if not content:
            return RuleDecision(0.0, "filler", tuple(words))
        kv = self.keyword_value(content)
        if kv is not None:
            return RuleDecision(kv, "keyword", tuple(words))
        vote = self.vote_value(content)
        if vote is not None:
            return RuleDecision(vote, "keyword_vote", tuple(words))
        if classify is None:   # keyword-only mode: what the rules cannot decide gives no feedback
            return RuleDecision(0.0, "no_classifier", tuple(words))
        label, score = classify(" ".join(content))
        return RuleDecision(self.label_value(label), "classifier", tuple(words), label=label, score=float(score))
