"""Where a table2 run's reward models err on their own test states (issue 8's `r_hat_corr_test`).

Reads a finished `protamer reproduce table2 --out DIR` run (its config.yaml, reward_models/<condition>/ and
test_states_<condition>.npz: the sampled test-episode states with their hidden score) and prints one JSON line
per seed: how the test states split by hidden score, r_hat's mean and spread within each score, the
correlation, and the correlation r_hat would have with its within-score spread removed (each state given its
class mean): the part of the shortfall that comes from ranking states of the same score differently rather
than from the classes' means. A compliant policy's test states are nearly all of one score, so a small spread
within it costs much correlation. Also: how much of each score lies in runs shorter than the teacher's noticing
time (the rule's longest `sustain`), the median length of the runs its states lie in, and the correlation with a "perceivable" score in which such runs take
the score of the run before them (a teacher who notices a touch after 0.1 s cannot judge a 50 ms lift of the
hand): a diagnostic beside the issue's metric, not a replacement. Where the rule reads only the observation and
the action (e.g. the lateral rule's touch norms), `by_clauses_held` splits the states further by which clauses
hold ("c0+c1": both hands touching, score 0 under the lateral rule; "none": no clause), with r_hat's mean there:
which states of one score the model over-rates.

    protamer analyze r-hat-on-test-states runs/table2 [--condition DTK]
"""

from __future__ import annotations

from pathlib import Path

import jax
import numpy as np

from mjx_protamer.experiments.stats import pearson as corr


def runs_of(x: np.ndarray):
    """(start, length, value) of each run of equal values of a 1-D array."""
    edges = np.flatnonzero(np.diff(x) != 0) + 1
    starts = np.concatenate([[0], edges])
    lengths = np.diff(np.concatenate([starts, [len(x)]]))
    return starts, lengths, x[starts]


def perceivable(score_episode: np.ndarray, min_samples: int) -> np.ndarray:
    """The score with every run shorter than `min_samples` (after the first) given the preceding run's score."""
    out = score_episode.copy()
    for start, length, _ in zip(*runs_of(score_episode)):
        if start > 0 and length < min_samples:
            out[start:start + length] = out[start - 1]
    return out


def clause_cells(rule, obs, action) -> np.ndarray | None:
    """A label per state naming the clauses that hold there ("c0", "c0+c1", "none"), or None when a clause
    reads something the saved test states lack (reward terms, body regions)."""
    from mjx_protamer.config import ConfigError
    from mjx_protamer.human.teachers import clauses_hold, rule_signals, signal_columns

    try:
        cols = signal_columns([c.signal for c in rule], (), obs.shape[-1], action.shape[-1])
    except ConfigError:
        return None
    sig = rule_signals(cols, obs, action, None, xp=np)
    held = clauses_hold(rule, sig, xp=np)
    names = np.array(["+".join(f"c{i}" for i in np.flatnonzero(h)) or "none" for h in held.reshape(-1, len(rule))])
    return names.reshape(held.shape[:-1])


def r_hat_on_test_states(run: Path, condition: str) -> list[dict]:
    """One line a seed of the condition's test states; a run or condition that is not there raises ConfigError."""
    from mjx_protamer.experiments.table2 import STATE_STRIDE, load_condition_reward_models, load_finished_condition

    cfg, states = load_finished_condition(run, condition)
    obs, action, score = states["obs"], states["action"], states["score"]
    nets, params = load_condition_reward_models(run, cfg, condition, obs.shape[-1], action.shape[-1])
    r_hat = np.asarray(jax.jit(jax.vmap(nets.apply))(params, obs, action))
    per_episode = cfg.pretrain.train.episode_length // STATE_STRIDE  # the samples are whole episodes in order
    notice = max(c.sustain for c in cfg.feedback.teacher.rule)
    min_samples = max(1, -(-notice // STATE_STRIDE))
    cells = clause_cells(cfg.feedback.teacher.rule, obs, action)
    lines = []
    for i, seed in enumerate(cfg.seeds):
        r, s = r_hat[i], score[i]
        classes = {}
        class_mean = np.zeros_like(r)
        episodes = s.reshape(-1, per_episode)
        run_len = np.zeros(episodes.shape, int)  # the length (samples) of the run each state lies in
        for e, ep in enumerate(episodes):
            for start, length, _ in zip(*runs_of(ep)):
                run_len[e, start:start + length] = length
        run_len = run_len.reshape(-1)
        short = run_len < min_samples
        sample_s = STATE_STRIDE * cfg.feedback.dt
        seen = np.concatenate([perceivable(ep, min_samples) for ep in episodes])
        for v in np.unique(s):
            m = s == v
            classes[f"{v:+.1f}"] = {"fraction": round(float(m.mean()), 3), "r_hat_mean": round(float(r[m].mean()), 3),
                                    "r_hat_std": round(float(r[m].std()), 3),
                                    "in_runs_shorter_than_noticing": round(float(short[m].mean()), 3),
                                    "median_run_s": round(float(np.median(run_len[m])) * sample_s, 3)}
            class_mean[m] = r[m].mean()
        by_cell = None if cells is None else {
            str(c): {"fraction": round(float((cells[i] == c).mean()), 3), "score": float(s[cells[i] == c][0]),
                     "r_hat_mean": round(float(r[cells[i] == c].mean()), 3),
                     "r_hat_std": round(float(r[cells[i] == c].std()), 3)}
            for c in np.unique(cells[i])}
        rnd = lambda x: None if x is None else round(x, 3)
        lines.append({"seed": seed, "states": int(len(s)), "score_std": round(float(s.std()), 3),
                      "r_hat_corr_test": rnd(corr(r, s)),
                      "corr_without_spread_within_score": rnd(corr(class_mean, s)),
                      "corr_with_perceivable_score": rnd(corr(r, seen)),
                      "noticing_steps": notice, "by_score": classes, "by_clauses_held": by_cell})
    return lines
