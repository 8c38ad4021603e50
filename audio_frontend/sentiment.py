"""Sentiment behind the rule layer: VADER (offline, ships its lexicon) or a transformers classifier.

Every classifier is a callable `text -> (label, score)`; labels are POSITIVE / NEGATIVE (or the
configured names) and, for VADER, NEUTRAL when |compound| is below `sentiment.vader_threshold`.
"""

from __future__ import annotations

from audio_frontend.errors import MissingWeightsError
from audio_frontend.rules import NEUTRAL_LABEL


class VaderClassifier:
    """VADER (Hutto & Gilbert 2014): a rule- and lexicon-based scorer for short informal text."""

    name = "vader"

    def __init__(self, threshold: float = 0.05, neutral_words=()):
        try:
            from vaderSentiment.vaderSentiment import SentimentIntensityAnalyzer
        except ImportError as e:
            raise MissingWeightsError(f"sentiment.kind=vader needs vaderSentiment ({e}); "
                                      f"pip install vaderSentiment==3.3.2 (in the audio extra)") from None
        self._sia = SentimentIntensityAnalyzer()
        for w in neutral_words:      # task words the lexicon mistakes for sentiment
            self._sia.lexicon.pop(w.lower(), None)
        self.threshold = threshold

    def __call__(self, text: str) -> tuple[str, float]:
        compound = float(self._sia.polarity_scores(text)["compound"])
        if compound >= self.threshold:
            return "POSITIVE", compound
        if compound <= -self.threshold:
            return "NEGATIVE", compound
        return NEUTRAL_LABEL, compound


class PipelineClassifier:
    """A transformers text-classification pipeline (DistilBERT SST-2 by default) as `text -> (label, score)`."""

    def __init__(self, pipe, name: str):
        self.pipe = pipe
        self.name = name

    def __call__(self, text: str) -> tuple[str, float]:
        out = self.pipe(text)
        top = out[0] if isinstance(out, list) else out
        if isinstance(top, list):
            top = max(top, key=lambda d: d["score"])
        return str(top["label"]), float(top["score"])


def load_sentiment(cfg, kind: str | None = None):
    """The classifier `sentiment.kind` asks for; "auto" takes DistilBERT when its weights load, else VADER."""
    kind = kind or cfg.kind
    if kind == "vader":
        return VaderClassifier(cfg.vader_threshold, cfg.vader_neutral_words)
    from audio_frontend.models import load_text_classifier, weights_on_disk
    if kind == "auto" and not weights_on_disk(cfg.model):
        return VaderClassifier(cfg.vader_threshold, cfg.vader_neutral_words)
    return PipelineClassifier(load_text_classifier(cfg), cfg.model)


def resolved_kind(cfg) -> str:
    """What `load_sentiment(cfg)` would load, without loading it."""
    if cfg.kind != "auto":
        return cfg.kind
    from audio_frontend.models import weights_on_disk
    return "distilbert" if weights_on_disk(cfg.model) else "vader"
