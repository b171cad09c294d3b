"""A warm-started sigma sweep checked solve by solve against the direct solve (the factor-PCG rules' tests)."""

from __future__ import annotations

import numpy as np

from pwas_hdl.fit import regularized_lsq as rl


def sweep_against_direct(solver, hth, b, gam, sigmas, order, cap: int) -> list[str]:
    """Solve ``hth + sigma gam`` for ``sigmas[order]`` in that order, each warm-started from the
    previous solution; a factor-PCG solve must converge within ``cap`` iterations and the stated
    weight bound of the direct solve, any other must equal it. Returns the methods used."""
    w, methods = None, []
    for i in order:
        w, info = solver.solve(hth, b, float(sigmas[i]), x0=w)
        methods.append(info.method)
        wd = rl._solve_spd((hth + sigmas[i] * gam).tocsc(), b)
        if info.method == "factor-pcg":
            assert info.converged and info.rel_residual <= rl.CG_RTOL
            assert 0 < info.iterations <= cap
            assert float(np.linalg.norm(w - wd)) <= info.weight_bound
        else:
            np.testing.assert_allclose(w, wd, rtol=1e-8, atol=1e-10)
    return methods
