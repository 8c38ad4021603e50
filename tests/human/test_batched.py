"""In-jit DeepTAMER pieces: lag weights match the host credit, window gathering, the device ring."""

import jax
import jax.numpy as jnp
import numpy as np
import optax

from mjx_protamer.human.batched import credit_windows, ring_add, ring_init, tamer_update
from mjx_protamer.human.channels import ChannelConfig
from mjx_protamer.human.clock import StepClock
from mjx_protamer.human.credit import CreditAssigner, CreditConfig, lag_weights
from mjx_protamer.human.events import FeedbackEvent
from mjx_protamer.human.reward_model import RewardMLP, reward_fn


def test_lag_weights_match_the_host_credit_on_a_regular_clock():
    """In-jit lag weights from the arrival step = the host credit of an event whose onset is the arrival less
    the channel's utterance and pipeline latency (0 for the other schemes, which take the arrival time)."""
    speech = ChannelConfig("speech")
    for scheme in ("channel", "step_window", "time_window"):
        cfg = CreditConfig(scheme=scheme, min_interval_steps=0)
        clock = StepClock(dt=0.05)
        clock.record_chunk(0, 200, t0=0.0)
        onset = 150 * 0.05 - (speech.arrival_offset_s if scheme == "channel" else 0.0)
        credit, _ = CreditAssigner(cfg, clock, speech).assign(FeedbackEvent(onset, onset, "simulated", 1.0))
        w = lag_weights(cfg, 0.05, speech)
        host = dict(zip(credit.steps, credit.weights))
        jit = {150 - j: float(w[j]) for j in range(len(w)) if w[j] > 0}
        assert host.keys() == jit.keys()
        np.testing.assert_allclose([host[k] for k in sorted(host)], [jit[k] for k in sorted(jit)], rtol=1e-5)


def test_credit_windows_gather_hand_checked():
    T, B = 6, 2
    obs = jnp.arange(T * B, dtype=jnp.float32).reshape(T, B, 1)  # obs = 2 t + b
    act = -obs
    valid = jnp.zeros((T, B), bool).at[1, 1].set(True).at[4, 0].set(True)
    value = jnp.zeros((T, B)).at[1, 1].set(-1.0).at[4, 0].set(0.5)
    o, a, w, h, n = credit_windows(obs, act, value, valid, jnp.array([1.0, 0.9, 0.81]), max_events=3)
    assert int(n) == 2
    o, w, h = np.asarray(o).reshape(3, 3), np.asarray(w).reshape(3, 3), np.asarray(h).reshape(3, 3)
    # event (t=1, b=1): steps 1, 0, (-1 absent); event (t=4, b=0): steps 4, 3, 2; third slot empty
    np.testing.assert_allclose(o[0, :2], [3, 1])
    np.testing.assert_allclose(w[0], [1.0, 0.9, 0.0])
    np.testing.assert_allclose(o[1], [8, 6, 4])
    np.testing.assert_allclose(w[1], [1.0, 0.9, 0.81])
    assert (w[2] == 0).all() and (h[0] == -1).all() and (h[1] == 0.5).all()


def test_ring_keeps_only_weighted_rows_and_wraps():
    ring = ring_init(4, 1, 1)
    x = jnp.arange(6, dtype=jnp.float32)[:, None]
    ring = ring_add(ring, x, x, jnp.array([1.0, 0, 1, 0, 1, 0]), x[:, 0])
    assert int(ring.size) == 3 and int(ring.ptr) == 3
    np.testing.assert_allclose(ring.obs[:3, 0], [0, 2, 4])
    ring = ring_add(ring, x + 10, x, jnp.array([1.0, 1, 0, 0, 0, 0]), x[:, 0])
    assert int(ring.size) == 4 and int(ring.ptr) == 1
    np.testing.assert_allclose(ring.obs[:, 0], [11, 2, 4, 10])


def test_tamer_update_fits_targets_in_jit():
    apply = reward_fn((32,))
    params = RewardMLP((32,)).init(jax.random.PRNGKey(0), jnp.zeros((1, 2)), jnp.zeros((1, 1)))
    opt = optax.adam(1e-2)
    ring = ring_init(256, 2, 1)
    obs = jax.random.normal(jax.random.PRNGKey(1), (64, 2))
    act = jnp.zeros((64, 1))
    target = jnp.sign(obs[:, 0])
    upd = jax.jit(lambda p, o, r, k: tamer_update(apply, opt, p, o, r, (obs, act, jnp.ones(64), target), k, 200))
    params, _, ring, loss = upd(params, opt.init(params), ring, jax.random.PRNGKey(2))
    assert int(ring.size) == 64 and float(loss) < 0.5
    assert np.corrcoef(np.asarray(apply(params, obs, act)), np.asarray(target))[0, 1] > 0.9
