"""Checks of the training data against the fitted sensor: what ``fit`` warns about after a fit.

A given ``--domain`` that clamps training regressors, and isolated target outliers (they set the
training RMSE, hence the CV's sigma and the default hardware word lengths). Warnings only: the fit
stands; the user decides whether the data are wrong.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

import numpy as np

from pwas_hdl.io.csv_table import split_trajectories

if TYPE_CHECKING:
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.io.csv_table import Table

__all__ = ["training_data_warnings", "class_label_note"]

#: At most this many distinct integer values make a target look like a class label.
LABEL_LIKE_VALUES = 10


def training_data_warnings(model: PWASVirtualSensor, table: Table, traj_col: str | None, u: Sequence[np.ndarray] | None,
                           y: Sequence[np.ndarray] | None, z: Sequence[np.ndarray], *, given_domain: bool,
                           classify: bool) -> list[str]:
    """Warnings about the training data seen through the fitted sensor (``fit`` prints them).

    Training regressors outside a given ``--domain`` (clamped: the sensor is fitted on values the data
    do not have), and a few target samples far off their neighbours in time (outliers): the training
    RMSE, the sigma the CV picks and the default hardware word lengths (sized by that RMSE) follow them. An outlier is a sample whose distance to the median of
    the 7 samples around it (a Hampel filter: steps and slow changes pass) exceeds both 10 robust
    standard deviations of those distances and 3 of the target, that stands twice as far from the
    target's median as any other sample, and that is one of at most 1 % of the samples.

    Parameters
    ----------
    model : PWASVirtualSensor
        The fitted (static) sensor.
    table : Table
        DATA as read (for the file's line numbers).
    traj_col : str or None
        The trajectory column (``--traj-col``).
    u, y : list of ndarray (T_k, n_u) / (T_k, n_y), or None
        The inputs / outputs per trajectory, as the sensor was fitted on them.
    z : list of ndarray, shape (T_k, nz)
        The targets per trajectory (physical units).
    given_domain : bool
        A ``--domain`` was given (the only case in which training regressors can be clamped).
    classify : bool
        A classifier (its labels are not checked for outliers).

    Returns
    -------
    list of str
        ``warning: ...`` lines, possibly none.
    """
    out: list[str] = []
    if given_domain:
        _, flags = model.predict(u, y, return_flags=True)
    if given_domain and flags.any():
        out.append(f"warning: {int(flags.sum())} of {flags.size} training regressors are outside --domain and were "
                   "clamped to its edge; widen --domain to cover the data (or leave it out: the data box times --gamma)")
    if classify:
        return out
    # outliers of a target: samples far from the median of their neighbours in time (a Hampel filter: steps
    # and slow changes pass), measured in robust standard deviations of those differences over the file
    spans = split_trajectories(table, traj_col)
    for i, t in enumerate(model.signal_names()[2]):
        dev, at, val = [], [], []
        for sl, zt in zip(spans, z):
            v = np.asarray(zt, float)[:, i]
            if v.size < 3:
                continue
            pad = np.pad(v, 3, mode="edge")
            med = np.median(np.lib.stride_tricks.sliding_window_view(pad, 7), axis=1)
            dev.append(v - med)
            at.append(np.arange(sl.start, sl.stop))
            val.append(v)
        if not dev:
            continue
        d, at_rows, zv = np.concatenate(dev), np.concatenate(at), np.concatenate(val)
        off = np.abs(zv - np.median(zv))
        spread = 1.4826 * float(np.median(off))  # robust standard deviation of the target
        # far from the neighbours against their noise (10 robust sigmas of d) and against the signal (3 of z):
        # a smooth trajectory has d = 0 nearly everywhere, so d's own scale alone would flag ordinary noise
        limit = max(10 * 1.4826 * float(np.median(np.abs(d))), 3 * spread)
        if not limit > 0:
            continue
        far = np.abs(d) > limit
        if not far.any() or far.all():
            continue
        # and apart from the rest of the values (twice as far from the median as any other): a heavy-tailed
        # target (y**2 of a noise) has its large values continue the tail, an outlier stands alone
        far = np.flatnonzero(far & (off > 2 * float(off[~far].max())))
        if far.size == 0 or far.size > max(1, d.size // 100):
            continue
        lines = ", ".join(str(table._line(int(at_rows[k]))) for k in far[:5]) + (", ..." if far.size > 5 else "")
        out.append(f"warning: {far.size} training samples of {t} (lines {lines}) are outliers, off the median of their "
                   f"neighbours in time by up to {float(np.abs(d[far]).max()):.4g} (the robust spread of {t} is "
                   f"{spread:.4g}): the fit, "
                   "the training RMSE, the sigma the CV picks and the default hardware word lengths (sized by that RMSE) "
                   "follow them; check those samples and remove or correct them")
    return out


def class_label_note(z: Sequence[np.ndarray], names: Sequence[str]) -> str | None:
    """A note when a regression target looks like a class label: 2 to :data:`LABEL_LIKE_VALUES`
    distinct values, all integers (``fit`` without ``--classify`` prints it; the fit stands).

    Parameters
    ----------
    z : list of ndarray, shape (T_k, nz)
        The targets per trajectory.
    names : sequence of str
        The ``nz`` target names.

    Returns
    -------
    str or None
        ``note: ...`` naming the first such target and its values, or None.
    """
    if not len(z):
        return None
    zz = np.concatenate([np.asarray(v, float).reshape(len(v), -1) for v in z])
    for i, t in enumerate(names):
        vals = np.unique(zz[:, i])
        if 2 <= vals.size <= LABEL_LIKE_VALUES and np.all(vals == np.round(vals)):
            shown = ", ".join(f"{v:g}" for v in vals)
            return (f"note: {t} takes only {vals.size} integer values ({shown}); if it is a class label, fit with "
                    "--classify (one score per class and an argmax, also in hardware) rather than a regression")
    return None
