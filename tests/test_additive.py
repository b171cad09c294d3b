"""Additive PWAS sensors (issue 15, item 1): subsets, joint fit, model file, CLI, bit-true model, generate."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import sparse

from pwas_hdl.errors import InputError
from pwas_hdl.fit.additive import AdditiveGrid, additive_tikhonov_matrix, parse_additive
from pwas_hdl.fit.geometry import Grid
from pwas_hdl.fit.regressors import LagStructure
from pwas_hdl.fit.regularized_lsq import solve_regularized, tikhonov_matrix
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
from pwas_hdl.fixedpoint.additive import AdditiveFixedPointModel
from pwas_hdl.fixedpoint.bittrue import FixedPointModel
from pwas_hdl.systems.lorenz import lorenz

DIMS_Y4 = LagStructure(0, 4, 0, 1).signal_of_dimension()  # y[t-3], y[t-2], y[t-1], y[t]
DIMS_U2Y3 = LagStructure(2, 3, 1, 1).signal_of_dimension()  # u[t-1], u[t], y[t-2], y[t-1], y[t]


@pytest.fixture
def cli(capsys):
    """Run the console entry point in-process: ``cli(args, expect=0)`` -> (stdout, stderr)."""
    from pwas_hdl.cli import main

    def run(args, expect=0):
        code = main([str(a) for a in args])
        cap = capsys.readouterr()
        assert code == expect, cap.err
        return SimpleNamespace(stdout=cap.out, stderr=cap.err)

    return run


@pytest.fixture(scope="module")
def lorenz_data():
    d = lorenz(3000, seed=1)
    return d


@pytest.fixture(scope="module")
def small_sensor(lorenz_data):
    """A small additive sensor for the hardware tests (3 lags, p = 3, sliding pairs: N = 32)."""
    d = lorenz_data
    return PWASVirtualSensor(mu=0, my=3, partitions=3, sigma=1e-2, additive="pairs", output_names=["y"],
                             target_names=["z"]).fit(None, d.y[:1000], d.z[:1000])


@pytest.fixture(scope="module")
def pairs_sensor(lorenz_data):
    d = lorenz_data
    return PWASVirtualSensor(mu=0, my=4, partitions=5, additive="pairs", output_names=["y"], target_names=["z"]).fit(
        None, d.y[:2000], d.z[:2000])


# ------------------------------------------------------------------------------------------ subsets
def test_named_rules_give_time_windows():
    assert parse_additive("time", DIMS_Y4) == ((0,), (1,), (2,), (3,))
    assert parse_additive("pairs", DIMS_Y4) == ((0, 1), (1, 2), (2, 3))
    assert parse_additive("triples", DIMS_Y4) == ((0, 1, 2), (1, 2, 3))
    # with an input: a part holds every signal of its lags (u has lags 1, 0; y has 2, 1, 0)
    assert parse_additive("time", DIMS_U2Y3) == ((2,), (0, 3), (1, 4))
    assert parse_additive("pairs", DIMS_U2Y3) == ((0, 2, 3), (0, 1, 3, 4))


def test_explicit_subsets_are_sorted_and_may_overlap():
    assert parse_additive("0,1; 1,2 ;3", DIMS_Y4) == ((0, 1), (1, 2), (3,))
    assert parse_additive("2,0", DIMS_Y4) == ((0, 2),)
    assert parse_additive([[3], [0, 1]], DIMS_Y4) == ((3,), (0, 1))


@pytest.mark.parametrize("spec, words", [
    ("0,4", "out of range"), ("0,1;;2", "empty"), ("0,0", "appears twice"), ("0,1;1,0", "repeats part 0"),
    ("0,x", "not a regressor index"), ("quads", "not a regressor index"), ("", "empty"), ("0,-1", "not a regressor index"),
    ("1,", "empty"), ([[]], "empty"), ([[0, 1.5]], "not an integer"),
])
def test_bad_subsets_are_refused(spec, words):
    with pytest.raises(InputError, match=words):
        parse_additive(spec, DIMS_Y4)


def test_windows_need_enough_lags():
    with pytest.raises(InputError, match=r"needs at least 3 lags per signal, the regressor has 2 distinct lags \(t-1, t\)"):
        parse_additive("triples", LagStructure(0, 2, 0, 1).signal_of_dimension())


# ------------------------------------------------------------------------------------------ fit
def test_stacked_basis_and_block_gamma():
    rng = np.random.default_rng(0)
    g = AdditiveGrid([0, 0, 0], [1, 2, 3], [2, 3, 4], [(0, 1), (1, 2)])
    x = rng.uniform(-0.2, 3.2, (50, 3))
    h = g.basis_matrix(x)
    parts = [Grid([0, 0], [1, 2], [2, 3]), Grid([0, 0], [2, 3], [3, 4])]
    want = sparse.hstack([parts[0].basis_matrix(x[:, [0, 1]]), parts[1].basis_matrix(x[:, [1, 2]])])
    assert h.shape == (50, 12 + 20) and g.n_vertices == 32 and g.part_sizes == [12, 20]
    assert abs(h - want).max() == 0
    w = rng.normal(size=32)
    assert np.allclose(h @ w, g.evaluate(w, x))
    gam = additive_tikhonov_matrix(g, 1).toarray()
    assert np.array_equal(gam[:12, :12], tikhonov_matrix(parts[0], 1).toarray()) and not gam[:12, 12:].any()


def test_joint_fit_is_the_regularised_least_squares_of_the_stacked_basis(lorenz_data):
    d = lorenz_data
    m = PWASVirtualSensor(mu=0, my=3, partitions=4, sigma=0.01, additive="time").fit(None, d.y[:1500], d.z[:1500])
    xi, _ = m.regressors(None, d.y[:1500])
    h = m.grid_.basis_matrix(xi)
    w = solve_regularized(h, d.z[2:1500, 0], 0.01, additive_tikhonov_matrix(m.grid_, 0), method="direct")
    assert np.allclose(m.weights_[:, 0], w, rtol=1e-8, atol=1e-8)
    # not identifiable without the penalty: a constant moves between parts, H'H is singular
    hth = (h.T @ h).toarray()
    assert np.linalg.matrix_rank(hth) < hth.shape[0]
    assert m.grid_.n_vertices == 15


def test_additive_sensor_fits_lorenz_with_few_weights(lorenz_data, pairs_sensor):
    d = lorenz_data
    m = pairs_sensor
    assert m.grid_.n_vertices == 3 * 36 and m.sigma_ > 0 and m.cv_ is not None
    zh = m.predict(None, d.y[2000:])
    rmse = float(np.sqrt(np.mean((zh[:, 0] - d.z_true[2003:, 0]) ** 2)))
    assert rmse < 0.5 * float(np.std(d.z_true[2003:, 0]))  # it estimates z (std about 80)
    # the estimate is the sum of the parts
    xi, _ = m.regressors(None, d.y[2000:])
    blocks = m.grid_.split_weights(m.weights_)
    total = sum(g.evaluate(w, xi[:, list(s)]) for g, s, w in zip(m.grid_.parts, m.grid_.subsets, blocks))
    assert np.allclose(total, zh)


def test_additive_with_observer_bank_is_refused():
    from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd

    with pytest.raises(InputError, match="lag front end"):
        PWASVirtualSensor(my=2, additive="time", front_end=ObserverBankFrontEnd())._check_params()


# ------------------------------------------------------------------------------------------ model file
def test_model_file_round_trip(pairs_sensor, tmp_path):
    m = pairs_sensor
    p = m.save(tmp_path / "m.json")
    d = json.loads(p.read_text())
    assert d["additive"] == {"spec": "pairs", "parts": [[0, 1], [1, 2], [2, 3]]}
    assert len(d["weights"]["z"]) == 108 and d["grid"]["partitions"] == [5, 5, 5, 5]
    m2 = PWASVirtualSensor.load(p)
    assert m2.to_json() == m.to_json() and np.array_equal(m2.weights_, m.weights_)
    assert m2.grid_ == m.grid_ and m2.get_params()["additive"] == "pairs"
    x = np.random.default_rng(1).uniform(-30, 30, (20, 4))
    assert np.array_equal(m2.predict_regressors(x), m.predict_regressors(x))


@pytest.mark.parametrize("edit, words", [
    (lambda d: d["additive"].update(parts=[[0, 1], [1, 2]]), "differ from the parts of additive.spec"),
    (lambda d: d["additive"].update(spec="0,7", parts=[[0, 7]]), "not a sorted list of distinct regressor indices"),
    (lambda d: d["additive"].update(spec="quads"), "additive.spec 'quads' is not valid"),
    (lambda d: d["weights"]["z"].pop(), "has 107 values, the grid has N = 108"),
    (lambda d: d["additive"].pop("parts"), "parts"),
])
def test_corrupt_additive_model_files_are_refused(pairs_sensor, edit, words):
    d = pairs_sensor.to_dict()
    edit(d)
    with pytest.raises(InputError, match=words):
        PWASVirtualSensor.from_dict(d)


def test_full_model_files_still_load(lorenz_data):
    d = lorenz_data
    m = PWASVirtualSensor(mu=0, my=2, partitions=4, sigma=1e-3).fit(None, d.y[:500], d.z[:500])
    dd = m.to_dict()
    assert "additive" not in dd and isinstance(PWASVirtualSensor.from_dict(dd).grid_, Grid)


# ------------------------------------------------------------------------------------------ CLI
def test_cli_fit_info_predict(tmp_path, cli):
    cli(["make-data", "lorenz", "-o", str(tmp_path / "tr.csv"), "--samples", "1500", "--test-out",
         str(tmp_path / "te.csv"), "--test-samples", "300"])
    r = cli(["fit", str(tmp_path / "tr.csv"), "-o", str(tmp_path / "m.json"), "-y", "y", "-z", "z", "--my", "6",
             "-p", "5", "--additive", "triples"])
    assert "N = 864 weights in 4 additive parts (triples)" in r.stderr  # progress lines go to stderr
    info = json.loads(cli(["info", str(tmp_path / "m.json")]).stdout)
    assert info["N"] == 864 and info["additive"]["parts"][0] == [0, 1, 2]
    r = cli(["predict", str(tmp_path / "m.json"), str(tmp_path / "te.csv"), "-o", str(tmp_path / "p.csv")])
    assert "RMSE of z_hat" in r.stderr


@pytest.mark.parametrize("spec, words", [("0,9", "out of range"), ("0;;1", "empty"), ("1,1", "appears twice"),
                                         ("0;0", "repeats part 0"), ("triples", "needs at least 3 lags")])
def test_cli_bad_additive_is_one_error_line(tmp_path, cli, spec, words):
    cli(["make-data", "lorenz", "-o", str(tmp_path / "tr.csv"), "--samples", "300"])
    r = cli(["fit", str(tmp_path / "tr.csv"), "-o", str(tmp_path / "m.json"), "-y", "y", "-z", "z", "--my", "2",
             "--additive", spec], expect=2)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and words in lines[0]
    assert not (tmp_path / "m.json").exists()


# ------------------------------------------------------------------------------------------ bit-true model
def test_bittrue_error_bound_holds(pairs_sensor):
    fx = AdditiveFixedPointModel.from_sensor(pairs_sensor)
    assert len(fx.parts) == 3 and fx.weight_codes.shape == (108, 1)
    assert fx.error_bound == pytest.approx(sum(p.error_bound_weight for p in fx.parts) + fx.output_format.lsb / 2)
    rng = np.random.default_rng(2)
    q = rng.integers(fx._qmin, fx._qmax + 1, (5000, fx.n))
    out, oor = fx.evaluate(q)
    err = np.abs(fx.to_physical_output(out) - fx.reference(q))
    assert oor.any() and not oor.all()
    assert err.max() <= fx.error_bound * (1 + 1e-12)
    # the reference is the float sensor at the represented inputs
    assert np.allclose(fx.reference(q), pairs_sensor.predict_regressors(fx.represented_inputs(q)), atol=1e-9)


def test_bittrue_error_bound_is_tight():
    """Weights 0.49 LSB above a code: every part errs by 0.49 LSB in one direction, so the sum errs by
    0.49 k LSB + the output rounding, near the bound k/2 + 1/2 output LSB."""
    g = AdditiveGrid([0.0] * 3, [1.0] * 3, [3, 3, 3], [(0,), (1, 2), (0, 2)])
    rng = np.random.default_rng(3)
    w = rng.integers(-40, 40, (g.n_vertices, 1)) + 0.49
    fx = AdditiveFixedPointModel(g, w, weight_frac=0, output_frac=1)
    q = rng.integers(fx._qmin, fx._qmax + 1, (4000, 3))
    err = np.abs(fx.to_physical_output(fx.evaluate(q)[0]) - fx.reference(q))
    assert fx.error_bound == pytest.approx(3 * 0.5 + 0.25)
    assert 3 * 0.49 <= err.max() <= fx.error_bound


def test_one_part_on_every_regressor_is_the_full_model():
    rng = np.random.default_rng(4)
    g = AdditiveGrid([0.0, -1.0], [2.0, 1.0], [4, 3], [(0, 1)])
    w = rng.normal(0, 5, (g.n_vertices, 2))
    fmt = dict(weight_frac=6, output_frac=4, output_bits=12)
    add = AdditiveFixedPointModel(g, w, **fmt)
    full = FixedPointModel(Grid([0.0, -1.0], [2.0, 1.0], [4, 3]), w, **fmt)
    q = rng.integers(full._qmin, full._qmax + 1, (3000, 2))
    assert np.array_equal(add.evaluate(q)[0], full.evaluate(q)[0])
    assert np.array_equal(add.evaluate(q)[1], full.evaluate(q)[1])
    assert add.error_bound == full.error_bound


# ------------------------------------------------------------------------------------------ generate
def test_explore_sweeps_additive_sensors(small_sensor, tmp_path, cli):
    """explore refused additive sensors; it sweeps them now, point by point the model generate builds
    (tests/test_explore_kinds.py checks the figures)."""
    small_sensor.save(tmp_path / "m.json")
    cli(["make-data", "lorenz", "-o", str(tmp_path / "d.csv"), "--samples", "300"])
    cli(["explore", str(tmp_path / "m.json"), str(tmp_path / "d.csv"), "-o", str(tmp_path / "ex"), "--input-bits", "12",
         "--weight-frac", "0", "--output-frac", "0"])
    res = json.loads((tmp_path / "ex" / "explore.json").read_text())
    assert res["model"]["kind"] == "additive" and all(p["bound_holds"] for p in res["points"])


def test_generate_refuses_what_additive_designs_lack(pairs_sensor):
    from pwas_hdl.design.generate import build_design

    # --memory-init readmemh is available (test_generate_readmemh_additive_hex_files_hold_the_words);
    # an unknown --memory-init is refused as for any design
    with pytest.raises(InputError, match=r"--memory-init \(memory_init\) must be one of inline, readmemh"):
        build_design(pairs_sensor, design="sensor", memory_init="rom")


def _inline_words(verilog: str) -> dict[str, list[int]]:
    """Memory name -> its words, from the inline initialisers (``part0_wmem1[3] = 10'h1f2;``)."""
    import re

    out: dict[str, list[int]] = {}
    for mo in re.finditer(r"^\s*(part[0-9]+_wmem[0-9]+)\[([0-9]+)\] = [0-9]+'h([0-9a-f]+);$", verilog, re.M):
        words = out.setdefault(mo.group(1), [])
        assert int(mo.group(2)) == len(words)
        words.append(int(mo.group(3), 16))
    return out


@pytest.mark.parametrize("design, opts", [("sensor", {}), ("core", {"memory": "corner", "ports": "amaranth"})])
def test_generate_readmemh_additive_hex_files_hold_the_words(small_sensor, tmp_path, design, opts):
    """generate --memory-init readmemh of an additive sensor: every .hex file of the manifest is written,
    holds the words of its part's memory plan (and of the inline design's initialisers) and is read by
    the Verilog's $readmemh of part<i>_wmem<b> under MEM_DIR; the folder passes the manifest's checks;
    byte-identical reruns."""
    import re

    from pwas_hdl.design.generate import build_design, generate
    from pwas_hdl.design.manifest import load_manifest, manifest_errors

    gd = build_design(small_sensor, design=design, memory_init="readmemh", **opts)
    assert build_design(small_sensor, design=design, memory_init="readmemh", **opts).files == gd.files
    inline = build_design(small_sensor, design=design, **opts)
    man, v = gd.manifest, gd.files[f"{gd.top}.v"]
    assert manifest_errors(json.loads(gd.files["manifest.json"])) == []
    assert man["memory"]["init"]["kind"] == "readmemh" and man["generator"]["options"]["memory_init"] == "readmemh"
    assert v.count("\nmodule ") == 1 and '  parameter MEM_DIR = "./";\n' in v
    assert "_wmem0[0] =" not in v and v.count("$readmemh(") == len(man["files"]["hex"]) == man["memory"]["memories"]
    parts = getattr(gd.component, "core", gd.component).parts
    words = _inline_words(inline.files[f"{inline.top}.v"])
    assert len(words) == len(man["files"]["hex"]) == sum(c.memory_plan.n_banks for c in parts)
    for h in man["files"]["hex"]:
        i, b = h["part"], h["bank"]
        assert h["file"] == f"{gd.top}_rom_p{i}_b{b}.hex"
        got = [int(w, 16) for w in gd.files[h["file"]].split()]
        plan = parts[i].memory_plan
        assert got == [int(w) for w in plan.contents[b]] == words[f"part{i}_wmem{b}"]
        assert len(got) == h["depth"] == plan.depth and h["width"] == plan.word_bits
        assert f'initial $readmemh({{MEM_DIR, "{h["file"]}"}}, part{i}_wmem{b}, 0, {len(got) - 1});' in v
    assert {k: t for k, t in gd.files.items() if k.endswith(".hex")} == {k: t for k, t in inline.files.items() if k.endswith(".hex")}
    assert "loads them with `$readmemh`" in gd.files["report.md"] and man["files"]["hex"][-1]["file"] in gd.files["report.md"]
    assert "rom:" in gd.files[f"{gd.top}.core"] and all(f"{h['file']}: {{copyto" in gd.files[f"{gd.top}.core"] for h in man["files"]["hex"])
    assert "#(.MEM_DIR(" in gd.files[f"{gd.top}_inst.v"]
    # on disk: the manifest's folder checks find every file; a missing one is named
    generate(small_sensor, tmp_path / "d", design=design, memory_init="readmemh", **opts)
    assert load_manifest(tmp_path / "d")["memory"]["init"]["kind"] == "readmemh"
    gone = man["files"]["hex"][1]["file"]
    (tmp_path / "d" / gone).unlink()
    with pytest.raises(InputError, match=re.escape(f"{gone} is missing (the Verilog reads it with $readmemh)")):
        load_manifest(tmp_path / "d")


def test_emit_additive_verilog_readmemh_checks(small_sensor):
    """emit_additive_verilog takes memory_init / hex_prefix as emit_verilog does (same checks, one file
    name per part and bank: hex_file_name), and refuses ROMs that are not the parts' memory plans."""
    from pwas_hdl.errors import InternalError
    from pwas_hdl.design.generate import fixed_point_model
    from pwas_hdl.hdl.additive_top import build_additive_core, emit_additive_verilog
    from pwas_hdl.hdl.emit import memory_hex_files
    from pwas_hdl.fixedpoint.memory_layout import hex_file_name
    from pwas_hdl.hdl.emit import _readmemh_files
    from pwas_hdl.hdl.weight_rom import RomEmission

    core = build_additive_core(fixed_point_model(small_sensor), pipeline="min")
    with pytest.raises(InputError, match="hex_prefix 'a/b' must be a plain file-name prefix"):
        emit_additive_verilog(core, "pwas_core", memory_init="readmemh", hex_prefix="a/b")
    with pytest.raises(InputError, match="memory_init"):
        emit_additive_verilog(core, "pwas_core", memory_init="rom")
    v = emit_additive_verilog(core, "pwas_core", memory_init="readmemh", hex_prefix="wt")
    files = memory_hex_files(core, "wt")
    assert list(files) == [hex_file_name("wt", b, i) for i, c in enumerate(core.parts) for b in range(c.memory_plan.n_banks)]
    assert [f'{{MEM_DIR, "{f}"}}' in v for f in files] == [True] * len(files) == [True] * v.count("$readmemh(")
    assert hex_file_name("wt", 2, 1) == "wt_p1_b2.hex" and hex_file_name("wt", 2) == "wt_b2.hex"
    # the ROMs met in elaboration must be the parts' memories with their words
    plans = [c.memory_plan for c in core.parts]
    good = RomEmission()
    for pl in plans:
        for b in range(pl.n_banks):
            good.add(pl.word_bits, pl.depth, [int(w) for w in pl.contents[b]])
    assert _readmemh_files(core, good, "wt")("part1_wmem0", plans[0].n_banks) == '{MEM_DIR, "wt_p1_b0.hex"}'
    with pytest.raises(InternalError, match="its contents differ from the memory plan"):
        _readmemh_files(core, good, "wt")("part1_wmem0", 0)  # ROM 0 holds part 0's bank 0
    for name in ("wmem0", "part2_wmem0", f"part0_wmem{plans[0].n_banks}"):
        with pytest.raises(InternalError, match=f"unexpected weight memory {name}"):
            _readmemh_files(core, good, "wt")(name, 0)
    short = RomEmission()
    short.add(plans[0].word_bits, plans[0].depth, [0])
    with pytest.raises(InternalError, match="1 weight memories in the design"):
        _readmemh_files(core, short, "wt")


def test_generate_manifest_and_deterministic(small_sensor):
    from pwas_hdl.design.generate import build_design
    from pwas_hdl.design.manifest import manifest_errors

    a = build_design(small_sensor, design="sensor")
    b = build_design(small_sensor, design="sensor")
    assert a.files == b.files  # byte-identical reruns
    man = a.manifest
    assert manifest_errors(json.loads(a.files["manifest.json"])) == []
    parts = man["additive"]["parts"]
    assert [p["regressors"] for p in parts] == [[0, 1], [1, 2]]
    assert parts[0]["names"] == ["y[t-2]", "y[t-1]"]
    assert all(p["memory"]["memories"] == 3 and p["latency"] == man["latency_cycles"] - 1 for p in parts)
    assert man["memory"]["memories"] == 6 and man["domain"]["n_vertices"] == 32
    assert [h["part"] for h in man["files"]["hex"]] == [0, 0, 0, 1, 1, 1]
    v = a.files["pwas_sensor.v"]
    assert "additive sensor: 2 parts" in v and v.count("\nmodule ") == 1 and "/work" not in v


@pytest.mark.rtl
def test_generated_additive_verilog_is_lint_clean(small_sensor, tmp_path):
    from pwas_hdl.design.generate import build_design
    from pwas_hdl.flow.toolchain import lint_verilog

    for design, opts in (("sensor", {}), ("core", {"pipeline": "max", "rounding": "truncate"}),
                         # the parts' other memories, pipelines, input scale, ports and odd word lengths
                         ("sensor", {"pipeline": "short", "memory": "corner", "input_scale": "exact", "ports": "amaranth"}),
                         ("core", {"pipeline": "max-lut", "memory": "replicated", "input_bits": 7, "weight_bits": 9,
                                   "output_bits": 11, "overflow": "saturate"}),
                         ("sensor", {"pipeline": "min", "input_bits": 9, "output_bits": 9, "overflow": "saturate"})):
        gd = build_design(small_sensor, design=design, **opts)
        path = tmp_path / f"{gd.top}.v"
        path.write_text(gd.files[f"{gd.top}.v"])
        r = lint_verilog(path)
        assert r.returncode == 0 and not r.stderr.strip(), r.stderr


@pytest.mark.rtl
def test_readmemh_additive_verilog_is_lint_clean(small_sensor, tmp_path):
    """--memory-init readmemh: the MEM_DIR parameter and the parts' $readmemh calls are lint-clean
    (verilator --lint-only -Wall) for both designs, the parts' memory layouts and port namings."""
    from pwas_hdl.design.generate import build_design
    from pwas_hdl.flow.toolchain import lint_verilog

    for design, opts in (("sensor", {}), ("core", {"pipeline": "max", "memory": "replicated"}),
                         ("sensor", {"pipeline": "short", "memory": "corner", "ports": "amaranth"})):
        gd = build_design(small_sensor, design=design, memory_init="readmemh", **opts)
        path = tmp_path / f"{gd.top}.v"
        path.write_text(gd.files[f"{gd.top}.v"])
        assert "$readmemh(" in path.read_text()
        r = lint_verilog(path)
        assert r.returncode == 0 and not r.stderr.strip(), r.stderr


# ------------------------------------------------------------------------------------------ benchmark smoke
@pytest.mark.slow
def test_benchmark_quick_smoke(tmp_path):
    from pwas_hdl import bench_results as br
    from pwas_hdl.benchmarks import additive as bench

    doc, _ = bench.run_additive(1, quick=True, progress=None)
    br.validate_results(doc)
    rows = {(r["estimator"], r["config"]["My"], r["stage"]): r for r in doc["rows"]}
    assert rows[("pwas-additive-pairs", 8, "float")]["config"]["N"] == 448
    assert rows[("pwas-full", 8, "float")]["value"] is None and "limit" in rows[("pwas-full", 8, "float")]["config"]["note"]
    assert rows[("pwas-full", 4, "bittrue")]["value"] > 0
    md = bench.markdown(doc)
    assert "| lorenz | My = 8 | additive-pairs | 7 | 448 |" in md and "16777216 (refused)" in md


@pytest.mark.parametrize("spec, full", [("pairs", True), ("0,1", True), ("time", False), ("0;1", False)])
def test_cli_additive_of_one_full_part_says_so(tmp_path, cli, spec, full):
    """--additive pairs over 2 lags is one part of both regressors: the full sensor, fitted without a
    word; now a note says so (and nothing is said when the parts drop interactions)."""
    cli(["make-data", "lorenz", "-o", str(tmp_path / "tr.csv"), "--samples", "300"])
    r = cli(["fit", str(tmp_path / "tr.csv"), "-o", str(tmp_path / "m.json"), "-y", "y", "-z", "z", "--my", "2",
             "-p", "3", "--sigma", "1e-3", "--additive", spec])
    assert (f"note: --additive {spec} gives one part over all 2 regressors, i.e. the full PWAS sensor" in r.stderr) is full
    if full:  # the way out: more lags for a named rule, smaller parts for explicit ones
        assert ("more lags (--my/--mu) give more parts" if spec == "pairs" else "give parts over fewer regressors") in r.stderr


# ------------------------------------------------------------------------------------------ additive classifiers
def _additive_classifier():
    from pwas_hdl.systems.lorenz import lorenz

    d = lorenz(1500, seed=5)
    z = d.z[:, 0]
    c = np.digitize(z, np.quantile(z, [1 / 3, 2 / 3]))
    return PWASVirtualSensor(my=3, partitions=3, sigma=1e-3, classify=True, additive="pairs", output_names=["y"],
                             target_names=["c"]).fit(None, d.y[:, 0], c)


@pytest.mark.parametrize("design, pipeline", [("core", "max"), ("sensor", None)])
def test_generate_additive_classifier(design, pipeline):
    """fit --additive --classify: the argmax stage after the sum (was refused: 'hardware for an additive
    classifier ... is not available yet'); the manifest has both entries, the class index ends the payload."""
    from pwas_hdl.design.generate import build_design
    from pwas_hdl.design.manifest import manifest_errors
    from pwas_hdl.hdl.argmax import argmax_latency
    from pwas_hdl.hdl.params import Pipeline

    s = _additive_classifier()
    a = build_design(s, design=design, pipeline=pipeline)
    assert a.files == build_design(s, design=design, pipeline=pipeline).files  # byte-identical reruns
    man = a.manifest
    assert manifest_errors(json.loads(a.files["manifest.json"])) == []
    assert man["classifier"]["target"] == "c" and man["classifier"]["classes"] == [0.0, 1.0, 2.0]
    parts = man["additive"]["parts"]
    stage = argmax_latency(3, Pipeline.cast(pipeline))
    assert all(p["latency"] + 1 + stage == man["latency_cycles"] for p in parts) and man["ii"] == 1
    out = next(p for p in man["ports"] if p["role"] == "out.payload")
    assert [f["name"] for f in out["fields"]] == ["c=0", "c=1", "c=2", "out_of_range", "class_index"]
    assert out["fields"][-1]["lsb"] + out["fields"][-1]["width"] == out["width"]
    assert "## Classifier" in a.files["report.md"]


@pytest.mark.rtl
def test_additive_classifier_verilog_is_lint_clean(tmp_path):
    from pwas_hdl.design.generate import build_design
    from pwas_hdl.flow.toolchain import lint_verilog

    s = _additive_classifier()
    for design, opts in (("core", {"pipeline": "max", "ports": "amaranth"}), ("sensor", {"pipeline": "min"})):
        gd = build_design(s, design=design, **opts)
        path = tmp_path / f"{gd.top}.v"
        path.write_text(gd.files[f"{gd.top}.v"])
        r = lint_verilog(path)
        assert r.returncode == 0 and not r.stderr.strip(), r.stderr
