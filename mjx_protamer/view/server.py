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
"""

from __future__ import annotations

import asyncio
import json
import secrets
import time
from importlib import resources

from aiohttp import WSMsgType, web

from mjx_protamer.human.attention import attention_event
from mjx_protamer.human.events import FeedbackEvent

PUSH_PERIOD_S = 0.02
STATUS_PERIOD_S = 0.25


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
        ws = web.WebSocketResponse(heartbeat=20.0)
        await ws.prepare(request)

        async def push():
            sent, last_status = -1, 0.0
            while not ws.closed:
                seq, frame = player.latest()
                if frame is not None and seq != sent:
                    await ws.send_bytes(frame)
                    sent = seq
                if time.time() - last_status > STATUS_PERIOD_S:
                    await ws.send_str(json.dumps(player.status_message()))
                    last_status = time.time()
                await asyncio.sleep(PUSH_PERIOD_S)

        pusher = asyncio.ensure_future(push())
        try:
            async for msg in ws:
                if msg.type != WSMsgType.TEXT:
                    continue
                try:
                    data = json.loads(msg.data)
                    if isinstance(data, dict) and data.get("type") == "attention":
                        await ws.send_str(json.dumps(attend(ws, bool(data.get("watching")))))
                        continue
                    value = float(data["value"])
                    if data.get("type") != "feedback" or value not in (1.0, -1.0, 0.0):
                        raise ValueError
                except (ValueError, KeyError, TypeError):
                    await ws.send_str(json.dumps({"type": "error", "error": "expected {type: feedback, value: 1|-1|0}"}))
                    continue
                await ws.send_str(json.dumps(give(value)))
        finally:
            pusher.cancel()
            attend(ws, False)  # a closed page is not watched
        return ws

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
