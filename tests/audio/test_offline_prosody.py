"""The offline prosody scorer: Praat features, per-speaker calibration, the calibration file, the CLI."""

import json
import shutil

import numpy as np
import pytest

from audio_frontend.errors import CalibrationError
from voice_helpers import run_cli, voice_config


def test_synth_set_layout_labels_tone_and_words(small_set):
    rows = [json.loads(line) for line in (small_set / "en-us" / "test" / "labels.jsonl").read_text().splitlines()]
    assert {r["kind"] for r in rows} == {"congruent", "against", "neutral", "filler"}
    for r in rows:
        assert (small_set / "en-us" / "test" / r["file"]).is_file()
        assert r["file"].split("/")[0] == r["tone"]                     # folders are by tone
        if r["kind"] == "against":
            assert {r["tone"], r["words"]} == {"pos", "neg"}            # words said in the opposite tone
    calib = (small_set / "en-us" / "calib" / "labels.jsonl").read_text()
    test = {r["text"] for r in rows}
    assert not test & {json.loads(line)["text"] for line in calib.splitlines()}   # unseen sentences


def test_synth_voice_probe_split_holds_one_word_keywords_in_both_tones_and_fillers(tmp_path):
    """`synth-voice --probe`: per speaker a probe/ split, labelled by words, of single keywords said in
    both tones (which a filler gate must leave signed) and fillers in two styles (which must give 0)."""
    from voice_helpers import need_synth

    from audio_frontend.labelled import find_labelled
    from audio_frontend.testset import PROBE_FILLERS, PROBE_ONE_WORD, make_test_set, plan_probe

    cfg = voice_config().sentiment
    rows = plan_probe()
    for words, keywords, label in ((PROBE_ONE_WORD[0], cfg.affirmative, "pos"),
                                   (PROBE_ONE_WORD[1], cfg.negative, "neg")):
        assert set(words) <= set(keywords)
        for w in words:
            assert {(r["tone"], r["words"], r["kind"]) for r in rows if r["text"] == w} == {
                ("pos", label, "one_word"), ("neg", label, "one_word")}
    assert set(PROBE_FILLERS) <= set(cfg.fillers)
    assert {(r["text"], r["tone"]) for r in rows if r["kind"] == "filler"} == {
        (w, t) for w in PROBE_FILLERS for t in ("fillers", "neu")}
    need_synth()
    counts = make_test_set(tmp_path, speakers=("en-us",), max_per_group=1, probe=True)
    assert counts["one_word"] == 2                       # max_per_group: one per tone
    probe = tmp_path / "en-us" / "probe"
    labels = sorted(find_labelled(probe, "words")[0])
    assert sorted(lab for _, lab in labels) == ["filler", "filler", "pos", "pos"]
    assert all(p.is_file() for p, _ in labels)
    assert json.loads((tmp_path / "synth_voice.json").read_text())["probe"] is True


def test_synthesised_fillers_are_one_syllable_not_spelled_letters():
    """espeak-ng reads "mm" as the letter names "em-em" (,Em'Em) and "hm" as "aitch-em": the set says
    those with phonemes, so each filler is one syllable at most (no secondary stress, one stress mark)."""
    import subprocess

    from voice_helpers import need_synth

    need_synth()
    from audio_frontend.testset import FILLERS, PROBE_FILLERS, SAID_AS

    def phonemes(text):
        return subprocess.run(["espeak-ng", "-q", "-x", "-v", "en-us", text], capture_output=True, text=True,
                              check=True).stdout.strip()
    assert "," in phonemes("mm") and "," in phonemes("hm")          # what espeak makes of them unaided
    for word in sorted(set(FILLERS[0] + FILLERS[1] + PROBE_FILLERS)):
        said = phonemes(SAID_AS.get(word, word))
        assert "," not in said and said.count("'") <= 1, (word, said)


def test_synthesised_hesitation_vowels_hold_one_vowel_in_every_voice():
    """The phoneme check above cannot see a glide: en-gb-scotland's "er" is one stressed phoneme ('3:) that
    it says as [e]->[ɐ], "yeah" without the [j] (F2 falls ~190 Hz in the filler style, ~370 Hz neutral).
    The set's hesitation vowels must hold one vowel (F2 of the last third of the voiced part within 100 Hz
    of the first third; steady vowels measure 0-40 Hz) in every voice, in both styles fillers are said in."""
    from voice_helpers import SR, need_synth

    need_synth()
    parselmouth = pytest.importorskip("parselmouth")
    from audio_frontend.synth import synthesize
    from audio_frontend.testset import SAID_AS, SPEAKERS, TONE_STYLE

    def f2_drift(x, female):
        snd = parselmouth.Sound(x.astype(np.float64), SR)
        pitch = snd.to_pitch(time_step=0.01)
        voiced = pitch.xs()[pitch.selected_array["frequency"] > 0]
        # Praat's rule of thumb: formant ceiling 5000 Hz for a male voice, 5500 Hz for a female one
        formants = snd.to_formant_burg(time_step=0.01, max_number_of_formants=5,
                                       maximum_formant=5500 if female else 5000)
        f2 = np.array([formants.get_value_at_time(2, t) for t in voiced])
        third = len(f2) // 3
        assert third >= 5, "too short to measure"
        return abs(np.nanmedian(f2[-third:]) - np.nanmedian(f2[:third]))

    glide = f2_drift(synthesize("er", "neutral", SR, voice="en-gb-scotland+m7"), female=False)
    assert glide > 200, glide                                     # what the measure is for
    for word in ("uh", "er"):
        for voice in SPEAKERS:
            for style in (TONE_STYLE["fillers"], TONE_STYLE["neu"]):
                drift = f2_drift(synthesize(SAID_AS.get(word, word), style, SR, voice=voice), "+f" in voice)
                assert drift < 100, (word, voice, style, drift)


def test_per_speaker_calibration_hears_tone_on_unseen_sentences(small_set):
    from audio_frontend.labelled import find_labelled, load_labelled
    from audio_frontend.scorers import FeatureProsodyScorer
    from audio_frontend.validation import calibrate_speaker, kinds_of

    cfg = voice_config()
    right, total, zeros_unsigned, unsigned, against = 0, 0, 0, 0, 0
    for speaker in ("en-us", "en-gb_f2"):
        record = calibrate_speaker(cfg, small_set / speaker / "calib")
        assert record["kind"] == "features" and 0.001 <= record["tau"] <= 1.0
        scorer = FeatureProsodyScorer(cfg, calibration=record)
        test = small_set / speaker / "test"
        kinds = kinds_of(test)
        files, _ = find_labelled(test, "tone")
        for path, lab, utt in load_labelled(files, cfg):
            value, d = scorer.score(utt.audio)
            assert d["probs"].keys() == {"neg", "neu", "pos"} and -1.0 <= value <= 1.0
            if lab in ("pos", "neg"):
                total += 1
                right += (value > 0) == (lab == "pos") and value != 0
            else:
                unsigned += 1
                zeros_unsigned += value == 0.0
            against += kinds[str(path)] == "against"
    # 24 signed test utterances (12 said against their words) from two voices: tone decides
    assert total == 24 and against == 12 and right / total >= 0.85
    assert zeros_unsigned / unsigned >= 0.6     # neutral speech and fillers mostly give no feedback


def test_without_neutral_samples_the_feature_calibration_is_refused(small_set, tmp_path, capsys):
    calib = tmp_path / "calib"
    shutil.copytree(small_set / "en-us" / "calib", calib)
    (calib / "labels.jsonl").unlink()
    shutil.rmtree(calib / "neu")
    shutil.rmtree(calib / "fillers")
    out = tmp_path / "cal.json"
    assert run_cli("calibrate", "--wav-dir", str(calib), "--out", str(out)) == 6
    err = capsys.readouterr().err
    assert "0 neutral" in err and "neu/" in err and not out.exists()


def test_calibrate_then_validate_voice_with_the_cli(small_set, tmp_path, capsys):
    cal = tmp_path / "cal.json"
    assert run_cli("calibrate", "--wav-dir", str(small_set / "en-us" / "calib"), "--out", str(cal), "--json") == 0
    rec = json.loads(capsys.readouterr().out)
    stored = json.loads(cal.read_text())
    assert stored["kind"] == "features" and stored["n_neu"] == 5 and stored["tau"] == pytest.approx(rec["tau"])
    assert len(stored["prosody_model"]["coef"]) == 3
    out = tmp_path / "v.json"
    rc = run_cli("validate-voice", str(small_set / "en-us" / "test"), "--json", "--out", str(out),
                 "--set", f"prosody.calibration_path={cal}")
    assert rc == 0
    res = json.loads(capsys.readouterr().out)
    assert json.loads(out.read_text())["sign_accuracy"] == res["sign_accuracy"] >= 0.8
    assert set(res["outcome_counts"]) == {"pos", "neg", "neu", "filler"}
    assert res["by_kind"]["against"]["n"] == 6
    ch = res["channel"]
    assert sum(ch["outcome_rates"]["pos"].values()) == pytest.approx(1.0)
    assert ch["event_latency_s"]["median"] >= ch["vad_wait_s"]["median"] > 0
    assert 0.2 < ch["utterance_s"]["median"] < 3.0


def test_per_speaker_validation_writes_the_channel_model(small_set, tmp_path, capsys):
    out = tmp_path / "channels.json"
    assert run_cli("validate-voice", str(small_set), "--per-speaker", "--scorer", "prosody", "--out", str(out)) == 0
    res = json.loads(out.read_text())
    assert res["speakers"] == ["en-gb_f2", "en-us"] and set(res["per_speaker"]["en-us"]) == {"prosody"}
    ch = res["channels"]["prosody"]
    assert ch["n_signed"] == 24 and ch["sign_accuracy"] >= 0.85
    assert "not real recordings" in res["source"]["note"]
    assert run_cli("validate-voice", str(small_set / "en-us"), "--per-speaker") == 3
    assert "no speaker folders" in capsys.readouterr().err


def test_feature_scorer_needs_its_own_calibration(tmp_path):
    from audio_frontend.calibration import write_calibration
    from audio_frontend.scorers import FeatureProsodyScorer, make_scorer

    cfg = voice_config(f"prosody.calibration_path={tmp_path / 'none.json'}")
    with pytest.raises(CalibrationError, match="protamer calibrate"):
        make_scorer(cfg, "prosody", need_tau=False)
    write_calibration(tmp_path / "w2v.json", {"tau": 0.3})        # a wav2vec2 (tau-only) calibration
    with pytest.raises(CalibrationError, match="is a wav2vec2 calibration"):
        FeatureProsodyScorer(voice_config(f"prosody.calibration_path={tmp_path / 'w2v.json'}"))
    write_calibration(tmp_path / "bad.json", {"tau": 0.3, "kind": "features",
                                              "prosody_model": {"features": ["f0"], "classes": ["neg", "neu", "pos"]}})
    with pytest.raises(CalibrationError, match="prosody_model is unusable"):
        FeatureProsodyScorer(voice_config(f"prosody.calibration_path={tmp_path / 'bad.json'}"))


def test_features_are_finite_on_speech_and_nan_without_voice():
    from audio_frontend.prosody_features import FEATURES, extract

    sr = 16000
    t = np.arange(sr) / sr
    vowel = (0.3 * np.sin(2 * np.pi * 150 * t) * (1 + 0.2 * np.sin(2 * np.pi * 3 * t))).astype(np.float32)
    f = extract(vowel, sr)
    assert set(f) == set(FEATURES) and all(np.isfinite(v) for v in f.values())
    assert f["f0_median_st"] == pytest.approx(12 * np.log2(150 / 100), abs=0.3)   # 150 Hz in semitones re 100 Hz
    noise = np.random.default_rng(0).normal(0, 0.1, sr).astype(np.float32)
    g = extract(noise, sr)
    assert np.isnan(g["f0_median_st"]) and np.isfinite(g["intensity_db"])
    assert all(np.isnan(v) for v in extract(np.zeros(sr, np.float32), sr).values())


def test_listen_uncalibrated_is_refused_for_the_feature_scorer(small_set, capsys):
    wav = next((small_set / "en-us" / "test" / "pos").glob("*.wav"))
    assert run_cli("listen", "--wav", str(wav), "--uncalibrated") == 6
    assert "prosody.kind=wav2vec2 only" in capsys.readouterr().err
