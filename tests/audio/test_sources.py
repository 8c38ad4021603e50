"""Audio sources and WAV input: every bad input gives a clear result or error."""

import sys
import types
import warnings

import numpy as np
import pytest

from audio_frontend.errors import AudioDeviceError, AudioInputError
from audio_frontend.sources import ArraySource, MicSource, WavSource, check_input_device, dbfs, load_wav
from voice_helpers import SR, write_wav


def tone(freq, seconds, sr=SR, amp=0.3):
    t = np.arange(int(seconds * sr)) / sr
    return (amp * np.sin(2 * np.pi * freq * t)).astype(np.float32)


def peak_freq(x, sr=SR):
    spec = np.abs(np.fft.rfft(x))
    return np.fft.rfftfreq(x.size, 1 / sr)[np.argmax(spec)]


def test_dbfs_of_known_levels():
    assert dbfs(np.zeros(100)) == float("-inf")
    assert abs(dbfs(np.full(100, 0.1)) - (-20.0)) < 1e-6


def test_wrong_rate_is_resampled_or_refused(tmp_path):
    p = write_wav(tmp_path / "a.wav", tone(440, 1.0, 8000), 8000)
    x = load_wav(p, SR)
    assert abs(x.size - SR) <= 2
    assert abs(peak_freq(x) - 440) < 3
    with pytest.raises(AudioInputError, match="8000 Hz.*16000 Hz is required"):
        load_wav(p, SR, on_wrong_rate="refuse")


def test_stereo_is_averaged_or_refused(tmp_path):
    left, right = tone(440, 0.5), np.zeros(SR // 2, np.float32)
    p = write_wav(tmp_path / "s.wav", np.stack([left, right], axis=1))
    x = load_wav(p, SR)
    assert x.ndim == 1 and np.allclose(x, left / 2, atol=1e-3)
    with pytest.raises(AudioInputError, match="2 channels; mono is required"):
        load_wav(p, SR, on_multichannel="refuse")


def test_empty_corrupt_and_missing_files(tmp_path):
    empty = tmp_path / "empty.wav"
    empty.write_bytes(b"")
    with pytest.raises(AudioInputError, match="empty"):
        load_wav(empty)
    no_samples = write_wav(tmp_path / "nos.wav", np.zeros(0, np.float32))
    with pytest.raises(AudioInputError, match="no samples"):
        load_wav(no_samples)
    corrupt = tmp_path / "corrupt.wav"
    corrupt.write_bytes(b"RIFF" + bytes(range(200)))
    with pytest.raises(AudioInputError, match="not a readable sound file"):
        load_wav(corrupt)
    with pytest.raises(AudioInputError, match="no such file"):
        load_wav(tmp_path / "missing.wav")


def test_silent_and_clipped_files(tmp_path):
    silent = write_wav(tmp_path / "silent.wav", np.zeros(SR, np.float32))
    assert load_wav(silent).size == SR        # allowed by default (a stream may be silent)
    with pytest.raises(AudioInputError, match="silent"):
        load_wav(silent, allow_silent=False)
    clipped = write_wav(tmp_path / "clip.wav", np.clip(tone(200, 1.0, amp=3.0), -1, 1))
    with pytest.warns(UserWarning, match="clipped"):
        load_wav(clipped)
    with pytest.raises(AudioInputError, match="clipped"):
        load_wav(clipped, on_clipped="refuse")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_wav(write_wav(tmp_path / "ok.wav", tone(200, 1.0)))   # a normal file warns nothing


def test_array_source_chunks_times_and_padding():
    x = np.arange(int(SR * 0.6), dtype=np.float32) / SR / 10
    chunks = list(ArraySource(x, SR, 0.25, t0=100.0).chunks())
    assert [round(t, 6) for t, _ in chunks] == [100.0, 100.25, 100.5]
    assert all(c.size == SR // 4 for _, c in chunks)
    assert np.array_equal(np.concatenate([c for _, c in chunks])[: x.size], x)
    assert not np.any(chunks[-1][1][int(0.1 * SR):])   # the last chunk is zero-padded
    with pytest.raises(AudioInputError, match="1-D mono"):
        ArraySource(np.zeros((10, 2)))
    with pytest.raises(AudioInputError, match="NaN"):
        ArraySource(np.array([0.0, np.nan]))


def test_wav_source_is_lazy_and_picklable(tmp_path):
    import pickle
    p = write_wav(tmp_path / "a.wav", tone(300, 0.5))
    src = pickle.loads(pickle.dumps(WavSource(p)))
    assert sum(c.size for _, c in src.chunks()) == SR // 2
    bad = WavSource(tmp_path / "nothere.wav")      # constructing does not read
    with pytest.raises(AudioInputError):
        list(bad.chunks())


def test_import_sounddevice_oserror_becomes_clear_message(monkeypatch):
    import builtins

    import audio_frontend.sources as s
    real_import = builtins.__import__

    def fake_import(name, *a, **k):
        if name == "sounddevice":
            raise OSError("PortAudio library not found")
        return real_import(name, *a, **k)
    monkeypatch.delitem(sys.modules, "sounddevice", raising=False)
    monkeypatch.setattr(builtins, "__import__", fake_import)
    with pytest.raises(AudioDeviceError, match="apt-get install libportaudio2"):
        s.import_sounddevice()


def test_no_input_device_is_a_clear_error(monkeypatch):
    fake = types.SimpleNamespace(
        query_devices=lambda *a, **k: (_ for _ in ()).throw(ValueError("No input device matching"))
        if a or k else [{"name": "hdmi", "max_input_channels": 0}])
    import audio_frontend.sources as s
    monkeypatch.setattr(s, "import_sounddevice", lambda: fake)
    with pytest.raises(AudioDeviceError, match="no usable audio input device.*found 0 input"):
        check_input_device()


def test_a_wav_cut_short_is_reported_as_truncated(tmp_path, capsys):
    from voice_helpers import run_cli

    whole = write_wav(tmp_path / "whole.wav", tone(300, 2.0))
    data = whole.read_bytes()
    cut = tmp_path / "cut.wav"
    cut.write_bytes(data[: len(data) // 3])            # the header still says 2 s
    with pytest.raises(AudioInputError, match=r"cut.wav: truncated: its header declares 2.00 s .* holds 0.6"):
        load_wav(cut)
    header_only = tmp_path / "header.wav"
    header_only.write_bytes(data[:44])
    with pytest.raises(AudioInputError, match="truncated.*holds 0.00 s"):
        load_wav(header_only)
    assert load_wav(whole).size == 2 * SR                # a complete file is untouched
    assert run_cli("listen", "--wav", str(cut), "--set", "prosody.tau=0.5") == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "truncated" in err[0]
