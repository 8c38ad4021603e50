"""Calibration: tau = median |valence|, refusals with reasons, atomic file, missing calibration."""

import json
import os

import pytest

from audio_frontend.calibration import compute_tau, load_calibration, resolve_tau, write_calibration
from audio_frontend.errors import CalibrationError
from voice_helpers import voice_config


def samples(pos, neg):
    return [("pos", v) for v in pos] + [("neg", v) for v in neg]


def test_tau_is_median_abs_valence():
    rec = compute_tau(samples([0.4, 0.2, 0.6], [-0.1, -0.3, 0.05]))
    assert rec["tau"] == pytest.approx(0.25)       # median of 0.05 0.1 0.2 0.3 0.4 0.6
    assert rec["n_pos"] == 3 and rec["n_neg"] == 3
    assert rec["sign_accuracy"] == pytest.approx(5 / 6)


def test_refusals_say_why():
    with pytest.raises(CalibrationError, match="too few samples: 2 positive and 3 negative"):
        compute_tau(samples([0.4, 0.2], [-0.1, -0.3, -0.2]))
    with pytest.raises(CalibrationError, match="tau = median"):
        compute_tau(samples([0.0, 0.0, 1e-5], [0.0, -1e-5, 0.0]))
    with pytest.raises(CalibrationError, match="all 6 samples have positive valence"):
        compute_tau(samples([0.4, 0.2, 0.6], [0.1, 0.3, 0.05]))
    with pytest.raises(CalibrationError, match="unusable"):
        compute_tau(samples([float("nan"), 0.2, 0.6], [-0.1, -0.3, -0.05]))


def test_write_is_atomic_and_round_trips(tmp_path):
    path = tmp_path / "cal" / "user.json"
    rec = compute_tau(samples([0.4, 0.2, 0.6], [-0.1, -0.3, -0.5]))
    write_calibration(path, rec)
    assert load_calibration(path)["tau"] == pytest.approx(rec["tau"])
    # a failed write (not JSON-able) leaves the previous file intact and no temporary files behind
    with pytest.raises(ValueError):
        write_calibration(path, {"tau": float("nan")})
    assert json.loads(path.read_text())["tau"] == pytest.approx(rec["tau"])
    assert os.listdir(path.parent) == ["user.json"]


def test_missing_or_bad_calibration(tmp_path):
    with pytest.raises(CalibrationError, match="no prosody calibration.*protamer calibrate"):
        load_calibration(tmp_path / "none.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(CalibrationError, match="unreadable"):
        load_calibration(bad)
    bad.write_text(json.dumps({"tau": 0}))
    with pytest.raises(CalibrationError, match="tau=0"):
        load_calibration(bad)


def test_resolve_tau_prefers_config_then_file(tmp_path):
    path = tmp_path / "c.json"
    write_calibration(path, {"tau": 0.3})
    assert resolve_tau(voice_config(f"prosody.calibration_path={path}").prosody)[0] == pytest.approx(0.3)
    assert resolve_tau(voice_config(f"prosody.calibration_path={path}", "prosody.tau=0.7").prosody)[0] == 0.7


@pytest.mark.parametrize("tau,why", [(1e-30, "outside"), (1e308, "outside"), (True, "must be a number"),
                                     ("0.5", "must be a number"), (None, "must be a number"), (2.0, "outside")])
def test_loading_applies_the_bounds_calibrate_writes_with(tmp_path, tau, why):
    path = tmp_path / "c.json"
    path.write_text(json.dumps({"tau": tau}))
    with pytest.raises(CalibrationError, match=f"{why}.*protamer calibrate"):
        load_calibration(path)
    path.write_text('{"tau": NaN}')
    with pytest.raises(CalibrationError, match="not finite"):
        load_calibration(path)
    path.write_text("[0.5]")
    with pytest.raises(CalibrationError, match="no 'tau'"):
        load_calibration(path)


def test_config_tau_has_the_same_bounds():
    from mjx_protamer.config import ConfigError

    assert voice_config("prosody.tau=1").prosody.tau == 1
    with pytest.raises(ConfigError, match="prosody.tau.*outside"):
        voice_config("prosody.tau=0.00001")
    with pytest.raises(ConfigError, match="prosody.tau.*outside"):
        voice_config("prosody.tau=5")
