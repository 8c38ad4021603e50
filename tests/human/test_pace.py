"""The pacer turns a shown chunk's spare time into extra updates, within the cap, and reports what it measured."""

from mjx_protamer.live.pace import UpdatePacer


def _pacer(paced=True, max_updates_per_step=8.0):
    # 50 steps at 5 ms: a chunk is shown for 250 ms
    return UpdatePacer(chunk_steps=50, dt=0.005, updates_per_step=1, max_updates_per_step=max_updates_per_step,
                       spare_fraction=0.8, unpaced_updates_per_step=2.0, paced=paced)


def test_spare_time_becomes_updates_at_the_measured_cost_within_the_cap():
    p = _pacer()
    assert p.next() == 0  # the first chunk measures the base cost
    p.observe(base_s=0.150, extra=0, extra_s=0.0)
    probe = p.next()  # then a probe measures one update's cost
    assert probe == 25
    p.observe(base_s=0.150, extra=probe, extra_s=probe * 0.002)
    assert p.next() == int(0.8 * (0.250 - 0.150) / 0.002)  # 40 of the 50 that would fill the spare 100 ms
    assert p.costs() == {"chunk_base_ms": 150.0, "extra_update_ms": 2.0, "shown_chunk_ms": 250.0}
    for _ in range(20):  # chunks slower than they are shown (a moving average follows them): no room to learn in
        p.observe(base_s=0.300, extra=0, extra_s=0.0)
    assert p.next() == 0
    fast = _pacer(max_updates_per_step=3.0)
    fast.observe(base_s=0.010, extra=0, extra_s=0.0)
    fast.observe(base_s=0.010, extra=25, extra_s=25 * 0.0001)
    assert fast.next() == 100  # the cap: 3 per shown step in all, 1 of them the chunk's own


def test_an_unpaced_session_gets_its_fixed_ratio_and_counts_updates_per_shown_step():
    p = _pacer(paced=False)
    assert p.next() == 50  # 2 per step: the chunk's own 50 and 50 more
    p.observe(base_s=0.1, extra=50, extra_s=0.1)
    p.observe(base_s=0.1, extra=50, extra_s=0.1)
    assert p.updates_per_step() == 2.0


def test_on_the_persons_clock_events_buy_the_updates_within_the_cap_and_a_backlog_carries_over():
    """`session.updates_per_event`: the chunks make none of their own; each event the learner took buys N."""
    from mjx_protamer.human.feedback_config import SessionConfig

    session = SessionConfig(updates_per_step=1, updates_per_event=60)
    assert session.chunk_updates_per_step == 0 and SessionConfig().chunk_updates_per_step == 1
    p = UpdatePacer(chunk_steps=50, dt=0.005, updates_per_step=session.chunk_updates_per_step, max_updates_per_step=3.0,
                    spare_fraction=0.8, unpaced_updates_per_step=2.0, paced=False, updates_per_event=60)
    cap = p.next()
    assert cap == 150  # 3 per shown step, none of them the chunk's own
    assert p.settle(cap, 0) == 0  # nobody spoke: no learning
    assert p.settle(cap, 1) == 60
    assert p.settle(cap, 4) == 150 and p.owed == 90
    assert p.settle(cap, 0) == 90 and p.owed == 0
    p.observe(base_s=0.1, extra=60, extra_s=0.1)
    p.observe(base_s=0.1, extra=0, extra_s=0.0)
    assert p.updates_per_step() == 0.6  # 60 updates over 100 shown steps
    clocked = _pacer(paced=False)
    assert clocked.settle(clocked.next(), 5) == 50  # by the clock, events change nothing
