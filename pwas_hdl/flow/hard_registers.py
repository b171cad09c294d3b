"""Pack fabric flip-flops into the registers of the ECP5 hard blocks (MULT18X18D, DP16KD).

Yosys' ``synth_ecp5`` maps every ``$mul`` to a combinational MULT18X18D and every synchronous ROM
to a DP16KD with ``REGMODE = NOREG``: it has no pass that moves the flip-flops around them into
the blocks' own registers (``lattice_dsp_nexus`` exists for Nexus only, and the ECP5 block-RAM
library of ``memory_libmap`` has no output-register option). Unpacked, the 18x18 multiplier's
combinational delay and the block RAM's long clock-to-output are on the critical path of every
pipeline (issue 14). :func:`pack_ecp5_registers` rewrites the mapped netlist (Yosys JSON, between
Yosys and nextpnr) the way the vendor's packer does:

* **DP16KD output register**: when every loaded data output ``DOx`` of a read port drives only the
  ``DI`` of a TRELLIS_FF clocked by the port's clock, without set/reset, all with one clock enable
  ``e``: ``REGMODE_x = "OUTREG"``, ``OCEx = e``, the flip-flops are removed and ``DOx`` drives their
  ``Q`` nets. (In the core this is the ``mem_out`` register: the read data register right after the
  read, enabled by ``advance`` like the read port.)
* **MULT18X18D input registers**: when every non-constant bit of *both* operands ``A`` and ``B`` is
  the ``Q`` of such a flip-flop (one clock, one enable): ``REG_INPUTA/B_CLK = "CLK0"``,
  ``..._CE = "CE0"``, the operand pins take the flip-flops' ``D`` nets (a flip-flop whose ``Q`` has
  no other load is removed). Only both operands together: nextpnr times a half-registered
  multiplier as a combinational one, so packing one side would lengthen the paths into the other.
* **MULT18X18D output register**: when every loaded product bit ``P`` drives only the ``DI`` of such
  a flip-flop: ``REG_OUTPUT_CLK = "CLK0"`` (enable ``CE0``, or ``CE1`` when it differs from the input
  registers'), the flip-flops are removed and ``P`` drives their ``Q`` nets.

Every rewrite moves a register across no logic (same clock, same enable, no reset, the same
value every cycle), so the function of the netlist is unchanged; nextpnr's ECP5 timing model then
uses the ``MULT18X18D_REGS_*`` and ``DP16KD REGMODE`` timings. The blocks' registers come out of
configuration at 0 like the flip-flops they replace (``GSR`` disabled, no reset).
"""

from __future__ import annotations

import os
from collections import defaultdict
from typing import Any

from pwas_hdl.flow.netlist_json import read_top, write_netlist

__all__ = ["pack_ecp5_registers"]

_CONST = ("0", "1", "x", "z")


def _ff_plain(cell: dict[str, Any]) -> bool:
    """A TRELLIS_FF without set/reset, clocked on the rising edge, with a CE pin or none."""
    if cell["type"] != "TRELLIS_FF":
        return False
    p, c = cell.get("parameters", {}), cell["connections"]
    if _par(p, "CLKMUX", "CLK") != "CLK" or _par(p, "CEMUX", "CE") not in ("CE", "1"):
        return False
    lsr = c.get("LSR", ["0"])[0]
    lsrmux = _par(p, "LSRMUX", "LSR")
    return (lsr == "0" and lsrmux == "LSR") or (lsr == "1" and lsrmux == "INV")


def _par(params: dict[str, Any], key: str, default: str) -> str:
    """A string parameter as Yosys writes it (padded with spaces to a multiple of 8 bits)."""
    v = params.get(key, default)
    return v.strip() if isinstance(v, str) else str(v)


def _ce(cell: dict[str, Any]):
    if _par(cell.get("parameters", {}), "CEMUX", "CE") == "1":
        return "1"
    return cell["connections"].get("CE", ["1"])[0]


class _Netlist:
    def __init__(self, module: dict[str, Any]):
        self.mod = module
        self.cells = module["cells"]
        self.drivers: dict[Any, tuple[str, str]] = {}
        self.sinks: dict[Any, list[tuple[str, str]]] = defaultdict(list)
        for name, cell in self.cells.items():
            dirs = cell.get("port_directions", {})
            for port, bits in cell["connections"].items():
                for b in bits:
                    if b in _CONST:
                        continue
                    if dirs.get(port) == "output":
                        self.drivers[b] = (name, port)
                    else:
                        self.sinks[b].append((name, port))
        for pname, port in module.get("ports", {}).items():
            for b in port["bits"]:
                if b in _CONST:
                    continue
                if port["direction"] == "input":
                    self.drivers[b] = ("$port", pname)
                else:
                    self.sinks[b].append(("$port", pname))

    def ff_driving(self, bit):
        """The plain flip-flop whose Q is ``bit`` (or None)."""
        d = self.drivers.get(bit)
        if d is None or d[0] == "$port" or d[1] != "Q":
            return None
        cell = self.cells[d[0]]
        return d[0] if _ff_plain(cell) else None

    def only_ff_sink(self, bit):
        """The plain flip-flop whose DI is the only load of ``bit`` (or None); 0 when unloaded."""
        s = self.sinks.get(bit, [])
        if not s:
            return 0
        if len(s) != 1 or s[0][0] == "$port" or s[0][1] != "DI":
            return None
        return s[0][0] if _ff_plain(self.cells[s[0][0]]) else None

    def connect(self, cell: str, port: str, bit) -> None:
        old = self.cells[cell]["connections"].get(port, ["0"])[0]
        self.cells[cell].setdefault("port_directions", {})[port] = "input"
        if old not in _CONST:
            self.sinks[old] = [s for s in self.sinks[old] if s != (cell, port)]
        self.cells[cell]["connections"][port] = [bit]
        if bit not in _CONST:
            self.sinks[bit].append((cell, port))

    def drive(self, cell: str, port: str, bit) -> None:
        """``cell.port`` (an output) drives ``bit`` instead of its old net."""
        self.cells[cell]["connections"][port] = [bit]
        self.drivers[bit] = (cell, port)

    def remove_ff(self, name: str) -> None:
        c = self.cells.pop(name)["connections"]
        for port in ("DI", "CE", "CLK", "LSR"):
            for b in c.get(port, []):
                if b not in _CONST:
                    self.sinks[b] = [s for s in self.sinks[b] if s[0] != name]
        q = c["Q"][0]
        if self.drivers.get(q, (None,))[0] == name:
            del self.drivers[q]


def _pack_bram_outputs(nl: _Netlist, stats: dict[str, int]) -> None:
    for name, cell in list(nl.cells.items()):
        if cell["type"] != "DP16KD":
            continue
        conn, par = cell["connections"], cell.setdefault("parameters", {})
        for x in ("A", "B"):
            if _par(par, f"REGMODE_{x}", "NOREG") != "NOREG":
                continue
            clk = conn.get(f"CLK{x}", ["0"])[0]
            if clk in _CONST or _par(par, f"CLK{x}MUX", f"CLK{x}") != f"CLK{x}":
                continue
            if conn.get(f"RST{x}", ["0"])[0] != "0" or conn.get(f"OCE{x}", ["1"])[0] != "1":
                continue
            pins = [(f"DO{x}{i}", conn[f"DO{x}{i}"][0]) for i in range(18) if f"DO{x}{i}" in conn]
            ffs, ces, ok = [], set(), True
            for pin, bit in pins:
                if bit in _CONST:
                    continue
                f = nl.only_ff_sink(bit)
                if f == 0:
                    continue
                if f is None or nl.cells[f]["connections"]["CLK"][0] != clk:
                    ok = False
                    break
                ffs.append((pin, f))
                ces.add(_ce(nl.cells[f]))
            if not ok or not ffs or len(ces) != 1:
                continue
            ce = ces.pop()
            for pin, f in ffs:
                q = nl.cells[f]["connections"]["Q"][0]
                nl.remove_ff(f)
                nl.drive(name, pin, q)
            par[f"REGMODE_{x}"] = "OUTREG"
            nl.connect(name, f"OCE{x}", ce)
            stats["bram_output_registers"] += 1
            stats["ffs_absorbed"] += len(ffs)


def _pack_mult(nl: _Netlist, stats: dict[str, int]) -> None:
    for name, cell in list(nl.cells.items()):
        if cell["type"] != "MULT18X18D":
            continue
        conn, par = cell["connections"], cell.setdefault("parameters", {})
        if any(_par(par, k, "NONE") != "NONE" for k in ("REG_INPUTA_CLK", "REG_INPUTB_CLK", "REG_OUTPUT_CLK")):
            continue
        # inputs: both operands, every non-constant bit the Q of a plain FF, one clock, one enable
        in_ffs, clks, ces, ok = [], set(), set(), True
        for pin in [f"A{i}" for i in range(18)] + [f"B{i}" for i in range(18)]:
            bit = conn.get(pin, ["0"])[0]
            if bit in _CONST:
                continue
            f = nl.ff_driving(bit)
            if f is None:
                ok = False
                break
            in_ffs.append((pin, f))
            clks.add(nl.cells[f]["connections"]["CLK"][0])
            ces.add(_ce(nl.cells[f]))
        has_a = any(p.startswith("A") for p, _ in in_ffs)
        has_b = any(p.startswith("B") for p, _ in in_ffs)
        pack_in = ok and has_a and has_b and len(clks) == 1 and len(ces) == 1
        clk = clks.pop() if pack_in else None
        ce_in = ces.pop() if pack_in else None
        # output: every loaded product bit drives only a plain FF's DI, one clock, one enable
        out_ffs, oclk, oces, ok = [], set(), set(), True
        for i in range(36):
            pin = f"P{i}"
            bit = conn.get(pin, ["x"])[0]
            if bit in _CONST:
                continue
            f = nl.only_ff_sink(bit)
            if f == 0:
                continue
            if f is None:
                ok = False
                break
            out_ffs.append((pin, f))
            oclk.add(nl.cells[f]["connections"]["CLK"][0])
            oces.add(_ce(nl.cells[f]))
        pack_out = ok and bool(out_ffs) and len(oclk) == 1 and len(oces) == 1 and (clk is None or oclk == {clk})
        if pack_out:
            clk = clk or next(iter(oclk))
        if not (pack_in or pack_out):
            continue
        nl.connect(name, "CLK0", clk)
        for k in ("RST0", "RST1"):
            nl.connect(name, k, "0")
        if pack_in:
            nl.connect(name, "CE0", ce_in)
            for x in ("A", "B"):
                par[f"REG_INPUT{x}_CLK"] = "CLK0"
                par[f"REG_INPUT{x}_CE"] = "CE0"
                par[f"REG_INPUT{x}_RST"] = "RST0"
            removable = set()
            for pin, f in in_ffs:
                nl.connect(name, pin, nl.cells[f]["connections"]["DI"][0])
                removable.add(f)
            for f in sorted(removable):
                q = nl.cells[f]["connections"]["Q"][0]
                if not nl.sinks.get(q):
                    nl.remove_ff(f)
                    stats["ffs_absorbed"] += 1
            stats["mult_input_registers"] += 1
        if pack_out:
            oce = oces.pop()
            cep = "CE0" if (not pack_in or oce == ce_in) else "CE1"
            nl.connect(name, cep, oce)
            par["REG_OUTPUT_CLK"] = "CLK0"
            par["REG_OUTPUT_CE"] = cep
            par["REG_OUTPUT_RST"] = "RST0"
            for pin, f in out_ffs:
                q = nl.cells[f]["connections"]["Q"][0]
                nl.remove_ff(f)
                nl.drive(name, pin, q)
            stats["mult_output_registers"] += 1
            stats["ffs_absorbed"] += len(out_ffs)


def pack_ecp5_registers(netlist: str | os.PathLike, top: str, *, mult_first: bool = False) -> dict[str, int]:
    """Move flip-flops into the DP16KD output and MULT18X18D input/output registers, in place.

    Parameters
    ----------
    netlist
        Yosys JSON netlist after ``synth_ecp5`` (rewritten in place).
    top
        The top module's name.
    mult_first
        Pack the multipliers before the block RAMs. One register between a DP16KD and a
        MULT18X18D qualifies as either block's; by default the block RAM's output register takes it
        (``mem_out``), with ``mult_first`` the multiplier's input registers (``mul_in`` without
        ``mem_out``, as :class:`~pwas_hdl.hdl.params.Pipeline` names it; ``pwas-hdl synth`` sets it
        from the registers the design builds, :func:`pwas_hdl.design.manifest.built_pipeline_registers`). Where both registers exist the result is the same.

    Returns
    -------
    dict
        ``bram_output_registers`` (DP16KD read ports with ``REGMODE = OUTREG``),
        ``mult_input_registers`` / ``mult_output_registers`` (MULT18X18D with registered operands /
        product), ``ffs_absorbed`` (TRELLIS_FF removed), ``dp16kd`` and ``mult18x18d`` (totals).
    """
    data, mod = read_top(netlist, top)
    stats = {"bram_output_registers": 0, "mult_input_registers": 0, "mult_output_registers": 0, "ffs_absorbed": 0}
    nl = _Netlist(mod)
    for step in ((_pack_mult, _pack_bram_outputs) if mult_first else (_pack_bram_outputs, _pack_mult)):
        step(nl, stats)
    stats["dp16kd"] = sum(1 for c in mod["cells"].values() if c["type"] == "DP16KD")
    stats["mult18x18d"] = sum(1 for c in mod["cells"].values() if c["type"] == "MULT18X18D")
    if stats["ffs_absorbed"] or stats["bram_output_registers"] or stats["mult_input_registers"] or stats["mult_output_registers"]:
        write_netlist(netlist, data)
    return stats
