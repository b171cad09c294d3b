"""Benchmark plants and the seed papers' own estimators (baselines).

Plants: the Lorenz system of seed 000 (lorenz), the synthetic closed-loop helicopter standing in
for seed 000's CE150 (helicopter), the three-tank system of seed 001 (three_tank), the switched
linear system of seed 003 (switched_linear). Estimators: the disturbance-decoupled sensors and
design procedure of seed 001 (decoupled_observer), the switched observer of seed 003
(switched_observer), the HLNN baseline of seed 000 (hlnn).
"""
