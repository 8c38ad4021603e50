"""The live view of a finetune session, in its own process: the learner never waits for it.

`LiveView(kind, run_config, feedback_queue).start()` spawns the view process and returns its URL (web)
or None (window). Each chunk the learner calls `offer(snapshot)`: a non-blocking put into a queue of
two; when the view is behind, the snapshot is dropped (counted in `dropped`), never waited for.

- web: the page of `server.py` (aiohttp, 127.0.0.1, random token); a render thread (`playback.Player`)
  draws the due step of the newest chunk; the page's buttons and keys feed the same FeedbackQueue as
  the terminal keyboard.
- window: MuJoCo's passive viewer (needs a display); + / - / 0 keys in the window feed the queue too.
"""

from __future__ import annotations

import multiprocessing as mp
import queue as queue_lib
import secrets
import sys
import threading
import time

KINDS = ("web", "window", "none")

# The view serves the person; the session's time is the learner's. On a small CPU machine Mesa's llvmpipe
# renders with a thread per core at the learner's priority and takes the spare time the pacer would spend on
# extra updates (issue 39's pace), so the view process renders on one thread at a lower priority and draws
# with what the learner and the listener leave.
VIEW_NICE = 10
VIEW_GL_THREADS = 1


def default_kind() -> str:
    """window where a display exists, else web."""
    import os

    return "window" if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY") else "web"


class LiveView:
    def __init__(self, kind: str, run_config, feedback_queue, port: int = 0, start_timeout_s: float = 120.0):
        if kind not in ("web", "window"):
            raise ValueError(f"view kind must be web or window, got {kind!r}")
        if kind == "window" and default_kind() != "window":
            raise RuntimeError("--view window needs a display (DISPLAY is not set); use --view web")
        if kind == "web":
            from mjx_protamer.view.gl import GLUnavailable, choose_backend

            if run_config.env_name != "toy":
                try:  # decided here so the view process inherits MUJOCO_GL
                    choose_backend()
                except GLUnavailable as e:
                    print(f"[view] note: {e}; the page shows status without pictures", flush=True)
        self.kind = kind
        self.timeout = start_timeout_s
        ctx = mp.get_context("spawn")
        self._snapshots = ctx.Queue(maxsize=2)
        self._ready = ctx.Queue(maxsize=1)
        self.token = secrets.token_urlsafe(16)
        self.process = ctx.Process(target=_main, name=f"view-{kind}", daemon=True,
                                   args=(kind, run_config, feedback_queue, self._snapshots, self._ready, port,
                                         self.token))
        self.offered = 0
        self.dropped = 0
        self.url: str | None = None

    def start(self) -> str | None:
        self.process.start()
        end = time.time() + self.timeout
        ok, what = False, f"the view process did not start within {self.timeout:.0f} s"
        while time.time() < end:
            try:
                ok, what = self._ready.get(timeout=0.5)
                break
            except queue_lib.Empty:
                if not self.process.is_alive():  # crashed without a word (e.g. in the GL driver)
                    what = f"the view process exited with code {self.process.exitcode} while starting"
                    break
        if not ok:
            self.close()
            raise RuntimeError(what)
        self.url = what
        return what

    def offer(self, snapshot: dict) -> bool:
        """Hand a chunk to the view without waiting; False (dropped) when the view is behind or gone."""
        self.offered += 1
        if not self.process.is_alive():
            self.dropped += 1
            return False
        try:
            self._snapshots.put_nowait(snapshot)
            return True
        except queue_lib.Full:
            self.dropped += 1
            return False

    def close(self) -> None:
        if self.process.is_alive():
            try:
                self._snapshots.put(None, timeout=1.0)
            except queue_lib.Full:
                pass
            self.process.join(5.0)
            if self.process.is_alive():
                self.process.terminate()
                self.process.join(2.0)
        self._snapshots.cancel_join_thread()


def _reader(snapshots, player, stop: threading.Event) -> None:
    while not stop.is_set():
        try:
            snap = snapshots.get(timeout=0.2)
        except queue_lib.Empty:
            continue
        except (EOFError, OSError):
            break
        if snap is None:
            break
        player.submit(snap)
    stop.set()


def _yield_to_learner() -> None:
    """Called first in the view process, before any GL context exists (Mesa reads LP_NUM_THREADS then)."""
    import os

    os.environ.setdefault("LP_NUM_THREADS", str(VIEW_GL_THREADS))
    try:
        os.nice(VIEW_NICE)
    except OSError:  # pragma: no cover - a platform without nice; the view still works
        pass


def _main(kind, run_config, feedback_queue, snapshots, ready, port, token) -> None:
    _yield_to_learner()
    try:
        if kind == "web":
            _serve_web(run_config, feedback_queue, snapshots, ready, port, token)
        else:
            from mjx_protamer.view.window import run_window

            run_window(run_config, feedback_queue, snapshots, ready)
    except Exception as e:
        try:
            ready.put_nowait((False, f"{type(e).__name__}: {e}"))
        except queue_lib.Full:
            print(f"[view] stopped: {type(e).__name__}: {e}", file=sys.stderr, flush=True)


def _serve_web(run_config, feedback_queue, snapshots, ready, port, token) -> None:
    import asyncio

    from mjx_protamer.view.playback import Player
    from mjx_protamer.view.scenes import make_scene
    from mjx_protamer.view.server import make_app, serve

    player = Player(lambda: make_scene(run_config)).start()
    stop = threading.Event()
    threading.Thread(target=_reader, args=(snapshots, player, stop), name="view-snapshots", daemon=True).start()

    async def main():
        runner, bound = await serve(make_app(player, feedback_queue, token), port)
        ready.put((True, f"http://127.0.0.1:{bound}/?token={token}"))
        while not stop.is_set():
            await asyncio.sleep(0.1)
        await asyncio.sleep(0.3)  # the last status reaches the page
        await runner.cleanup()

    try:
        asyncio.run(main())
    finally:
        player.stop()
    time.sleep(0)
