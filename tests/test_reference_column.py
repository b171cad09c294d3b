"""One source of truth for the reference column of a data file: the reference of quantity ``t`` (a
target, or a classifier's class label) is column ``t_true`` if the file has it, else ``t``
(:func:`pwas_hdl.io.csv_table.reference_column_names`, :meth:`Table.reference_column
<pwas_hdl.io.csv_table.Table.reference_column>`), for every command that scores against it.
"""

from __future__ import annotations

import pytest

from pwas_hdl.errors import InputError
from pwas_hdl.io.csv_table import Table, check_trajectory_column, reference_column_names


def _table(header, n=4):
    return Table("d.csv", list(header), [[repr(float(i))] * len(header) for i in range(n)])


def test_reference_column_names_and_the_lookup_agree():
    assert reference_column_names("z") == ("z_true", "z")
    assert _table(["y", "z", "z_true"]).reference_column("z") == "z_true"
    assert _table(["y", "z"]).reference_column("z") == "z"
    assert _table(["y"]).reference_column("z") is None


@pytest.mark.parametrize("col", reference_column_names("c"))
def test_a_trajectory_column_is_never_a_reference_column(col):
    t = _table(["y", "c", "c_true"])
    with pytest.raises(InputError, match="is the reference the estimates are compared with"):
        check_trajectory_column(t, col, ["y"], ["c"])
