"""PWAS classifiers: one-hot targets on one shared grid, argmax decision (the one owner of the convention).

A class label column ``c`` with distinct values ``k_1 < ... < k_C`` becomes ``C`` regression
targets named ``c=k_i`` (1 where the label is ``k_i``, else 0). They share one locator: the
PWAS weights are an ``(N, C)`` matrix, exactly a multi-target sensor (``nz = C``). The decision
is the class of the largest score, ties to the lowest class index (``numpy.argmax``), in software
and in a hardware argmax stage alike. The model file records ``"classifier": {"target": c,
"classes": [k_1, ..., k_C]}`` (see :mod:`pwas_hdl.fit.virtual_sensor`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

import numpy as np

from pwas_hdl.errors import InputError, InternalError

if TYPE_CHECKING:
    from pwas_hdl.io.csv_table import Table

__all__ = ["class_labels", "one_hot", "class_target_names", "score_column", "decide", "label_text", "class_scores", "label_column",
           "check_true_labels", "true_labels"]

#: Most classes a classifier may have (one PWAS output each).
MAX_CLASSES = 64

#: Most offending values :func:`check_true_labels` names (the rest are counted).
SHOWN_BAD_LABELS = 3


def class_labels(values: np.ndarray) -> list[float]:
    """Sorted distinct labels of a label column (numbers); refuses a single class or too many.

    Parameters
    ----------
    values : numpy.ndarray
        The label column, any shape (flattened), ``(T,)`` typically; numbers.

    Returns
    -------
    list of float
        The ``C`` distinct labels in increasing order, ``2 <= C <=`` :data:`MAX_CLASSES`.

    Raises
    ------
    InputError
        A non-finite label, a single distinct value, or more than :data:`MAX_CLASSES` of them.
    """
    v = np.asarray(values, dtype=float).reshape(-1)
    if not np.all(np.isfinite(v)):
        raise InputError("the class column has non-finite values")
    labels = sorted(set(v.tolist()))
    if len(labels) < 2:
        raise InputError(f"the class column has a single value {labels}; a classifier needs at least 2 classes: give a "
                         "-z/--targets column with two or more labels, or fit without --classify")
    if len(labels) > MAX_CLASSES:
        raise InputError(f"the class column has {len(labels)} distinct values, more than the limit {MAX_CLASSES}; "
                         "is it really a class label?")
    return labels


def one_hot(values: np.ndarray, classes: Sequence[float]) -> np.ndarray:
    """``(T, C)`` one-hot matrix of labels ``values`` over ``classes``.

    Parameters
    ----------
    values : numpy.ndarray, shape (T,) or any shape of T elements
        ``T`` labels (flattened).
    classes : sequence of float
        The ``C`` classes (column order), as from :func:`class_labels`.

    Returns
    -------
    numpy.ndarray, shape (T, C)
        Float array: 1.0 where ``values[t] == classes[i]``, else 0.0.

    Raises
    ------
    InputError
        A label that is not one of ``classes``.
    """
    v = np.asarray(values, dtype=float).reshape(-1)
    cls = np.asarray(classes, dtype=float)
    hit = v[:, None] == cls[None, :]
    if not np.all(hit.any(axis=1)):
        bad = v[~hit.any(axis=1)][0]
        raise InputError(f"label {bad:g} is not one of the classes {[label_text(c) for c in classes]}")
    return hit.astype(float)


def label_text(c: float) -> str:
    """A label as text: integers without a decimal point.

    Parameters
    ----------
    c : float
        A class label.

    Returns
    -------
    str
        ``"3"`` for 3.0, ``repr(float(c))`` (``"0.5"``) otherwise.
    """
    return str(int(c)) if float(c).is_integer() else repr(float(c))


def class_target_names(target: str, classes: Sequence[float]) -> list[str]:
    """Target names of the one-hot outputs: ``target=k``.

    Parameters
    ----------
    target : str
        Name of the class label column.
    classes : sequence of float
        The ``C`` classes.

    Returns
    -------
    list of str
        ``C`` names ``f"{target}={label_text(k)}"``, in the order of ``classes``.
    """
    return [f"{target}={label_text(c)}" for c in classes]


def score_column(target: str, c: float) -> str:
    """CSV column name of the score of class ``c``: ``<target>_score_<k>``.

    The one name ``predict`` writes and ``simulate`` suffixes with ``_hw``, ``_bittrue`` and
    ``_float`` (the model file keeps the target names of :func:`class_target_names`).

    Parameters
    ----------
    target : str
        Name of the class label column.
    c : float
        A class label.

    Returns
    -------
    str
        ``f"{target}_score_{label_text(c)}"``.
    """
    return f"{target}_score_{label_text(c)}"


def decide(scores: np.ndarray, classes: Sequence[float]) -> np.ndarray:
    """Class labels of the rows of ``scores`` (m, C): argmax, ties to the lowest index.

    Parameters
    ----------
    scores : numpy.ndarray
        ``(m, C)`` scores, one column per class (the PWAS outputs).
    classes : sequence of float
        The ``C`` classes, in the column order of ``scores``.

    Returns
    -------
    numpy.ndarray
        ``(m,)`` float array of the decided labels.

    Raises
    ------
    InputError
        ``scores`` is not 2-D with ``len(classes)`` columns.
    """
    s = np.asarray(scores, dtype=float)
    if s.ndim != 2 or s.shape[1] != len(classes):
        raise InputError(f"scores have shape {s.shape}; expected (m, {len(classes)})")
    return np.asarray(classes, dtype=float)[np.argmax(s, axis=1)]


def label_column(labels: np.ndarray, classes: Sequence[float]) -> np.ndarray:
    """Labels as a CSV column writes them: integers when every class is an integer (``1``, not ``1.0``).

    Parameters
    ----------
    labels : ndarray, shape (m,)
        Class labels (values of ``classes``).
    classes : sequence of float
        The classifier's classes.

    Returns
    -------
    ndarray, shape (m,)
        ``int64`` when every class is integral, else the labels as floats.
    """
    lab = np.asarray(labels, dtype=float)
    return lab.astype(np.int64) if all(float(c).is_integer() for c in classes) else lab


def class_scores(true: np.ndarray, pred: np.ndarray, classes: Sequence[float]) -> dict:
    """Accuracy and per-class F1: ``{"accuracy": a, "f1": [f1 of each class in order]}``.

    scikit-learn's ``accuracy_score`` and ``f1_score(labels=classes, average=None, zero_division=0)``
    on the labels' indices in their sorted union: scikit-learn refuses a label column with a
    non-integral value (``0.5``, or ``1e20``, which overflows its integer check) as "continuous",
    and ``fit --classify`` accepts any finite labels.

    Parameters
    ----------
    true, pred : numpy.ndarray
        ``(T,)`` true and decided labels (flattened).
    classes : sequence of float
        The ``C`` classes; the order of the F1 list.

    Returns
    -------
    dict
        ``{"accuracy": float, "f1": list of C floats}``; the F1 of a class absent from both
        ``true`` and ``pred`` is 0.
    """
    t = np.asarray(true, dtype=float).reshape(-1)
    p = np.asarray(pred, dtype=float).reshape(-1)
    if t.shape != p.shape or t.size == 0:
        raise InternalError(f"class_scores: {t.size} true and {p.size} decided labels (same non-zero number expected)")
    from sklearn.metrics import accuracy_score, f1_score

    cls = np.asarray([float(c) for c in classes])
    union = np.unique(np.concatenate([t, p, cls]))  # equal labels, equal indices
    ti, pi, ci = (np.searchsorted(union, v) for v in (t, p, cls))
    f1 = f1_score(ti, pi, labels=ci, average=None, zero_division=0)
    return {"accuracy": float(accuracy_score(ti, pi)), "f1": [float(v) for v in f1]}


def check_true_labels(labels: np.ndarray, classes: Sequence[float], target: str, where: str, *, owner: str | None = None) -> None:
    """Refuse true class labels that are none of the classifier's classes.

    Such a label is most likely another column under the label's name (a continuous target, say):
    scored, every row of it would count as a wrong decision. ``predict``, ``explore`` and
    ``simulate`` all refuse it with this one message (``simulate`` of an estimator design too, for
    the modes its detector decides).

    Parameters
    ----------
    labels : numpy.ndarray
        The true labels of the rows that are scored (any shape, flattened).
    classes : sequence of float
        The classifier's ``C`` classes.
    target : str
        The classifier's label name (``classifier_["target"]``).
    where : str
        Where the labels come from, for the message: ``"<file>: column '<c>'"``.
    owner : str, optional
        Whose classes they are, for the message (default ``"classifier '<target>'"``).

    Raises
    ------
    InputError
        One line: ``where``, the offending values (the first :data:`SHOWN_BAD_LABELS` distinct
        ones in row order, the others counted), how many rows hold one, the classes and the
        classifier.
    """
    v = np.asarray(labels, dtype=float).reshape(-1)
    bad = ~np.isin(v, np.asarray(classes, dtype=float))
    if not bad.any():
        return
    vals = list(dict.fromkeys(label_text(x) for x in v[bad].tolist()))  # distinct, in row order
    shown = ", ".join(vals[:SHOWN_BAD_LABELS])
    what = (f"label {shown} is not one of" if len(vals) == 1 else
            f"labels {shown}{f' and {len(vals) - SHOWN_BAD_LABELS} more' if len(vals) > SHOWN_BAD_LABELS else ''} are not among")
    owner = owner if owner is not None else f"classifier {target!r}"
    raise InputError(f"{where}: {what} the classes {[label_text(c) for c in classes]} of {owner} "
                     f"({int(bad.sum())} of {v.size} rows); give the true class labels in this column "
                     "(the decisions are scored against them)")


def true_labels(table: "Table", target: str, classes: Sequence[float], rows: np.ndarray) -> tuple[str, np.ndarray] | None:
    """The true class of the scored rows of a data file, checked.

    The column is :meth:`Table.reference_column <pwas_hdl.io.csv_table.Table.reference_column>`
    of the label: ``<target>_true`` if the file has it, else ``<target>``; every value of ``rows``
    must be one of ``classes`` (:func:`check_true_labels`).

    Parameters
    ----------
    table : pwas_hdl.io.csv_table.Table
        The data file.
    target : str
        The classifier's label name.
    classes : sequence of float
        The classifier's classes.
    rows : numpy.ndarray of int, shape (m,)
        The data rows whose decisions are scored.

    Returns
    -------
    (str, numpy.ndarray) or None
        The column's name and its labels at ``rows`` (float, shape ``(m,)``); None when the file
        has neither column.

    Raises
    ------
    InputError
        A cell of the column that is not a number, or a label of ``rows`` that is no class.
    """
    col = table.reference_column(target)
    if col is None:
        return None
    lab = table.numeric([col])[np.asarray(rows, dtype=np.int64), 0]
    check_true_labels(lab, classes, target, f"{table.path}: column {col!r}")
    return col, lab
