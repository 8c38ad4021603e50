"""The feedback-vs-baseline contrast table2 reports: issue 8's unpaired criterion and the paired interval."""

import numpy as np
import pytest

from mjx_protamer.experiments.table2 import contrast

T4 = 2.7764451051977987  # Student t, 97.5%, 4 degrees of freedom

# teacher_score per seed, habituation on, lateral rule (docs/experiments.md): DTK above DDPG on every seed
DDPG = [-0.166, 0.404, 0.538, 0.199, 0.0651]
DTK = [0.274, 0.614, 0.739, 0.887, 0.398]


def _half_width(x):
    return T4 * np.std(x, ddof=1) / np.sqrt(len(x))


def test_contrast_gives_issue_8s_verdict_and_a_paired_interval():
    c = contrast(DDPG, DTK)
    assert c["difference"] == pytest.approx(np.mean(DTK) - np.mean(DDPG))
    assert c["ci95_sum"] == pytest.approx(_half_width(DDPG) + _half_width(DTK))
    # 0.37 apart, the two intervals sum to 0.65: not beyond them; but every seed rose, by 0.20-0.69
    assert c["beyond_ci95_sum"] is False
    diffs = np.subtract(DTK, DDPG)
    assert c["paired"]["seed_values"] == pytest.approx(list(diffs))
    assert c["paired"]["ci95"] == pytest.approx(_half_width(diffs))
    assert c["paired_beyond_zero"] is True
    # the pairing is what carries it: the same values with the seeds shuffled are no longer paired-significant
    shuffled = contrast(DDPG, [DTK[i] for i in (3, 0, 1, 4, 2)])
    assert shuffled["difference"] == pytest.approx(c["difference"])
    assert shuffled["paired_beyond_zero"] is False


def test_contrast_beyond_the_sum_and_with_missing_seeds():
    assert contrast([-0.07, -0.03, -0.04, -0.08, -0.10], [0.56, 0.86, 0.69, 0.80, -0.16])["beyond_ci95_sum"] is True
    c = contrast([0.1, None, 0.2, 0.1, 0.0], [0.5, 0.6, None, 0.5, 0.4])
    assert c["paired"]["seed_values"][1:3] == [None, None]
    assert c["paired"]["mean"] == pytest.approx(0.4)
    assert contrast([0.1], [0.5])["difference"] is None  # one seed: no interval, no verdict
