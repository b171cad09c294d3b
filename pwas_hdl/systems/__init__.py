"""Benchmark plants and the seed papers' own estimators (baselines): the Lorenz system of seed 000 (lorenz)."""
