"""What each learner of a live session is, where code outside the builder must know: one table of traits.

The spec's checks and manifest, the session's save and `reproduce live` ask a learner's traits, never its name,
so a learner added here (and built in live/build.py, the one place that chooses one) needs no branch elsewhere.
"""

from __future__ import annotations

import dataclasses


@dataclasses.dataclass(frozen=True)
class LearnerKind:
    # learns a model of the person's reward (DeepTAMER's r_hat), which `reproduce live` scores against the rule
    reward_model: bool
    # keeps learning with nobody speaking (DDPG from the intrinsic reward). Deep COACH learns from corrections
    # alone: without feedback its policy is the checkpoint's, so `reproduce live` runs no session for that arm
    learns_without_feedback: bool
    # takes silences as feedback (the reward model's silent rows), so it can be told to count them only while the
    # person watches (`feedback.credit.silence_needs_attention`)
    counts_silences: bool
    # a pretrain run's learner: starts from the checkpoint's replay, and its save is a run `protamer eval` and
    # `protamer finetune --checkpoint` load (a config.yaml beside the networks)
    pretrain_run: bool
    # takes --coach-init and --coach-log-std (the Gaussian policy Deep COACH samples from)
    gaussian_policy: bool
    # learns by updates from a replay, as many as the pacer gives it (the spare time, or what events bought):
    # a session reports its updates per shown step. Deep COACH updates once per correction
    replay_updates: bool


LEARNER_KINDS = {
    "ddpg": LearnerKind(reward_model=True, learns_without_feedback=True, counts_silences=True, pretrain_run=True,
                        gaussian_policy=False, replay_updates=True),
    "coach": LearnerKind(reward_model=False, learns_without_feedback=False, counts_silences=False,
                         pretrain_run=False, gaussian_policy=True, replay_updates=False),
}
LEARNERS = tuple(LEARNER_KINDS)
