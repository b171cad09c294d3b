"""Names that end up in generated Verilog: module names and signal names (the one check of each,
used by `generate`, the estimator builder and the hdl builders of every top).

A module name (``generate --name``) must be a simple identifier of Verilog-2005 (IEEE 1364-2005,
3.7) that is a keyword neither of Verilog-2005 nor of SystemVerilog (IEEE 1800-2017, Annex B:
a superset of the Verilog keywords), so that the same file reads in Icarus, Verilator, Yosys and
SystemVerilog tools. ``$`` is legal in identifiers but refused here: file names and FuseSoC VLNVs
are made from the module name. Signal names (CSV columns) appear in comments and, sanitised, in
register names: they must be printable, one line.
"""

from __future__ import annotations

import re
from typing import Iterable

from pwas_hdl.errors import InputError
from pwas_hdl.limits import MAX_NAME_LENGTH

__all__ = ["VERILOG_KEYWORDS", "check_module_name", "check_signal_names"]

#: Reserved words of IEEE 1800-2017 Annex B (includes every IEEE 1364-2005 keyword).
VERILOG_KEYWORDS: frozenset[str] = frozenset(
    """
    accept_on alias always always_comb always_ff always_latch and assert assign assume automatic before
    begin bind bins binsof bit break buf bufif0 bufif1 byte case casex casez cell chandle checker class
    clocking cmos config const constraint context continue cover covergroup coverpoint cross deassign
    default defparam design disable dist do edge else end endcase endchecker endclass endclocking endconfig
    endfunction endgenerate endgroup endinterface endmodule endpackage endprimitive endprogram endproperty
    endspecify endsequence endtable endtask enum event eventually expect export extends extern final
    first_match for force foreach forever fork forkjoin function generate genvar global highz0 highz1 if
    iff ifnone ignore_bins illegal_bins implements implies import incdir include initial inout input
    inside instance int integer interconnect interface intersect join join_any join_none large let
    liblist library local localparam logic longint macromodule matches medium modport module nand
    negedge nettype new nexttime nmos nor noshowcancelled not notif0 notif1 null or output package packed
    parameter pmos posedge primitive priority program property protected pull0 pull1 pulldown pullup
    pulsestyle_ondetect pulsestyle_onevent pure rand randc randcase randsequence rcmos real realtime ref
    reg reject_on release repeat restrict return rnmos rpmos rtran rtranif0 rtranif1 s_always s_eventually
    s_nexttime s_until s_until_with scalared sequence shortint shortreal showcancelled signed small soft
    solve specify specparam static string strong strong0 strong1 struct super supply0 supply1
    sync_accept_on sync_reject_on table tagged task this throughout time timeprecision timeunit tran
    tranif0 tranif1 tri tri0 tri1 triand trior trireg type typedef union unique unique0 unsigned until
    until_with untyped use uwire var vectored virtual void wait wait_order wand weak weak0 weak1 while
    wildcard wire with within wor xnor xor
    """.split()
)

_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def check_module_name(name: str, what: str = "--name") -> str:
    """Refuse a module name that is not a plain Verilog identifier or is a keyword.

    Parameters
    ----------
    name : str
    what : str
        The option that gave it, for the message.

    Returns
    -------
    str
        ``name``.

    Raises
    ------
    InputError
        Empty, longer than :data:`~pwas_hdl.limits.MAX_NAME_LENGTH`, not ``[A-Za-z_][A-Za-z0-9_]*``,
        or a Verilog / SystemVerilog keyword (case-sensitive, as in Verilog).
    """
    if not isinstance(name, str) or not name:
        raise InputError(f"{what}: the module name is empty; give a Verilog identifier such as pwas_core")
    if len(name) > MAX_NAME_LENGTH:
        raise InputError(f"{what}: the module name has {len(name)} characters, more than the limit of {MAX_NAME_LENGTH}")
    if not _IDENT.fullmatch(name):
        raise InputError(
            f"{what} {name!r} is not a Verilog identifier: use letters, digits and '_', starting with a letter or '_'"
        )
    if name in VERILOG_KEYWORDS:
        raise InputError(f"{what} {name!r} is a Verilog/SystemVerilog keyword; choose another module name (e.g. {name}_0)")
    return name


def check_signal_names(names: Iterable[str], what: str = "signal") -> None:
    """Refuse signal names that would break a generated file: empty, not printable, multi-line.

    Parameters
    ----------
    names : iterable of str
        The names to check (a non-string counts as empty).
    what : str
        What they name (``"signal"``, ``"target"``...), for the message.

    Raises
    ------
    InputError
        A name with a line break, a control or invisible character, or an empty name.
    """
    for nm in names:
        if not isinstance(nm, str) or not nm.strip():
            raise InputError(f"{what} name {nm!r} is empty; rename it in the data and re-run fit")
        if not nm.isprintable():
            raise InputError(
                f"{what} name {nm!r} has a line break or another control character, which would break the generated "
                "Verilog; rename it in the data and re-run fit"
            )
