"""The execution layer (`pwas_hdl.flow.executor`): serial and Dask runs give identical results.

The distributed tests start a 2-worker `distributed.LocalCluster` (worker processes on this
machine); they compare the JSON of `explore` (synthesising real design points with Yosys) and of
`bench lorenz --quick` with the serial run's, key by key, with only the timings left out.
"""

from __future__ import annotations

import json
import threading
from pathlib import Path

import numpy as np
import pytest
from helpers.cli import CliRunner

from pwas_hdl.cli import app
from pwas_hdl.errors import InputError
from pwas_hdl.flow.executor import Executor, TaskFailed, environment_versions
from pwas_hdl.io.csv_table import write_csv
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
from pwas_hdl.systems.lorenz import lorenz

runner = CliRunner()

#: Keys whose values are wall-clock measurements (they differ from run to run by nature).
_TIMING_KEYS = ("time", "_s", "seconds", "wall")


def _without_timings(obj):
    if isinstance(obj, dict):
        return {k: _without_timings(v) for k, v in obj.items() if not any(t in k for t in _TIMING_KEYS)}
    if isinstance(obj, list):
        return [_without_timings(v) for v in obj]
    return obj


# ------------------------------------------------------------------------------ module-level tasks
def _square(x: int) -> int:
    return x * x


def _flaky(path: str) -> str:
    """Fails on its first call for a given path, succeeds on the second (a retried task)."""
    p = Path(path)
    if not p.exists():
        p.write_text("tried")
        raise OSError("first attempt fails")
    return p.read_text()


def _always_fails(x: int) -> int:
    raise ValueError(f"task {x} is broken")


# ------------------------------------------------------------------------------ serial behaviour
def test_serial_map_keeps_order_and_retries_once(tmp_path):
    ex = Executor()
    assert ex.kind == "serial" and not ex.distributed
    assert ex.map(_square, [3, 1, 2]) == [9, 1, 4]
    assert ex.map(_flaky, [str(tmp_path / "a")]) == ["tried"]  # failed once, retried, passed
    with pytest.raises(TaskFailed, match=r"task point-7 failed twice: ValueError: task 7 is broken"):
        ex.map(_always_fails, [7], labels=["point-7"])
    res = ex.map(_always_fails, [1, 2], return_exceptions=True)
    assert all(isinstance(r, TaskFailed) for r in res) and "task 2 is broken" in str(res[1])


def test_progress_is_reported():
    seen = []
    Executor().map(_square, range(4), progress=lambda d, t: seen.append((d, t)))
    assert seen[0] == (0, 4) and seen[-1] == (4, 4) and len(seen) == 5


@pytest.mark.parametrize("kw, msg", [
    ({"workers": -1}, "--workers must be a non-negative integer"),
    ({"workers": 10**6}, "more than the 256"),
    ({"scheduler": "localhost"}, "tcp://HOST:PORT"),
])
def test_bad_settings_are_input_errors(kw, msg):
    with pytest.raises(InputError, match=msg):
        Executor(**kw)


def test_labels_must_match_items():
    with pytest.raises(InputError, match="2 labels for 1 tasks"):
        Executor().map(_square, [1], labels=["a", "b"])


def test_cli_refuses_bad_workers(tmp_path):
    r = runner.invoke(app, ["bench", "lorenz", "--json", str(tmp_path / "b.json"), "--quick", "--workers", "-3"])
    assert r.exit_code == 2 and "--workers must be a non-negative integer" in r.output
    assert not (tmp_path / "b.json").exists()


# ------------------------------------------------------------------------------ on a LocalCluster
@pytest.fixture(scope="module")
def cluster():
    with Executor(workers=2) as ex:
        yield ex


@pytest.mark.slow
def test_local_cluster_map_and_versions(cluster):
    assert cluster.kind == "local-cluster" and cluster.describe()["workers"] == 2
    assert cluster.map(_square, range(7)) == [x * x for x in range(7)]
    assert cluster.tool_versions() == environment_versions()
    res = cluster.map(_always_fails, [5], return_exceptions=True)
    assert isinstance(res[0], TaskFailed) and "task 5 is broken" in str(res[0])


@pytest.mark.slow
def test_bench_lorenz_quick_identical_on_two_workers(tmp_path, cluster):
    """On the module's 2-worker LocalCluster through --scheduler (one cluster start for the file;
    --workers N makes the same Executor, see test_system_bench_quick_identical_on_two_workers)."""
    serial, dist = tmp_path / "serial.json", tmp_path / "dist.json"
    r1 = runner.invoke(app, ["bench", "lorenz", "--quick", "--seeds", "2", "--json", str(serial)])
    assert r1.exit_code == 0, r1.output
    r2 = runner.invoke(app, ["bench", "lorenz", "--quick", "--seeds", "2", "--scheduler", cluster.address, "--json", str(dist)])
    assert r2.exit_code == 0, r2.output
    a, b = json.loads(serial.read_text()), json.loads(dist.read_text())
    assert [s["seed"] for s in b["rows"][0]["config"]["per_seed"]] == [0, 1]
    assert _without_timings(a) == _without_timings(b)
    # the numbers themselves, not only their presence
    assert a["rows"][0]["value"] == b["rows"][0]["value"]
    assert [s["rmsee"] for s in a["rows"][0]["config"]["per_seed"]] == [s["rmsee"] for s in b["rows"][0]["config"]["per_seed"]]


@pytest.mark.slow
@pytest.mark.rtl  # the three-tank --quick run replays a recurrent sensor on Icarus in each task
def test_system_bench_quick_identical_on_two_workers(tmp_path):
    """`bench three-tank --quick --workers 2` (a LocalCluster the command starts): the same rows
    and config as serial; the execution record names what ran it, with the workers' (equal) tool
    versions."""
    docs = {}
    for kind, extra in (("serial", []), ("dist", ["--workers", "2"])):
        out = tmp_path / f"{kind}.json"
        r = runner.invoke(app, ["bench", "three-tank", "--quick", "-o", str(out), *extra])
        assert r.exit_code == 0, r.output
        docs[kind] = json.loads(out.read_text())
    a, b = docs["serial"], docs["dist"]
    ea, eb = a["config"].pop("execution"), b["config"].pop("execution")
    assert (ea["kind"], ea["workers"]) == ("serial", 1) and (eb["kind"], eb["workers"]) == ("local-cluster", 2)
    assert ea["tool_versions"] == eb["tool_versions"] == environment_versions()
    assert a["rows"] and _without_timings(a["rows"]) == _without_timings(b["rows"])
    assert _without_timings(a["config"]) == _without_timings(b["config"])
    assert [r["value"] for r in a["rows"]] == [r["value"] for r in b["rows"]]  # the numbers, exactly


def test_bench_helpers_merge_runs_in_order():
    from pwas_hdl import bench_results as br

    parts = br.map_runs(_square, [3, 1, 2])
    assert parts == [9, 1, 4]
    merged = {}
    for part in ({"a": [1]}, {"a": [2], "b": [3]}, {"b": [4]}):
        br.extend_lists(merged, part)
    assert merged == {"a": [1, 2], "b": [3, 4]} and list(merged) == ["a", "b"]
    rec = br.execution_record()
    assert rec["kind"] == "serial" and rec["tool_versions"]["numpy"]


def test_system_bench_refuses_bad_workers(tmp_path):
    r = runner.invoke(app, ["bench", "switched-linear", "--quick", "-o", str(tmp_path / "b.json"), "--workers", "-1"])
    assert r.exit_code == 2 and "--workers must be a non-negative integer" in r.output
    r = runner.invoke(app, ["bench", "lorenz-hlnn", "--quick", "-o", str(tmp_path / "b.json"), "--scheduler", "nohost"])
    assert r.exit_code == 2 and "tcp://HOST:PORT" in r.output
    assert not (tmp_path / "b.json").exists()


@pytest.mark.slow
def test_cv_folds_on_two_workers_choose_the_serial_sigma_and_weights(cluster):
    """The CV grid (5 folds x 9 sigmas) through the cluster: one task per fold, the same result."""
    from pwas_hdl.fit import regularized_lsq as rl

    tr, _ = lorenz(1300, seed=1).split(1000)
    kw = dict(my=2, partitions=4, gamma=1.2, sigma=None, sigma_grid=list(np.logspace(-6, 2, 9)), cv_folds=5)
    serial = PWASVirtualSensor(**kw).fit(None, tr.y, tr.z)
    seen = []
    lock = threading.Lock()  # as the command line's progress display holds one: a callback that does not pickle

    def progress(d, t):
        with lock:
            seen.append((d, t))

    dist = PWASVirtualSensor(**kw).fit(None, tr.y, tr.z, executor=cluster, progress=progress)
    assert serial.cv_.solver["method"] == "direct"
    assert dist.sigma_ == serial.sigma_
    assert np.array_equal(dist.weights_, serial.weights_)
    assert np.array_equal(dist.cv_.fold_mse, serial.cv_.fold_mse) and dist.cv_.solver["solves"] == 45
    assert {k: v for k, v in dist.cv_.solver.items() if k != "weight_bound"} == {k: v for k, v in serial.cv_.solver.items() if k != "weight_bound"}
    assert seen[-1] == (45, 45) and all(d % 9 == 0 for d, _ in seen)  # per fold: the tasks ran on the cluster
    # the map hook itself: distributed only when asked
    calls = []
    assert rl._map_folds(lambda f, progress: calls.append(f) or f, 3, None, 9, None) == [0, 1, 2] and calls == [0, 1, 2]


def test_cli_fit_refuses_bad_workers(tmp_path):
    d = lorenz(200, seed=0)
    write_csv(tmp_path / "d.csv", d.columns())
    r = runner.invoke(app, ["fit", str(tmp_path / "d.csv"), "-o", str(tmp_path / "m.json"), "-y", "y", "-z", "z",
                            "--my", "1", "-p", "2", "--workers", "-2"])
    assert r.exit_code == 2 and "--workers must be a non-negative integer" in r.output
    assert not (tmp_path / "m.json").exists()


@pytest.mark.slow
@pytest.mark.synth
def test_explore_measured_identical_on_two_workers(tmp_path, cluster):
    from pwas_hdl.flow.explore import explore

    d = lorenz(1300, seed=1)
    train, test = d.split(1000)
    m = PWASVirtualSensor(my=2, partitions=3, gamma=1.2, sigma=1e-4, output_names=["y"], target_names=["z"])
    m.fit(None, train.y, train.z)
    write_csv(tmp_path / "test.csv", test.columns())
    kw = dict(input_bits=[8, 12], weight_frac=[-2, 0], output_frac=[0], resources="generic", measure_max=2)
    serial = explore(m, tmp_path / "test.csv", **kw)
    dist = explore(m, tmp_path / "test.csv", **kw, executor=cluster)
    assert serial["measured"]["errors"] == [] and len(serial["measured"]["points"]) >= 2
    assert json.dumps(_without_timings(serial), sort_keys=True) == json.dumps(_without_timings(dist), sort_keys=True)


@pytest.mark.slow
@pytest.mark.synth
def test_timing_closure_identical_on_two_workers(tmp_path, cluster):
    from pwas_hdl.design.generate import build_design

    d = lorenz(800, seed=0)
    m = PWASVirtualSensor(my=2, partitions=2, gamma=1.2, sigma=1e-3).fit(None, d.y, d.z)
    path = tmp_path / "tiny.json"
    m.save(path)
    serial = build_design(path, target_mhz=60, fpga_target="ecp5", input_bits=12)
    dist = build_design(path, target_mhz=60, fpga_target="ecp5", input_bits=12, executor=cluster)
    assert serial.manifest["timing"]["met"] is True
    assert dist.manifest["timing"] == serial.manifest["timing"]
    assert dist.files == serial.files


@pytest.mark.slow
def test_speedup_benchmark_quick_smoke(tmp_path, cluster):
    """The --quick toy sweep on the module's cluster (--scheduler; the LocalCluster start of --workers
    is the cluster fixture's)."""
    import importlib

    bench = importlib.import_module("pwas_hdl.benchmarks.distributed_speedup")
    assert bench.main(["--quick", "--scheduler", cluster.address, "--outdir", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "distributed_speedup_quick.json").read_text())
    assert res["sweeps"]["toy"]["identical"] is True and res["sweeps"]["toy"]["tasks"] == 4
    assert bench._lpt_makespan([3.0, 2.0, 2.0, 1.0], 2) == 4.0
