"""The benchmark scripts keep the command line's error contract (pwas_hdl.bench_results.script_main):
bad input is one ``error:`` line, exit status 2 and nothing written, not a traceback."""

from __future__ import annotations

import importlib
import re

import pytest

from pwas_hdl.bench_results import script_main
from pwas_hdl.resources import benchmarks_dir


@pytest.mark.parametrize("script, args", [
    ("distributed_speedup", ["--quick", "--scheduler", "nohost"]),
    ("hw_tables", ["--scheduler", "localhost:1"]),
])
def test_bad_option_is_one_error_line_and_nothing_written(tmp_path, capsys, script, args):
    bench = importlib.import_module(f"pwas_hdl.benchmarks.{script}")
    out = tmp_path / "out"
    assert script_main(bench.main, [*args, "--outdir", str(out)]) == 2
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: --scheduler must be an address like tcp://HOST:PORT"), err
    assert "Traceback" not in err and not out.exists()


def test_a_bug_is_a_traceback_and_status_3(capsys):
    def broken(argv=None):
        raise KeyError("x")

    assert script_main(broken, []) == 3
    err = capsys.readouterr().err
    assert "Traceback" in err and "internal error" in err


def test_every_script_entry_uses_script_main():
    """A script whose ``__main__`` block only calls ``main`` goes through script_main."""
    plain = []
    for path in sorted(benchmarks_dir().glob("*.py")):
        text = path.read_text(encoding="utf-8")
        block = text.split('if __name__ == "__main__":', 1)[1] if 'if __name__ == "__main__":' in text else ""
        if re.search(r"^\s+(sys\.exit\(|raise SystemExit\()?main\(\)\)?\s*$", block, re.M):
            plain.append(path.name)
    assert plain == []


def test_every_script_entry_keeps_the_contract_and_writes_outside_the_package():
    """Every ``__main__`` block goes through script_main (or bench_main, which uses it), and no
    script writes its results next to itself by default (from the wheel: into site-packages);
    ``--outdir`` defaults to bench_results.default_outdir."""
    bad_entry, bad_out = [], []
    for path in sorted(benchmarks_dir().glob("*.py")):
        text = path.read_text(encoding="utf-8")
        if 'if __name__ == "__main__":' in text:
            block = text.split('if __name__ == "__main__":', 1)[1]
            if "script_main(" not in block and "bench_main(" not in block:
                bad_entry.append(path.name)
        for m in re.finditer(r'add_argument\("--outdir"[^)]*default=([^,)]+)', text):
            if "default_outdir(" not in m.group(1):
                bad_out.append(f"{path.name}: --outdir default {m.group(1)}")
        if re.search(r'^\s*(out|outdir) = (HERE|benchmarks_dir\(\)) / "results"\s*$', text, re.M):  # an output folder
            bad_out.append(f"{path.name}: writes into its own folder")
    assert bad_entry == [] and bad_out == [], (bad_entry, bad_out)


def test_fit_scale_quick_smoke_records_the_memory_plan(tmp_path, monkeypatch):
    """benchmarks/fit_scale.py (issue 18) end to end on its smallest point: both orders fitted in child
    processes, the direct reference, and the memory plan and limit in the results."""
    import json

    monkeypatch.setenv("PWAS_HDL_MAX_MEMORY", "2G")
    bench = importlib.import_module("pwas_hdl.benchmarks.fit_scale")
    assert script_main(bench.main, ["--quick", "--points", "2:7", "--outdir", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "fit_scale_quick.json").read_text())
    assert res["setup"]["memory_limit"] == {"bytes": 2 * 2**30, "source": "$PWAS_HDL_MAX_MEMORY"}
    rows = res["rows"]
    assert [(r["n"], r["p"], r["order"], r["status"]) for r in rows] == [(2, 7, 0, "ok"), (2, 7, 1, "ok")]
    for r in rows:
        assert r["memory_plan"]["processes"] == 1 and r["memory_plan"]["reason"] is None
        assert r["estimated_mib"] > 0 and r["direct"]["status"] in ("ok", "is the direct solve")
    assert "Memory limit 2048 MiB ($PWAS_HDL_MAX_MEMORY)" in (tmp_path / "fit_scale_quick.md").read_text()


def test_cg_preconditioners_quick_smoke(tmp_path):
    """benchmarks/cg_preconditioners.py (issue 18) on its quick point: every preconditioner of each
    order ran on fold 0, and the systems it reports converged have the solver's residual."""
    import json

    from pwas_hdl.fit.regularized_lsq import CG_RTOL

    bench = importlib.import_module("pwas_hdl.benchmarks.cg_preconditioners")
    assert script_main(bench.main, ["--quick", "--outdir", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "cg_preconditioners_quick.json").read_text())
    rows = res["rows"]
    expected = [(0, s, name) for s in bench.QUICK_SIGMAS for name in bench.PRECONDITIONERS[0]]
    expected += [(1, s, name) for s in bench.QUICK_SIGMAS for name in bench.PRECONDITIONERS[1]]
    assert [(r["order"], r["sigma"], r["preconditioner"]) for r in rows] == expected
    # zero order is restricted to the touched vertices, first order keeps the whole 6^4 grid
    assert {r["rows"] for r in rows if r["order"] == 1} == {6**4}
    assert all(r["rows"] < 6**4 for r in rows if r["order"] == 0)
    assert all(r["rel_residual"] <= 10 * CG_RTOL for r in rows if r["converged"])
    assert any(r["converged"] for r in rows) and (tmp_path / "cg_preconditioners_quick.md").is_file()


def test_cg_preconditioners_subset(tmp_path):
    """--preconditioners runs only the named ones, each order those it has (amg: first order only),
    and the Markdown splits an iteration into A @ v and the rest."""
    import json

    bench = importlib.import_module("pwas_hdl.benchmarks.cg_preconditioners")
    args = ["--quick", "--sigmas", "1e-2", "--preconditioners", "jacobi,amg", "--outdir", str(tmp_path)]
    assert script_main(bench.main, args) == 0
    rows = json.loads((tmp_path / "cg_preconditioners_quick.json").read_text())["rows"]
    assert [(r["order"], r["preconditioner"]) for r in rows] == [(0, "jacobi"), (1, "jacobi"), (1, "amg")]
    md = (tmp_path / "cg_preconditioners_quick.md").read_text()
    assert "| an iteration (ms) | of it not A @ v (ms) |" in md
    r = rows[0]
    per = 1e3 * r["cg_cpu_s"] / r["iterations"]
    assert f"| {per:.2f} | {per - r['matvec_cpu_ms']:.2f} |" in md


@pytest.mark.parametrize("script, args, message", [
    ("cg_preconditioners", ["--points", "4"], "--points takes n:p pairs"),
    ("cg_preconditioners", ["--points", "9:9"], "--points: at most"),
    ("cg_preconditioners", ["--sigmas", "1e-2,-1"], "--sigmas takes positive numbers"),
    ("cg_preconditioners", ["--maxiter", "0"], "--maxiter must be a count"),
    ("cg_preconditioners", ["--preconditioners", "jacobi,ilu"], "--preconditioners takes names from"),
    ("first_order_floor", ["--points", "2:x"], "--points takes n:p pairs"),
    ("first_order_floor", ["--points", "2:2000"], "--points: at most"),
    ("first_order_floor", ["--quick", "--stem", "a/b"], "--stem must be a plain file name"),
    ("cg_preconditioners", ["--quick", "--stem", ".."], "--stem must be a plain file name"),
    ("fit_scale", ["--quick", "--stem", "../x"], "--stem must be a plain file name"),
    ("rtl_random_configs", ["--count", "0"], "--count"),
    ("rtl_random_configs", ["--samples", "5"], "--samples must be in 20..100000"),
    ("rtl_random_configs", ["--seed", "-1"], "--seed and --first must be >= 0"),
    ("rtl_random_configs", ["--named", "--first", "44"], "--first must be below 44, the number of named configurations"),
    ("rtl_random_configs", ["--quick", "--stem", "a/b"], "--stem must be a plain file name"),
    ("generate_scale", ["--points", "2:x"], "--points takes n:p pairs"),
    ("generate_scale", ["--points", "2:4000"], "--points: at most"),
    ("generate_scale", ["--points", "0:3"], "--points: n must be in 1..6"),
    ("generate_scale", ["--samples", "5"], "--samples must be in 20..100000"),
    ("generate_scale", ["--quick", "--stem", "a/b"], "--stem must be a plain file name"),
    ("timing_closure_kinds", ["--kinds", "plain-core,nope"], "--kinds takes names from"),
    ("timing_closure_kinds", ["--kinds", "plain-core,plain-core"], "--kinds names a kind twice"),
    ("timing_closure_kinds", ["--clock-mhz", "0"], "--clock-mhz must be in (0, 2000) MHz"),
    ("timing_closure_kinds", ["--quick", "--stem", "a/b"], "--stem must be a plain file name"),
    ("timing_closure_kinds", ["--kinds", "plain-core", "--isqrt-every", "2"], "--isqrt-every applies to the observer-bank kinds"),
    ("timing_closure_kinds", ["--kinds", "bank-sensor", "--isqrt-every", "0"], "--isqrt-every must be a positive integer"),
    ("recurrence_speed", ["--samples", "5"], "--samples must be in 50..100000"),
    ("recurrence_speed", ["--repeats", "0"], "--repeats must be in 1..20"),
    ("recurrence_speed", ["--before-points", "4"], "--before-points must be in 1..3"),
    ("recurrence_speed", ["--quick", "--stem", "a/b"], "--stem must be a plain file name"),
])
def test_benchmark_bad_option(tmp_path, capsys, script, args, message):
    bench = importlib.import_module(f"pwas_hdl.benchmarks.{script}")
    out = tmp_path / "out"
    assert script_main(bench.main, [*args, "--outdir", str(out)]) == 2
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith(f"error: {message}"), lines
    assert not out.exists()


def test_first_order_floor_quick_smoke(tmp_path):
    """benchmarks/first_order_floor.py (issue 18) on its quick point: both orders' CV ran with the same
    number of solves, the budget is twice the zero-order CPU a solve, and the kernels were measured on
    the whole first-order grid."""
    import json

    bench = importlib.import_module("pwas_hdl.benchmarks.first_order_floor")
    assert script_main(bench.main, ["--quick", "--outdir", str(tmp_path)]) == 0
    (row,) = json.loads((tmp_path / "first_order_floor_quick.json").read_text())["rows"]
    assert (row["n"], row["p"], row["T"]) == (2, 127, 10_000)
    assert row["zero"]["solves"] == row["first"]["solves"] == 5 * 21 + 1
    assert row["budget_ms_per_solve"] == 2.0 * row["zero"]["cpu_ms_per_solve"]
    k = row["kernels"]
    assert k["rows"] == 128**2 and k["levels"] >= 2
    assert all(k[key] > 0 for key in ("matvec_ms", "gauss_seidel_ms", "vcycle_ms", "vcycle_block_ms"))
    assert row["iterations_in_budget"] == row["budget_ms_per_solve"] / (k["vcycle_ms"] + k["matvec_ms"])
    assert "| 2 | 127 | 16384 |" in (tmp_path / "first_order_floor_quick.md").read_text()



def test_recurrence_speed_quick_smoke(tmp_path):
    """benchmarks/recurrence_speed.py --quick: the fast recurrence, the lockstep and explore's points
    equal the reference loop's (times are recorded, never asserted)."""
    import json

    bench = importlib.import_module("pwas_hdl.benchmarks.recurrence_speed")
    assert script_main(bench.main, ["--quick", "--outdir", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "recurrence_speed_quick.json").read_text())
    assert [r["sensor"] for r in res["per_sample"]] == ["Mz=1", "Mz=1 warped"]
    assert all(r["identical"] for r in res["per_sample"] + res["many_trajectories"])
    assert [r["trajectories"] for r in res["many_trajectories"]] == list(bench.QUICK_COUNTS)
    assert res["explore"]["before"]["identical_points"] and res["explore"]["evaluated"] > 0
    assert (tmp_path / "recurrence_speed_quick.md").read_text() == bench.markdown(res)


@pytest.mark.synth
def test_timing_closure_kinds_quick_smoke(tmp_path):
    """benchmarks/timing_closure_kinds.py --quick: the plain core's search meets its target, and the row
    agrees with the design built (the manifest's latency is the chosen candidate's)."""
    import json

    bench = importlib.import_module("pwas_hdl.benchmarks.timing_closure_kinds")
    assert script_main(bench.main, ["--quick", "--clock-mhz", "50", "--outdir", str(tmp_path)]) == 0
    (row,) = json.loads((tmp_path / "timing_closure_kinds_quick.json").read_text())["rows"]
    assert row["kind"] == "plain-core" and row["met"] and row["chosen_fmax_mhz"] >= 50
    assert row["manifest_latency_cycles"] == row["chosen_latency_cycles"] in [c["latency_cycles"] for c in row["measured"]]
    assert "| plain-core | core | parallel | yes |" in (tmp_path / "timing_closure_kinds_quick.md").read_text()


@pytest.mark.rtl
def test_rtl_random_configs_quick_smoke(tmp_path):
    """benchmarks/rtl_random_configs.py --quick: three drawn configurations generated and replayed on
    Icarus; none differs from the bit-true model or crashes, and the draw depends on (seed, index) only."""
    import json

    bench = importlib.import_module("pwas_hdl.benchmarks.rtl_random_configs")
    assert script_main(bench.main, ["--quick", "--outdir", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "rtl_random_configs_quick.json").read_text())
    assert res["count"] == 3 and len(res["configs"]) == 3 and res["counts"]["FAIL"] == res["counts"]["error"] == 0
    passed = [r for r in res["configs"] if r["outcome"] == "pass"]
    assert passed and all(r["checks"]["bit_exact"] and r["mismatches"] == 0 for r in passed)
    assert bench.draw_config(0, 1) == bench.draw_config(0, 1) != bench.draw_config(1, 1)
    assert (tmp_path / "rtl_random_configs_quick.md").read_text() == bench.markdown(res)


def test_scratch_folder_is_removed_unless_kept(tmp_path, monkeypatch):
    import tempfile

    from pwas_hdl.bench_results import scratch_folder

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    with scratch_folder("pwas-x-") as work:
        (work / "design").mkdir()
        (work / "design" / "a.v").write_text("module a; endmodule\n")
    assert not work.exists()
    with pytest.raises(RuntimeError):
        with scratch_folder("pwas-x-") as work:
            (work / "f").write_text("x")
            raise RuntimeError("a failed run")
    assert not work.exists() and list((tmp_path / "tmp").iterdir()) == []
    with scratch_folder("pwas-x-", tmp_path / "keep" / "me") as work:  # --workdir: created and kept
        (work / "f").write_text("x")
    assert (tmp_path / "keep" / "me" / "f").read_text() == "x"


def test_rtl_random_configs_leaves_nothing_in_the_temp_folder(tmp_path, monkeypatch):
    """The sweep generated its designs, simulator builds and work folders in a mkdtemp folder it never removed
    (a 100-configuration run left up to 3 GB in /tmp); the results in --outdir are all it leaves now."""
    import tempfile

    bench = importlib.import_module("pwas_hdl.benchmarks.rtl_random_configs")
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    seen = []

    def fake_run(cfg, simulator, samples, root, cache):  # what run_config leaves: a design folder and a cache
        (root / cfg.name).mkdir(parents=True)
        (root / cfg.name / "design.v").write_text("module d; endmodule\n")
        cache.mkdir(exist_ok=True)
        seen.append(root)
        return {**bench._describe(cfg), "outcome": "refused", "message": "stub", "seconds": 0.0}

    monkeypatch.setattr(bench, "run_config", fake_run)
    assert script_main(bench.main, ["--quick", "--outdir", str(tmp_path / "out")]) == 0
    assert seen and all(str(r).startswith(str(tmp)) for r in seen)
    assert list(tmp.iterdir()) == [], list(tmp.iterdir())
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["rtl_random_configs_quick.json", "rtl_random_configs_quick.md"]


@pytest.mark.rtl
def test_generate_scale_quick_smoke(tmp_path):
    """benchmarks/generate_scale.py --quick: one small point generated both ways and simulated on
    Icarus without a mismatch; the readmemh Verilog is smaller than the inline one."""
    import json

    bench = importlib.import_module("pwas_hdl.benchmarks.generate_scale")
    assert script_main(bench.main, ["--quick", "--outdir", str(tmp_path)]) == 0
    doc = json.loads((tmp_path / "generate_scale_quick.json").read_text())
    (row,) = doc["rows"]
    assert (row["n"], row["p"], row["N"]) == (2, 15, 256) and doc["samples"] == 200
    assert row["simulate_inline"]["mismatches"] == row["simulate_readmemh"]["mismatches"] == 0
    assert row["generate_readmemh"]["verilog_bytes"] < row["generate_inline"]["verilog_bytes"]
    assert all(row[k]["wall_s"] > 0 and row[k]["peak_rss_mib"] > 0 for k in
               ("generate_inline", "generate_readmemh", "simulate_inline", "simulate_readmemh"))
    assert "| 2 | 15 | 256 |" in (tmp_path / "generate_scale_quick.md").read_text()


@pytest.mark.parametrize("script, run_name, args", [
    ("observer_bank_rtl", "run", ["--quick"]),
    ("bank_taps_rtl", "run", ["--quick"]),
    ("observer_bank_synth", "run", ["--quick"]),
    ("observer_bank_summary", "collect", []),
])
def test_a_missing_outdir_is_created_not_an_error_after_the_run(tmp_path, monkeypatch, capsys, script, run_name, args):
    """From the wheel in a new folder (--outdir ./benchmarks-results, absent), these scripts ran for
    minutes and then failed with 'folder ... does not exist'. The run is replaced by a stub here."""
    bench = importlib.import_module(f"pwas_hdl.benchmarks.{script}")
    calls = []
    monkeypatch.setattr(bench, run_name, lambda *a, **k: calls.append(1) or ([] if run_name == "collect" else {"rows": []}))
    monkeypatch.setattr(bench, "markdown", lambda doc: "table\n")
    out = tmp_path / "new" / "results"
    assert script_main(bench.main, [*args, "--outdir", str(out)]) == 0, capsys.readouterr().err
    assert calls and sorted(p.suffix for p in out.iterdir()) in ([".json", ".md"], [".md"])


@pytest.mark.parametrize("script, run_name", [("observer_bank_rtl", "run"), ("bank_taps_rtl", "run"),
                                              ("observer_bank_synth", "run")])
def test_an_outdir_that_is_a_file_is_refused_before_the_run(tmp_path, monkeypatch, capsys, script, run_name):
    bench = importlib.import_module(f"pwas_hdl.benchmarks.{script}")
    calls = []
    monkeypatch.setattr(bench, run_name, lambda *a, **k: calls.append(1) or {"rows": []})
    (tmp_path / "f").write_text("x")
    assert script_main(bench.main, ["--quick", "--outdir", str(tmp_path / "f")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --outdir") and "not a folder" in err and not calls, err
