"""`protamer analyze r-hat-on-test-states`: the "perceivable" score merges runs shorter than the teacher's
noticing time."""

import numpy as np

from mjx_protamer.analyze import r_hat_on_test_states


def test_runs_are_found_with_their_lengths_and_values():
    starts, lengths, values = r_hat_on_test_states.runs_of(np.array([1, 1, 0, 0, 0, 1, -1]))
    assert starts.tolist() == [0, 2, 5, 6] and lengths.tolist() == [2, 3, 1, 1] and values.tolist() == [1, 0, 1, -1]


def test_a_lift_shorter_than_noticing_takes_the_touch_around_it_and_a_long_one_stays():
    ep = np.array([0, 1, 1, 1, 0, 1, 1, 0, 0, 0, 0, 1], float)
    seen = r_hat_on_test_states.perceivable(ep, min_samples=3)
    # the episode's first run keeps its score; the 1-sample lift is merged; the 4-sample gap stays; the last
    # 1-sample touch is too short to notice and takes the gap's 0
    assert seen.tolist() == [0, 1, 1, 1, 1, 1, 1, 0, 0, 0, 0, 0]
    assert r_hat_on_test_states.corr(np.array([0.0, 1.0]), np.array([0.0, 2.0])) == 1.0
    assert r_hat_on_test_states.corr(np.ones(3), np.arange(3.0)) is None


def test_states_split_by_the_clauses_that_hold_and_rules_reading_regions_are_skipped():
    from mjx_protamer.human.teachers import Clause

    lateral = (Clause("obs_norm:2:4", 1.0, above=0.05), Clause("obs_norm:0:2", -1.0, above=0.05))
    obs = np.zeros((2, 3, 4), np.float32)  # (seeds, states, obs)
    obs[0, 0, 2] = 1.0  # right only
    obs[0, 1, [0, 3]] = 1.0  # both hands
    obs[1, 2, 1] = 0.04  # a left-hand graze below the clause's threshold: no clause holds
    cells = r_hat_on_test_states.clause_cells(lateral, obs, np.zeros((2, 3, 1), np.float32))
    assert cells.tolist() == [["c0", "c0+c1", "none"], ["none", "none", "none"]]
    head = (Clause("region:head", 1.0, above=0.5),)
    assert r_hat_on_test_states.clause_cells(head, obs, np.zeros((2, 3, 1), np.float32)) is None
