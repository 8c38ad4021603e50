"""The keyboard front end: keys -> events in the queue, each press confirmed; no terminal needed."""

import io
import time

from mjx_protamer.human.keyboard import KeyboardFeedback, parse_key
from mjx_protamer.human.queue import FeedbackQueue


def test_keys_map_to_values():
    assert [parse_key(k) for k in "+-0x="] == [1.0, -1.0, 0.0, None, 1.0]


def test_thread_reads_keys_confirms_and_queues():
    q = FeedbackQueue(maxsize=2)
    out = io.StringIO()
    kb = KeyboardFeedback(q, stream=io.StringIO("+x-0q+"), out=out).start()
    kb._thread.join(5)
    text = out.getvalue()
    assert "[feedback] +1 accepted" in text and "[feedback] -1 accepted" in text
    assert "[feedback] 0 refused: queue full" in text  # the third press overflows a queue of 2
    assert kb.stop_requested.is_set() and kb.presses == 3  # 'q' stops reading; the last '+' is unread
    events = q.drain()
    assert [(e.value, e.source) for e in events] == [(1.0, "keyboard"), (-1.0, "keyboard")]
    assert abs(events[0].t_start - time.time()) < 5 and q.overflow == 1
