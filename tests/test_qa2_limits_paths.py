"""Results files without machine paths (bench_results.portable_paths) and one upper limit for the
count options of every bench (bench_results.check_count, limits.MAX_BENCH_COUNT)."""

from __future__ import annotations

import importlib
import re

import pytest

from pwas_hdl.bench_results import check_count, portable_paths
from pwas_hdl.errors import InputError, ResourceLimit
from pwas_hdl.limits import MAX_BENCH_COUNT
from pwas_hdl.resources import benchmarks_dir
from tests.helpers.cli import CliRunner
from tests.helpers.folders import tree


def test_reason_names_the_log_relative_to_the_design_folder():
    reason = ("the design does not fit iCE40HX8K-CT256: logic cells (LUT4 + FF): the design needs 8253; choose a larger "
              "device (--device/--package) (see /tmp/pwas-obs-synth-70rkgbal/d/synth/ice40/nextpnr.log)")
    out = portable_paths(reason, ["/tmp/pwas-obs-synth-70rkgbal/d"])
    assert out.endswith("(see synth/ice40/nextpnr.log)") and "/tmp/" not in out
    assert "(--device/--package)" in out and "LUT4 + FF" in out  # option pairs are not paths
    # outside every root: the file name; relative paths, fractions and URLs stay
    assert portable_paths("log: /home/u/x/nextpnr.log, 1/2 of a/b") == "log: nextpnr.log, 1/2 of a/b"
    assert portable_paths("see https://github.com/a/b and --workdir /tmp/lhw2") == "see https://github.com/a/b and --workdir lhw2"
    assert portable_paths("/work/r/d", ["/work/r/d"]) == "."


def test_committed_results_hold_no_machine_paths():
    bad = []
    for p in sorted((benchmarks_dir() / "results").glob("*")):
        if p.suffix in (".md", ".json"):
            for m in re.finditer(r"(/tmp/|/work/|/home/)\S*", p.read_text(encoding="utf-8")):
                bad.append(f"{p.name}: {m.group(0)[:80]}")
    assert bad == []


def test_check_count_is_one_rule():
    assert check_count("--runs", 5) == 5 and check_count("--runs", MAX_BENCH_COUNT) == MAX_BENCH_COUNT
    with pytest.raises(ResourceLimit, match=r"--runs = 1001 exceeds the limit of 1000"):
        check_count("--runs", MAX_BENCH_COUNT + 1)
    for bad in (0, -3, True, 2.5):
        with pytest.raises(InputError, match="--seeds must be >= 1 and an integer"):
            check_count("--seeds", bad)


@pytest.mark.parametrize("args", [
    ["bench", "three-tank", "--runs", "1000000000"],
    ["bench", "lorenz", "--seeds", "1000000000"],
    ["bench", "battery", "--runs", "1001"],
])
def test_bench_commands_refuse_a_huge_count(tmp_path, args):
    import pwas_hdl.cli

    res = CliRunner().invoke(pwas_hdl.cli.app, [*args, "-o", str(tmp_path / "r.json")])
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()] if hasattr(res, "stderr") else res.output.splitlines()
    assert res.exit_code == 2 and len(lines) == 1 and "exceeds the limit of 1000" in lines[0], res.output
    assert tree(tmp_path) == {}


@pytest.mark.parametrize("script, args", [
    ("perf", ["--repeats", "1000000000"]),
    ("lorenz_tables", ["--seeds", "1000000000"]),
    ("additive", ["--runs", "1000000000"]),
])
def test_bench_scripts_refuse_a_huge_count(tmp_path, capsys, script, args):
    from pwas_hdl.bench_results import script_main

    bench = importlib.import_module(f"pwas_hdl.benchmarks.{script}")
    assert script_main(bench.main, [*args, "--outdir", str(tmp_path / "o")]) == 2
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and "exceeds the limit of 1000" in lines[0], lines
    assert not (tmp_path / "o").exists()


def test_bench_help_states_the_limit():
    import pwas_hdl.cli

    res = CliRunner().invoke(pwas_hdl.cli.app, ["bench", "three-tank", "--help"])
    assert res.exit_code == 0 and "1..1000" in res.output
