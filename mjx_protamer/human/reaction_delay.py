"""A person's reaction delay, measured from a recorded finetune session. NumPy, no JAX.

Why: credit assignment spreads each feedback over the reaction-delay distribution of its channel, and that
distribution's spread is what ranks the channels' reward models (docs/experiments.md, "what the channels'
reaction delays explain": at the keyboard's 0.35 +- 0.1 s the voice channels' models reach the keyboard's;
at speech's 0.8 +- 0.25 s the keyboard's exact labels fall to speech's level). The presets are assumptions
from the reaction-time literature; this measures the person in front of the infant, through the channel
they use, including what the page's frames and the voice front end add.

Protocol (docs/human_feedback.md, "Measuring your reaction delay"): a finetune session in which the person
gives feedback (a key, or a word) as soon as they see a named touch begin, e.g. "say 'good' each time a hand
arrives at the head" (`finetune --calibrate head`); the session records when each touch began on the
presentation clock (`touches.py`, `shown_touches`) and when each feedback began (`t_start`: the key press, or
the utterance's onset from the VAD).

Model: a feedback is either a reaction to one of the touch onsets before it, with delay ~ Normal(mean, std)
inside the window [lo, hi] (a response within 0.1 s of an onset is an anticipation, not a reaction), or
unrelated (a feedback on something else, a touch missed in the record), at a constant rate over the session.
For feedback j and onsets i, p(j) = pi * (1/N) sum_i N(t_j - s_i; mean, std) + (1 - pi) / T, N onsets in T
seconds. EM fits (mean, std, pi), started from a grid of means across the window (the likelihood has a local
maximum per onset spacing) and the best kept; the mean's CI by bootstrap over the feedback. The channel's
`delay_min_s` is the 2.5th percentile of the delays of the feedback more likely a reaction than not (the very
fastest is often an unrelated feedback).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from mjx_protamer.human.attention import is_attention

WINDOW_S = (0.1, 2.5)  # shortest and longest delay counted as a reaction
# A touch begins when it follows at least this long without that touch (contact chatter of a few steps is one
# touch). 0.1 s: every simulated person who sees re-touches after gaps of 0.1-0.5 s is fitted (a coarser one
# 0.02-0.05 s early with a voice channel's delay), while at 0.3 s half of those who see re-touches after 0.1 s
# gaps get no fit (docs/experiments.md, "Measuring a reaction delay from a session").
MIN_GAP_S = 0.1
MIN_REACTIONS = 10  # fewer feedback events with an onset in their window cannot fit a spread
# In a calibration most feedback reacts to the touch; feedback at random times can still hold a tight cluster
# of 10-20% "reactions" (4 of 10 random sessions of 100 events fitted with MIN_REACTIONS alone), which this
# rules out (none of the tests' 30).
MIN_REACTING = 0.5
BOOTSTRAP = 200  # resamples of the feedback for the mean's CI


@dataclasses.dataclass(frozen=True)
class DelayFit:
    mean_s: float
    std_s: float
    min_s: float  # 2.5th percentile of the delays of the feedback judged reactions (responsibility >= 0.5)
    mean_ci95_s: float  # half-width of the 95% bootstrap interval (the larger side)
    # the fitted Normal's mass outside the window: the fit ignores it (untruncated moments), so above a few
    # percent the std and the reacting fraction come out low (the command notes it above 2.5%); widen --window-s
    outside_window: float
    reacted: float  # pi: the fraction of the feedback that reacted to an onset
    reactions: float  # sum of the responsibilities
    n_feedback: int
    n_onsets: int
    window_s: tuple[float, float]
    delays_s: tuple[float, ...]  # per feedback: delay to its most likely onset (nan: none in the window)
    responsibility: tuple[float, ...]  # per feedback: P(a reaction to some onset)

    def channel_overrides(self, prefix: str = "feedback.teacher.channel") -> list[str]:
        """The `--set` values that make credit (and a simulated teacher) use this delay."""
        return [f"{prefix}.delay_mean_s={self.mean_s:.3f}", f"{prefix}.delay_std_s={self.std_s:.3f}",
                f"{prefix}.delay_min_s={self.min_s:.3f}"]

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["delays_s"] = [None if math.isnan(x) else round(x, 5) for x in self.delays_s]
        d["responsibility"] = [round(x, 5) for x in self.responsibility]
        d["window_s"] = list(self.window_s)
        return d


class NotEnoughReactions(ValueError):
    pass


def _candidates(onsets: np.ndarray, responses: np.ndarray, window) -> tuple[np.ndarray, np.ndarray]:
    """(delays (J, M), mask (J, M)): each response's delays to the onsets inside its window."""
    lo, hi = window
    first = np.searchsorted(onsets, responses - hi, side="left")
    last = np.searchsorted(onsets, responses - lo, side="right")
    m = max(1, int((last - first).max(initial=0)))
    idx = first[:, None] + np.arange(m)[None, :]
    mask = idx < last[:, None]
    delays = responses[:, None] - onsets[np.minimum(idx, len(onsets) - 1)] if len(onsets) else np.zeros_like(idx, float)
    return np.where(mask, delays, 0.0), mask


def _em(delays, mask, rate_ratio: float, mean: float, std: float, iters: int, tol: float):
    """EM from one start; returns (log-likelihood, mean, std, pi, per-candidate responsibilities), the
    likelihood and responsibilities those of the returned parameters."""
    pi, ll_prev = 0.5, -np.inf
    for _ in range(iters + 1):
        z = (delays - mean) / std
        dens = np.where(mask, np.exp(-0.5 * z * z) / (std * math.sqrt(2 * math.pi)), 0.0)
        react = pi * rate_ratio * dens  # rate_ratio = T / N: a reaction's density against the background's 1/T
        total = react.sum(axis=1) + (1.0 - pi)
        resp = react / total[:, None]
        ll = float(np.log(total).sum())
        w = resp.sum()
        if ll - ll_prev < tol or w <= 1e-9:
            break
        ll_prev = ll
        mean = float((resp * delays).sum() / w)
        std = max(0.01, float(np.sqrt((resp * (delays - mean) ** 2).sum() / w)))
        pi = float(np.clip(w / len(delays), 1e-6, 1 - 1e-6))
    return ll, mean, std, pi, resp


def fit_reaction_delay(onsets, responses, duration_s: float, window=WINDOW_S, iters: int = 500,
                       tol: float = 1e-9) -> DelayFit:
    """Fit the delay from stimulus onset times and feedback onset times (seconds, one clock) over a session
    of `duration_s`. Raises NotEnoughReactions when fewer than MIN_REACTIONS feedback have an onset in
    their window."""
    onsets = np.sort(np.asarray(onsets, np.float64))
    responses = np.sort(np.asarray(responses, np.float64))
    lo, hi = map(float, window)
    if not (0 <= lo < hi and math.isfinite(hi)):
        raise ValueError(f"the delay window must be 0 <= lo < hi < inf, got {window}")
    delays, mask = _candidates(onsets, responses, (lo, hi))
    has = mask.any(axis=1)
    if int(has.sum()) < MIN_REACTIONS:
        raise NotEnoughReactions(f"only {int(has.sum())} of {len(responses)} feedback events came {lo:g}-{hi:g} s "
                                 f"after an onset ({len(onsets)} onsets); a fit needs at least {MIN_REACTIONS}")
    rate_ratio = max(duration_s, hi) / len(onsets)
    best = None
    for m0 in np.linspace(lo, hi, max(3, math.ceil((hi - lo) / 0.1) + 1))[1:-1]:  # about every 0.1 s
        out = _em(delays, mask, rate_ratio, float(m0), 0.15, iters, tol)
        if best is None or out[0] > best[0] + 1e-9:
            best = out
    _, mean, std, pi, resp = best
    react = resp.sum(axis=1)
    if react.sum() < MIN_REACTIONS - 1e-3 or pi < MIN_REACTING:  # (pi is clipped below 1)
        raise NotEnoughReactions(f"only {react.sum():.0f} of {len(responses)} feedback events ({100 * pi:.0f}%) look "
                                 f"like reactions to the {len(onsets)} onsets; a fit needs at least {MIN_REACTIONS} "
                                 f"and {100 * MIN_REACTING:.0f}% of the feedback")
    likeliest = np.where(has, delays[np.arange(len(delays)), resp.argmax(axis=1)], np.nan)
    sure = (react >= 0.5) & has
    fastest = float(np.percentile(likeliest[sure], 2.5)) if sure.any() else max(lo, mean - 2.0 * std)
    n = float(react.sum())
    inside = 0.5 * (math.erf((hi - mean) / (std * math.sqrt(2))) - math.erf((lo - mean) / (std * math.sqrt(2))))
    # The CI by bootstrap over the feedback events (EM again from the fit on each resample): 1.96 std / sqrt(n)
    # alone ignores which onset each feedback answered and held the population mean for 79 of 90 simulated
    # persons (docs/experiments.md, "Measuring a reaction delay from a session").
    rng = np.random.default_rng(0)
    boot = []
    for _ in range(BOOTSTRAP):
        i = rng.integers(0, len(delays), len(delays))
        boot.append(_em(delays[i], mask[i], rate_ratio, mean, std, iters, 1e-6)[1])
    lo_b, hi_b = np.percentile(boot, [2.5, 97.5])
    return DelayFit(mean_s=mean, std_s=std, min_s=fastest, mean_ci95_s=float(max(mean - lo_b, hi_b - mean)),
                    outside_window=1.0 - inside,
                    reacted=pi, reactions=n, n_feedback=len(responses), n_onsets=len(onsets), window_s=(lo, hi),
                    delays_s=tuple(float(x) for x in likeliest), responsibility=tuple(float(x) for x in react))


# --------------------------------------------------------------------------- a recorded session's feedback

def feedback_onsets(records: list[dict], sign: str = "any") -> np.ndarray:
    """t_start of the session's feedback events (attention events excluded) of a sign: '+', '-' or 'any'
    (nonzero)."""
    keep = {"+": lambda v: v > 0, "-": lambda v: v < 0, "any": lambda v: v != 0}[sign]
    return np.asarray(sorted(e.t_start for r in records for e in r.get("events", [])
                             if not is_attention(e) and keep(e.value)), np.float64)
