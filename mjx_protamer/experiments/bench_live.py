"""`protamer bench live`: does a live session keep real time while the learner learns, the page draws and the
listener transcribes?

Runs one paced `protamer finetune` session (its own process, as a person runs it) for `--seconds` with the web
view and, by default, the Whisper listener fed by the simulated speaker (the heaviest channel), while a client
reads the page's status over its websocket as a browser would. Reports what the session measured itself
(session.json's pace: shown steps per second, the real-time factor, updates per shown step), the page's frames per
second, and the listener's delivery (latency from the end of the words to the event, sign accuracy, misses;
speaker.jsonl). Nothing here is a timed test: the numbers are printed (`--json`).
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path


def add_arguments(p) -> None:
    p.add_argument("--checkpoint", type=Path, required=True, help="a pretrain run (the main job's, for the figure "
                   "the docs give)")
    p.add_argument("--seconds", type=float, default=60.0, help="shown time after the session is ready (default 60)")
    p.add_argument("--feedback", default="whisper", choices=("whisper", "prosody", "simulated:keyboard", "none"),
                   help="whisper/prosody: the simulated speaker through that listener; simulated:keyboard: no "
                   "listener, and unpaced like every simulated teacher's session: the learner alone (default whisper)")
    p.add_argument("--view", default="web", choices=("web", "none"))
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="a session setting, e.g. --set session.max_updates_per_step=4")


def _watch_page(url: str, frames: list, stop: threading.Event) -> None:
    """A websocket client on the page: the status messages it would show (their frame counts)."""
    import asyncio

    import aiohttp

    async def main():
        ws_url = url.replace("http://", "ws://").replace("/?token=", "/ws?token=")
        async with aiohttp.ClientSession() as session:
            async with session.ws_connect(ws_url) as ws:
                await ws.send_str(json.dumps({"type": "attention", "watching": True}))
                while not stop.is_set():
                    try:
                        msg = await ws.receive(timeout=0.5)
                    except asyncio.TimeoutError:
                        continue
                    if msg.type == aiohttp.WSMsgType.TEXT:
                        data = json.loads(msg.data)
                        if data.get("type") == "status" and "frames" in data:
                            frames.append((time.time(), int(data["frames"])))
                    elif msg.type in (aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.ERROR):
                        break

    try:
        asyncio.run(main())
    except Exception as e:  # the page went away with the session
        frames.append((time.time(), f"{type(e).__name__}: {e}"))


def run_live_benchmark(args) -> dict:
    import os
    import platform

    out = Path(tempfile.mkdtemp(prefix="bench-live-")) / "session"
    argv = [sys.executable, "-m", "mjx_protamer.cli", "finetune", "--checkpoint", str(args.checkpoint),
            "--out", str(out), "--view", args.view, "--seconds", str(args.seconds), "--autosave-s", "0",
            "--feedback", args.feedback]
    if args.feedback in ("whisper", "prosody"):
        argv += ["--listen-source", "speaker"]
    for o in args.overrides:
        argv += ["--set", o]
    frames: list = []
    stop = threading.Event()
    watcher = None
    lines: list[str] = []
    t0 = time.time()
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    for line in proc.stdout:
        lines.append(line)
        if line.startswith("[view] http://") and watcher is None:
            watcher = threading.Thread(target=_watch_page, args=(line.split(" ", 1)[1].strip(), frames, stop),
                                       daemon=True)
            watcher.start()
    code = proc.wait()
    stop.set()
    if watcher is not None:
        watcher.join(5)
    if code != 0:
        raise RuntimeError(f"the session failed (exit {code}):\n{''.join(lines[-20:])}")
    manifest = json.loads((out / "session.json").read_text())
    pace = manifest["measured_pace"][-1]
    counts = [(t, n) for t, n in frames if isinstance(n, int)]
    fps = (counts[-1][1] - counts[0][1]) / (counts[-1][0] - counts[0][0]) if len(counts) > 1 else None
    speaker = None
    if (out / "speaker.jsonl").is_file():
        speaker = json.loads((out / "speaker.jsonl").read_text().strip().splitlines()[-1])["summary"]
    chunk_steps = int(manifest["chunk_steps"])
    dt = float(manifest["feedback_config"]["dt"])
    shown_steps_s = pace.get("shown_s", 0) / dt / pace["wall_s"] if pace.get("wall_s") else None
    return {"checkpoint": str(args.checkpoint), "feedback": args.feedback, "view": args.view,
            "seconds": args.seconds, "chunk_steps": chunk_steps,
            "shown_steps_per_s": shown_steps_s, "realtime": pace.get("realtime"),
            "updates_per_shown_step": pace.get("updates_per_step"),
            "updates_per_s": (pace["updates_per_step"] * shown_steps_s) if shown_steps_s and pace.get(
                "updates_per_step") else None,
            "chunk_base_ms": pace.get("chunk_base_ms"), "extra_update_ms": pace.get("extra_update_ms"),
            "shown_chunk_ms": pace.get("shown_chunk_ms"),
            "view_frames_per_s": fps, "listener": speaker, "process_wall_s": time.time() - t0,
            "machine": {"cpus": os.cpu_count(), "load_avg_1m_at_end": os.getloadavg()[0], "python":
                        platform.python_version(), "processor": platform.processor() or platform.machine()},
            "session_dir": str(out)}
