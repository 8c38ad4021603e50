"""Command-line numbers checked like config values: finite, within a range, whole where they count something,
a seed a uint32. Every command checks its numbers with these before it loads anything; a bad one is a
ConfigError (one line, exit 2).

The parsers give these flags as strings (argparse `type=str`), so `nan`, `1e12`, `-5`, `2^64 + 1` or a number of
5,000 digits all reach the same one-line refusal instead of argparse's usage block or an OverflowError later.
Pure Python (no JAX): the voice commands use it too.
"""

from __future__ import annotations

import math

from mjx_protamer.config import SEED_MAX, ConfigError


def number(name: str, value, lo: float, hi: float, integer: bool = False):
    """A command-line number checked like a config value: finite and within [lo, hi] (whole with `integer`)."""
    try:
        x = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ConfigError(f"{name} must be a number, got {_shown(value)}") from None
    if not math.isfinite(x) or not lo <= x <= hi or (integer and x != int(x)):
        kind = "a whole number" if integer else "a number"
        raise ConfigError(f"{name} must be {kind} within {lo:g}..{hi:g}, got {_shown(value)}")
    return int(x) if integer else x


def seed(name: str, value):
    """A seed from the command line: a whole number in 0..2^32-1 (None stays None: the run's own seed)."""
    if value is None:
        return None
    try:
        x = number(name, value, 0, SEED_MAX, integer=True)
    except ConfigError:
        raise ConfigError(f"{name} must be a seed, a whole number within 0..2^32-1, got {_shown(value)}") from None
    return x


def _shown(value) -> str:
    """The value as given, shortened: a 5,000-digit number is not echoed whole."""
    text = repr(value)
    return text if len(text) <= 40 else f"{text[:20]}...{text[-8:]} ({len(text)} characters)"


def port(name: str, value) -> int:
    """A TCP port from the command line: a whole number within 1..65535."""
    return number(name, value, 1, 65535, integer=True)


def address(name: str, value) -> str:
    """HOST:PORT from the command line (an IPv6 host in brackets: [::1]:1234); the port checked like `port`."""
    host, sep, text = str(value).rpartition(":")
    if not sep or not host or (host.startswith("[") != host.endswith("]")):
        raise ConfigError(f"{name} must be HOST:PORT, e.g. 10.0.0.1:1234, got {_shown(value)}")
    port(f"{name}'s port", text)
    return str(value)
