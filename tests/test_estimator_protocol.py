"""The scikit-learn estimator protocol of the estimators beyond PWASVirtualSensor's own basics
(tests/test_fit.py): the nested observer-bank front end, refits, parameter validation in fit."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.base import clone

from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor


def test_observer_bank_front_end_is_a_nested_estimator():
    """get_params(deep=True) lists the front end's parameters, set_params reaches them, clone works on
    the front end alone and gives the sensor a fresh unfitted one, the repr shows its parameters
    (it was a plain object: no front_end__* parameters, set_params(front_end__n_models=..) failed,
    clone(front_end) raised TypeError and the repr was '<... object at 0x..>')."""
    from pwas_hdl.systems.pv_benchmark import make_pv_dataset

    fe = ObserverBankFrontEnd(n_models=3, window=3)
    m = PWASVirtualSensor(my=0, partitions=2, sigma=0.1, front_end=fe)
    deep = m.get_params(deep=True)
    assert deep["front_end"] is fe and deep["front_end__n_models"] == 3 and deep["front_end__window"] == 3
    assert {k for k in deep if k.startswith("front_end__")} == {f"front_end__{k}" for k in fe.get_params()}
    assert "ObserverBankFrontEnd(n_models=3, window=3)" in repr(m)
    assert m.set_params(front_end__n_models=2) is m and fe.n_models == 2
    c = clone(fe)
    assert type(c) is ObserverBankFrontEnd and c is not fe and c.get_params() == fe.get_params()

    tr, _, _ = make_pv_dataset("pv-benchmark", 1200, 10, seed=2)
    m.fit(tr.u, tr.y, tr.z)
    assert m.front_end_.n_models_ == 2 and not hasattr(fe, "models_")  # fitted on a copy
    c = clone(m)
    assert c.front_end is not m.front_end and not hasattr(c.front_end, "models_")
    assert c.get_params(deep=True) == {**m.get_params(deep=True), "front_end": c.front_end}
    np.testing.assert_array_equal(c.fit(tr.u, tr.y, tr.z).weights_, m.weights_)
