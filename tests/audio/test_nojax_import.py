"""The voice front end is a host process beside the learner: importing it must not import JAX."""

import json
import subprocess
import sys

CODE = r"""
import sys, json, argparse, importlib
mods = ["audio_frontend", "audio_frontend.config", "audio_frontend.errors", "audio_frontend.sources",
        "audio_frontend.vad", "audio_frontend.rules", "audio_frontend.calibration", "audio_frontend.models",
        "audio_frontend.scorers", "audio_frontend.listen", "audio_frontend.labelled", "audio_frontend.report",
        "audio_frontend.synth", "audio_frontend.bench", "audio_frontend.sentiment", "audio_frontend.prosody_features",
        "audio_frontend.prosody_model", "audio_frontend.preflight", "audio_frontend.testset",
        "audio_frontend.validation", "audio_frontend.vad_compare", "mjx_protamer.commands.voice"]
for m in mods:
    importlib.import_module(m)
p = argparse.ArgumentParser(); sub = p.add_subparsers()
importlib.import_module("mjx_protamer.commands.voice").register(sub)
print(json.dumps({k: k in sys.modules for k in ("jax", "jaxlib", "torch", "transformers", "faster_whisper",
                                               "sounddevice", "sklearn", "parselmouth", "silero_vad")}))
"""


def test_front_end_imports_without_jax_or_heavy_libraries():
    out = subprocess.run([sys.executable, "-c", CODE], capture_output=True, text=True, check=True)
    loaded = json.loads(out.stdout.strip().splitlines()[-1])
    assert not loaded["jax"] and not loaded["jaxlib"], "the voice front end must never import JAX"
    # heavy dependencies are imported inside the functions that need them
    assert not any(loaded[k] for k in ("torch", "transformers", "faster_whisper", "sounddevice", "sklearn",
                                       "parselmouth", "silero_vad")), loaded


def test_voice_commands_are_registered_in_the_cli():
    from mjx_protamer import cli
    assert "mjx_protamer.commands.voice" in cli.COMMAND_MODULES
