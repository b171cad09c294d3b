"""Bit-true argmax of the PWAS output codes: the class decision of the hardware classifier.

A PWAS classifier (:mod:`pwas_hdl.fit.classifier`) has ``C`` one-hot score targets on one grid;
its hardware adds an argmax stage after the core (:class:`pwas_hdl.hdl.argmax.ArgmaxStage`). This
module is the stage's bit-true specification, on the core's *output codes* (signed integers,
after rounding and saturation, exactly what the core puts in its payload):

* a pairwise compare tree in the one reduction order of :mod:`pwas_hdl.fixedpoint.reduction`: a
  node combines the winners ``(i_a, v_a)`` of a lower block of class indices and ``(i_b, v_b)``
  of the next block and keeps ``b`` only if ``v_b > v_a`` (``select="max"``; ``v_b < v_a`` for
  ``select="min"``), otherwise ``a``;
* hence every node returns the *lowest* index among the best values of its block, and the root
  the lowest index among the best codes: exactly ``numpy.argmax`` (``numpy.argmin``), the tie
  rule of the software classifier (:func:`pwas_hdl.fit.classifier.decide`).

Relation to the float classifier. Let ``s(x)`` be the float scores at the physical input ``x_q``
the input codes represent (:meth:`FixedPointModel.reference
<pwas_hdl.fixedpoint.bittrue.FixedPointModel.reference>`) and ``e`` the model's error bound
(``error_bound``, physical units): every output code satisfies ``|code * lsb - s_i| <= e`` (no
saturation). If the float winner ``a`` leads every other class by more than ``2 e``
(``s_a - s_b > 2 e``) then ``code_a > code_b`` strictly and the hardware class is ``a``. So the
hardware and the float classifier (at the represented inputs) can only differ where the float
margin (best minus runner-up score) is at most ``2 e``; :func:`agreement` measures both. Against
the float classifier at the *unquantised* inputs the input rounding adds differences near the
decision boundaries that no bound here covers (also measured by :func:`agreement`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from pwas_hdl.errors import InputError
from pwas_hdl.fixedpoint.reduction import tree_depth, tree_reduce

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = ["TIE_RULE", "SELECT", "index_width", "compare_levels", "argmax_index", "margins", "agreement"]

#: The tie rule, in words (the manifest's ``classifier.tie_rule``).
TIE_RULE = "lowest class index among equal best codes (numpy.argmax)"
#: What the stage selects: the largest code (classifier scores) or the smallest (e.g. residuals).
SELECT = ("max", "min")


def index_width(n_classes: int) -> int:
    """Bits of the class index ``0 .. n_classes - 1`` (at least 1).

    Parameters
    ----------
    n_classes : int
        ``C >= 1``, the number of classes.

    Returns
    -------
    int
        The index width in bits.

    Raises
    ------
    InputError
        ``n_classes < 1``.
    """
    if int(n_classes) < 1:
        raise InputError(f"an argmax needs at least one class, got {n_classes}")
    return max(1, (int(n_classes) - 1).bit_length())


def compare_levels(n_classes: int) -> int:
    """Levels of the pairwise compare tree: ``ceil(log2(n_classes))`` (0 for one class).

    Parameters
    ----------
    n_classes : int
        ``C >= 1``, the number of classes.

    Returns
    -------
    int
        Compare levels of the tree (combinational levels, not cycles).
    """
    return tree_depth(int(n_classes))


def argmax_index(codes: "ArrayLike", select: str = "max") -> np.ndarray:
    """Class index of each row of ``codes`` by the hardware's compare tree.

    Parameters
    ----------
    codes : array_like of int, shape (m, C)
        Output codes of the ``C`` scores (any integers; the core's signed ``B_out``-bit codes).
    select : {"max", "min"}
        Largest (default) or smallest code wins.

    Returns
    -------
    ndarray of int64, shape (m,)
        The winning index; ties go to the lowest index (equal to ``numpy.argmax`` /
        ``numpy.argmin`` of ``codes`` along axis 1).
    """
    if select not in SELECT:
        raise InputError(f"select must be one of {', '.join(SELECT)}, got {select!r}")
    c = np.asarray(codes)
    if c.ndim != 2 or c.shape[1] < 1:
        raise InputError(f"codes must have shape (m, C) with C >= 1, got {c.shape}")
    if c.dtype.kind not in "iu":
        raise InputError(f"codes must be integers (output codes), got dtype {c.dtype}")
    c = c.astype(np.int64)
    m = c.shape[0]

    def node(a, b, _level, _i):
        ia, va = a
        ib, vb = b
        take_b = vb > va if select == "max" else vb < va
        return np.where(take_b, ib, ia), np.where(take_b, vb, va)

    leaves = [(np.full(m, i, dtype=np.int64), c[:, i]) for i in range(c.shape[1])]
    return tree_reduce(leaves, node)[0]


def margins(scores: "ArrayLike") -> np.ndarray:
    """Best minus runner-up score of each row of ``scores``.

    Parameters
    ----------
    scores : array_like of float, shape (m, C)
        Float scores (physical units).

    Returns
    -------
    ndarray of float64, shape (m,)
        The margins (the units of ``scores``); ``inf`` when ``C = 1``.

    Raises
    ------
    InputError
        ``scores`` is not 2-D.
    """
    s = np.asarray(scores, dtype=float)
    if s.ndim != 2:
        raise InputError(f"scores must have shape (m, C), got {s.shape}")
    if s.shape[1] < 2:
        return np.full(s.shape[0], np.inf)
    top2 = np.sort(s, axis=1)[:, -2:]
    return top2[:, 1] - top2[:, 0]


def agreement(float_scores: "ArrayLike", codes: "ArrayLike", error_bound: float) -> dict:
    """How often the hardware class equals the float classifier's, and where it may not.

    Parameters
    ----------
    float_scores : array_like, shape (m, C)
        Float scores (physical units), e.g. :meth:`FixedPointModel.reference` at the codes'
        inputs (the bound applies) or the float sensor at the unquantised inputs.
    codes : array_like of int, shape (m, C)
        The bit-true output codes of the same samples.
    error_bound : float
        The model's ``error_bound`` (physical units): differences are only possible where the
        float margin is ``<= 2 * error_bound``.

    Returns
    -------
    dict
        ``samples``, ``agree``, ``agreement`` (fraction), ``differ``, ``differ_within_margin``
        (differences where the float margin ``<= 2 e``), ``differ_outside_margin`` (0 whenever the
        bound holds), ``near_ties`` (samples with margin ``<= 2 e``), ``margin_limit`` (``2 e``).
    """
    s = np.asarray(float_scores, dtype=float)
    c = np.asarray(codes)
    if s.shape != c.shape:
        raise InputError(f"float_scores {s.shape} and codes {c.shape} must have the same shape")
    hw = argmax_index(c)
    fl = np.argmax(s, axis=1)
    near = margins(s) <= 2.0 * float(error_bound)
    differ = hw != fl
    m = int(len(hw))
    return {
        "samples": m,
        "agree": int(m - differ.sum()),
        "agreement": float(1.0 - differ.mean()) if m else float("nan"),
        "differ": int(differ.sum()),
        "differ_within_margin": int((differ & near).sum()),
        "differ_outside_margin": int((differ & ~near).sum()),
        "near_ties": int(near.sum()),
        "margin_limit": 2.0 * float(error_bound),
    }
