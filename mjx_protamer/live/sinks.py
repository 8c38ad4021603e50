"""Where a live session's chunks go: the terminal, the live view (page or window) and the session record.

Each sink takes every chunk with its outcomes (`chunk(...)`); none of them is waited for by the learner beyond
writing a line: the view drops chunks it cannot keep up with (view/live.py), the record is one fsynced line.
"""

from __future__ import annotations

import numpy as np

from mjx_protamer.human.attention import is_attention


def calibration_prompt(touch: str) -> str:
    """What `finetune --calibrate TOUCH` asks of the person, on the terminal and the page."""
    what = {"left_hand": "the left hand start touching", "right_hand": "the right hand start touching"}.get(
        touch, f"a hand arrive at the {touch.replace('_', ' ')}")
    return f"calibration: give feedback (+, or say 'good') as soon as you see {what}, every time"


class TerminalSink:
    """A status line per chunk; each drained event with what became of it."""

    def chunk(self, learner, chunk, outcomes, pace: dict) -> None:
        m = chunk.metrics
        print(f"[step {learner.first_step:>7}] contact {m['contact_rate']:.2f} reward {m['step_reward']:+.3f} "
              f"events {learner.events} {learner.progress(pace)}", flush=True)
        self.outcomes(outcomes)

    @staticmethod
    def outcomes(outcomes) -> None:
        for o in outcomes:
            if is_attention(o.event):
                print(f"[attention] {o.text}", flush=True)
                continue
            label = o.event.details.get("transcript") or o.event.details.get("key") or ""
            head = f"[event] {o.event.source} {o.event.value:+.2f}" + (f" ({label!r})" if label else "")
            print(f"{head}: {o.text}", flush=True)


def last_event(outcomes) -> dict | None:
    """The last drained feedback event and what became of it, for the page."""
    feedback = [o for o in outcomes if not is_attention(o.event)]
    if not feedback:
        return None
    o = feedback[-1]
    return {"value": float(o.event.value), "source": o.event.source, "t": float(o.event.t_start), "outcome": o.text}


class ViewSink:
    """The live view (its own process): each chunk's steps, the reward model's prediction on them, the status."""

    def __init__(self, view, spec):
        self.view = view
        self.spec = spec
        self.last_event = None

    def chunk(self, learner, chunk, outcomes, pace: dict) -> None:
        self.last_event = last_event(outcomes) or self.last_event
        r_hat = learner.predict(chunk)
        status = {"learner": learner.kind, "feedback": self.spec.feedback,
                  "contact_rate": float(chunk.metrics["contact_rate"]),
                  "step_reward": float(chunk.metrics["step_reward"]), **learner.status(), **pace}
        if self.spec.calibrate:
            status["prompt"] = calibration_prompt(self.spec.calibrate)
        self.view.offer({"first_step": int(chunk.first_step), "t0": float(chunk.t0), "dt": float(learner.dt),
                         "obs": np.asarray(chunk.obs, np.float32), "action": np.asarray(chunk.action, np.float32),
                         "r_hat": None if r_hat is None else np.asarray(r_hat, np.float32), "status": status,
                         "last_event": self.last_event})

    def close(self) -> None:
        self.view.close()
        print(f"[view] closed: {self.view.offered} chunks offered, {self.view.dropped} dropped", flush=True)


class RecordSink:
    """The session record (live/record.py): a checked line per chunk, with its drain and extra updates."""

    def __init__(self, recorder):
        self.recorder = recorder
        self.chunks = 0

    def chunk(self, learner, chunk, outcomes, pace: dict) -> None:
        self.recorder.chunk(self.chunks, chunk.first_step, chunk.t0, [o.event for o in outcomes],
                            extra=pace["extra"], touches=chunk.touches)
        self.chunks += 1

    def close(self) -> None:
        self.recorder.close()


SNAPSHOTS = "snapshots"  # a session's snapshot folder (`--snapshot-every-s`)


class SnapshotSink:
    """The policy as it stands every `every_steps` shown steps (`--snapshot-every-s`), for a curve of what a
    session has taught by each minute: OUT/snapshots/step_<n>/ (the deterministic actor, the same tree a final
    save's actor is; checksummed, written once). A snapshot is taken after the chunk's drain and extra updates, so
    the one at step n is the actor a session stopped after n steps ends with."""

    def __init__(self, out, every_steps: int):
        self.dir = out / SNAPSHOTS
        self.every = max(1, int(every_steps))

    def chunk(self, learner, chunk, outcomes, pace: dict) -> None:
        from mjx_protamer.errors import WriteFailed
        from mjx_protamer.experiments.checkpoints import save_model

        end = learner.first_step  # steps shown after this chunk
        if end // self.every == (end - learner.chunk_steps) // self.every:
            return
        where = self.dir / f"step_{end:08d}"
        try:
            save_model(where, learner.actor_params())
        except Exception as e:  # OSError, or orbax's wrapping of one
            raise WriteFailed(f"the snapshot {where} could not be written ({type(e).__name__}: {e})") from None

    def close(self) -> None:
        pass


def snapshot_steps(session) -> list[int]:
    """The steps at which a session's snapshots were taken, in order."""
    d = session / SNAPSHOTS
    return sorted(int(p.name[5:]) for p in d.glob("step_*") if p.name[5:].isdigit()) if d.is_dir() else []


def start_view(kind: str, pre, queue, port: int):
    """The LiveView process (web page or window), or (None, reason) when it cannot start."""
    if kind == "none":
        return None, None
    from mjx_protamer.view.live import LiveView

    try:
        view = LiveView(kind, pre, queue, port=port)
        url = view.start()
    except Exception as e:  # RuntimeError: the view process's own report, already naming its error
        return None, str(e) if type(e) is RuntimeError else f"{type(e).__name__}: {e}"
    print(f"[view] {url}" if url else "[view] MuJoCo viewer window open (+ / - / 0 keys there)", flush=True)
    return view, None
