"""Learners: DDPG (the backbone) and Deep COACH."""
