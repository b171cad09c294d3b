"""The weight ROMs (pwas_hdl.hdl.weight_rom): a Memory under Amaranth, a black box spliced back in
the Verilog -- the same memory text, and the same reads in Icarus."""

from __future__ import annotations

import re
import shutil
import subprocess

import pytest
from amaranth.hdl import Const, Module
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from pwas_hdl.errors import InternalError
from pwas_hdl.hdl.weight_rom import BLACKBOX_PREFIX, RomEmission, rom_emission, splice_roms, weight_rom
from pwas_hdl.hdl.yosys_convert import component_verilog, component_verilog_roms


class _Toy(wiring.Component):
    """One ROM of ``depth`` words of 7 bits (``contents`` padded with zeros), read with ``en``."""

    def __init__(self, depth: int, contents, const_en: bool = False):
        self.depth, self.contents, self.const_en = depth, contents, const_en
        aw = max(1, (depth - 1).bit_length())
        super().__init__({"addr": In(aw), "en": In(1), "data": Out(7)})

    def elaborate(self, platform):
        m = Module()
        en = Const(1, 1) if self.const_en else self.en
        addr = self.addr if self.depth > 1 else None
        m.d.comb += self.data.eq(weight_rom(m, "wmem0", 7, self.depth, self.contents, addr, en))
        return m


def _memory_lines(text: str) -> list[str]:
    return [re.sub(r"^\S+ <= ", "<= ", ln.strip()) for ln in text.splitlines() if re.search(r"\bwmem[0-9]+\b", ln)]


@pytest.mark.parametrize("const_en", [False, True])
def test_spliced_text_is_amaranths_memory(const_en):
    """Outside an emission the ROM is Amaranth's Memory; its conversion and the spliced black box
    declare, initialise (the missing words as 0) and read the memory in the same lines."""
    from amaranth.back import verilog

    toy = _Toy(5, [3, 0x7F, 1], const_en)
    ref = verilog.convert(toy, name="toy", emit_src=False)
    got = component_verilog(_Toy(5, [3, 0x7F, 1], const_en), "toy")
    assert BLACKBOX_PREFIX not in got and BLACKBOX_PREFIX not in ref
    assert _memory_lines(got) == _memory_lines(ref)
    assert "wmem0[3] = 7'h00;" in got and "wmem0[1] = 7'h7f;" in got
    assert ("if (en)" in got) != const_en


def test_emission_registers_each_rom_in_order():
    with rom_emission() as reg:
        from amaranth.back import rtlil

        rtlil.convert(_Toy(4, [1, 2, 3, 4]), name="toy", emit_src=False)
    assert [(r.width, r.depth, r.contents) for r in reg.roms] == [(7, 4, (1, 2, 3, 4))]
    with rom_emission() as other:  # a new registry each time
        assert other.roms == []


def test_too_many_words_refused():
    m = Module()
    m._MustUse__silence = True  # never elaborated
    with pytest.raises(InternalError, match="3 words for depth 2"):
        weight_rom(m, "wmem0", 4, 2, [1, 2, 3], None, Const(1, 1))


def test_splice_refuses_unknown_missing_or_incomplete_instances():
    text, reg = component_verilog_roms(_Toy(4, [1, 2, 3, 4]), "toy")
    assert f"{BLACKBOX_PREFIX}0 wmem0 (" in text
    with pytest.raises(InternalError, match="expected 0..1"):  # a ROM whose instance is not in the text
        reg2 = RomEmission()
        reg2.add(7, 4, [1]), reg2.add(7, 4, [2])
        splice_roms(text, reg2)
    with pytest.raises(InternalError, match="unexpected ROM instance"):  # an instance of no registered ROM
        splice_roms(text, RomEmission())
    with pytest.raises(InternalError, match="ports"):
        splice_roms(re.sub(r"^\s*\.EN\(.*\),?\n", "", text, flags=re.M), reg)
    with pytest.raises(InternalError, match="ports"):  # a port with nothing connected: no `assign  = ...;`
        splice_roms(re.sub(r"\.DATA\(.*\)", ".DATA()", text), reg)
    with pytest.raises(InternalError, match="is taken"):
        splice_roms(text.replace("endmodule", "  wire wmem0_q;\nendmodule"), reg)


def test_readmemh_form():
    text, reg = component_verilog_roms(_Toy(4, [1, 2, 3, 4]), "toy")
    out = splice_roms(text, reg, lambda name, k: f'"{name}_{k}.hex"')
    assert 'initial $readmemh("wmem0_0.hex", wmem0, 0, 3);' in out and "wmem0[0] =" not in out


@pytest.mark.rtl
@pytest.mark.skipif(shutil.which("iverilog") is None, reason="needs Icarus Verilog")
@pytest.mark.parametrize("depth", [1, 6])
def test_spliced_rom_reads_in_icarus(depth, tmp_path):
    """Icarus: ``data`` takes ``mem[addr]`` at a rising edge while ``en`` is high and holds it while
    ``en`` is low (a one-word ROM has no address)."""
    words = [(11 * a + 5) % 128 for a in range(depth)]
    text = component_verilog(_Toy(depth, words), "toy")
    aw = max(1, (depth - 1).bit_length())
    reads = [(a % depth, 1) for a in range(depth)] + [((depth - 1) % depth, 1), (0, 0), (0, 0)]
    steps = "\n".join(f"    addr = {a}; en = {e}; #1 clk = 1; #1 clk = 0; $display(\"%0d\", data);" for a, e in reads)
    tb = f"""module tb;
  reg clk = 0, rst = 0, en = 0;
  reg [{aw - 1}:0] addr = 0;
  wire [6:0] data;
  toy dut(.clk(clk), .rst(rst), .addr(addr), .en(en), .data(data));
  initial begin
{steps}
    $finish;
  end
endmodule
"""
    (tmp_path / "toy.v").write_text(text)
    (tmp_path / "tb.v").write_text(tb)
    subprocess.run(["iverilog", "-g2005", "-o", str(tmp_path / "a.out"), str(tmp_path / "tb.v"), str(tmp_path / "toy.v")],
                   check=True, capture_output=True, text=True)
    out = subprocess.run(["vvp", "-n", str(tmp_path / "a.out")], check=True, capture_output=True, text=True).stdout
    got = [int(x) for x in out.split()]
    want = [words[a] for a, _ in reads[:depth]] + [words[-1]] * 3  # en low: held
    assert got == want


def test_inline_to_readmemh_only_when_the_words_are_the_files():
    from pwas_hdl.hdl.weight_rom import inline_to_readmemh

    words = [3, 0x7F, 1, 0, 0]
    text = component_verilog(_Toy(5, words), "toy")
    other = "  reg [3:0] ram [1:0];\n  initial begin\n    ram[0] = 4'h0;\n    ram[1] = 4'h0;\n  end\n"
    text = text.replace("endmodule", other + "endmodule")
    out = inline_to_readmemh(text, {"wmem0": ("../d/toy_b0.hex", words)})
    assert out is not None and 'initial $readmemh("../d/toy_b0.hex", wmem0, 0, 4);' in out
    assert "wmem0[0] =" not in out and other in out  # another array's initialiser is left as it is
    assert out.replace('  initial $readmemh("../d/toy_b0.hex", wmem0, 0, 4);\n', "") == re.sub(
        r"  initial begin\n(    wmem0\[[0-9]\] = 7'h[0-9a-f]+;\n)+  end\n", "", text)
    assert inline_to_readmemh(text, {"wmem0": ("x.hex", [3, 0x7F, 1, 0, 1])}) is None  # a word differs
    assert inline_to_readmemh(text, {"wmem0": ("x.hex", words[:4])}) is None  # another depth
    assert inline_to_readmemh(text, {"wmem0": ("x.hex", words), "wmem1": ("y.hex", words)}) is None  # no wmem1
