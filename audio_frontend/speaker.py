"""A simulated speaker: synthesised praise and reproach played into the real voice pipeline like a microphone.

A simulated teacher in a live session decides when to praise or reproach; what it says has to reach the
learner the way a person's voice does, through the listener process (source -> VAD -> scorer -> event), so
that the session runs on the measured channel (its misses, wrong signs and latency) and not on a model of it.

- `SpeakerBank`: one espeak-ng voice's utterances (testset's sentences: praise in the positive tone, reproach
  in the angry one, fillers in the filler style, and the neutral calibration sentences; and single words of
  praise and reproach, `SPEAKER_WORDS`, for a speaker who talks fast), synthesised once into a folder with a
  manifest, and reused while voice, seed, rate and recipe match.
- `SpeakerSource`: an `AudioSource` that plays like a microphone at real-time pace (background noise; each
  chunk delivered once its last sample is due, stamped with the wall-clock time of its first sample) and
  says what the learner asks for on a command queue, reporting each utterance it plays on a "spoken" queue;
  in sentences (`says="sentences"`, the test sentences) or in single words (`says="words"`).
  It is picklable and loads the bank in the process that plays it (the spawned listener).
- `calibrate_speaker`: that voice's prosody calibration from the bank's calibration sentences through the
  code `protamer calibrate --wav-dir` uses, so a session can use `--feedback prosody` with nobody recording.

Commands are dicts `{"id": int, "t": wall-clock time the words should start (None: now), "sign": +1 | -1 |
0, "pick": an utterance id or None}`; `END` (or None) ends the stream. Reports are dicts `{"id", "sign",
"text", "utterance", "t_start", "t_end", "requested_t", "delay_s"}` with `t_start`/`t_end` the wall-clock
bounds of the words (the channel model's 30 dB criterion, `labelled.speech_bounds`), or `{"id", "error"}`
for a command that was refused. Wall clock is `time.time()`, the clock the listener stamps events with.
Synthesised voices are not people (docs/voice.md, "What these figures cannot tell").
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import queue as queue_lib
import shutil
import sys
import tempfile
import threading
import time
import zlib
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Iterator

import numpy as np

from audio_frontend.errors import AudioInputError
from audio_frontend.sources import AudioSource

BANK_FORMAT = 2  # 2: utterances have a `form` (sentence, word, filler)
MANIFEST = "speaker_bank.json"
LABELS = "labels.jsonl"
# Short on purpose: in a stream the silence around an utterance is the stream's own; the test set's long
# pads (0.3 s / 0.6 s) would only push the words away from the time they were asked for.
PAD_S = (0.1, 0.1)
# espeak-ng ends each utterance with 0.3-0.6 s of near-silence; cut after the last sample above this level
TAIL_FLOOR = 10 ** (-60 / 20)
DEFAULT_NOISE_DBFS = -60.0
# The pause between utterances said one after another: a person does not talk over themselves, and a pause
# longer than the VAD's hangover (0.25 s) keeps each utterance its own segment, hence its own event.
GAP_S = 0.5
END = "end"
# tone -> (kind, sign). Neutral sentences are in the bank only to calibrate (the feature model needs a
# neutral class); a session says fillers for sign 0.
KIND_OF_TONE = {"pos": ("praise", 1), "neg": ("reproach", -1), "fillers": ("filler", 0), "neu": ("neutral", 0)}
_CALIBRATION_LABEL = {"pos": "pos", "neg": "neg", "fillers": "filler", "neu": "neu"}
COMMAND_KEYS = {"id", "t", "sign", "pick"}
# What a speaker who talks fast says: one word of praise or reproach, in the matching tone (testset's probe
# keywords; "okay" left out: it is as often lukewarm as praise). Whisper + rules got these right 143 of 156 on
# the probe voices (docs/voice.md). Not calibration material: the prosody calibration stays on sentences.
SPEAKER_WORDS = (["yes", "yeah", "good", "great", "nice", "perfect", "excellent"],
                 ["no", "nope", "bad", "wrong", "stop"])
SAYS = ("sentences", "words")


def bank_plan() -> list[dict]:
    """What the bank holds: testset's calibration lists (flagged `calibration`), its test lists, and the single
    words (last, so that the sentences' jitter draws are those of a bank without them)."""
    from audio_frontend.testset import FILLERS, NEGATIVE, NEUTRAL, POSITIVE

    rows = []
    for split, name in ((0, "calib"), (1, "test")):
        groups = [("pos", POSITIVE), ("neg", NEGATIVE), ("fillers", FILLERS)]
        if split == 0:
            groups.append(("neu", NEUTRAL))
        for tone, lists in groups:
            rows += [dict(id=f"{tone}-{name}-{i:02d}", text=text, tone=tone, calibration=split == 0,
                          form="filler" if tone == "fillers" else "sentence")
                     for i, text in enumerate(lists[split])]
    for tone, words in (("pos", SPEAKER_WORDS[0]), ("neg", SPEAKER_WORDS[1])):
        rows += [dict(id=f"{tone}-word-{i:02d}", text=w, tone=tone, calibration=False, form="word")
                 for i, w in enumerate(words)]
    return rows


def _recipe_digest() -> str:
    """Changes when anything that shapes the sound changes (sentences, styles, jitter, phonemes, pads)."""
    from audio_frontend.synth import STYLES
    from audio_frontend.testset import JITTER, SAID_AS, TONE_STYLE

    recipe = {"plan": bank_plan(), "styles": STYLES, "jitter": JITTER, "said_as": SAID_AS, "tone_style": TONE_STYLE,
              "pad_s": PAD_S, "tail_floor": TAIL_FLOOR}
    return hashlib.sha256(json.dumps(recipe, sort_keys=True).encode()).hexdigest()[:16]


@dataclass(frozen=True)
class BankUtterance:
    id: str
    text: str
    tone: str               # pos, neg, fillers, neu (testset.TONE_STYLE)
    kind: str               # praise, reproach, filler, neutral
    sign: int               # +1, -1, 0
    calibration: bool       # one of testset's calibration sentences (not said in a session by default)
    form: str               # sentence, word (one keyword) or filler
    file: str               # relative to the bank folder
    duration_s: float       # the whole file, pads included
    speech_start_s: float   # where the words begin and end in the file (speech_bounds: within 30 dB of the peak)
    speech_end_s: float


def _read_manifest(directory: Path) -> dict | None:
    try:
        record = json.loads((directory / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError, UnicodeDecodeError):
        return None
    return record if isinstance(record, dict) else None


class SpeakerBank:
    """One voice's synthesised utterances in a folder: WAVs, labels.jsonl and the manifest (written last)."""

    def __init__(self, directory: Path, voice: str, seed: int, sample_rate: int, utterances: list[BankUtterance]):
        self.directory = Path(directory)
        self.voice = voice
        self.seed = seed
        self.sample_rate = sample_rate
        self.utterances = tuple(utterances)
        self._by_id = {u.id: u for u in self.utterances}
        self._audio: dict[str, np.ndarray] = {}

    @staticmethod
    def manifest_for(voice: str, seed: int, sample_rate: int) -> dict:
        return {"format": BANK_FORMAT, "voice": voice, "seed": int(seed), "sample_rate": int(sample_rate),
                "recipe": _recipe_digest()}

    @classmethod
    def build(cls, directory: str | Path, voice: str = "en-us", seed: int = 0, sample_rate: int = 16000
              ) -> "SpeakerBank":
        """The bank in `directory`, synthesised unless one with this voice, seed, rate and recipe is there.
        Written into a temporary sibling folder and renamed into place, so a reader never sees half a bank."""
        import soundfile as sf

        from audio_frontend.labelled import speech_bounds
        from audio_frontend.synth import require_tools, with_silence
        from audio_frontend.testset import utterance

        directory = Path(directory)
        want = cls.manifest_for(voice, seed, sample_rate)
        have = _read_manifest(directory)
        if have is not None and all(have.get(k) == v for k, v in want.items()):
            return cls.load(directory)
        if have is None and directory.exists() and (not directory.is_dir() or any(directory.iterdir())):
            raise AudioInputError(f"{directory}: exists but holds no {MANIFEST}, so it is not a speaker bank (and is "
                                  f"left alone); choose a new or empty folder")
        require_tools()
        directory.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{directory.name}.", suffix=".tmp", dir=directory.parent))
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o777 & ~umask)   # mkdtemp makes 0700; a bank is as readable as any other folder
        try:
            rng = np.random.default_rng([int(seed), zlib.crc32(voice.encode())])
            labels = []
            for row in bank_plan():
                x = utterance(row["text"], row["tone"], voice, rng, sample_rate, pad_s=(0.0, 0.0))
                loud = np.flatnonzero(np.abs(x) > TAIL_FLOOR)
                x = with_silence(x[: loud[-1] + 1] if loud.size else x, PAD_S[0], PAD_S[1], sample_rate)
                file = f"{row['id']}.wav"
                sf.write(str(tmp / file), x, sample_rate, subtype="PCM_16")
                x, _ = sf.read(str(tmp / file), dtype="float32")     # bounds of what is stored
                start, end = speech_bounds(x, sample_rate)
                kind, sign = KIND_OF_TONE[row["tone"]]
                labels.append(BankUtterance(id=row["id"], text=row["text"], tone=row["tone"], kind=kind, sign=sign,
                                            calibration=row["calibration"], form=row["form"], file=file,
                                            duration_s=x.size / sample_rate, speech_start_s=float(start),
                                            speech_end_s=float(end)))
            (tmp / LABELS).write_text("".join(json.dumps(asdict(u), sort_keys=True) + "\n" for u in labels),
                                      encoding="utf-8")
            from audio_frontend.calibration import write_json_atomic
            write_json_atomic(tmp / MANIFEST, {**want, "n_utterances": len(labels), "created": time.time(),
                                               "note": "synthesised with espeak-ng + sox: not a real speaker"})
            if directory.exists():   # an empty folder or a stale bank (other voice, seed or recipe): replaced whole
                old = Path(tempfile.mkdtemp(prefix=f".{directory.name}.", suffix=".old", dir=directory.parent))
                os.replace(directory, old / "bank")
                os.replace(tmp, directory)
                shutil.rmtree(old, ignore_errors=True)
            else:
                try:
                    os.replace(tmp, directory)
                except OSError:   # another process put its bank there meanwhile: use it if it is this one
                    have = _read_manifest(directory)
                    if have is None or any(have.get(k) != v for k, v in want.items()):
                        raise
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        return cls.load(directory)

    @classmethod
    def load(cls, directory: str | Path) -> "SpeakerBank":
        directory = Path(directory)
        manifest = _read_manifest(directory)
        if manifest is None:
            raise AudioInputError(f"{directory}: no speaker bank there (no readable {MANIFEST}); make one with "
                                  f"audio_frontend.speaker.SpeakerBank.build('{directory}', voice=...)")
        if manifest.get("format") != BANK_FORMAT:
            raise AudioInputError(f"{directory}: speaker bank format {manifest.get('format')!r}, this version reads "
                                  f"{BANK_FORMAT}; build it again")
        try:
            rows = [json.loads(line) for line in (directory / LABELS).read_text(encoding="utf-8").splitlines()
                    if line.strip()]
            utterances = [BankUtterance(**r) for r in rows]
        except (OSError, json.JSONDecodeError, TypeError) as e:
            raise AudioInputError(f"{directory / LABELS}: unreadable ({e}); build the bank again") from None
        missing = [u.file for u in utterances if not (directory / u.file).is_file()]
        if missing:
            raise AudioInputError(f"{directory}: speaker bank lacks {missing[:3]}; build it again")
        return cls(directory, manifest["voice"], manifest["seed"], manifest["sample_rate"], utterances)

    def get(self, utt_id: str) -> BankUtterance:
        try:
            return self._by_id[utt_id]
        except KeyError:
            raise KeyError(f"no utterance {utt_id!r} in the speaker bank {self.directory}") from None

    def audio(self, utt_id: str) -> np.ndarray:
        """The utterance's samples (mono float32 at `sample_rate`), read once."""
        if utt_id not in self._audio:
            import soundfile as sf

            x, sr = sf.read(str(self.directory / self.get(utt_id).file), dtype="float32")
            if sr != self.sample_rate or x.ndim != 1:
                raise AudioInputError(f"{self.directory / self.get(utt_id).file}: {sr} Hz, {x.ndim} dimension(s); "
                                      f"the bank says mono {self.sample_rate} Hz: build it again")
            self._audio[utt_id] = x
        return self._audio[utt_id]

    def pool(self, sign: int, include_calibration: bool = False, says: str = "sentences") -> list[BankUtterance]:
        """What the speaker says for `sign`: praise or reproach in sentences or single words (`says`), or fillers
        (neutral sentences only by pick)."""
        form = "filler" if sign == 0 else {"sentences": "sentence", "words": "word"}[says]
        return [u for u in self.utterances if u.sign == sign and u.form == form
                and (include_calibration or not u.calibration)]


def make_speaker_channel(ctx=None):
    """(commands, spoken): the queues between the learner and a `SpeakerSource`, from a spawn context
    (the listener is a spawned process). The learner puts commands and reads reports."""
    import multiprocessing as mp

    ctx = ctx or mp.get_context("spawn")
    return ctx.Queue(), ctx.Queue()


def check_command(cmd) -> str | None:
    """Why a command cannot be carried out as written (None when its form is fine)."""
    if not isinstance(cmd, dict):
        return f"a command is a dict with {sorted(COMMAND_KEYS)} or {END!r}, got {cmd!r}"
    extra = set(cmd) - COMMAND_KEYS
    if extra:
        return f"unknown command keys {sorted(extra)}; use {sorted(COMMAND_KEYS)}"
    if not isinstance(cmd.get("id"), int) or isinstance(cmd.get("id"), bool):
        return f"'id' must be an int, got {cmd.get('id')!r}"
    sign = cmd.get("sign")
    if isinstance(sign, bool) or sign not in (-1, 0, 1):
        return f"'sign' must be +1, -1 or 0, got {sign!r}"
    t = cmd.get("t")
    if t is not None and (isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t)):
        return f"'t' must be a finite wall-clock time or None, got {t!r}"
    if cmd.get("pick") is not None and not isinstance(cmd["pick"], str):
        return f"'pick' must be an utterance id (str) or None, got {cmd['pick']!r}"
    return None


class _Picker:
    """Per sign, the pool in a seeded shuffled order, reshuffled every round; never the same utterance
    twice in a row (a teacher varies their words)."""

    def __init__(self, pools: dict[int, list[BankUtterance]], seed: int):
        self.pools = pools
        self.rng = np.random.default_rng([int(seed), 1])
        self.order: dict[int, list[int]] = {s: [] for s in pools}
        self.last: dict[int, str | None] = {s: None for s in pools}

    def next(self, sign: int) -> BankUtterance:
        pool = self.pools[sign]
        if not self.order[sign]:
            order = [int(i) for i in self.rng.permutation(len(pool))]
            if len(order) > 1 and pool[order[0]].id == self.last[sign]:
                order.append(order.pop(0))
            self.order[sign] = order
        u = pool[self.order[sign].pop(0)]
        self.last[sign] = u.id
        return u


@dataclass
class _Play:
    cmd_id: int
    utt: BankUtterance
    audio: np.ndarray
    start: int             # sample (from the stream's first) where the file begins
    words: int             # sample where its words begin
    requested_t: float


class _Schedule:
    """What the speaker will say and when, in samples of the stream; the source paces and delivers it."""

    def __init__(self, bank: SpeakerBank, t0: float, sample_rate: int, chunk: int, gap_s: float, seed: int,
                 include_calibration: bool, says: str = "sentences"):
        self.bank = bank
        self.t0 = t0
        self.sr = sample_rate
        self.n = chunk
        self.gap = int(round(gap_s * sample_rate))
        self.include_calibration = include_calibration
        self.picker = _Picker({s: bank.pool(s, include_calibration, says) for s in (1, -1, 0)}, seed)
        self.plays: list[_Play] = []
        self.free_at = 0      # the first sample the next words may start at (after the last words + the pause)

    def _choose(self, cmd: dict) -> BankUtterance:
        sign = int(cmd["sign"])
        pick = cmd.get("pick")
        if pick is None:
            if not self.picker.pools[sign]:
                raise ValueError(f"the speaker bank has nothing of sign {sign:+d} to say")
            return self.picker.next(sign)
        try:
            u = self.bank.get(pick)
        except KeyError as e:
            raise ValueError(str(e.args[0])) from None
        if u.calibration and not self.include_calibration:
            raise ValueError(f"utterance {pick!r} is a calibration sentence; this speaker says test sentences "
                             f"only (include_calibration=True to allow it)")
        if u.sign != sign:
            raise ValueError(f"utterance {pick!r} ({u.kind}) has sign {u.sign:+d}, the command says {sign:+d}")
        return u

    def command(self, cmd: dict, now: float, next_chunk: int) -> _Play:
        """Schedule a checked command read at wall time `now` while chunk `next_chunk` is not yet delivered."""
        u = self._choose(cmd)
        lead = int(round(u.speech_start_s * self.sr))
        t = cmd.get("t")
        if t is not None and t >= now:
            words = int(round((t - self.t0) * self.sr))
        else:   # a moment already past: as soon as possible, from the chunk after the one being recorded now
            words = (int((now - self.t0) * self.sr) // self.n + 1) * self.n + lead
        # delivered chunks cannot change, and the speaker finishes what it is saying (then pauses) first
        start = max(words - lead, next_chunk * self.n, self.free_at - lead)
        play = _Play(int(cmd["id"]), u, self.bank.audio(u.id), start, start + lead, now if t is None else float(t))
        self.free_at = start + int(round(u.speech_end_s * self.sr)) + self.gap
        self.plays.append(play)
        return play

    def mix(self, i: int, out: np.ndarray) -> list[_Play]:
        """Add what is said during chunk `i` to `out`; return the plays whose words begin in it."""
        a, b = i * self.n, (i + 1) * self.n
        begun = []
        for p in self.plays:
            lo, hi = max(a, p.start), min(b, p.start + p.audio.size)
            if lo < hi:
                out[lo - a:hi - a] += p.audio[lo - p.start:hi - p.start]
            if a <= p.words < b:
                begun.append(p)
        self.plays = [p for p in self.plays if p.start + p.audio.size > b]
        return begun

    def report(self, p: _Play) -> dict:
        t_start = self.t0 + p.words / self.sr
        return {"id": p.cmd_id, "sign": p.utt.sign, "text": p.utt.text, "utterance": p.utt.id, "t_start": t_start,
                "t_end": self.t0 + p.start / self.sr + p.utt.speech_end_s,
                "requested_t": p.requested_t, "delay_s": t_start - p.requested_t}


class SpeakerSource(AudioSource):
    """A microphone in a room where a simulated teacher speaks when told to (see the module docstring).

    bank_dir: a folder `SpeakerBank.build` wrote (loaded in the process that plays); commands / spoken: the
    queues of `make_speaker_channel` (spoken may be None: no reports); noise_dbfs: white background noise
    (None: digital silence), seeded by `seed`, which also seeds the choice of utterances; include_calibration:
    also say the sentences `calibrate_speaker` fits on (by default a session hears only unseen sentences);
    gap_s: the pause after an utterance before the next one is said; says: what praise and reproach are said in,
    "sentences" (the test sentences) or "words" (`SPEAKER_WORDS`; a command's `pick` may name any utterance).
    """

    def __init__(self, bank_dir: str | Path, commands, spoken=None, sample_rate: int = 16000, chunk_s: float = 0.25,
                 noise_dbfs: float | None = DEFAULT_NOISE_DBFS, seed: int = 0, include_calibration: bool = False,
                 gap_s: float = GAP_S, says: str = "sentences"):
        if says not in SAYS:
            raise ValueError(f"says must be one of {', '.join(SAYS)}, got {says!r}")
        self.bank_dir = str(bank_dir)
        self.commands = commands
        self.spoken = spoken
        self.sample_rate = sample_rate
        self.chunk_s = chunk_s
        self.noise_dbfs = noise_dbfs
        self.seed = seed
        self.include_calibration = include_calibration
        self.gap_s = gap_s
        self.says = says
        self._stop = threading.Event()

    @classmethod
    def from_config(cls, config, bank_dir: str | Path, commands, spoken=None, **kw) -> "SpeakerSource":
        """Rate and chunk from the voice config's audio section, as the microphone would have them."""
        return cls(bank_dir, commands, spoken, config.audio.sample_rate, config.audio.chunk_s, **kw)

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_stop"] = None
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._stop = threading.Event()

    def _open_bank(self) -> SpeakerBank:
        bank = SpeakerBank.load(self.bank_dir)
        if bank.sample_rate != self.sample_rate:
            raise AudioInputError(f"speaker bank {self.bank_dir} is at {bank.sample_rate} Hz but the stream runs at "
                                  f"{self.sample_rate} Hz (audio.sample_rate); build a bank at {self.sample_rate} Hz")
        for u in bank.utterances:   # read every file now: no disk access inside the real-time loop
            bank.audio(u.id)
        return bank

    def _put_report(self, report: dict) -> None:
        if self.spoken is not None:
            self.spoken.put(report)

    def chunks(self) -> Iterator[tuple[float, np.ndarray]]:
        bank = self._open_bank()
        n, sr = self.chunk_samples, self.sample_rate
        noise = np.random.default_rng([int(self.seed), 0])
        sigma = None if self.noise_dbfs is None else 10 ** (self.noise_dbfs / 20)
        t0 = time.time()
        schedule = _Schedule(bank, t0, sr, n, self.gap_s, self.seed, self.include_calibration, self.says)
        i = 0
        while not self._stop.is_set():
            due = t0 + (i + 1) * n / sr
            # read commands while the chunk is being "recorded"; it is delivered once its last sample is due
            while True:
                if self._stop.is_set():
                    return
                wait = due - time.time()
                try:   # in short waits, so that stop() ends the stream without waiting for the chunk
                    cmd = self.commands.get(timeout=min(wait, 0.05)) if wait > 0 else self.commands.get_nowait()
                except queue_lib.Empty:
                    if time.time() < due:
                        continue
                    break
                except (EOFError, OSError, ValueError):   # the queue is closed or its sender is gone
                    return
                if cmd is None or cmd == END:
                    return
                problem = check_command(cmd)
                if problem is None:
                    try:
                        schedule.command(cmd, time.time(), i)
                    except ValueError as e:
                        problem = str(e)
                if problem is not None:
                    print(f"[speaker] command refused: {problem}", file=sys.stderr, flush=True)
                    self._put_report({"id": cmd.get("id") if isinstance(cmd, dict) else None, "error": problem})
            chunk = (noise.normal(0.0, sigma, n) if sigma is not None else np.zeros(n)).astype(np.float32)
            for p in schedule.mix(i, chunk):
                self._put_report(schedule.report(p))
            np.clip(chunk, -1.0, 1.0, out=chunk)
            yield t0 + i * n / sr, chunk
            i += 1

    def stop(self) -> None:
        self._stop.set()

    def close(self) -> None:
        self._stop.set()


def calibrate_speaker(bank: SpeakerBank | str | Path, voice_config, out_path: str | Path,
                      noise_dbfs: float | None = DEFAULT_NOISE_DBFS, seed: int = 0) -> dict:
    """Fit the bank voice's prosody calibration (`prosody.kind: features`) from its calibration sentences
    (praise, reproach, neutral sentences and fillers) and write it to `out_path` atomically; returns the record.

    Each sentence is heard as the listener will hear it in a session: in background noise at `noise_dbfs`
    (the source's default), cut to its VAD span (what `protamer calibrate --wav-dir` does with a recording).
    """
    from audio_frontend.calibration import feature_calibration, write_calibration
    from audio_frontend.labelled import utterance_of
    from audio_frontend.prosody_features import extract
    from audio_frontend.synth import with_silence

    bank = bank if isinstance(bank, SpeakerBank) else SpeakerBank.load(bank)
    sr = voice_config.audio.sample_rate
    if bank.sample_rate != sr:
        raise AudioInputError(f"speaker bank {bank.directory} is at {bank.sample_rate} Hz but audio.sample_rate is "
                              f"{sr} Hz; build a bank at {sr} Hz")
    p = voice_config.prosody
    rng = np.random.default_rng([int(seed), 2])
    samples = []
    for u in bank.utterances:
        if u.calibration:
            x = with_silence(bank.audio(u.id), 0.5, 0.75, sr, noise_dbfs=noise_dbfs, seed=int(rng.integers(1 << 31)))
            seg = utterance_of(x, voice_config).audio
            samples.append((_CALIBRATION_LABEL[u.tone], extract(seg, sr, p.pitch_floor_hz, p.pitch_ceiling_hz)))
    record = feature_calibration(samples, p)
    record.update(user=f"simulated speaker {bank.voice} (seed {bank.seed})", speaker_bank=str(bank.directory),
                  noise_dbfs=noise_dbfs)
    path = write_calibration(out_path, record)
    return {**record, "path": str(path)}
