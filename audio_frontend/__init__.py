"""The voice front end: microphone / WAV / array sources, VAD, prosody and Whisper scorers, host process.

Runs as a host process beside the learner and never imports JAX. Heavy dependencies (torch,
transformers, faster-whisper, sounddevice) are imported inside the functions that need them.
Entry point for the learner: `audio_frontend.listen.start_listener(queue, config, scorer, source)`.
"""

__all__ = ["config", "errors", "sources", "vad", "rules", "calibration", "models", "scorers", "listen", "bench",
           "sentiment", "prosody_features", "prosody_model", "preflight", "labelled", "report", "synth", "testset",
           "validation", "vad_compare"]
