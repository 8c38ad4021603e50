"""The live page's websocket (view/server.py) against hostile messages: deeply nested JSON, a 400-digit number, a
message over the size limit, binary garbage, JSON that is not a mapping. Each is answered with an error message
(or, over the size limit, the connection is closed by aiohttp) and logged with its reason; the handler never
raises, nothing reaches the feedback queue, and the page goes on working (a valid message afterwards is acked).

In process: `make_app` served by aiohttp's test server on 127.0.0.1, a stand-in player and queue (no JAX).
"""

from __future__ import annotations

import asyncio
import json
import logging

import pytest

aiohttp = pytest.importorskip("aiohttp")

from aiohttp import WSMsgType  # noqa: E402
from aiohttp.test_utils import TestClient, TestServer  # noqa: E402

from mjx_protamer.view import server  # noqa: E402


class Player:
    def latest(self):
        return 0, None  # no frame yet: only status messages are pushed

    def status_message(self):
        return {"type": "status"}


class Queue:
    def __init__(self):
        self.offered = []

    def offer(self, event):
        self.offered.append(event)
        return True, None


async def _exchange(messages, then_valid: bool = True):
    """Send each message on one connection; (replies other than status, the queue, whether it stayed open)."""
    queue = Queue()
    app = server.make_app(Player(), queue, token="t")
    async with TestClient(TestServer(app)) as client:
        ws = await client.ws_connect("/ws?token=t")
        replies = []

        async def next_reply():
            while True:
                msg = await asyncio.wait_for(ws.receive(), timeout=10)
                if msg.type != WSMsgType.TEXT:
                    return msg
                data = json.loads(msg.data)
                if data.get("type") != "status":
                    return data

        for kind, payload in messages:
            await (ws.send_bytes(payload) if kind == "bytes" else ws.send_str(payload))
            replies.append(await next_reply())
        open_after = not ws.closed
        if then_valid and open_after:
            await ws.send_str(json.dumps({"type": "feedback", "value": 1}))
            replies.append(await next_reply())
        await ws.close()
    return replies, queue.offered, open_after


HOSTILE = {
    "deeply nested JSON": ("str", "[" * 3000 + "]" * 3000),
    "nested deeper than the recursion limit": ("str", '{"a":' * 2000 + "1" + "}" * 2000),
    "a 400-digit number": ("str", json.dumps({"type": "feedback", "value": 10 ** 400})),
    "a 5000-digit number": ("str", '{"type": "feedback", "value": ' + "9" * 5000 + "}"),
    "1e400 (inf)": ("str", '{"type": "feedback", "value": 1e400}'),
    "NaN": ("str", '{"type": "feedback", "value": NaN}'),
    "a string value": ("str", json.dumps({"type": "feedback", "value": "1"})),
    "a nested value": ("str", json.dumps({"type": "feedback", "value": [[[1]]]})),
    "true as a value": ("str", json.dumps({"type": "feedback", "value": True})),
    "binary garbage": ("bytes", bytes(range(256)) * 4),
    "not JSON": ("str", "\x00\xff{{{"),
    "a JSON list": ("str", "[1, 2, 3]"),
    "a JSON string": ("str", '"feedback"'),
    "a JSON number": ("str", "1"),
    "null": ("str", "null"),
    "attention without a boolean": ("str", json.dumps({"type": "attention", "watching": "yes"})),
}


@pytest.mark.parametrize("name", list(HOSTILE))
def test_a_hostile_message_is_answered_with_an_error_logged_and_the_page_goes_on(name, caplog):
    caplog.set_level(logging.WARNING, logger=server.__name__)
    replies, offered, open_after = asyncio.run(_exchange([HOSTILE[name]]))
    assert open_after
    assert replies[0]["type"] == "error" and len(replies[0]["error"]) < 300, replies[0]
    assert replies[1]["type"] == "ack" and replies[1]["accepted"] is True  # the page still works
    assert len(offered) == 1 and offered[0].value == 1.0  # only the valid message reached the queue
    logged = [r.getMessage() for r in caplog.records if r.name == server.__name__]
    assert len(logged) == 1 and replies[0]["error"] in logged[0], logged
    assert all(len(line) < 400 for line in logged)  # a huge value is not echoed


def test_a_message_over_the_size_limit_closes_the_connection_with_a_logged_reason(caplog):
    caplog.set_level(logging.WARNING, logger=server.__name__)
    big = json.dumps({"type": "feedback", "value": 1, "pad": "x" * (server.MAX_MSG_BYTES * 4)})
    replies, offered, open_after = asyncio.run(_exchange([("str", big)], then_valid=False))
    assert replies[0].type in (WSMsgType.CLOSE, WSMsgType.CLOSED, WSMsgType.CLOSING)
    assert replies[0].data == 1009  # "message too big"
    assert not offered
    logged = [r.getMessage() for r in caplog.records if r.name == server.__name__]
    assert len(logged) == 1 and "could not be received" in logged[0] and "closed" in logged[0], logged


def test_a_flood_of_bad_messages_is_logged_a_bounded_number_of_times(caplog):
    caplog.set_level(logging.WARNING, logger=server.__name__)
    replies, offered, open_after = asyncio.run(_exchange([("str", "[1]")] * (server.MAX_LOGGED + 15)))
    assert open_after and all(r["type"] == "error" for r in replies[:-1]) and replies[-1]["type"] == "ack"
    logged = [r.getMessage() for r in caplog.records if r.name == server.__name__]
    assert len(logged) == server.MAX_LOGGED and "further ones from this page are not logged" in logged[-1]


def test_valid_messages_are_still_acked_and_attention_still_answered():
    replies, offered, _ = asyncio.run(_exchange([
        ("str", json.dumps({"type": "feedback", "value": -1})), ("str", json.dumps({"type": "feedback", "value": 0})),
        ("str", json.dumps({"type": "attention", "watching": True}))], then_valid=False))
    assert [r["type"] for r in replies] == ["ack", "ack", "attention"]
    assert [r["value"] for r in replies[:2]] == [-1.0, 0.0] and replies[2]["watching"] is True
    assert [e.value for e in offered[:2]] == [-1.0, 0.0]
