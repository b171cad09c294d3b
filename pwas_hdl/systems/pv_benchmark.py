"""Seed 004's parameter-varying benchmark (E1) and its 4-mode switching variant (E2).

Masti, Bernardini, Bemporad, "A machine-learning approach to synthesize virtual sensors for
parameter-varying systems", EJC 2021, eq. (14) and (16)-(18); assumption ids refer to
``shared/design/seed-specs/seed_004.md``.

Plant (14a)::

    x_{k+1} = H x_k + (alpha/2) atan(x_k) + log(rho_k + 1) F u_k      x in R^5, u in R^2
    y_k     = -(1 + exp(rho_k)) C x_k                                   C = [0 0 0 0 1]   (A1)

Scheduling parameter, the quantity to estimate:

* ``"random-walk"`` (14c)-(14d): ``p_k = 0.999 rho_k + 0.03 w_k``, ``w_k ~ N(0, 1)``;
  ``rho_{k+1} = p_k`` if ``|p_k| <= 0.95`` else ``p_k / 2``;
* ``"cosine"`` (16): ``p_k = cos(k / 200)`` passed through the same halving (14c);
* E2 (18): ``rho_{k+1} = floor(4 k / N) / 2`` (4 modes 0, 0.5, 1, 1.5 in equal blocks), alpha = 0.

``x_0 = 0``, ``rho_0 = 0`` (A2, no burn-in); natural logarithm (A3); ``u_k ~ N(0, I_2)``
(Section 4.2). The generators return noise-free data in physical units; normalisation and the
measurement noise of Section 4.2 are :func:`pwas_hdl.systems.normalization.normalize_with_noise`
(see :func:`make_pv_dataset`).
"""

from __future__ import annotations

import numpy as np

from pwas_hdl.errors import InputError, choice_text, option_text
from pwas_hdl.limits import check_seed
from pwas_hdl.systems.lorenz import PlantData
from pwas_hdl.systems.normalization import Normalization, normalize_with_noise

__all__ = [
    "H", "F", "C_ROWS", "MODES", "pv_benchmark", "switching4", "make_pv_dataset", "RHO_LAWS",
]

#: State matrix of eq. (14b), copied exactly.
H = np.array(
    [
        [0.0, 0.1, 0.0, 0.0, 0.0],
        [0.0, 0.0, -1.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 0.0, 1.0],
        [-0.00909, 0.0329, 0.29013, -1.05376, 1.69967],
    ]
)
#: Input matrix of eq. (14b), copied exactly (0.917661 has six decimals in the paper too).
F = np.array(
    [
        [-0.71985, -0.1985],
        [0.57661, 0.917661],
        [1.68733, -0.68733],
        [-2.14341, 2.94341],
        [1.0, 1.0],
    ]
)
#: Output rows: the paper prints ``[0 0 0 1]`` for a 5-state system (A1). ``"e5"`` (default) reads
#: it as the last state, ``"e4"`` as the fourth (the sensitivity check of A1).
C_ROWS = {"e5": np.array([0.0, 0.0, 0.0, 0.0, 1.0]), "e4": np.array([0.0, 0.0, 0.0, 1.0, 0.0])}
#: The four mode values of E2, eq. (18).
MODES = np.array([0.0, 0.5, 1.0, 1.5])
RHO_LAWS = ("random-walk", "cosine")
MAX_SAMPLES = 2_000_000


def _check_n(n: int) -> None:
    if not isinstance(n, (int, np.integer)) or n < 1:
        raise InputError(f"the number of samples must be an integer >= 1, got {n!r}")
    if n > MAX_SAMPLES:
        from pwas_hdl.errors import ResourceLimit

        raise ResourceLimit(f"{n} samples requested; the limit is {MAX_SAMPLES}")


def _halve(p: float) -> float:
    """Eq. (14c): keep ``p`` inside [-0.95, 0.95], halve it outside."""
    return p if -0.95 <= p <= 0.95 else p / 2.0


def _simulate(u: np.ndarray, rho: np.ndarray, alpha: float, c_row: np.ndarray) -> np.ndarray:
    """Outputs of eq. (14a) for given inputs (T, 2) and parameter sequence (T,); x_0 = 0."""
    x = np.zeros(5)
    y = np.empty(u.shape[0])
    gain_in = np.log(rho + 1.0)
    gain_out = -(1.0 + np.exp(rho))
    fu = u @ F.T
    for k in range(u.shape[0]):
        y[k] = gain_out[k] * (c_row @ x)
        x = H @ x + (0.5 * alpha) * np.arctan(x) + gain_in[k] * fu[k]
    return y


def pv_benchmark(
    n_samples: int,
    seed: int = 0,
    rho_law: str = "random-walk",
    alpha: float = 1.0,
    output_row: str = "e5",
    beta: float = 200.0,
) -> PlantData:
    """Noise-free data of the parameter-varying benchmark, eq. (14) (E1).

    Parameters
    ----------
    n_samples : int
        Samples ``k = 0 .. n_samples - 1``.
    seed : int
        Seed of the input ``u_k ~ N(0, I_2)`` and of the random walk ``w_k`` (14d).
    rho_law : {"random-walk", "cosine"}
        (14c)-(14d) or (16) with ``p_k = cos(k / beta)``.
    alpha : float
        Weight of the atan nonlinearity (paper: 1 in E1, 0 in E2).
    output_row : {"e5", "e4"}
        Reading of the printed output row (A1).
    beta : float
        Period parameter of (16) (paper: 200).

    Returns
    -------
    PlantData
        ``u`` (T, 2) named ``u1, u2``; ``y`` (T, 1); ``z = z_true = rho`` (T, 1), dimensionless.
    """
    _check_n(n_samples)
    if rho_law not in RHO_LAWS:
        raise InputError(choice_text(option_text("rho_law"), RHO_LAWS, rho_law))
    if output_row not in C_ROWS:
        raise InputError(f"output_row must be one of {', '.join(C_ROWS)}, got {output_row!r}")
    rng = np.random.default_rng(seed)
    u = rng.normal(0.0, 1.0, (n_samples, 2))
    rho = np.empty(n_samples)
    rho[0] = 0.0
    if rho_law == "random-walk":
        w = rng.normal(0.0, 1.0, n_samples)
        for k in range(n_samples - 1):
            rho[k + 1] = _halve(0.999 * rho[k] + 0.03 * w[k])
    else:
        for k in range(n_samples - 1):
            rho[k + 1] = _halve(float(np.cos(k / beta)))
    y = _simulate(u, rho, alpha, C_ROWS[output_row])
    return PlantData(u, y[:, None], rho[:, None].copy(), rho[:, None].copy(), {"u": ["u1", "u2"], "y": ["y"], "z": ["rho"]})


def switching4(n_samples: int, seed: int = 0, output_row: str = "e5") -> PlantData:
    """Noise-free data of the 4-mode switching linear system of E2 (eqs. 17-18).

    The plant is (14a) with ``alpha = 0`` and ``rho_{k+1} = floor(4 k / N) / 2`` with
    ``N = n_samples`` (B2: the training and the test set each use their own N), ``rho_0 = 0``.
    Mode 1 (rho = 0) has ``log(rho + 1) = 0``: the output is identically zero there.

    Parameters
    ----------
    n_samples : int
        Samples ``k = 0 .. n_samples - 1`` (also the ``N`` of eq. 18: four blocks of ``N / 4``).
    seed : int
        Seed of the input ``u_k ~ N(0, I_2)``.
    output_row : {"e5", "e4"}
        Reading of the printed output row (A1).

    Returns
    -------
    PlantData
        As :func:`pv_benchmark`; ``z`` holds the mode value in {0, 0.5, 1, 1.5}.
    """
    _check_n(n_samples)
    if output_row not in C_ROWS:
        raise InputError(f"output_row must be one of {', '.join(C_ROWS)}, got {output_row!r}")
    rng = np.random.default_rng(seed)
    u = rng.normal(0.0, 1.0, (n_samples, 2))
    k = np.arange(n_samples)
    rho = np.zeros(n_samples)
    rho[1:] = np.floor(4 * k[:-1] / n_samples) / 2.0
    y = _simulate(u, rho, 0.0, C_ROWS[output_row])
    return PlantData(u, y[:, None], rho[:, None].copy(), rho[:, None].copy(), {"u": ["u1", "u2"], "y": ["y"], "z": ["rho"]})


def make_pv_dataset(
    system: str,
    n_train: int,
    n_test: int,
    seed: int = 0,
    noise: float = 0.03,
    rho_law: str = "random-walk",
    test_rho_law: str | None = None,
    output_row: str = "e5",
) -> tuple[PlantData, PlantData, Normalization]:
    """Training and test sets as in Section 4.2: independent runs, normalised, noisy.

    Parameters
    ----------
    system : {"pv-benchmark", "switching-4"}
    n_train, n_test : int
        Samples of each set (paper: up to 25 000 and 5 000).
    seed : int
        One run: the plant seeds of both sets and the noise are drawn from it.
    noise : float
        Noise std after normalisation (paper 0.03).
    rho_law, test_rho_law : str
        Parameter law of the training and the test set (Table 7 trains on "random-walk" and tests on
        "cosine"); ``test_rho_law`` defaults to ``rho_law``. E1 only.
    output_row : str
        A1 reading.

    Returns
    -------
    train, test : PlantData
        Normalised with the training statistics; ``z_true`` noise-free (normalised).
    norm : Normalization
    """
    check_seed(seed)
    ss = np.random.SeedSequence(seed)
    s_train, s_test, s_noise = (int(s.generate_state(1)[0]) for s in ss.spawn(3))
    if system == "pv-benchmark":
        tr = pv_benchmark(n_train, s_train, rho_law, output_row=output_row)
        te = pv_benchmark(n_test, s_test, test_rho_law or rho_law, output_row=output_row)
        noisy_target = True
    elif system == "switching-4":
        tr = switching4(n_train, s_train, output_row=output_row)
        te = switching4(n_test, s_test, output_row=output_row)
        noisy_target = False  # "the measurements about the mode ... are noise-free" (B5)
    else:
        raise InputError(f"unknown system {system!r}; use pv-benchmark or switching-4")
    trn, (ten,), norm = normalize_with_noise(tr, [te], noise, np.random.default_rng(s_noise), noisy_target)
    return trn, ten, norm
