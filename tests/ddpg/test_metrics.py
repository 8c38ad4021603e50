"""The paper's four metrics on hand-made per-step signals."""

from __future__ import annotations

import numpy as np
import pytest

from mjx_protamer.experiments import metrics


def test_episode_metrics_by_hand():
    contact = np.array([0, 0, 0, 1, 1, 0, 1, 0, 0, 0])
    regions = np.zeros((10, 8))
    regions[3, 2] = 1
    regions[4, [2, 5]] = 1
    regions[6, 7] = 1
    speed = np.array([0.0, 0.5, 2.0, 2.0, 0.99, 1.0, 3.0, 0.1, 1.5, 2.5])
    m = metrics.episode_metrics(contact, regions, speed)
    assert m == {"first_touch_step": 3, "contact_rate": 0.3, "unique_regions": 3, "freeze_ratio": 0.4}


def test_no_touch_counts_the_episode_length():
    m = metrics.episode_metrics(np.zeros(7), np.zeros((7, 8)), np.full(7, 5.0))
    assert m == {"first_touch_step": 7, "contact_rate": 0.0, "unique_regions": 0, "freeze_ratio": 0.0}
    m = metrics.episode_metrics(np.ones(4), np.ones((4, 8)), np.zeros(4))
    assert m == {"first_touch_step": 0, "contact_rate": 1.0, "unique_regions": 8, "freeze_ratio": 1.0}


def test_summarize_means_and_per_episode_lists():
    contact = np.array([[0, 1, 1, 1], [0, 0, 0, 0]])
    regions = np.zeros((2, 4, 8))
    regions[0, 1:, 0] = 1
    regions[0, 3, 4] = 1
    speed = np.array([[2, 2, 0, 0], [0, 0, 0, 0]])
    s = metrics.summarize(contact, regions, speed)
    assert s["per_episode"]["first_touch_step"] == [1, 4]
    assert s["first_touch_step"] == 2.5
    assert s["contact_rate"] == pytest.approx(0.375)
    assert s["unique_regions"] == 1.0
    assert s["freeze_ratio"] == pytest.approx(0.75)
    assert s["episodes"] == 2
    assert "unique_regions" in metrics.format_table(s, metrics.PAPER_DDPG)


def test_mismatched_lengths_are_an_error():
    with pytest.raises(ValueError):
        metrics.episode_metrics(np.zeros(3), np.zeros((4, 8)), np.zeros(3))


def test_counts_in_jax_give_the_numpy_metrics():
    """The jitted evaluator counts with jax.numpy; the metrics must be the NumPy ones, number for number."""
    import jax.numpy as jnp

    rng = np.random.default_rng(0)
    contact = (rng.random((3, 9)) < 0.3).astype(np.float32)
    contact[2] = 0  # an episode without a touch: first_touch_step is the length
    regions = (rng.random((3, 9, 8)) < 0.2).astype(np.float32)
    speed = rng.random((3, 9)).astype(np.float32) * 2
    counts = metrics.episode_counts(jnp.asarray(contact), jnp.asarray(regions), jnp.asarray(speed), 0.7, xp=jnp)
    s = metrics.from_counts({k: np.asarray(v) for k, v in counts.items()}, 9)
    assert s == metrics.summarize(contact, regions, speed, 0.7)
    assert s["per_episode"] == {name: [metrics.episode_metrics(c, r, v, 0.7)[name] for c, r, v in
                                       zip(contact, regions, speed)] for name in metrics.METRIC_NAMES}
    assert s["region_touch_frequency"] == [float(f) for f in (regions > 0).reshape(-1, 8).mean(axis=0)]
