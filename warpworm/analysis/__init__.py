"""Measures on simulations: gait metrics and search, the paper's virtual experiments, fits, plots."""
