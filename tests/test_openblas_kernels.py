"""CHOLMOD (cvxopt's wheel) with OpenBLAS kernels the CPU supports (issue 18, twelfth pass): the
bundled OpenBLAS 0.3.15 takes its SSE3 kernels on CPUs newer than itself, 2.7x slower per
supernodal factorisation on this project's machine; ``import_cholmod`` picks the kernels from the
CPU's own flags, leaves a user's ``OPENBLAS_CORETYPE`` alone and does not pass its own on."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from scipy import sparse

from pwas_hdl.fit.sparse_cholesky import OPENBLAS_CORETYPES, cholmod_available, openblas_coretype

AVX512 = "fpu sse sse2 avx avx2 fma avx512f avx512cd avx512bw avx512dq avx512vl"


@pytest.mark.parametrize("flags,core", [
    (AVX512, "SkylakeX"),
    ("fpu sse sse2 avx avx2 fma", "Haswell"),
    ("fpu sse sse2 avx avx512f avx2", None),        # avx2 without fma: neither set
    ("fpu sse sse2 sse3", None),
])
def test_coretype_from_the_flags(flags, core):
    assert openblas_coretype(f"processor\t: 0\nflags\t\t: {flags}\n") == core


def test_coretype_needs_every_cpu_to_have_the_flags():
    two = f"processor\t: 0\nflags\t\t: {AVX512}\n\nprocessor\t: 1\nflags\t\t: fpu sse avx avx2 fma\n"
    assert openblas_coretype(two) == "Haswell"
    assert openblas_coretype("no flags here") is None
    assert [c for c, _ in OPENBLAS_CORETYPES] == ["SkylakeX", "Haswell"]


def _child(code: str, env: dict) -> str:
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


CHILD = """
import os, numpy as np, threadpoolctl
from scipy import sparse
from pwas_hdl.fit.sparse_cholesky import PatternCholesky, openblas_coretype
rng = np.random.default_rng(0)
b = sparse.random(300, 300, density=0.05, random_state=1)
a = (b @ b.T + 300 * sparse.identity(300)).tocsc()
chol = PatternCholesky(a)
chol.factorize(chol.align(a))
x = rng.standard_normal(300)
res = np.linalg.norm(a @ chol.solve(a @ x) - a @ x) / np.linalg.norm(a @ x)
arch = [i['architecture'] for i in threadpoolctl.threadpool_info() if i['prefix'] == 'libopenblas']
print(openblas_coretype(), arch[0] if arch else None, os.environ.get('OPENBLAS_CORETYPE'), res < 1e-13)
"""


@pytest.mark.skipif(not cholmod_available() or not sys.platform.startswith("linux"), reason="needs cvxopt on Linux")
def test_cholmod_loads_the_cpus_kernels_and_solves():
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    core, arch, left, ok = _child(CHILD, env).split()
    assert ok == "True" and left == "None"  # solved to rounding; the variable not passed on
    if core != "None":
        assert arch == core
    # a user's setting wins
    core2, arch2, left2, ok2 = _child(CHILD, {**env, "OPENBLAS_CORETYPE": "Prescott"}).split()
    assert (arch2, left2, ok2) == ("Prescott", "Prescott", "True")
