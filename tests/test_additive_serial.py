"""Additive sensors on the serial architecture (``generate --architecture serial`` of a ``fit --additive`` model).

Every part is a serial core without rounding (one multiplier per target, ``n_i + 1`` cycles per
sample, one memory of ``N_i`` words); one input throttle at the largest part's II drives them all,
a shorter part's sum waits in its output register, then the additive design's exact sum and one
rounding. Configurations: ``sim/pwas_designs.ADDITIVE_SERIAL_CONFIGS``. Checked here: the manifest
(II, latency, architecture, memories), header and report, byte-identical reruns, Verilator lint, the
refusals that remain, an additive classifier generated on the serial parts, and in cocotb on Icarus and Verilator (full speed, stalls and backpressure, a
reset mid-stream) that every output equals the additive bit-true model and the parallel design's
output on the same stimulus; a flipped weight bit in the smallest part is caught.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers.cli import CliRunner
from helpers.design_cache import DesignCache, parallel_twin

from pwas_hdl.verify.simulation import Run, load_design, run_rtl, segment, sim_module, standard_runs

designs = sim_module("pwas_designs")
stimulus = sim_module("pwas_stimulus")
mutations = sim_module("pwas_mutations")
SERIAL = {c.name: c for c in designs.ADDITIVE_SERIAL_CONFIGS}


def _parallel_twin(cfg):
    return parallel_twin(cfg, cfg.name.replace("as-", "ap-"))


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    return DesignCache(tmp_path_factory.mktemp("additive_serial"))


def _codes(d, seed: int, m: int = 200) -> np.ndarray:
    return stimulus.design_codes(d, m, seed=seed)


def test_the_configurations_have_parts_of_different_dimensions():
    from pwas_hdl.design.generate import fixed_point_model

    assert {c.design for c in SERIAL.values()} == {"core", "sensor"}
    assert all(c.options["architecture"] == "serial" for c in SERIAL.values())
    fxs = {c.name: fixed_point_model(c.model()) for c in SERIAL.values()}
    unequal = [nm for nm, fx in fxs.items() if len({len(s) for s in fx.subsets}) > 1]
    assert {SERIAL[nm].design for nm in unequal} == {"core", "sensor"}
    assert any(a > 0 for fx in fxs.values() for a in fx.align)


@pytest.mark.parametrize("name", list(SERIAL))
def test_manifest_states_ii_latency_architecture_memory(name, folders):
    from pwas_hdl.design.manifest import manifest_errors
    from pwas_hdl.hdl.params import Pipeline
    from pwas_hdl.hdl.serial_core import serial_latency

    cfg = SERIAL[name]
    folder = folders(cfg)
    man = json.loads((folder / "manifest.json").read_text())
    assert manifest_errors(man) == []
    parts = man["additive"]["parts"]
    dims = [len(p["regressors"]) for p in parts]
    pl = Pipeline.cast(cfg.options.get("pipeline"))
    assert [p["latency"] for p in parts] == [serial_latency(pl, n) for n in dims]
    assert man["ii"] == max(dims) + 1 == man["architecture"]["ii"] == man["architecture"]["cycles_per_sample"]
    assert man["latency_cycles"] == serial_latency(pl, max(dims)) + 1
    arch = man["architecture"]
    assert arch["kind"] == "serial" and arch["multipliers"] == len(parts) * cfg.nz
    assert man["generator"]["options"]["architecture"] == "serial"
    assert man["memory"]["kind"] == "single" and man["memory"]["layout_spec"]["kind"] == "single"
    assert man["memory"]["memories"] == len(parts) == len(man["files"]["hex"])
    assert all(p["memory"]["memories"] == 1 and p["memory"]["depth"] == p["n_vertices"] for p in parts)
    ready = next(p["name"] for p in man["ports"] if p["role"] == "in.ready")
    assert f"one transfer every {man['ii']} advancing cycles" in man["flow_control"][ready]
    top = man["top"]
    v = (folder / f"{top}.v").read_text()
    assert f"additive sensor: {len(parts)} parts" in v and "each a serial PWAS core" in v
    assert f"II {man['ii']} (one sample every {man['ii']} clocks)" in v
    rep = (folder / "report.md").read_text()
    assert "## Additive parts" in rep and "each a serial PWAS core" in rep and "serial architecture" in rep


def test_rerun_is_byte_identical(tmp_path):
    cfg = SERIAL["as-s-u2y2-1+3-min"]
    a = cfg.generate(tmp_path / "a")
    b = cfg.generate(tmp_path / "b")
    assert a.files == b.files


def test_parallel_twin_is_unchanged_by_the_serial_option(folders):
    """The parallel twin is the parallel additive design (II 1, equal part latencies)."""
    man = json.loads((folders(_parallel_twin(SERIAL["as-c-n4-z2-max-trunc"])) / "manifest.json").read_text())
    assert man["ii"] == 1 and man["architecture"]["kind"] == "parallel"
    assert len({p["latency"] for p in man["additive"]["parts"]}) == 1
    assert man["architecture"]["multipliers"] == sum(len(p["regressors"]) + 1 for p in man["additive"]["parts"]) * 2


@pytest.mark.parametrize("opts, msg", [
    ({"memory": "banked"}, "--memory banked does not apply to --architecture serial"),
    ({"memory": "corner", "design": "core"}, "--memory corner does not apply to --architecture serial"),
])
def test_build_design_refusals(opts, msg):
    from pwas_hdl.design.generate import build_design
    from pwas_hdl.errors import InputError

    cfg = SERIAL["as-s-y3-pairs"]
    with pytest.raises(InputError, match=msg):
        build_design(cfg.model(), **{"design": "sensor", "architecture": "serial", **opts})


@pytest.mark.parametrize("design", ["core", "sensor"])
def test_cli_serial_additive_classifier_is_generated(design, tmp_path):
    """An additive classifier on the serial architecture (was refused: 'the argmax stage follows the
    parallel core only'): the argmax stage after the serial parts' sum, II = the largest part's n + 1,
    the latency the serial sum's + the stage's. (Bit-exact RTL: tests/test_serial_classifier.py.)"""
    from pwas_hdl.cli import app
    from pwas_hdl.fit.model_file import write_model
    from pwas_hdl.hdl.argmax import argmax_latency
    from pwas_hdl.hdl.params import Pipeline
    from pwas_hdl.hdl.serial_core import serial_latency

    cfg = designs.DesignConfig("acls", design, 0, 3, 0, 1, 3, 3, {}, seed=3, classes=(0, 1, 2), additive="pairs")
    model = tmp_path / "m.json"
    write_model(cfg.model(), model)
    out = tmp_path / "out"
    r = CliRunner().invoke(app, ["generate", str(model), "-o", str(out), "--design", design, "--architecture", "serial"])
    assert r.exit_code == 0, r.output
    man = json.loads((out / "manifest.json").read_text())
    assert man["architecture"]["kind"] == "serial" and man["ii"] == 3 and "additive" in man
    assert man["classifier"]["n_classes"] == 3 and man["classifier"]["stage_latency_cycles"] == argmax_latency(3, None) == 1
    assert man["latency_cycles"] == serial_latency(Pipeline.cast(None), 2) + 1 + 1


@pytest.mark.rtl
@pytest.mark.parametrize("name", list(SERIAL))
def test_serial_additive_rtl_is_lint_clean(name, folders, tmp_path):
    from pwas_hdl.flow.toolchain import lint_verilog

    for init in ("inline", "readmemh"):
        d = load_design(folders(SERIAL[name], init))
        path = tmp_path / init / f"{d.top}.v"  # the file named after the module (Verilator's DECLFILENAME)
        path.parent.mkdir()
        path.write_text(d.verilog)
        r = lint_verilog(path)
        assert r.returncode == 0 and not r.stderr.strip(), r.stderr


# every configuration on Icarus (against the parallel design too), Verilator on the one whose parts
# differ in size (the CI budget; benchmarks/rtl_random_configs.py runs serial additives on both)
RTL_CASES = [(name, "icarus") for name in SERIAL] + [("as-s-u2y2-1+3-min", "verilator")]


@pytest.mark.rtl
@pytest.mark.parametrize("name, simulator", RTL_CASES)
def test_serial_additive_rtl_bit_exact_with_model_and_parallel(name, simulator, folders, sim_cache, tmp_path):
    """Full speed (II = the largest part's n + 1 from the handshake, latency = manifest), stalls and
    backpressure, a mid-stream reset: every output equals the additive bit-true model, and the
    parallel additive design's output on the same stimulus, sample for sample."""
    cfg = SERIAL[name]
    d = load_design(folders(cfg))
    assert "additive" in d.manifest and d.manifest["architecture"]["kind"] == "serial"
    codes = _codes(d, seed=13)
    runs = standard_runs(d, codes, seed=13)
    res = run_rtl(d, runs, simulator, cache_dir=sim_cache, work_dir=tmp_path / "s", debug=False)
    assert res.passed and res.mismatches == 0, res.report()
    assert set(res.latencies) == {d.latency} == {int(d.manifest["latency_cycles"])}, res.report()
    assert res.ii == float(d.manifest["ii"]) > 1
    per_stream = len(segment(d, codes).src)
    assert res.outputs >= 2 * per_stream + len(runs[2].segments[1].src)
    assert res.within_bound, res.report()
    oor = np.concatenate([o for run in res.hw for _, o in run])
    assert oor.any() and not oor.all()
    if simulator != "icarus":
        return
    dp = load_design(folders(_parallel_twin(cfg)))
    resp = run_rtl(dp, standard_runs(dp, codes, seed=13), simulator, cache_dir=sim_cache, work_dir=tmp_path / "p", debug=False)
    assert resp.passed, resp.report()
    compared = 0
    for run, ra, rb in zip(runs, res.hw, resp.hw):
        for seg, (zs, os_), (zp, op) in zip(run.segments, ra, rb):
            if seg.drain:
                assert zs.shape == zp.shape
            k = min(len(zs), len(zp))
            np.testing.assert_array_equal(zs[:k], zp[:k])
            np.testing.assert_array_equal(os_[:k], op[:k])
            compared += k
    assert compared >= 2 * per_stream


@pytest.mark.rtl
@pytest.mark.parametrize("name, simulator", [("as-c-n4-z2-max-trunc", "icarus"), ("as-s-u2y2-1+3-min", "verilator")])
def test_serial_additive_readmemh_rtl_equals_bittrue_model(name, simulator, folders, sim_cache, tmp_path):
    d = load_design(folders(SERIAL[name], "readmemh"))
    assert d.manifest["memory"]["init"]["kind"] == "readmemh"
    assert '$readmemh({MEM_DIR, "' in d.verilog and "_wmem0[0] =" not in d.verilog
    codes = _codes(d, seed=17, m=150)
    res = run_rtl(d, standard_runs(d, codes, seed=17), simulator, cache_dir=sim_cache, work_dir=tmp_path, debug=False)
    assert res.passed and res.mismatches == 0, res.report()
    assert set(res.latencies) == {d.latency} and res.ii == float(d.manifest["ii"])


def _smallest_part_word(d):
    """(part, addr, bit) of a weight of the smallest part read by the stimulus: the word of its
    first vertex at the lower corner, a bit worth two output LSBs of target 0."""
    fx = d.model
    dims = [len(s) for s in fx.subsets]
    part = dims.index(min(dims))
    return part, 0, fx.weight_format.frac - fx.output_format.frac + 1


@pytest.mark.rtl
@pytest.mark.parametrize("name, simulator", [("as-s-u2y2-1+3-min", "icarus"), ("as-c-n4-z2-max-trunc", "verilator")])
def test_flipped_weight_of_the_smallest_part_is_caught(name, simulator, folders, sim_cache, tmp_path):
    """A corrupted weight in the part whose sum waits in its output register: the bench fails."""
    d = load_design(folders(SERIAL[name]))
    part, addr, bit = _smallest_part_word(d)
    text, desc = mutations.flip_weight_bit(d.verilog, 0, addr, bit, part=part)
    assert text != d.verilog
    path = tmp_path / f"{d.top}.v"
    path.write_text(text)
    dm = load_design(d.outdir, verilog=path)
    codes = _codes(d, seed=19, m=300)
    res = run_rtl(dm, [Run("full-speed", [segment(dm, codes)])], simulator, cache_dir=sim_cache, work_dir=tmp_path / "run",
                  debug=False)
    assert not res.passed and res.mismatches > 0, f"{desc}: the testbench did not notice\n{res.report()}"
    assert "differ from the bit-true model" in res.report()
