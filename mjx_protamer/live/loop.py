"""The one loop of a live session: a chunk, its feedback, spare-time learning, the sinks, autosave, pace.

Per chunk: the pacer decides the chunk's extra updates; the learner computes the chunk; the sources see it
(a simulated teacher scores it and gives feedback); the learner drains the queue and learns from it; the extra
updates run with the new reward model; the sinks get the chunk (terminal, view, record); every `autosave_s`
everything is saved; a paced session then waits until the chunk has been shown in real time. The sources start
once the first chunk has run (compiled): what a person does before then would be lost. The loop ends on
`--max-chunks`, `--seconds` (counted from the first chunk shown), a source's stop (q, the end of a WAV), or a
signal (the first SIGINT/SIGTERM after the current chunk, a second SIGINT at once).
"""

from __future__ import annotations

import dataclasses
import math
import signal
import time

from mjx_protamer.errors import WriteFailed  # a save or a record line could not be written: the session ends


class Stopper:
    """SIGINT/SIGTERM: the first one stops after the current chunk (which then gets saved); a second SIGINT
    interrupts at once (still saving what there is)."""

    def __init__(self):
        self.signum: int | None = None
        self._old = {}

    def __enter__(self):
        for s in (signal.SIGINT, signal.SIGTERM):
            self._old[s] = signal.signal(s, self._handle)
        return self

    def _handle(self, signum, frame):
        if self.signum is not None and signum == signal.SIGINT:
            raise KeyboardInterrupt
        self.signum = signum
        name = "Ctrl-C" if signum == signal.SIGINT else "SIGTERM"
        print(f"\n[finetune] {name}: stopping after this chunk, then saving (Ctrl-C again to stop at once)",
              flush=True)

    def __exit__(self, *exc):
        for s, h in self._old.items():
            signal.signal(s, h)


@dataclasses.dataclass
class LoopResult:
    chunks: int = 0
    interrupted: bool = False
    write_error: str | None = None
    t_ready: float | None = None  # when the first chunk had run (the sources started)
    t_end: float | None = None

    def pace(self, shown_s: float) -> dict:
        """The shown chunks after the first against the wall time they took (real time: 1.0)."""
        if self.t_ready is None or self.chunks < 2:
            return {"chunks": self.chunks}
        wall = self.t_end - self.t_ready
        shown = (self.chunks - 1) * shown_s
        return {"chunks": self.chunks, "shown_s": shown, "wall_s": wall, "realtime": shown / max(wall, 1e-9)}


def run_loop(spec, learner, sources, sinks, pacer, clock, stopper: Stopper, autosave, on_ready) -> LoopResult:
    """Run chunks until a stop; `autosave()` saves (raising WriteFailed), `on_ready()` runs after the first
    chunk (it starts the sources). Returns how it ended; the caller saves and cleans up."""
    from mjx_protamer.human.clock import VirtualClock

    result = LoopResult()
    shown_s = learner.chunk_steps * learner.dt
    paced = spec.pace and spec.live
    t_end = math.inf  # --seconds counts from the first chunk shown: compiles and model loads do not
    last_save = time.time()
    slow_said = False
    t_next = None  # when the next chunk is due to be shown (paced)
    try:
        while time.time() < t_end and stopper.signum is None:
            if spec.max_chunks and result.chunks >= spec.max_chunks:
                break
            if any(s.stop_requested for s in sources):
                break
            t_start = time.time()
            extra = pacer.next()
            chunk = learner.step_chunk(clock())
            if isinstance(clock, VirtualClock):
                clock.set(chunk.t0 + learner.chunk_steps * learner.dt)
            for s in sources:
                s.observe(chunk)
            outcomes = learner.take_events(chunk.first_step + learner.chunk_steps - 1)
            for s in sources:
                s.drained(outcomes)
            extra = pacer.settle(extra, sum(o.why is None for o in outcomes))
            t_a = time.time()
            learner.extra_updates(extra)
            t_b = time.time()
            pace = {"extra": extra, "updates_per_step": pacer.updates_per_step() if pacer.chunks else 0.0,
                    "realtime": shown_s / max(t_b - t_start, 1e-9)}
            for sink in sinks:
                sink.chunk(learner, chunk, outcomes, pace)
            result.chunks += 1
            if result.chunks == 1:  # compiled and running: now the feedback sources start
                if stopper.signum is not None:
                    break
                on_ready()
                result.t_ready = time.time()
                if spec.seconds > 0:
                    t_end = time.time() + spec.seconds
            if spec.autosave_s > 0 and time.time() - last_save >= spec.autosave_s:
                t_save = time.time()
                autosave()
                last_save = time.time()
                print(f"[finetune] autosaved at step {learner.first_step} ({last_save - t_save:.1f} s)", flush=True)
            finished = False
            for s in sources:
                line = s.poll()
                if line:
                    print(f"[finetune] {line}", flush=True)
                finished = finished or s.finished
            pacer.observe(base_s=(t_a - t_start) + (time.time() - t_b), extra=extra, extra_s=t_b - t_a)
            if finished:  # a recording is over: its last events were drained with this chunk
                break
            if paced:  # show the chunks at real-time pace: each on a fixed schedule, so jitter does not add up
                t_next = shown_s + (t_next if t_next is not None and t_next > t_start - shown_s else t_start)
                spare = t_next - time.time()
                if spare > 0:
                    time.sleep(spare)
                elif result.chunks > 1 and not slow_said and shown_s / (time.time() - t_start) < 0.95:
                    print(f"[finetune] note: this machine runs chunks slower than real time "
                          f"({shown_s / (time.time() - t_start):.2f}x); feedback is mapped to the steps shown "
                          "when you gave it", flush=True)
                    slow_said = True
    except KeyboardInterrupt:
        result.interrupted = True
        print("\n[finetune] interrupted: saving", flush=True)
    except WriteFailed as e:
        result.write_error = str(e)
    result.interrupted = result.interrupted or stopper.signum is not None
    result.t_end = time.time()
    return result
