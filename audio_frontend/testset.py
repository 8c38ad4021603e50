"""A labelled, synthesised voice test set (`protamer synth-voice DIR`): several speakers, tone vs words.

Layout: DIR/<speaker>/<split>/<tone>/<nnn>.wav with split `calib` (what `protamer calibrate --wav-dir`
reads), `test` (other sentences) and, with `--probe`, `probe` (one-word keywords and fillers), tone `pos`,
`neg`, `neu` (neutral sentences) or `fillers`, and a DIR/<speaker>/<split>/labels.jsonl giving each
file's tone, words (the sentiment of what is said), kind (`congruent`, `against` = words said in the
opposite tone, `neutral`, `filler`, `one_word`) and text. Speakers are
espeak-ng voices and variants; tone is set by espeak pitch / speed / amplitude and sox effects
(`audio_frontend.synth.STYLES`), jittered per utterance. Synthesised voices are not real recordings.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from audio_frontend.calibration import write_json_atomic

SPEAKERS = ("en-us", "en-gb", "en-us+m3", "en-gb+f2", "en-us+f4", "en-gb-scotland+m7")
TONE_STYLE = {"pos": "positive", "neg": "angry", "neu": "neutral", "fillers": "filler"}

# (calibration sentences, test sentences): never the same sentence in both.
POSITIVE = (["good job", "well done", "yes, great", "nice one", "that's it, perfect"],
            ["wonderful, keep going", "I love that", "excellent work", "you did it", "yes, that was great",
             "beautiful", "brilliant move"])
NEGATIVE = (["no, stop that", "that is wrong", "bad move", "don't do that", "not like that"],
            ["terrible", "I hate that", "awful", "that was horrible", "no, wrong way", "stop it now",
             "that is really bad"])
NEUTRAL = (["the robot moved its arm", "now try the other hand", "it is moving"],
           ["okay, let us see", "what is it doing", "look at the hand"])
FILLERS = (["hmm", "uh"], ["um", "mm", "er"])

# The probe split (`synth-voice --probe`): what a filler gate must tell apart. Single keywords said in
# both tones (they must keep their sign) and every filler of `sentiment.fillers` but "umm", in the filler
# and the neutral style (they must give 0). Not in calib/ or test/, so the standard figures do not move.
PROBE_ONE_WORD = (["yes", "yeah", "good", "great", "nice", "perfect", "excellent", "okay"],
                  ["no", "nope", "bad", "wrong", "stop"])
PROBE_FILLERS = ["hmm", "hm", "mm", "mmm", "uh", "um", "er", "erm", "ah", "eh", "oh", "uhm"]

JITTER = {"pitch": 6, "speed": 12, "amplitude": 15}

# espeak-ng reads some fillers as letter names: "mm" as "em-em" (,Em'Em), "mmm" as "em-em-em", "hm" as
# "aitch-em", "uhm" as "oom". Those are said with phonemes ([[...]]): a held hum, "h" into a hum, a schwa
# into a hum. Before this, Whisper heard the spelled "em-em" as "Yeah man..." or "Amen", which is what
# was said, not a filler misheard.
# "er" is said as a steady long [əː] ([[@2:]], the same vowel in every voice): en-gb-scotland says "er" as a
# glide [e]->[ɐ], "yeah" without its [j], a word rather than a hesitation (Whisper writes "Yeah."; docs/voice.md).
SAID_AS = {"mm": "[[m:m:]]", "mmm": "[[m:m:m:]]", "hm": "[[hm:m:]]", "uhm": "[[@m:]]", "er": "[[@2:]]"}


def plan(split: int, against: bool) -> list[dict]:
    """The utterances of one split (0 calib, 1 test): tone, words label, kind, text."""
    rows = [dict(tone="pos", words="pos", kind="congruent", text=t) for t in POSITIVE[split]]
    rows += [dict(tone="neg", words="neg", kind="congruent", text=t) for t in NEGATIVE[split]]
    if against:   # words said in the opposite tone: what the prosody scorer must hear through
        rows += [dict(tone="neg", words="pos", kind="against", text=t) for t in POSITIVE[split]]
        rows += [dict(tone="pos", words="neg", kind="against", text=t) for t in NEGATIVE[split]]
    rows += [dict(tone="neu", words="neu", kind="neutral", text=t) for t in NEUTRAL[split]]
    rows += [dict(tone="fillers", words="filler", kind="filler", text=t) for t in FILLERS[split]]
    return rows


def plan_probe() -> list[dict]:
    """The probe split: one-word keywords in both tones (kind `one_word`), fillers in two styles."""
    pos, neg = PROBE_ONE_WORD
    rows = [dict(tone=t, words="pos", kind="one_word", text=w) for w in pos for t in ("pos", "neg")]
    rows += [dict(tone=t, words="neg", kind="one_word", text=w) for w in neg for t in ("neg", "pos")]
    rows += [dict(tone=t, words="filler", kind="filler", text=w) for w in PROBE_FILLERS for t in ("fillers", "neu")]
    return rows


def utterance(text: str, tone: str, voice: str, rng: np.random.Generator, sample_rate: int = 16000,
              noise_dbfs: float | None = None, pad_s: tuple[float, float] = (0.3, 0.6)) -> np.ndarray:
    from audio_frontend.synth import STYLES, synthesize, with_silence

    style = TONE_STYLE[tone]
    base = STYLES[style]
    kw = {k: int(np.clip(base[k] + rng.integers(-j, j + 1), 0, 99 if k == "pitch" else 200))
          for k, j in JITTER.items()}
    x = synthesize(SAID_AS.get(text, text), style, sample_rate, voice=voice, **kw)
    return with_silence(x, pad_s[0], pad_s[1], sample_rate, noise_dbfs=noise_dbfs,
                        seed=int(rng.integers(1 << 31)))


def make_test_set(root: str | Path, speakers=SPEAKERS, sample_rate: int = 16000, noise_dbfs: float | None = None,
                  seed: int = 0, max_per_group: int | None = None, against: bool = True, probe: bool = False) -> dict:
    """Write the set; returns counts. `max_per_group` keeps the first N sentences of each list (tests);
    `probe` also writes a `probe/` split per speaker (`plan_probe`)."""
    import soundfile as sf

    from audio_frontend.synth import require_tools

    require_tools()
    root = Path(root)
    counts: dict[str, int] = {}
    for s_i, speaker in enumerate(speakers):
        for split_i, split in enumerate(("calib", "test", "probe") if probe else ("calib", "test")):
            rng = np.random.default_rng([seed, s_i, split_i])
            rows = plan_probe() if split == "probe" else plan(split_i, against and split == "test")
            if max_per_group:
                seen: dict[tuple, int] = {}
                kept = []
                for r in rows:
                    key = (r["tone"], r["kind"])
                    seen[key] = seen.get(key, 0) + 1
                    if seen[key] <= max_per_group:
                        kept.append(r)
                rows = kept
            folder = root / speaker.replace("+", "_") / split
            labels = []
            for i, r in enumerate(rows):
                x = utterance(r["text"], r["tone"], speaker, rng, sample_rate, noise_dbfs)
                rel = f"{r['tone']}/{i:03d}.wav"
                (folder / r["tone"]).mkdir(parents=True, exist_ok=True)
                sf.write(str(folder / rel), x, sample_rate, subtype="PCM_16")
                labels.append({"file": rel, "speaker": speaker, **r})
                counts[r["kind"]] = counts.get(r["kind"], 0) + 1
            tmp = folder / "labels.jsonl.tmp"
            tmp.write_text("".join(json.dumps(x, sort_keys=True) + "\n" for x in labels), encoding="utf-8")
            tmp.replace(folder / "labels.jsonl")
    write_json_atomic(root / "synth_voice.json", {
        "speakers": list(speakers), "sample_rate": sample_rate, "noise_dbfs": noise_dbfs, "seed": seed,
        "max_per_group": max_per_group, "probe": probe, "counts": counts,
        "note": "synthesised with espeak-ng + sox: not real recordings"})
    return counts
