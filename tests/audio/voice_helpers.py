"""Helpers shared by the voice front-end tests (imported as a plain module)."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

SR = 16000


def need_synth():
    from audio_frontend.synth import missing_tools
    missing = missing_tools()
    if missing:
        pytest.skip(f"needs {', '.join(missing)} (apt-get install espeak-ng sox); CI installs them")


def voice_config(*overrides):
    from audio_frontend.config import VoiceConfig
    from mjx_protamer.config import load_config
    return load_config(VoiceConfig, None, list(overrides))


def write_wav(path, x, sr=SR, subtype="PCM_16"):
    import soundfile as sf
    path.parent.mkdir(parents=True, exist_ok=True)
    sf.write(str(path), np.asarray(x), sr, subtype=subtype)
    return path


def has_espeak() -> bool:
    return shutil.which("espeak-ng") is not None and shutil.which("sox") is not None


def run_cli(*argv):
    """A voice command in this process; returns its exit code."""
    import argparse

    from mjx_protamer.commands import voice
    p = argparse.ArgumentParser()
    voice.register(p.add_subparsers())
    args = p.parse_args(list(argv))
    return args.handler(args)
