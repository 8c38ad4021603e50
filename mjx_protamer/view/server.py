"""The live page of `protamer finetune --view web`: aiohttp on 127.0.0.1, a random token in the URL.

GET /?token=T serves the page; GET /ws?token=T is a websocket on which the server pushes the newest
frame (binary JPEG, only when a new one exists: a slow browser skips frames) and a status message (JSON)
a few times a second, and the page sends {"type": "feedback", "value": +1 | -1 | 0}. Each value goes into
the learner's FeedbackQueue exactly as a terminal key press would (source "keyboard"), and the page
gets {"type": "ack", ...} with the queue's verdict. The page also sends {"type": "attention", "watching": bool}
when it connects and whenever it is shown or hidden (the Page Visibility API); while any page is visible the
teacher is watching, and each change (a page closing counts as hidden) goes into the queue as an attention
event (human/attention.py), answered with {"type": "attention", "watching": ...}. Requests without the token
get 403.

Anything else a connection sends is answered with {"type": "error", "error": REASON} and logged (at most
MAX_LOGGED lines a connection): binary data, text that is not JSON or is nested past Python's recursion limit,
JSON that is not a mapping, a value that is not exactly 1, -1 or 0. A message over MAX_MSG_BYTES closes the
connection (aiohttp's max_msg_size, code 1009), also logged. The handler never raises: the page and the learner
go on.
"""

from __future__ import annotations

import asyncio
import json
import logging
import secrets
import time
from importlib import resources

from aiohttp import WSMsgType, web

from mjx_protamer.human.attention import attention_event
from mjx_protamer.human.events import FeedbackEvent

PUSH_PERIOD_S = 0.02
STATUS_PERIOD_S = 0.25


MAX_MSG_BYTES = 16 * 1024  # the page sends a few dozen bytes a message; aiohttp closes a connection that sends more
MAX_LOGGED = 20  # reasons logged per connection

log = logging.getLogger(__name__)


def _short(value) -> str:
    """A value for a log line or an error reply, at most about 40 characters (a 400-digit number is not echoed)."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) >= 10 ** 30:
        return f"a {len(str(abs(value)))}-digit number"
    if not isinstance(value, (str, int, float, type(None))):
        return f"a {type(value).__name__}"  # a list or mapping is not echoed (it may be nested deeply)
    text = repr(value)
    return text if len(text) <= 40 else text[:30] + f"... ({len(text)} characters)"


def make_app(player, feedback_queue, token: str | None = None, on_feedback=None) -> web.Application:
    token = token or secrets.token_urlsafe(16)
    page = resources.files("mjx_protamer.view").joinpath("page.html").read_text(encoding="utf-8")
    app = web.Application()
    app["token"] = token

    def authorised(request) -> bool:
        return secrets.compare_digest(request.query.get("token", ""), token)

    async def index(request):
        if not authorised(request):
            raise web.HTTPForbidden(text="missing or wrong token: open the URL printed by protamer finetune")
        return web.Response(text=page, content_type="text/html")

    def give(value: float) -> dict:
        t = time.time()
        key = {1.0: "+", -1.0: "-", 0.0: "0"}[value]
        ok, reason = feedback_queue.offer(FeedbackEvent(t, t, "keyboard", value, {"key": key, "via": "web"}))
        if on_feedback is not None:
            on_feedback(value, ok, reason)
        return {"type": "ack", "value": value, "accepted": ok, "reason": reason, "t": t}

    visible: set = set()  # the connections whose page is visible now
    watching = [False]  # what the queue was last told

    def attend(ws, on: bool) -> dict:
        (visible.add if on else visible.discard)(ws)
        now = bool(visible)
        if now != watching[0]:
            ok, _ = feedback_queue.offer(attention_event(time.time(), now, "web page"))
            if ok:
                watching[0] = now
        return {"type": "attention", "watching": watching[0]}

    async def ws_handler(request):
        if not authorised(request):
            raise web.HTTPForbidden(text="missing or wrong token")
        ws = web.WebSocketResponse(heartbeat=20.0, max_msg_size=MAX_MSG_BYTES)
        await ws.prepare(request)

        async def push():
            sent, last_status = -1, 0.0
            try:
                while not ws.closed:
                    seq, frame = player.latest()
                    if frame is not None and seq != sent:
                        await ws.send_bytes(frame)
                        sent = seq
                    if time.time() - last_status > STATUS_PERIOD_S:
                        await ws.send_str(json.dumps(player.status_message()))
                        last_status = time.time()
                    await asyncio.sleep(PUSH_PERIOD_S)
            except (ConnectionError, RuntimeError):  # the page went away between two pushes
                pass

        pusher = asyncio.ensure_future(push())
        said = [0]  # reasons logged for this connection (a flood is not echoed line by line)

        def complain(reason: str) -> None:
            said[0] += 1
            if said[0] <= MAX_LOGGED:
                log.warning("live page %s: %s%s", request.remote, reason,
                            "; further ones from this page are not logged" if said[0] == MAX_LOGGED else "")

        try:
            async for msg in ws:
                try:
                    reply, reason = answer(ws, msg)
                except Exception as e:  # never out of the handler: the page and the learner go on
                    reply = {"type": "error", "error": "the message could not be handled"}
                    reason = f"a message could not be handled ({type(e).__name__}: {str(e)[:80]})"
                if reason is not None:
                    complain(reason)
                if reply is None:
                    continue
                try:
                    await ws.send_str(json.dumps(reply))
                except (ConnectionError, RuntimeError):  # the page went away meanwhile
                    break
        finally:
            pusher.cancel()
            attend(ws, False)  # a closed page is not watched
        return ws

    def answer(ws, msg) -> tuple[dict | None, str | None]:
        """(the reply to one websocket message or None, why it was refused or ignored or None)."""
        expected = "expected {type: feedback, value: 1|-1|0} or {type: attention, watching: true|false}"
        if msg.type == WSMsgType.ERROR:  # e.g. over max_msg_size: aiohttp has closed the connection (1009)
            return None, f"a message could not be received ({msg.data}); the connection was closed"
        if msg.type != WSMsgType.TEXT:
            kind = "binary" if msg.type == WSMsgType.BINARY else msg.type.name.lower()
            why = f"a {kind} message was ignored: the page sends JSON text"
            return {"type": "error", "error": why}, why
        try:
            data = json.loads(msg.data)
        except (ValueError, RecursionError):  # not JSON, an int of over 4,300 digits, nesting past Python's stack
            why = f"not a JSON message ({len(msg.data)} characters); {expected}"
            return {"type": "error", "error": why}, why
        if not isinstance(data, dict):
            why = f"a JSON {type(data).__name__} is not a message; {expected}"
            return {"type": "error", "error": why}, why
        if data.get("type") == "attention" and isinstance(data.get("watching"), bool):
            return attend(ws, data["watching"]), None
        value = data.get("value")
        if (data.get("type") != "feedback" or isinstance(value, bool) or not isinstance(value, (int, float))
                or value not in (1, -1, 0)):
            why = f"{expected}; got type {_short(data.get('type'))} value {_short(value)}"
            return {"type": "error", "error": why}, why
        return give(float(value)), None

    app.router.add_get("/", index)
    app.router.add_get("/ws", ws_handler)
    return app


async def serve(app: web.Application, port: int = 0) -> tuple[web.AppRunner, int]:
    """Start serving on 127.0.0.1 (port 0: a free one); returns the runner and the port."""
    runner = web.AppRunner(app, access_log=None)
    await runner.setup()
    site = web.TCPSite(runner, "127.0.0.1", port)
    await site.start()
    return runner, runner.addresses[0][1]
