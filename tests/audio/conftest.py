"""Fixtures for the voice front end: tiny offline models and synthesised speech.

Models are randomly initialised and tiny (built in a few seconds, once per session) but go through the
real loading code and the real transformers pipelines. Their classifier heads are set by hand so their
output is known: the prosody model always prefers one label, the sentiment model always says POSITIVE.
"""

from __future__ import annotations

import json
import os
import shutil

import numpy as np
import pytest

SR = 16000
W2V_LABELS = ["neu", "hap", "ang", "sad"]


def _w2v(path, labels, favourite):
    import torch
    from transformers import Wav2Vec2Config, Wav2Vec2FeatureExtractor, Wav2Vec2ForSequenceClassification

    torch.manual_seed(0)
    cfg = Wav2Vec2Config(hidden_size=16, num_hidden_layers=1, num_attention_heads=2, intermediate_size=32,
                         conv_dim=(16, 16, 16), conv_kernel=(10, 3, 3), conv_stride=(5, 4, 4),
                         num_conv_pos_embeddings=16, num_conv_pos_embedding_groups=2, classifier_proj_size=8,
                         vocab_size=8, id2label=dict(enumerate(labels)),
                         label2id={v: i for i, v in enumerate(labels)})
    m = Wav2Vec2ForSequenceClassification(cfg)
    with torch.no_grad():
        m.classifier.weight.zero_()
        bias = torch.zeros(len(labels))
        bias[labels.index(favourite)] = 3.0
        m.classifier.bias.copy_(bias)
    m.save_pretrained(path)
    Wav2Vec2FeatureExtractor(feature_size=1, sampling_rate=SR, do_normalize=True,
                             return_attention_mask=True).save_pretrained(path)
    return str(path)


def _whisper(path):
    import torch
    from transformers import (GenerationConfig, WhisperConfig, WhisperFeatureExtractor,
                              WhisperForConditionalGeneration, WhisperProcessor, WhisperTokenizer)
    from transformers.convert_slow_tokenizer import bytes_to_unicode

    torch.manual_seed(0)
    os.makedirs(path / "tok", exist_ok=True)
    # a byte-level BPE with no merges: every byte is a token, plus Whisper's special tokens
    vocab = {c: i for i, c in enumerate(bytes_to_unicode().values())}
    (path / "tok" / "vocab.json").write_text(json.dumps(vocab))
    (path / "tok" / "merges.txt").write_text("#version: 0.2\n")
    eot = "<|endoftext|>"
    tok = WhisperTokenizer(str(path / "tok" / "vocab.json"), str(path / "tok" / "merges.txt"), unk_token=eot,
                           bos_token=eot, eos_token=eot, pad_token=eot)
    specials = ["<|startoftranscript|>", "<|en|>", "<|transcribe|>", "<|translate|>", "<|startoflm|>",
                "<|startofprev|>", "<|nocaptions|>", "<|notimestamps|>"]
    tok.add_special_tokens({"additional_special_tokens": specials})
    ids = dict(zip(specials, tok.convert_tokens_to_ids(specials)))
    eot_id = tok.convert_tokens_to_ids(eot)
    cfg = WhisperConfig(vocab_size=len(tok), num_mel_bins=80, encoder_layers=1, decoder_layers=1, d_model=16,
                        encoder_attention_heads=2, decoder_attention_heads=2, encoder_ffn_dim=32,
                        decoder_ffn_dim=32, max_source_positions=1500, max_target_positions=64,
                        decoder_start_token_id=ids["<|startoftranscript|>"], eos_token_id=eot_id,
                        pad_token_id=eot_id, bos_token_id=eot_id, suppress_tokens=[], begin_suppress_tokens=[])
    m = WhisperForConditionalGeneration(cfg)
    gc = GenerationConfig.from_model_config(cfg)
    gc.no_timestamps_token_id = ids["<|notimestamps|>"]
    gc.is_multilingual = False
    gc.max_length = 64
    m.generation_config = gc
    out = path / "model"
    m.save_pretrained(out)
    WhisperProcessor(feature_extractor=WhisperFeatureExtractor(feature_size=80), tokenizer=tok).save_pretrained(out)
    return str(out)


def _distilbert(path):
    import torch
    from transformers import DistilBertConfig, DistilBertForSequenceClassification, DistilBertTokenizer

    torch.manual_seed(0)
    os.makedirs(path, exist_ok=True)
    words = ["[PAD]", "[UNK]", "[CLS]", "[SEP]", "[MASK]"] + \
        "the robot baby is doing very well good bad that was not nice touch your hand".split()
    (path / "vocab.txt").write_text("\n".join(words) + "\n")
    DistilBertTokenizer(str(path / "vocab.txt")).save_pretrained(path)
    cfg = DistilBertConfig(vocab_size=len(words), dim=16, n_layers=1, n_heads=2, hidden_dim=32,
                           max_position_embeddings=64, id2label={0: "NEGATIVE", 1: "POSITIVE"},
                           label2id={"NEGATIVE": 0, "POSITIVE": 1})
    m = DistilBertForSequenceClassification(cfg)
    with torch.no_grad():   # always POSITIVE, so a test can tell the rules from the classifier
        m.classifier.weight.zero_()
        m.classifier.bias.copy_(torch.tensor([0.0, 3.0]))
    m.save_pretrained(path)
    return str(path)


@pytest.fixture(scope="session")
def tiny_models(tmp_path_factory):
    pytest.importorskip("torch")
    pytest.importorskip("transformers")
    root = tmp_path_factory.mktemp("tiny_models")
    return {
        "prosody_hap": _w2v(root / "w2v_hap", W2V_LABELS, "hap"),
        # label order differs and 'ang' is the favourite: valence must come out negative
        "prosody_ang_permuted": _w2v(root / "w2v_ang", ["ang", "sad", "hap", "neu"], "ang"),
        "whisper": _whisper(root / "whisper"),
        "sentiment": _distilbert(root / "distilbert"),
    }


@pytest.fixture(scope="session")
def speech():
    """Synthesised utterances (16 kHz mono float32), made once."""
    from voice_helpers import need_synth

    need_synth()
    from audio_frontend.synth import synthesize
    return {
        "good job": synthesize("good job", "positive"),
        "yes": synthesize("yes", "neutral"),
        "no": synthesize("no", "angry"),
        "bad": synthesize("bad", "angry", speed=120),
        "hmm": synthesize("hmm", "filler"),
    }


@pytest.fixture(scope="session")
def small_set(tmp_path_factory):
    """A small `protamer synth-voice` set: two voices, three sentences per tone and kind (made once)."""
    from voice_helpers import need_synth

    need_synth()
    pytest.importorskip("parselmouth")
    from audio_frontend.testset import make_test_set

    root = tmp_path_factory.mktemp("synth_voice")
    make_test_set(root, speakers=("en-us", "en-gb+f2"), max_per_group=3)
    return root
