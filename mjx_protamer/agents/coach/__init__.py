"""Deep COACH (Arumugam et al. 2019): a Gaussian policy learned from corrective human feedback.

- `config.CoachConfig`: hyper-parameters (L = 10, lambda = 0.35, delay 1 step, lr 2.5e-4, ...);
- `networks.GaussianPolicy`: tanh-squashed mean MLP and a state-independent log std;
- `losses.coach_loss`: the eligibility-trace surrogate with importance ratios and an entropy bonus;
- `replay.WindowReplay`: windows of L steps, each with the feedback that judged it;
- `learner.CoachLearner`: the host driver: act, record steps, turn feedback into windows and updates.

How a scalar signal becomes a correction: see `learner.py` and docs/human_feedback.md.
"""

from mjx_protamer.agents.coach.config import CoachConfig
from mjx_protamer.agents.coach.learner import CoachLearner

__all__ = ["CoachConfig", "CoachLearner"]
