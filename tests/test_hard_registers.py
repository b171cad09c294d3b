"""ECP5 hard-block register packing (pwas_hdl.flow.hard_registers) on hand-made Yosys JSON netlists.

No tools: each netlist is a few cells written here the way ``synth_ecp5`` writes them (a
MULT18X18D whose operands come from TRELLIS_FFs and whose product goes into TRELLIS_FFs, a DP16KD
read port followed by flip-flops). The tests check what is packed, what is refused (a flip-flop
with a reset, another clock, a second load, an unregistered operand) and that the rewired nets
keep their drivers and loads.
"""

from __future__ import annotations

import json
from pathlib import Path

from pwas_hdl.flow.hard_registers import pack_ecp5_registers

CLK, CE = 2, 3


class _Builder:
    def __init__(self):
        self.next = 10
        self.cells = {}

    def net(self):
        self.next += 1
        return self.next

    def ff(self, name, di, *, clk=CLK, ce=CE, lsr="0", lsrmux="LSR"):
        q = self.net()
        self.cells[name] = {
            "type": "TRELLIS_FF",
            "parameters": {"CEMUX": "CE      ", "CLKMUX": "CLK", "GSR": "DISABLED", "LSRMUX": lsrmux, "REGSET": "RESET",
                           "SRMODE": "LSR_OVER_CE"},
            "port_directions": {"CE": "input", "CLK": "input", "DI": "input", "LSR": "input", "Q": "output"},
            "connections": {"CE": [ce], "CLK": [clk], "DI": [di], "LSR": [lsr], "Q": [q]},
        }
        return q

    def lut(self, name, *ins):
        out = self.net()
        conns = {f"{p}": [b] for p, b in zip("ABCD", ins)}
        conns["Z"] = [out]
        self.cells[name] = {"type": "LUT4", "parameters": {"INIT": "0"}, "connections": conns,
                            "port_directions": {**{p: "input" for p in "ABCD"[: len(ins)]}, "Z": "output"}}
        return out

    def mult(self, name, a, b):
        conns, dirs = {}, {}
        for i in range(18):
            conns[f"A{i}"] = [a[i] if i < len(a) else "0"]
            conns[f"B{i}"] = [b[i] if i < len(b) else b[-1]]  # sign extension: the top bit repeated
            dirs[f"A{i}"] = dirs[f"B{i}"] = "input"
        p = [self.net() for _ in range(36)]
        for i in range(36):
            conns[f"P{i}"] = [p[i]]
            dirs[f"P{i}"] = "output"
        self.cells[name] = {"type": "MULT18X18D", "parameters": {}, "connections": conns, "port_directions": dirs}
        return p

    def bram(self, name, addr):
        conns = {"CLKA": [CLK], "CEA": [CE], "OCEA": ["1"], "RSTA": ["0"], "CLKB": ["0"], "CEB": ["0"], "OCEB": ["1"], "RSTB": ["0"]}
        dirs = {k: "input" for k in conns}
        for i, bit in enumerate(addr):
            conns[f"ADA{i}"] = [bit]
            dirs[f"ADA{i}"] = "input"
        do = [self.net() for _ in range(18)]
        for i in range(18):
            conns[f"DOA{i}"] = [do[i]]
            dirs[f"DOA{i}"] = "output"
        self.cells[name] = {"type": "DP16KD", "parameters": {"REGMODE_A": "NOREG", "REGMODE_B": "NOREG", "CLKAMUX": "CLKA"},
                            "connections": conns, "port_directions": dirs}
        return do

    def write(self, path: Path, outputs: dict[str, list]) -> Path:
        ports = {"clk": {"direction": "input", "bits": [CLK]}, "ce": {"direction": "input", "bits": [CE]},
                 **{k: {"direction": "output", "bits": v} for k, v in outputs.items()}}
        path.write_text(json.dumps({"modules": {"top": {"ports": ports, "cells": self.cells, "netnames": {}}}}))
        return path


def _cells(path: Path) -> dict:
    return json.loads(path.read_text())["modules"]["top"]["cells"]


def _driver(cells: dict, bit) -> tuple[str, str]:
    found = [(n, p) for n, c in cells.items() for p, bits in c["connections"].items()
             if c["port_directions"].get(p) == "output" and bit in bits]
    assert len(found) == 1, found
    return found[0]


def _mul_design(tmp_path: Path, *, b_reset: bool = False, a_unregistered: bool = False, out_other_clock: bool = False,
                p_second_load: bool = False) -> tuple[Path, dict]:
    g = _Builder()
    ins = [g.net() for _ in range(6)]
    a = [g.lut(f"pa{i}", ins[i]) if a_unregistered else g.ff(f"ra{i}", ins[i]) for i in range(3)]
    b = [g.ff(f"rb{i}", ins[3 + i], lsr=(4 if b_reset else "0")) for i in range(3)]
    p = g.mult("mul", a, b)
    outs = [g.ff(f"rp{i}", p[i], clk=(5 if out_other_clock else CLK)) for i in range(6)]
    extra = {"x": [g.lut("other", p[0])]} if p_second_load else {}
    return g.write(tmp_path / "net.json", {"y": outs, **extra}), {"ins": ins, "outs": outs}


def test_multiplier_input_and_output_registers_are_packed(tmp_path: Path):
    path, nets = _mul_design(tmp_path)
    stats = pack_ecp5_registers(path, "top")
    assert stats == {"bram_output_registers": 0, "mult_input_registers": 1, "mult_output_registers": 1,
                     "ffs_absorbed": 12, "dp16kd": 0, "mult18x18d": 1}
    cells = _cells(path)
    assert sorted(cells) == ["mul"]  # every flip-flop went into the block
    m = cells["mul"]
    par = m["parameters"]
    assert par["REG_INPUTA_CLK"] == par["REG_INPUTB_CLK"] == par["REG_OUTPUT_CLK"] == "CLK0"
    assert par["REG_INPUTA_CE"] == par["REG_OUTPUT_CE"] == "CE0"
    assert m["connections"]["CLK0"] == [CLK] and m["connections"]["CE0"] == [CE]
    # the operands are the flip-flops' D nets now (sign extension included), the product drives their Q nets
    assert [m["connections"][f"A{i}"][0] for i in range(4)] == nets["ins"][:3] + ["0"]
    assert [m["connections"][f"B{i}"][0] for i in range(5)] == nets["ins"][3:] + [nets["ins"][5]] * 2
    for i, q in enumerate(nets["outs"]):
        assert _driver(cells, q) == ("mul", f"P{i}")


def test_registers_with_a_reset_another_clock_or_a_second_load_stay(tmp_path: Path):
    path, _ = _mul_design(tmp_path, b_reset=True)
    stats = pack_ecp5_registers(path, "top")
    assert (stats["mult_input_registers"], stats["mult_output_registers"], stats["ffs_absorbed"]) == (0, 1, 6)
    assert "REG_INPUTA_CLK" not in _cells(path)["mul"]["parameters"] and "rb0" in _cells(path)

    # the block has one clock (CLK0): a product register on another clock than the operand registers stays
    path, _ = _mul_design(tmp_path, out_other_clock=True)
    stats = pack_ecp5_registers(path, "top")
    assert (stats["mult_input_registers"], stats["mult_output_registers"]) == (1, 0)
    assert "REG_OUTPUT_CLK" not in _cells(path)["mul"]["parameters"] and "rp0" in _cells(path)

    path, _ = _mul_design(tmp_path, p_second_load=True)
    stats = pack_ecp5_registers(path, "top")
    assert (stats["mult_input_registers"], stats["mult_output_registers"]) == (1, 0)  # P0 also feeds a LUT


def test_one_registered_operand_is_not_packed(tmp_path: Path):
    """nextpnr times a half-registered MULT18X18D as a combinational one: both operands or none."""
    path, _ = _mul_design(tmp_path, a_unregistered=True)
    stats = pack_ecp5_registers(path, "top")
    assert (stats["mult_input_registers"], stats["mult_output_registers"]) == (0, 1)
    assert "rb0" in _cells(path)


def test_block_ram_output_register(tmp_path: Path):
    g = _Builder()
    addr = [g.ff(f"ra{i}", g.net()) for i in range(4)]
    do = g.bram("mem", addr)
    outs = [g.ff(f"rd{i}", do[i]) for i in range(11)]  # DOA11..17 unloaded
    path = g.write(tmp_path / "net.json", {"y": outs})
    stats = pack_ecp5_registers(path, "top")
    assert (stats["bram_output_registers"], stats["ffs_absorbed"], stats["dp16kd"]) == (1, 11, 1)
    cells = _cells(path)
    assert cells["mem"]["parameters"]["REGMODE_A"] == "OUTREG" and cells["mem"]["connections"]["OCEA"] == [CE]
    assert all(f"rd{i}" not in cells for i in range(11)) and all(f"ra{i}" in cells for i in range(4))
    for i, q in enumerate(outs):
        assert _driver(cells, q) == ("mem", f"DOA{i}")


def _bram_reg_mult(tmp_path: Path) -> Path:
    """block RAM -> one register (with the other operand's register beside it) -> multiplier."""
    g = _Builder()
    addr = [g.ff(f"ra{i}", g.net()) for i in range(4)]
    do = g.bram("mem", addr)
    b = [g.ff(f"rd{i}", do[i]) for i in range(3)]
    a = [g.ff(f"rm{i}", g.net()) for i in range(3)]
    p = g.mult("mul", a, b)
    return g.write(tmp_path / "net.json", {"y": p[:6]})


def test_one_register_between_block_ram_and_multiplier(tmp_path: Path):
    """By default the block RAM's output register takes it (then only one operand of the multiplier
    is registered: not packed); mult_first (a mul_in register without mem_out) gives it to the
    multiplier's input registers, both operands."""
    path = _bram_reg_mult(tmp_path)
    stats = pack_ecp5_registers(path, "top")
    assert (stats["bram_output_registers"], stats["mult_input_registers"], stats["ffs_absorbed"]) == (1, 0, 3)
    assert "rm0" in _cells(path) and _cells(path)["mem"]["parameters"]["REGMODE_A"] == "OUTREG"

    path = _bram_reg_mult(tmp_path)
    stats = pack_ecp5_registers(path, "top", mult_first=True)
    assert (stats["bram_output_registers"], stats["mult_input_registers"], stats["ffs_absorbed"]) == (0, 1, 6)
    cells = _cells(path)
    assert cells["mem"]["parameters"]["REGMODE_A"] == "NOREG" and not any(k.startswith(("rd", "rm")) for k in cells)
    m = cells["mul"]
    assert m["parameters"]["REG_INPUTB_CLK"] == "CLK0" and m["connections"]["B0"] == [_cells(path)["mem"]["connections"]["DOA0"][0]]
