"""In-place edits of a Yosys JSON netlist (``write_json``) between synthesis and nextpnr.

The one owner of reading a netlist's top module and writing the edited netlist back, used by the
flow steps that change it: :mod:`pwas_hdl.flow.hard_registers` (registers packed into the hard
blocks) and :mod:`pwas_hdl.flow.floorplan` (sites of the hard blocks). The write is atomic (a
temporary file in the same folder, then ``os.replace``), so a failed step never leaves half a
netlist for nextpnr.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

__all__ = ["read_top", "write_netlist"]


def read_top(netlist: str | os.PathLike, top: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """``(netlist, module)``: the parsed netlist and its module ``top`` (Yosys may write it ``\\top``).

    Parameters
    ----------
    netlist : str or os.PathLike
        A Yosys JSON netlist file.
    top : str
        The module's name.

    Returns
    -------
    data : dict
        The whole parsed netlist.
    module : dict
        ``data["modules"]``'s entry of ``top`` (the same object: edits to it edit ``data``).

    Raises
    ------
    KeyError
        The netlist has no module ``top``.
    """
    path = Path(netlist)
    data = json.loads(path.read_text(encoding="utf-8"))
    mods = data["modules"]
    mod = mods.get(top) or mods.get("\\" + top)
    if mod is None:
        raise KeyError(f"module {top!r} not in {path}")
    return data, mod


def write_netlist(netlist: str | os.PathLike, data: dict[str, Any]) -> None:
    """Write ``data`` (as :func:`read_top` returned it, edited) back to ``netlist``, atomically.

    Parameters
    ----------
    netlist : str or os.PathLike
        The JSON netlist file to replace.
    data : dict
        The whole netlist.
    """
    path = Path(netlist)
    tmp = path.with_name(path.name + f".{os.getpid()}.tmp")
    tmp.write_text(json.dumps(data), encoding="utf-8")
    os.replace(tmp, path)
