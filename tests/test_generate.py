"""`pwas-hdl generate`: the folder, its determinism, lint cleanliness and clean failures."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers.cli import CliRunner

from pwas_hdl.cli import app
from pwas_hdl.design.generate import build_design, generate
from pwas_hdl.design.manifest import load_manifest, port
from pwas_hdl.flow.toolchain import lint_verilog
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

runner = CliRunner()


@pytest.fixture(scope="module")
def lorenz_model(lorenz_table2):
    """The Table II model file (My = 4, p = 7, N = 4096; shared conftest fit)."""
    return lorenz_table2.model


@pytest.fixture(scope="module")
def lorenz_core(lorenz_model, tmp_path_factory):
    out = tmp_path_factory.mktemp("gen") / "core"
    res = runner.invoke(app, ["generate", str(lorenz_model), "-o", str(out)])
    assert res.exit_code == 0, res.output
    return out


def test_lorenz_core_folder(lorenz_core):
    man = load_manifest(lorenz_core)
    names = {p.name for p in lorenz_core.iterdir()}
    assert {"pwas_core.v", "manifest.json", "report.md", "model.json", "pwas_core_inst.v", "pwas_core.core"} <= names
    hexes = man["files"]["hex"]
    assert len(hexes) == 5 and all(h["file"] in names for h in hexes)
    assert man["ii"] == 1 and man["latency_cycles"] >= 1
    # Banked memory: about N words, at most 1.3 N, far below (n+1) N.
    mem = man["memory"]
    assert mem["n_vertices"] == 4096
    assert mem["words"] <= 1.3 * 4096
    # Inputs are 12-bit signed codes, every lag of y shares one format.
    pin = port(man, "in.payload")
    assert [f["width"] for f in pin["fields"]] == [12] * 4
    assert len({json.dumps(f["format"], sort_keys=True) for f in pin["fields"]}) == 1
    assert pin["width"] == 48
    pout = port(man, "out.payload")
    assert [f["name"] for f in pout["fields"]] == ["z", "out_of_range"]
    assert man["error_bound"]["lsb"] > 0
    # No absolute path anywhere in what was written.
    for p in lorenz_core.iterdir():
        text = p.read_text()
        assert str(lorenz_core) not in text and "/tmp/" not in text and "/work/" not in text, p.name


def test_hex_files_hold_the_weight_codes(lorenz_core, lorenz_model):
    man = load_manifest(lorenz_core)
    gd = build_design(lorenz_model)
    rom = gd.model.rom  # (banks, depth, nz)
    for h in man["files"]["hex"]:
        words = [int(line, 16) for line in (lorenz_core / h["file"]).read_text().split()]
        (fld,) = h["fields"]
        bits = fld["width"]
        codes = [w - (1 << bits) if w >= 1 << (bits - 1) else w for w in words]
        assert codes == rom[h["bank"], :, 0].tolist()


@pytest.mark.slow
def test_generate_is_deterministic(lorenz_model, tmp_path):
    a = generate(lorenz_model, tmp_path / "a")
    b = generate(lorenz_model, tmp_path / "b")
    assert a.files == b.files
    for name in a.files:
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()


@pytest.mark.rtl  # runs Verilator's linter
@pytest.mark.parametrize("design, init", [("core", "inline"), ("sensor", "inline"), ("core", "readmemh")])
def test_verilog_is_lint_clean(lorenz_model, tmp_path, design, init):
    gd = generate(lorenz_model, tmp_path / design, design=design, memory_init=init)
    res = lint_verilog(tmp_path / design / f"{gd.top}.v", gd.top)
    assert res.returncode == 0 and "%Warning" not in res.stderr, res.stderr[-3000:]


@pytest.mark.rtl  # runs Verilator's linter
@pytest.mark.parametrize("pipeline", ["short", "max", "max-lut"])
def test_issue14_pipelines_are_lint_clean(lorenz_tiny, tmp_path, pipeline):
    """The latency / throughput presets of issue 14 (product register only; offset, bank and split
    multipliers) keep the Verilog clean under verilator -Wall, in the core and the sensor top."""
    for design in ("core", "sensor"):
        gd = generate(lorenz_tiny.model, tmp_path / design, design=design, pipeline=pipeline)
        res = lint_verilog(tmp_path / design / f"{gd.top}.v", gd.top)
        assert res.returncode == 0 and "%Warning" not in res.stderr, res.stderr[-3000:]


def test_bad_options_write_nothing(lorenz_model, tmp_path):
    out = tmp_path / "x"
    for args, msg in [
        (["--weight-bits", "8"], "does not fit the weight format"),
        (["--design", "gpu"], "--design (design) must be core or sensor"),
        (["--memory", "dual"], "--memory (memory) must be one of banked, replicated, corner"),
        (["--name", "9bad"], "identifier"),
        (["--input-bits", "2"], "too small"),
        # --fpga is checked without --clock-mhz / --goal too (it was silently ignored, exit 0)
        (["--fpga", "foo"], "--fpga (fpga_target) must be one of ecp5, ice40, got 'foo'"),
        (["--fpga", "generic"], "--fpga (fpga_target) must be one of ecp5, ice40"),
    ]:
        res = runner.invoke(app, ["generate", str(lorenz_model), "-o", str(out), *args])
        assert res.exit_code == 2, (args, res.output)
        assert msg in res.output, (args, res.output)
        assert not out.exists()
    # A folder that generate did not make is never overwritten.
    keep = tmp_path / "user"
    keep.mkdir()
    (keep / "notes.txt").write_text("mine")
    res = runner.invoke(app, ["generate", str(lorenz_model), "-o", str(keep)])
    assert res.exit_code == 2 and "not made by pwas-hdl generate" in res.output
    assert [p.name for p in keep.iterdir()] == ["notes.txt"]


def test_regenerate_replaces_own_folder(lorenz_tiny, tmp_path):
    out = tmp_path / "g"
    generate(lorenz_tiny.model, out)
    generate(lorenz_tiny.model, out, memory="replicated")
    man = load_manifest(out)
    n, n_vertices = len(man["lags"]["regressors"]), man["domain"]["n_vertices"]
    assert man["memory"]["words"] == (n + 1) * n_vertices  # n + 1 copies
    assert len(man["files"]["hex"]) == n + 1
    assert sorted(p.name for p in out.iterdir()) == sorted(build_design(lorenz_tiny.model, memory="replicated").files)


def test_saturate_option_warns_and_builds(lorenz_model):
    with pytest.warns(UserWarning):
        gd = build_design(lorenz_model, weight_bits=8, overflow="saturate")
    assert gd.model.n_weights_saturated > 0
    assert gd.manifest["error_bound"]["includes_weight_saturation"] is True
    assert gd.model.weight_codes.min() >= -(2 ** 7) and gd.model.weight_codes.max() <= 2 ** 7 - 1


@pytest.mark.rtl  # runs Verilator's linter
def test_two_targets_share_one_word_per_bank(tmp_path):
    rng = np.random.default_rng(1)
    u = rng.uniform(-1, 1, (400, 1))
    y = np.cumsum(u, axis=0) * 0.1
    z = np.hstack([u * y, u + y])
    m = PWASVirtualSensor(mu=2, my=1, partitions=[3, 3, 4], sigma=1e-3, input_names=["u"], output_names=["y"],
                          target_names=["a", "b"]).fit(u, y, z)
    gd = generate(m, tmp_path / "two", design="sensor")
    man = gd.manifest
    assert [f["name"] for f in port(man, "out.payload")["fields"]] == ["a", "b", "out_of_range"]
    rom = gd.model.rom
    for h in man["files"]["hex"]:
        words = [int(line, 16) for line in (tmp_path / "two" / h["file"]).read_text().split()]
        for i, fld in enumerate(h["fields"]):
            bits = fld["width"]
            codes = [((w >> fld["lsb"]) & ((1 << bits) - 1)) for w in words]
            codes = [c - (1 << bits) if c >= 1 << (bits - 1) else c for c in codes]
            assert codes == rom[h["bank"], :, i].tolist()
    res = lint_verilog(tmp_path / "two" / f"{gd.top}.v", gd.top)
    assert res.returncode == 0 and "%Warning" not in res.stderr, res.stderr[-3000:]


def test_verilog_header_names_generator_model_formats_ports(lorenz_tiny, tmp_path):
    import hashlib

    from pwas_hdl import __version__

    gd = generate(lorenz_tiny.model, tmp_path / "h", design="sensor")
    text = (tmp_path / "h" / f"{gd.top}.v").read_text()
    header = text[: text.index("/* Generated by Amaranth")]
    assert all(line.startswith("//") for line in header.strip().splitlines())
    assert header.startswith(f"// {gd.top}: PWAS virtual-sensor top generated by pwas-hdl {__version__}")
    sha = hashlib.sha256((tmp_path / "h" / "model.json").read_bytes()).hexdigest()
    assert f"model.json SHA-256 {sha}" in header
    man = gd.manifest
    assert f"latency {man['latency_cycles']} cycles" in header and f"II {man['ii']}" in header
    fm = man["formats"]
    assert fm["weight"]["str"] in header and fm["output"]["str"] in header
    for prt in man["ports"]:
        assert f"//   {prt['name']} " in header, prt["name"]
        for f in prt.get("fields", []):
            assert f"[{f['lsb'] + f['width'] - 1}:{f['lsb']}]" in header and f" {f['name']}: " in header
    assert "2**--" not in header and f"synchronous reset, active {man['reset']['polarity']}" in header
    # the meanings name the design's own ports (AXI-Stream by default), never the other naming
    assert "in__payload" not in header and "out__valid" not in header
    # deterministic and path-free (the same inputs give the same header)
    again = build_design(lorenz_tiny.model, design="sensor").files[f"{gd.top}.v"]
    assert again == text and str(tmp_path) not in header


def test_regenerate_keeps_results_and_marks_them_stale(lorenz_tiny, tmp_path):
    from pwas_hdl.design.report import STALE_NOTE, collect_report, report_markdown, stale_results
    from pwas_hdl.io.atomic import TEMP_MARK

    out = tmp_path / "g"
    first = generate(lorenz_tiny.model, out)
    h = first.manifest["design_hash"]
    assert len(h) == 64
    (out / "sim").mkdir()
    sim = {"simulator": "icarus", "samples": 3, "mismatches": 0, "latency_cycles": {}, "ii": {}, "design_hash": h}
    (out / "sim" / "icarus.json").write_text(json.dumps(sim))
    (out / "synth" / "generic").mkdir(parents=True)
    (out / "synth" / "generic" / "synth.json").write_text(json.dumps({"target": "generic", "luts": 10, "ffs": 5, "fmax_mhz": None, "design_hash": h}))
    (out / "synth" / "generic" / "synth.log").write_text("log")
    (out / "notes.txt").write_text("mine")
    # same inputs: same hash, nothing stale, everything kept
    again = generate(lorenz_tiny.model, out)
    assert again.manifest["design_hash"] == h and stale_results(out) == []
    assert not any(e["stale"] for e in collect_report(out)["simulation"] + collect_report(out)["synthesis"])
    # another design in the same folder: the old generated files go, results and user files stay, marked stale
    other = generate(lorenz_tiny.model, out, name="other", memory="replicated", pipeline="min")
    assert other.manifest["design_hash"] != h
    names = {p.name for p in out.iterdir()}
    assert names == set(other.files) | {"sim", "synth", "notes.txt"}, names
    assert not any(n.startswith("pwas_core") for n in names)
    assert (out / "notes.txt").read_text() == "mine" and (out / "synth" / "generic" / "synth.log").is_file()
    assert stale_results(out) == ["sim/icarus.json", "synth/generic/synth.json"]
    rep = collect_report(out)
    assert rep["simulation"][0]["stale"] and rep["synthesis"][0]["stale"]
    md = report_markdown(rep)
    assert md.count(STALE_NOTE) == 2 and not [p.name for p in out.iterdir() if TEMP_MARK in p.name]  # no temporaries left
    # a result without a design hash (older pwas-hdl) counts as made for an earlier design
    (out / "sim" / "old.json").write_text(json.dumps({k: v for k, v in sim.items() if k != "design_hash"}))
    assert "sim/old.json" in stale_results(out)
    # back to the first design: its results are current again; the CLI names what is still stale
    res = runner.invoke(app, ["generate", str(lorenz_tiny.model), "-o", str(out)])
    assert res.exit_code == 0 and stale_results(out) == ["sim/old.json"]
    assert f"kept sim/old.json ({STALE_NOTE}" in res.output and "icarus.json" not in res.output


def test_every_verilog_file_names_generator_model_and_formats(lorenz_tiny, tmp_path):
    """Each .v file of a design folder starts with a header naming pwas-hdl with its version, the model
    (its SHA-256) and the number formats; the instantiation template used to name neither the model nor the
    design it is for (only 'see manifest.json'), and said '1 clock cycles'."""
    import hashlib

    from pwas_hdl import __version__
    from pwas_hdl.systems.switched_observer import estimator_config
    from pwas_hdl.fit.estimator_file import write_estimator

    est = tmp_path / "est.json"
    write_estimator(estimator_config((0.3, 0.4), 1), est)
    for out, src, args in ((tmp_path / "s", lorenz_tiny.model, ["--design", "sensor"]), (tmp_path / "e", est, [])):
        assert runner.invoke(app, ["generate", str(src), "-o", str(out), *args]).exit_code == 0
        man = load_manifest(out)
        model = out / man["files"]["model"]
        sha = hashlib.sha256(model.read_bytes()).hexdigest()
        fmts = [f["format"]["str"] for p in man["ports"] for f in p.get("fields", []) if f.get("format")]
        assert fmts
        for v in sorted(out.glob("*.v")):
            lines = v.read_text().splitlines()
            n = next(i for i, ln in enumerate(lines) if not ln.startswith("//"))
            head = "\n".join(lines[:n])  # the leading comment block
            assert n >= 3, v.name
            assert f"pwas-hdl {__version__}" in head, v.name
            assert f"{model.name} SHA-256 {sha}" in head, v.name
            assert all(f in head for f in fmts), v.name
            assert "1 clock cycles" not in head, v.name


def test_saturate_warning_is_one_warning_line_on_the_command_line(lorenz_tiny, tmp_path):
    """`generate --overflow saturate` printed Python's raw UserWarning: '/path/to/pwas_hdl/fixedpoint/bittrue.py:482:
    UserWarning: ...' and the source line after it (the install path, and not the `warning:` form of every other
    warning of the command line), also under -q."""
    for args in ([], ["-q"]):
        r = runner.invoke(app, [*args, "generate", str(lorenz_tiny.model), "-o", str(tmp_path / f"g{len(args)}"),
                                "--weight-bits", "3", "--overflow", "saturate"])
        assert r.exit_code == 0, r.output
        lines = [ln for ln in r.output.splitlines() if "saturated" in ln]
        assert len(lines) == 1 and lines[0].startswith("warning: ") and "weight(s) saturated" in lines[0], r.output
        assert "UserWarning" not in r.output and ".py:" not in r.output and "model = cls(" not in r.output, r.output


#: Options of ``generate`` with no lint test of their own elsewhere (the corner memory is simulated
#: in test_corner_front but never linted; --input-scale exact only runs under cocotb's Verilator
#: with -Wno-fatal; odd word lengths only through PWASCore, not the sensor top's lag bank), each
#: on the tiny Lorenz sensor (My = 2, p = 3): a few seconds a case.
OPTION_CASES = {
    "core-corner-readmemh": dict(design="core", memory="corner", memory_init="readmemh"),
    "sensor-corner-min": dict(design="sensor", memory="corner", pipeline="min"),
    "core-exact-scale-short": dict(design="core", input_scale="exact", pipeline="short"),
    "sensor-exact-scale-serial": dict(design="sensor", input_scale="exact", architecture="serial"),
    "sensor-odd-widths": dict(design="sensor", input_bits=7, weight_bits=9, weight_frac=-5, output_bits=11),
    "core-odd-widths-max-amaranth": dict(design="core", input_bits=7, weight_bits=9, weight_frac=-5, output_bits=11,
                                         pipeline="max", ports="amaranth"),
    "sensor-goal-latency": dict(design="sensor", goal="latency"),  # the goal's replicated memory (p = 3)
    "core-serial-readmemh-min-amaranth": dict(design="core", architecture="serial", memory_init="readmemh",
                                              pipeline="min", ports="amaranth"),
}


@pytest.mark.rtl  # runs Verilator's linter
@pytest.mark.parametrize("case", list(OPTION_CASES))
def test_generate_options_lint_clean_deterministic_path_free(lorenz_tiny, tmp_path, case):
    """Each option set: the design and its instantiation template (inside a module that declares the
    manifest's ports) pass ``verilator --lint-only -Wall``; a second build gives the same bytes in
    every file; no file holds an absolute path."""
    import subprocess

    from pwas_hdl.flow.toolchain import require, tool_env

    opts = OPTION_CASES[case]
    gd = generate(lorenz_tiny.model, tmp_path / "a", **opts)
    again = build_design(lorenz_tiny.model, **opts)
    assert sorted(again.files) == sorted(gd.files)
    for name in gd.files:
        data = (tmp_path / "a" / name).read_bytes()
        assert data == (again.files[name].encode() if isinstance(again.files[name], str) else again.files[name]), name
        for path in (str(tmp_path), "/tmp/", "/work/", "/root/"):
            assert path.encode() not in data, (name, path)
    if case == "sensor-goal-latency":
        assert gd.manifest["generator"]["options"]["memory"] == "replicated"
    res = lint_verilog(tmp_path / "a" / f"{gd.top}.v", gd.top)
    assert res.returncode == 0 and "%Warning" not in res.stderr, res.stderr[-3000:]
    decl = ",\n".join("  {} wire {}{}".format("input" if p["direction"] == "input" else "output",
                                                f"[{p['width'] - 1}:0] " if p["width"] > 1 else "", p["name"])
                       for p in gd.manifest["ports"])
    inst = gd.manifest["files"]["instance_template"]
    (tmp_path / "a" / "wrap.v").write_text(f"module wrap(\n{decl}\n);\n{gd.files[inst]}\nendmodule\n")
    r = subprocess.run([require("verilator"), "--lint-only", "-Wall", "--top-module", "wrap", "wrap.v", f"{gd.top}.v"],
                       capture_output=True, text=True, env=tool_env(), cwd=tmp_path / "a", check=False)
    assert r.returncode == 0 and "%Warning" not in r.stderr, r.stderr[-3000:]
