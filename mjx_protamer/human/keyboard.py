"""Keyboard feedback: + / - / 0 read live from the terminal in a host thread, each press confirmed.

`KeyboardFeedback(queue).start()` puts the terminal (stdin, or any tty `stream`) in cbreak mode (single keys, no Enter) and reads
keys in a daemon thread: '+' (or '=') -> +1, '-' -> -1, '0' -> 0; every press becomes a
FeedbackEvent(source="keyboard", t_start = t_end = the wall-clock time of the press) put into the
FeedbackQueue, and a confirmation line is printed at once ("[feedback] +1 accepted" or the reason it
was refused). 'q' asks the learner to stop (`stop_requested`). `stop()` restores the terminal.
Pure Python (no JAX). `parse_key` and `handle_key` are separate so tests need no terminal.
"""

from __future__ import annotations

import sys
import threading
import time
from typing import Callable, TextIO

from mjx_protamer.human.events import FeedbackEvent

KEY_VALUES = {"+": 1.0, "=": 1.0, "-": -1.0, "_": -1.0, "0": 0.0}


def parse_key(ch: str) -> float | None:
    """The feedback value of a key, or None for any other key."""
    return KEY_VALUES.get(ch)


class KeyboardFeedback:
    def __init__(self, queue, stream: TextIO | None = None, out: TextIO | None = None,
                 clock: Callable[[], float] = time.time):
        self.queue = queue
        self.stream = stream if stream is not None else sys.stdin
        self.out = out if out is not None else sys.stdout
        self.clock = clock
        self.stop_requested = threading.Event()
        self.presses = 0
        self._thread: threading.Thread | None = None
        self._saved_tty = None

    def handle_key(self, ch: str) -> bool | None:
        """Turn one key into an event and confirm it; None when the key is not feedback."""
        if ch in ("q", "Q"):
            self.stop_requested.set()
            self.out.write("[feedback] q: stopping after this chunk\n")
            self.out.flush()
            return None
        value = parse_key(ch)
        if value is None:
            return None
        t = self.clock()
        ok, reason = self.queue.offer(FeedbackEvent(t, t, "keyboard", value, {"key": ch}))
        self.presses += 1
        shown = f"{value:+.0f}" if value else "0"
        self.out.write(f"[feedback] {shown} accepted\n" if ok else f"[feedback] {shown} refused: {reason}\n")
        self.out.flush()
        return ok

    def _run(self) -> None:
        while not self.stop_requested.is_set():
            ch = self.stream.read(1)
            if not ch:  # end of input
                break
            self.handle_key(ch)

    def start(self) -> "KeyboardFeedback":
        if self._isatty():
            import termios
            import tty

            fd = self.stream.fileno()
            self._saved_tty = termios.tcgetattr(fd)
            tty.setcbreak(fd)  # single keys, no Enter; Ctrl-C still sends SIGINT
            termios.tcflush(fd, termios.TCIFLUSH)  # keys typed before now (e.g. while compiling) are dropped
        self.out.write("[feedback] keys: + good, - bad, 0 neutral, q quit\n")
        self.out.flush()
        self._thread = threading.Thread(target=self._run, name="keyboard-feedback", daemon=True)
        self._thread.start()
        return self

    def _isatty(self) -> bool:
        try:
            return self.stream.isatty()
        except (AttributeError, ValueError, OSError):
            return False

    def stop(self) -> None:
        """Stop reading and restore the terminal (idempotent)."""
        self.stop_requested.set()
        if self._saved_tty is not None:
            import termios

            try:
                termios.tcsetattr(self.stream.fileno(), termios.TCSADRAIN, self._saved_tty)
            except (termios.error, ValueError, OSError):
                pass  # the terminal is gone
            self._saved_tty = None
