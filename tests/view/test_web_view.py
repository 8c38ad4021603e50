"""The live page of `protamer finetune --view web` in a real browser: Debian's chromium, headless, driven
by Playwright (its own browser download is not used: executable_path)."""

from __future__ import annotations

import io
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from mjx_protamer.human.queue import FeedbackLog

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "JAX_PLATFORMS": "cpu", "PYTHONUNBUFFERED": "1"}
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync"]


class Session:
    """A finetune subprocess whose output is collected by a thread (the pipe never fills)."""

    def __init__(self, argv):
        self.proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=ENV,
                                     cwd=ROOT)
        self.lines: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        for line in self.proc.stdout:
            self.lines.append(line)

    def wait_for(self, prefix: str, timeout: float = 300.0) -> str:
        end = time.time() + timeout
        while time.time() < end:
            for line in list(self.lines):
                if line.startswith(prefix):
                    return line.strip()
            if self.proc.poll() is not None:
                break
            time.sleep(0.1)
        raise AssertionError(f"{prefix!r} not seen; output:\n{''.join(self.lines)[-3000:]}")


# Headless chromium is always "visible"; a person's hidden tab is played by overriding the property the page
# reads and firing the event the browser would.
_SET_VISIBILITY = """(state) => {
  Object.defineProperty(document, "visibilityState", {value: state, configurable: true});
  document.dispatchEvent(new Event("visibilitychange"));
}"""


def _image(png: bytes) -> np.ndarray:
    import imageio.v3 as iio
    return iio.imread(io.BytesIO(png)).astype(int)


def test_live_page_in_headless_chromium_shows_the_run_feeds_the_queue_and_says_when_it_is_watched(toy_run, tmp_path):
    sync_api = pytest.importorskip("playwright.sync_api")
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        pytest.skip("needs Debian's chromium (apt-get install chromium; scripts/test.sh does as root)")
    out = tmp_path / "ft"
    s = Session([sys.executable, "-m", "mjx_protamer.cli", "finetune", "--feedback", "web", "--view", "web",
                 "--checkpoint", str(toy_run), "--out", str(out), "--seconds", "600",
                 "--set", "feedback.credit.silence_needs_attention=true"])
    try:
        url = s.wait_for("[view] http://127.0.0.1:").split(" ", 1)[1]
        s.wait_for("[finetune] ready: give feedback now")
        with sync_api.sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": 1000, "height": 640})
            assert page.goto(url.split("?")[0]).status == 403  # no token, no page
            assert page.goto(url).status == 200
            page.wait_for_function("Number(document.getElementById('frame').dataset.seq) >= 3", timeout=60_000)
            first = _image(page.locator("#frame").screenshot())
            time.sleep(1.5)
            second = _image(page.locator("#frame").screenshot())
            assert np.abs(first - second).mean() > 0.2, "the picture does not move"
            page.click("#good")
            page.wait_for_function("document.getElementById('ack').textContent === '+1 accepted'", timeout=10_000)
            time.sleep(0.5)
            page.keyboard.press("-")  # the page's keys, as in the terminal
            page.wait_for_function("document.getElementById('ack').textContent === '-1 accepted'", timeout=10_000)
            # the learner drained and credited them; the page shows what the last one credited
            page.wait_for_function("document.getElementById('last').textContent.includes('credited steps')",
                                   timeout=20_000)
            assert page.inner_text("#learner").startswith("ddpg, feedback web")
            # the learner spends the time a chunk is shown on more updates, and says so
            page.wait_for_function("document.getElementById('pace').textContent.includes('updates per shown step')",
                                   timeout=20_000)
            assert float(page.inner_text("#pace").split()[0]) >= 1.0
            assert int(page.inner_text("#step")) > 0  # the step on screen
            # the page says whether it is seen: hidden (another tab, a minimised window), then shown again
            assert page.inner_text("#attention") == "the learner knows you are watching"
            page.evaluate(_SET_VISIBILITY, "hidden")
            page.wait_for_function("document.getElementById('attention').textContent.endsWith('away')", timeout=10_000)
            page.evaluate(_SET_VISIBILITY, "visible")
            page.wait_for_function("document.getElementById('attention').textContent.endsWith('watching')",
                                   timeout=10_000)
            s.wait_for("[attention] watching (web page): silent steps count", timeout=30)
            page.screenshot(path=str(tmp_path / "live_page.png"))
            browser.close()  # a closed page is not watched
        end = time.time() + 30
        while "".join(s.lines).count("[attention] not watching (web page)") < 2 and time.time() < end:
            time.sleep(0.2)
        s.proc.send_signal(signal.SIGINT)
        assert s.proc.wait(120) == 130
    finally:
        if s.proc.poll() is None:
            s.proc.kill()
    text = "".join(s.lines)
    logged = FeedbackLog.read(out / "feedback.jsonl")
    events = [e for e in logged if e.source != "attention"]
    assert [e.value for e in events] == [1.0, -1.0], text
    assert all(e.source == "keyboard" and e.details["via"] == "web" for e in events)
    # watching from the first connection, away, back, and away when the browser closed: in the log and the
    # session record, so a replay gates the same silences
    assert [e.value for e in logged if e.source == "attention"] == [1.0, 0.0, 1.0, 0.0]
    recorded = (out / "session_chunks.jsonl").read_text()
    assert recorded.count('"source": "attention"') == 4
    assert "silence_needs_attention: a silent step teaches" in text
    assert text.count("accepted, credited steps") == 2
    assert "[view] closed" in text and (tmp_path / "live_page.png").stat().st_size > 10_000


class _StatusOnly:
    """A player with no pictures whose status carries what a session would put there."""

    def __init__(self, status: dict):
        self.status = status

    def latest(self):
        return 0, None

    def status_message(self) -> dict:
        return {"type": "status", **self.status}


def _serve_in_thread(app):
    """Serve an aiohttp app on a free port from a background event loop; (url base, stop)."""
    import asyncio

    from mjx_protamer.view.server import serve

    loop = asyncio.new_event_loop()
    started = threading.Event()
    box = {}

    def run():
        asyncio.set_event_loop(loop)
        box["runner"], box["port"] = loop.run_until_complete(serve(app))
        started.set()
        loop.run_forever()

    threading.Thread(target=run, daemon=True).start()
    assert started.wait(30)

    def stop():
        asyncio.run_coroutine_threadsafe(box["runner"].cleanup(), loop).result(10)
        loop.call_soon_threadsafe(loop.stop)

    return f"http://127.0.0.1:{box['port']}", stop


def test_a_calibration_sessions_snapshot_carries_its_task_and_pace_into_the_pages_status():
    """The path the prompt and the learning pace take without a browser: the session's view sink, the view
    process's Player, the status message the page receives."""
    from types import SimpleNamespace

    from mjx_protamer.live.learner import Chunk
    from mjx_protamer.live.sinks import ViewSink, calibration_prompt
    from mjx_protamer.view.playback import Player

    learner = SimpleNamespace(kind="coach", dt=0.005, predict=lambda chunk: None,
                              status=lambda: {"events": 3, "corrections": 2, "credited": 2, "updates": 7})
    chunk = Chunk(50, 100.0, 100.0 + 0.005 * np.arange(5), np.zeros((5, 3)), np.zeros((5, 2)), np.zeros((5, 1)), None,
                  {"contact_rate": 1.0, "step_reward": 0.5})
    for calibrate, expected in (("head", calibration_prompt("head")), (None, None)):
        player = Player(scene_factory=None)
        view = SimpleNamespace(offer=player.submit)
        ViewSink(view, SimpleNamespace(feedback="keyboard", calibrate=calibrate)).chunk(
            learner, chunk, [], {"extra": 40, "updates_per_step": 1.8, "realtime": 1.4})
        status = player.status_message()
        assert status.get("prompt") == expected
        assert status["updates_per_step"] == 1.8 and status["realtime"] == 1.4 and status["credited"] == 2


def test_a_calibration_session_shows_its_task_on_the_page_and_an_ordinary_one_does_not():
    """`finetune --calibrate head` puts its prompt in the status; the page shows it above the picture, where a
    person looks, and shows nothing there for an ordinary session."""
    sync_api = pytest.importorskip("playwright.sync_api")
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        pytest.skip("needs Debian's chromium (apt-get install chromium; scripts/test.sh does as root)")
    from mjx_protamer.human.queue import FeedbackQueue
    from mjx_protamer.live.sinks import calibration_prompt
    from mjx_protamer.view.server import make_app

    prompt = calibration_prompt("head")
    assert "as soon as you see a hand arrive at the head" in prompt
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS)
        for status, shown in (({"learner": "ddpg", "feedback": "web", "prompt": prompt}, True),
                              ({"learner": "ddpg", "feedback": "web"}, False)):
            base, stop = _serve_in_thread(make_app(_StatusOnly(status), FeedbackQueue(8), token="t"))
            try:
                page = browser.new_page(viewport={"width": 1000, "height": 640})
                assert page.goto(f"{base}/?token=t").status == 200
                page.wait_for_function("document.getElementById('learner').textContent.startsWith('ddpg')",
                                       timeout=20_000)
                assert page.locator("#prompt").is_visible() is shown
                if shown:
                    assert page.inner_text("#prompt") == prompt
                    box, frame = page.locator("#prompt").bounding_box(), page.locator("#frame").bounding_box()
                    assert box["y"] + box["height"] <= frame["y"]  # above the picture
                page.close()
            finally:
                stop()
        browser.close()


def test_a_web_session_whose_page_cannot_start_exits_before_the_learner_starts(toy_run, tmp_path):
    """`--feedback web` takes feedback from the page alone: with its port taken there is no way to give feedback,
    so the session ends with a clear line and a non-zero exit before anything is compiled."""
    import socket

    taken = socket.socket()
    taken.bind(("127.0.0.1", 0))
    taken.listen(1)
    port = taken.getsockname()[1]
    try:
        p = subprocess.run([sys.executable, "-m", "mjx_protamer.cli", "finetune", "--feedback", "web", "--view", "web",
                            "--port", str(port), "--checkpoint", str(toy_run), "--out", str(tmp_path / "ft")],
                           capture_output=True, text=True, env=ENV, cwd=ROOT, timeout=300)
    finally:
        taken.close()
    assert p.returncode == 2, p.stdout + p.stderr
    assert "--feedback web: the live page cannot start" in p.stderr and "--port" in p.stderr
    assert "compiling" not in p.stdout and not (tmp_path / "ft" / "checkpoints").exists()
