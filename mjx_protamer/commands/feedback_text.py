"""How an accepted feedback event is described, in the terminal and on the live page."""

from __future__ import annotations


def outcome_text(run, got, why, learner: str) -> str:
    """What an accepted event did: the steps it credited (DDPG) or corrected (COACH), or why nothing."""
    if why is not None:
        return f"accepted, not used: {why}"
    if learner == "coach":
        c = run.learner.config
        end = got - c.human_delay_steps
        return (f"accepted, corrects steps {end - c.window + 1}..{end} (the window "
                f"{c.human_delay_steps} steps before step {got})")
    return f"accepted, credited steps {min(got.steps)}..{max(got.steps)} (lands on step {got.step})"
