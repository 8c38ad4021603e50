"""The finetune session's side of the live view: start it, and hand it each chunk without waiting."""

from __future__ import annotations

from mjx_protamer.commands.feedback_text import outcome_text


def default_view() -> str:
    from mjx_protamer.view.live import default_kind
    return default_kind()


def start_view(kind: str, pre, run, port: int):
    """The LiveView process (web page or window), or None (--view none, or it could not start: the
    session goes on without it)."""
    if kind == "none":
        return None
    from mjx_protamer.view.live import LiveView

    try:
        view = LiveView(kind, pre, run.queue, port=port)
        url = view.start()
    except Exception as e:  # RuntimeError: the view process's own report, already naming its error
        why = str(e) if type(e) is RuntimeError else f"{type(e).__name__}: {e}"
        print(f"[view] not available ({why}); the session goes on without it", flush=True)
        return None
    print(f"[view] {url}" if url else "[view] MuJoCo viewer window open (+ / - / 0 keys there)", flush=True)
    return view


def calibration_prompt(touch: str) -> str:
    """What `finetune --calibrate TOUCH` asks of the person, on the terminal and the page."""
    what = {"left_hand": "the left hand start touching", "right_hand": "the right hand start touching"}.get(
        touch, f"a hand arrive at the {touch.replace('_', ' ')}")
    return f"calibration: give feedback (+, or say 'good') as soon as you see {what}, every time"


def last_event(run, learner: str) -> dict | None:
    """The last drained event and what became of it, for the page."""
    from mjx_protamer.human.attention import is_attention

    feedback = [o for o in run.outcomes if not is_attention(o[0])]
    if not feedback:
        return None
    event, got, why = feedback[-1]
    return {"value": float(event.value), "source": event.source, "t": float(event.t_start),
            "outcome": outcome_text(run, got, why, learner)}


def snapshot(run, args, m, t_wall: float, dt: float, last_event) -> dict:
    """What the view needs of a chunk: its steps (observations, actions) shown from `t_wall`, the reward
    model's prediction on them and the learner's status."""
    import numpy as np

    c = run.last_chunk
    r_hat = None
    if args.learner == "ddpg" and run.use_model:
        r_hat = np.asarray(run.model.predict(c["obs"], c["action"])).reshape(-1).astype(np.float32)
    status = {"learner": args.learner, "feedback": args.feedback, "contact_rate": float(m["contact_rate"]),
              "step_reward": float(m["step_reward"]), "events": int(run.events),
              "credited": int(run.credited) if args.learner == "ddpg" else int(run.corrections),
              "updates": int(run.model.updates) if args.learner == "ddpg" else int(run.learner.updates)}
    if getattr(args, "calibrate", None):
        status["prompt"] = calibration_prompt(args.calibrate)
    return {"first_step": int(c["first_step"]), "t0": float(t_wall), "dt": float(dt),
            "obs": np.asarray(c["obs"], np.float32), "action": np.asarray(c["action"], np.float32),
            "r_hat": r_hat, "status": status, "last_event": last_event}
