"""Deep COACH: a Gaussian policy learned from corrective human feedback."""
