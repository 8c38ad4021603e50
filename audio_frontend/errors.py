"""Errors of the voice front end; each message says what went wrong and how to fix it."""

from __future__ import annotations


class VoiceError(RuntimeError):
    """Base class. `exit_code` is what the CLI and the listener process exit with."""

    exit_code = 1


class AudioInputError(VoiceError):
    """A WAV file or array that cannot be used (empty, corrupt, wrong rate when refused, ...)."""

    exit_code = 3


class AudioDeviceError(VoiceError):
    """No PortAudio library, no input device, or the device refused to open."""

    exit_code = 4


class MissingWeightsError(VoiceError):
    """A model's weights are neither on disk nor downloadable; the message names what is expected."""

    exit_code = 5


class CalibrationError(VoiceError):
    """A calibration that is missing, unreadable or cannot work (too few samples, tau 0, one sign)."""

    exit_code = 6


EXIT_CODES = {cls.exit_code: cls.__name__ for cls in (AudioInputError, AudioDeviceError, MissingWeightsError,
                                                         CalibrationError)}


def describe_exit(exitcode: int | None) -> str:
    """A line for the learner when the listener process is gone (`proc.exitcode`)."""
    if exitcode is None:
        return "voice listener is running"
    if exitcode == 0:
        return "voice listener stopped normally"
    if exitcode < 0:
        return f"voice listener was killed by signal {-exitcode}"
    name = EXIT_CODES.get(exitcode, "an unexpected error")
    return f"voice listener died with exit code {exitcode} ({name}; see its stderr)"
