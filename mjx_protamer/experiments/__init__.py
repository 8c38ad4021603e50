"""Experiments: metrics, runs that reproduce the paper's table and figures, plots."""
