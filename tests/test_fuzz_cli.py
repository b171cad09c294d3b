"""Property-based CLI suite (issue 9): every command, valid, edge and broken inputs.

The promise, for every generated input: exit 0 with a correct output, or exit 2 with exactly one
``error:`` line and the file tree unchanged (no output, no temporary); never a traceback. Sizes
above the stated limits run in a subprocess under ``RLIMIT_AS`` (:data:`MEMORY_LIMIT`), so that an
allocation before the check would show as a MemoryError or a signal instead of the clean refusal.

Budget: a fixed number of examples per command (:data:`BUDGET`), derandomised (the same examples
on every run, no example database), no deadline; ``simulate`` and ``synth`` stop where the
simulator / synthesis tool would start (a patched runner raises :class:`Reached`), so the suite
never runs one.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterator
from unittest import mock

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from pwas_hdl.limits import MAX_SAMPLES, MAX_SIGMA_CANDIDATES, MAX_VERTICES

from helpers.folders import tree


#: Examples per command at scale 1 (fixed: the suite's run time is bounded).
BUDGET = {"fit": 60, "fit-map": 40, "predict": 50, "info": 50, "generate": 25, "simulate": 30, "synth": 25,
          "export-testbench": 20, "explore": 12, "report": 40, "make-data": 40, "bench": 10, "limits": 8}
#: Address-space limit of the subprocess runs (bytes).
MEMORY_LIMIT = 3 * 2**30

#: Budget factor per hypothesis profile (tests/conftest.py): ``ci`` (CI=true) runs twice the budget,
#: ``dev`` (the default, the fast local subset) half of it, at least :data:`MIN_EXAMPLES` per command.
PROFILE_SCALE = {"ci": 2.0, "dev": 0.5}
MIN_EXAMPLES = 5
#: ``PWAS_FUZZ_SCALE=k`` runs k times the profile's budget (a longer local hunt).
SCALE = max(1, int(os.environ.get("PWAS_FUZZ_SCALE", "1")))
FUZZ_SCALE = PROFILE_SCALE.get(settings.get_current_profile_name(), 1.0) * SCALE
#: ``PWAS_FUZZ_RANDOM=1`` draws new examples (with ``pytest --hypothesis-seed=N`` to repeat a run).
RANDOM = os.environ.get("PWAS_FUZZ_RANDOM")


def examples(command: str) -> int:
    """Examples drawn for ``command`` under the loaded profile."""
    return max(MIN_EXAMPLES, round(BUDGET[command] * FUZZ_SCALE))


def _settings(command: str):
    return settings(max_examples=examples(command), deadline=None, derandomize=RANDOM is None, database=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow,
                                           HealthCheck.data_too_large, HealthCheck.filter_too_much])


class Reached(BaseException):
    """Raised by the patched simulator / synthesis runner: the inputs were accepted up to there
    (a BaseException, so that the CLI's error mapping lets it through to the test)."""


class Result:
    """What one in-process run of ``pwas_hdl.cli.main`` printed and returned."""

    def __init__(self, exit_code: int, stdout: str, stderr: str, exception: BaseException | None) -> None:
        self.exit_code, self.stdout, self.stderr, self.exception = exit_code, stdout, stderr, exception
        self.output = stderr + stdout
        self.exc_info = exception


# ------------------------------------------------------------------------------------------------ helpers


@contextmanager
def scratch(base: Path, copy: tuple[str, ...] = ()) -> Iterator[Path]:
    d = Path(tempfile.mkdtemp(prefix="fuzz-", dir=base))
    for nm in copy:
        src = base / nm
        if src.is_dir():
            shutil.copytree(src, d / nm)
        else:
            shutil.copy(src, d / nm)
    try:
        yield d
    finally:
        shutil.rmtree(d, ignore_errors=True)


def run(args: list[Any], cwd: Path) -> Result:
    """Run the real entry point (``main``: Click usage errors included) in this process, in ``cwd``."""
    import io
    from contextlib import redirect_stderr, redirect_stdout

    from pwas_hdl.cli import main

    old = os.getcwd()
    os.chdir(cwd)
    out, err = io.StringIO(), io.StringIO()
    term = signal.getsignal(signal.SIGTERM)  # main() installs its SIGTERM handler: not for the rest of pytest
    try:
        with redirect_stdout(out), redirect_stderr(err):
            try:
                code, exc = main([str(a) for a in args]), None
            except Reached as e:
                code, exc = -1, e
            except SystemExit as e:  # noqa: PT017 - main() should return, not exit
                code, exc = e.code, e
        return Result(code, out.getvalue(), err.getvalue(), exc)
    finally:
        signal.signal(signal.SIGTERM, term)
        os.chdir(old)


def check_promise(res, before: dict, after: dict, ok: Callable[[], None] | None = None, args=None) -> str:
    """Exit 0 (then ``ok()`` checks the output) or exit 2 with one error line and nothing changed."""
    out = _check(res, before, after, ok, args)
    event(out)  # pytest --hypothesis-show-statistics: how many examples were accepted / refused
    log = os.environ.get("PWAS_FUZZ_LOG")  # a record of every example (for looking at the mix)
    if log:
        with open(log, "a", encoding="utf-8") as fh:
            fh.write(json.dumps({"outcome": out, "args": [str(a)[:80] for a in (args or [])],
                                 "output": res.output.strip()[-300:]}) + "\n")
    return out


def _check(res, before: dict, after: dict, ok: Callable[[], None] | None, args) -> str:
    if isinstance(res.exception, Reached):
        return "reached"
    assert res.exception is None, (args, res.output, res.exc_info)
    assert "Traceback" not in res.output, (args, res.output)
    if res.exit_code == 0:
        if ok is not None:
            ok()
        return "ok"
    assert res.exit_code == 2, (args, res.exit_code, res.output)
    errors = [ln for ln in res.output.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1, (args, res.output)
    assert after == before, (args, res.output, set(after) ^ set(before))
    return "refused"


# ------------------------------------------------------------------------------------------------ fixtures
@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Path:
    """A folder with valid data (d.csv, t.csv), a tiny model (m.json) and its generated design (g/)."""
    d = tmp_path_factory.mktemp("fuzz")
    assert run(["make-data", "lorenz", "-o", d / "d.csv", "--samples", 300, "--test-out", d / "t.csv",
                "--test-samples", 60], d).exit_code == 0
    assert run(["fit", d / "d.csv", "-o", d / "m.json", "-y", "y", "-z", "z", "--my", 2, "-p", 2,
                "--sigma", "1e-3"], d).exit_code == 0
    res = run(["generate", d / "m.json", "-o", d / "g"], d)
    assert res.exit_code == 0, res.output
    return d


# ------------------------------------------------------------------------------------------------ strategies
GOOD_CELL = st.one_of(
    st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False).map(repr),
    st.integers(-1000, 1000).map(str),
)
BAD_CELL = st.sampled_from(["1_0", "\u0661", "\uff13", "nan", "inf", "-Infinity", "", "abc", "1e999", "0x10", "1.2.3",
                            "\x00", " ", "--1", "1e", "\u00a0"])
EDGE_CELL = st.sampled_from(["-0", "1e308", "-1e308", "5e-324", " 7 ", "+.5", "1E3", "\u00a02"])


#: Ways a CSV file is broken (at least one is applied to a broken file) and valid edge cases.
CSV_BREAKS = ("dup", "empty_name", "newline_name", "bom2", "missing_column", "blank_row", "ragged", "latin1",
              "huge_cell", "open_quote", "bad_cell", "bad_cell", "no_rows", "empty_file")
CSV_EDGES = ("space_name", "bom", "traj_column", "blank_end", "crlf")


@st.composite
def csv_bytes(draw, columns=("y", "z", "z_true"), broken: bool = True) -> bytes:
    """A CSV file: a smooth valid signal with valid edge cases (BOM, CRLF, spaces around names,
    trailing blank lines, a trajectory column) and, when ``broken``, one or two drawn corruptions."""
    edges = set(draw(st.lists(st.sampled_from(CSV_EDGES), max_size=2, unique=True), "csv edges"))
    breaks = set(draw(st.lists(st.sampled_from(CSV_BREAKS), min_size=1, max_size=2, unique=True), "csv breaks")) if broken else set()
    header = list(columns)
    if "traj_column" in edges:
        header.append("run")
    n = 0 if "no_rows" in breaks else draw(st.integers(30, 60))
    rows = [[repr(float(np.sin(0.3 * i * (k + 1)) * (k + 1) + 0.01 * k)) for k in range(len(columns))]
            + ([str(i // 15)] if "traj_column" in edges else []) for i in range(n)]
    if "dup" in breaks:
        header.append(header[0])
    if "empty_name" in breaks:
        header[-1] = ""
    if "space_name" in edges:
        header[0] = " " + header[0] + " "
    if "newline_name" in breaks:
        header[0] = '"' + header[0] + '\nx"'
    if "missing_column" in breaks:
        header = header[1:]
    if "bad_cell" in breaks and rows:
        r = draw(st.integers(0, len(rows) - 1))
        rows[r][draw(st.integers(0, len(columns) - 1))] = draw(st.one_of(BAD_CELL, EDGE_CELL), "cell")
    lines = [",".join(header)] + [",".join(r) for r in rows]
    if "blank_row" in breaks and len(lines) > 2:
        lines.insert(draw(st.integers(2, len(lines) - 1)), "")
    if "blank_end" in edges:
        lines += ["", ""]
    if "ragged" in breaks and len(lines) > 1:
        lines[-1] += ",1"
    if "huge_cell" in breaks and len(lines) > 1:
        lines[1] = "9" * (128 * 1024 + 1) + lines[1][lines[1].find(","):]
    if "open_quote" in breaks and len(lines) > 1:
        lines[1] = '"' + lines[1]
    text = ("\r\n" if "crlf" in edges else "\n").join(lines) + "\n"
    data = text.encode("utf-8")
    if "bom" in edges or "bom2" in breaks:
        data = b"\xef\xbb\xbf" * (2 if "bom2" in breaks else 1) + data
    if "latin1" in breaks:
        k = draw(st.integers(0, max(0, len(data) - 1)))
        data = data[:k] + b"\xe9" + data[k:]
    if "empty_file" in breaks:
        data = b""
    return data


def _paths(d: Any, prefix=()) -> list[tuple]:
    out = []
    if isinstance(d, dict):
        for k, v in d.items():
            out.append(prefix + (k,))
            if k != "weights" or len(prefix) > 0:
                out += _paths(v, prefix + (k,))
            else:
                out += [prefix + (k, t) for t in v]
    elif isinstance(d, list) and len(d) <= 8:
        for i, v in enumerate(d):
            out.append(prefix + (i,))
            out += _paths(v, prefix + (i,))
    return out


BAD_VALUES = st.sampled_from([None, 2.7, "2", -1, 0, 10**30, [], {}, True, "nan", 1e308, -1e308, [1, 2], "x" * 50,
                              "y\nz", 2.0])


@st.composite
def mutated_json(draw, valid: dict) -> bytes:
    """A JSON document derived from ``valid``: unchanged, one key deleted or retyped, truncated, garbage."""
    kind = draw(st.sampled_from(["same", "delete", "set", "set", "set", "truncate", "garbage", "bom", "nan"]))
    d = json.loads(json.dumps(valid))
    if kind == "same":
        return json.dumps(d).encode()
    if kind == "garbage":
        return draw(st.sampled_from([b"", b"\xff\xfe\x00", b"[]", b"null", b"{", b"42"]))
    if kind == "truncate":
        text = json.dumps(d)
        return text[: draw(st.integers(0, len(text) - 1))].encode()
    if kind == "bom":
        return b"\xef\xbb\xbf" + json.dumps(d).encode()
    if kind == "nan":
        text = json.dumps(d)
        return text.replace("1", "NaN", 1).encode()
    path = draw(st.sampled_from(_paths(d)))
    node = d
    for k in path[:-1]:
        node = node[k]
    if kind == "delete":
        del node[path[-1]]
    else:
        node[path[-1]] = draw(BAD_VALUES)
    return json.dumps(d).encode()


def _prepare(work: Path) -> None:
    """Things the broken paths refer to: a folder ``sub``, a non-empty foreign folder ``full``."""
    (work / "sub").mkdir(exist_ok=True)
    (work / "full").mkdir(exist_ok=True)
    (work / "full" / "keep.txt").write_text("user file")


class Knobs:
    """Draws the inputs of one example: all valid, or (``broken``) some of them broken.

    Half the examples are valid end to end, so that the "exit 0 with a correct output" side of the
    promise is exercised as much as the refusals.
    """

    def __init__(self, data) -> None:
        self.data = data
        self.broken = data.draw(st.booleans(), "broken")

    def bad(self, label: str) -> bool:
        return self.broken and self.data.draw(st.integers(0, 2), f"break {label}?") == 0

    def choose(self, label: str, good: list, bad: list | st.SearchStrategy = ()) -> Any:
        if self.bad(label):
            return self.data.draw(bad if isinstance(bad, st.SearchStrategy) else st.sampled_from(list(bad)), label)
        return self.data.draw(st.sampled_from(good), label)

    def option(self, name: str, good: list, bad: list | st.SearchStrategy = ()) -> list:
        """``[name, value]``, or ``[]`` when the drawn value is None (option left out)."""
        v = self.choose(name, good, bad) if bad else self.data.draw(st.sampled_from(good), name)
        return [] if v is None else [name, v]

    def csv(self, columns) -> bytes:
        return self.data.draw(csv_bytes(columns, broken=self.bad("csv")), "csv")

    def json_doc(self, valid: dict, label: str) -> bytes:
        if self.bad(label):
            return self.data.draw(mutated_json(valid), label)
        return json.dumps(valid).encode()

    def out(self, good: str, label: str = "out", folder: bool = False) -> str:
        return self.choose(label, [good], BAD_DIRS if folder else BAD_FILES)


BAD_FILES = ["", ".", "nodir/x", "d.csv", "d.csv/x", "a" * 300 + ".x", "sub"]
BAD_DIRS = ["", "d.csv", "d.csv/x", "a" * 300, "full"]


# ------------------------------------------------------------------------------------------------ fit
NAN, INF = float("nan"), float("inf")


@_settings("fit")
@given(data=st.data())
def test_fuzz_fit(base, data):
    k = Knobs(data)
    csv = k.csv(("y", "z"))
    args = ["fit", "data.csv", "-o", k.out("m2.json"), "-y", "y", "-z", "z"]
    args += k.option("--my", [1, 2, None], [0, 10**6, 25, "abc", "1.5"])  # non-numeric: a Click usage error
    args += k.option("-p", ["1", "3", "2,2", None], ["0", "-1", "x", "99999999999", "1.5", "", "2,2,2,2"])
    args += k.option("--gamma", [1.0, 1.5, None], [0.5, NAN, INF, "x"])
    args += k.option("--bogus-option", [None], ["1"])
    if k.data.draw(st.booleans(), "cv?"):
        args += k.option("--sigma-grid", ["logspace:-3:1:3", "0.1,1"], ["logspace:0:1:100000000000", "", "a", "logspace:1:2", "0,1"])
        args += k.option("--folds", [2, 3, None], [0, 1, 10**9])
    else:
        args += k.option("--sigma", [1e-3, 1.0], [0.0, -1.0, NAN, INF])
    args += k.option("--tikhonov", [0, 1, None], [2, -1])
    args += k.option("--traj-col", [None], ["nope", "y"])
    args += k.option("--domain", [None, "-9:9,-9:9"], ["a", "0:1", "1:0,1:0", "nan:1,0:1"])
    args += k.option("--blank-rows", ["error", "break", None], ["x"])
    args += k.option("--breakpoints", [None, "quantile", "quantile-pow2"], ["x", "d.csv", "nofile.json"])
    with scratch(base, ("d.csv",)) as work:
        _prepare(work)
        (work / "data.csv").write_bytes(csv)
        before = tree(work)
        res = run(args, work)

        def ok():
            from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

            m = PWASVirtualSensor.load(work / args[3])
            assert np.all(np.isfinite(m.weights_)) and m.signal_names()[1:] == (["y"], ["z"])
            assert set(tree(work)) - set(before) == {args[3]}

        check_promise(res, before, tree(work), ok, args)


@_settings("fit-map")
@given(data=st.data())
def test_fuzz_fit_map(base, data):
    k = Knobs(data)
    recurrent = data.draw(st.booleans(), "with --state?")
    csv = k.csv(("a", "s", "f") if recurrent else ("a", "b", "f"))
    args = ["fit-map", "samples.csv", "-o", k.out("m2.json"), "-u", "a", "-z", "f"]
    args += ["--state", "s"] + k.option("--z0", ["0.5"], [None, "x", "1,2", "nan", ""]) if recurrent else \
        k.option("-y", ["b", None], ["nope", "f", "a"])
    args += k.option("-p", ["2", "3", "2,3", None], ["0", "-1", "x", "99999999999", "1.5", "", "2,2,2"])
    args += k.option("--sigma", [1e-8, 1e-3, None], [0.0, -1.0, NAN, INF, "x"])
    args += k.option("--test-fraction", [0.0, 0.2, None], [-0.1, 1.0, 1.5, NAN, "x"])
    args += k.option("--seed", [0, 5, None], [-1, "x"])
    args += k.option("--domain", [None, "-9:9,-9:9"], ["a", "0:1", "1:0,1:0", "nan:1,0:1"])
    args += k.option("--blank-rows", ["error", "break", None], ["x"])
    with scratch(base, ("d.csv",)) as work:
        _prepare(work)
        (work / "samples.csv").write_bytes(csv)
        before = tree(work)
        res = run(args, work)

        def ok():
            from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

            m = PWASVirtualSensor.load(work / args[3])
            assert np.all(np.isfinite(m.weights_))
            err = json.loads((work / args[3]).read_text())["map_fit"]
            assert all(np.isfinite(v) for key in ("max_error", "rms_error") for v in err[key].values()), err
            assert set(tree(work)) - set(before) == {args[3]}

        check_promise(res, before, tree(work), ok, args)


# ------------------------------------------------------------------------------------------------ predict / info
@_settings("predict")
@given(data=st.data())
def test_fuzz_predict(base, data):
    k = Knobs(data)
    model = k.json_doc(json.loads((base / "m.json").read_text()), "model")
    csv = k.csv(("y", "z_true"))
    args = ["predict", "model.json", "data.csv", "-o", k.out("p.csv")]
    args += k.option("--traj-col", [None], ["nope"])
    args += k.option("--blank-rows", ["error", "break", None], ["x"])
    with scratch(base, ("d.csv",)) as work:
        _prepare(work)
        (work / "model.json").write_bytes(model)
        (work / "data.csv").write_bytes(csv)
        before = tree(work)
        res = run(args, work)

        def ok():
            lines = (work / args[4]).read_text().splitlines()
            assert lines[0] == "row,z_hat,out_of_domain"
            vals = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]])
            assert len(vals) >= 1 and np.all(np.isfinite(vals))
            assert "RMSE of z_hat against column z_true" in res.output

        check_promise(res, before, tree(work), ok, args)


@_settings("info")
@given(data=st.data())
def test_fuzz_info(base, data):
    k = Knobs(data)
    valid = json.loads((base / "m.json").read_text())
    model = k.json_doc(valid, "model")
    with scratch(base) as work:
        (work / "model.json").write_bytes(model)
        before = tree(work)
        res = run(["info", "model.json"], work)

        def ok():
            d = json.loads(res.stdout)
            assert d["N"] == 9 and d["n"] == 2 and "weights" not in d

        check_promise(res, before, tree(work), ok, ["info", model[:300]])


# ------------------------------------------------------------------------------------------------ generate
@_settings("generate")
@given(data=st.data())
def test_fuzz_generate(base, data):
    k = Knobs(data)
    model = k.json_doc(json.loads((base / "m.json").read_text()), "model")
    args = ["generate", "model.json", "-o", k.out("gen", folder=True)]
    args += k.option("--name", [None, "top_1", "Module"], ["module", "a b", "x" * 300, "1x", "logic", "", "y\nz"])
    args += k.option("--design", ["core", "sensor", None], ["x"])
    args += k.option("--memory", ["banked", "replicated", None], ["x"])
    args += k.option("--pipeline", ["min", "max", None], ["x"])
    args += k.option("--memory-init", ["inline", "readmemh", None], ["x"])
    args += k.option("--input-bits", [8, 12, None], [0, 1, 41, 10**20, "twelve"])
    args += k.option("--input-fill", [0.5, None], [0.0, 2.0, NAN])
    args += k.option("--weight-frac", [None, 0, 3], [-100, 10**20, -(10**20)])
    args += k.option("--weight-bits", [None, 16], [0, 200])
    args += k.option("--output-frac", [None], [-100, 10**6])
    args += k.option("--overflow", ["error", "saturate", None], ["x"])
    args += k.option("--rounding", ["half_up", "truncate", None], ["x"])
    args += k.option("--architecture", ["parallel", "serial", None], ["x", "Serial"])
    args += k.option("--target-mhz", [None], [NAN, -5.0, 0.0])  # a valid one would run nextpnr: never drawn
    with scratch(base) as work:
        _prepare(work)
        (work / "d.csv").write_text("y,z\n1,2\n")
        (work / "model.json").write_bytes(model)
        before = tree(work)
        res = run(args, work)

        def ok():
            man = json.loads((work / args[3] / "manifest.json").read_text())
            top = man["top"]
            v = (work / args[3] / f"{top}.v").read_text()
            assert f"module {top}" in v and "\n" not in top
            assert not [p for p in os.listdir(work) if ".pwas-tmp-" in p]
            assert set(tree(work)) - set(before) >= {args[3] + "/", f"{args[3]}/manifest.json"}

        check_promise(res, before, tree(work), ok, args)


# ------------------------------------------------------------------------------------------------ simulate / synth
def _folder_variant(k: Knobs, base: Path, work: Path) -> str:
    """The generated folder; broken: a hand-edited manifest, a missing model, a file, no folder."""
    kind = k.choose("folder", ["good"], ["manifest", "manifest", "manifest", "missing_model", "file", "none", "empty"])
    if kind in ("good", "manifest", "missing_model"):
        shutil.copytree(base / "g", work / "g")
        if kind == "manifest":
            valid = json.loads((base / "g" / "manifest.json").read_text())
            (work / "g" / "manifest.json").write_bytes(k.data.draw(mutated_json(valid), "manifest"))
        if kind == "missing_model":
            (work / "g" / "model.json").unlink()
        return "g"
    if kind == "file":
        return "d.csv"
    if kind == "empty":
        (work / "e").mkdir()
        return "e"
    return "nothere"


@_settings("simulate")
@given(data=st.data())
def test_fuzz_simulate(base, data):
    k = Knobs(data)
    csv = k.csv(("y", "z_true"))
    with scratch(base, ("d.csv",)) as work, mock.patch("pwas_hdl.verify.simulation.run_rtl", side_effect=Reached):
        _prepare(work)
        folder = _folder_variant(k, base, work)
        (work / "data.csv").write_bytes(csv)
        args = ["simulate", folder, "data.csv", "-o", k.out("s.csv")]
        args += k.option("--simulator", ["icarus", "verilator", None], ["x"])
        args += k.option("--json", [None, "s2.json"], BAD_FILES + ["s.csv"])
        args += k.option("--stall", [0.0, 0.5, None], [1.0, -1.0, NAN, "x"])
        args += k.option("--seed", [0, 3, None], [-1])
        args += k.option("--build-dir", [None, "bd"], ["d.csv", "d.csv/b"])
        args += k.option("--traj-col", [None], ["nope"])
        args += k.option("--blank-rows", ["error", "break", None], ["x"])
        before = tree(work)
        res = run(args, work)
        # the simulator is never run: valid inputs end at the patched runner
        assert res.exit_code != 0 or isinstance(res.exception, Reached), (args, res.output)
        check_promise(res, before, tree(work), None, args)


@_settings("synth")
@given(data=st.data())
def test_fuzz_synth(base, data):
    k = Knobs(data)
    with scratch(base, ("d.csv",)) as work, mock.patch("pwas_hdl.flow.synthesis._run_tool", side_effect=Reached):
        _prepare(work)
        folder = _folder_variant(k, base, work)
        args = ["synth", folder]
        args += k.option("--fpga", ["ecp5", "ice40", "generic", None], ["x"])
        args += k.option("--device", [None], ["zz"])
        args += k.option("--clock-mhz", [None, 50.0], [0.0, -1.0, NAN])
        args += k.option("--seed", [None, 1], [-1, "x"])
        args += k.option("--json", [None, "r.json"], BAD_FILES)
        before = tree(work)
        res = run(args, work)
        assert res.exit_code != 0 or isinstance(res.exception, Reached), (args, res.output)
        check_promise(res, before, tree(work), None, args)


@_settings("export-testbench")
@given(data=st.data())
def test_fuzz_export_testbench(base, data):
    k = Knobs(data)
    with scratch(base, ("d.csv",)) as work:
        _prepare(work)
        folder = _folder_variant(k, base, work)
        args = ["export-testbench", folder]
        args += k.option("-o", ["tb", None], BAD_DIRS)
        args += ["--samples", k.choose("--samples", [1, 20], [0, -1, 10**12, "x", ""])]
        args += k.option("--seed", [0, 3, None], [-1, "x"])
        args += k.option("--stall", [0.0, 0.3, None], [-0.1, 1.5, NAN, "x"])
        before = tree(work)
        res = run(args, work)

        def ok():
            rel = args[args.index("-o") + 1] if "-o" in args else f"{folder}/tb"
            out = work / rel
            names = {p.name for p in out.iterdir()}
            assert {"run_icarus.sh", "run_verilator.sh", "files.f"} <= names and any(n.startswith("tb_") for n in names)
            lines = [ln for ln in (out / next(n for n in names if n.endswith("_tb_in.hex"))).read_text().splitlines() if ln]
            assert len(lines) >= int(args[args.index("--samples") + 1])
            new = set(tree(work)) - set(before)  # only the testbench folder, nothing beside it
            assert new and all(p.startswith(rel.rstrip("/") + "/") for p in new), new

        check_promise(res, before, tree(work), ok, args)


# ------------------------------------------------------------------------------------------------ explore / report
@_settings("explore")
@given(data=st.data())
def test_fuzz_explore(base, data):
    k = Knobs(data)
    model = k.json_doc(json.loads((base / "m.json").read_text()), "model")
    csv = k.csv(("y", "z_true"))
    args = ["explore", "model.json", "data.csv", "-o", k.out("ex", folder=True)]
    args += k.option("--input-bits", ["10,12", "12"], ["2:100000000", "1", "x", "12:8", ""])
    args += k.option("--weight-frac", ["0:1", "3"], ["-100", "x"])
    args += k.option("--output-frac", ["1", "0:1"], ["40"])
    args += k.option("--resources", ["estimate", None], ["x"])
    args += k.option("--cost", ["total_bits", "memory_bits", None], ["x"])
    args += k.option("--synth-dir", [None], ["d.csv", "d.csv/x"])
    args += k.option("--measure-max", [None], [0, -1])
    args += k.option("--blank-rows", ["error", "break", None], ["x"])
    with scratch(base, ("d.csv",)) as work:
        _prepare(work)
        (work / "model.json").write_bytes(model)
        (work / "data.csv").write_bytes(csv)
        before = tree(work)
        res = run(args, work)

        def ok():
            r = json.loads((work / args[4] / "explore.json").read_text())
            assert r["points"] and any(not p["is_default"] or r["sweep"]["default_in_sweep"] for p in r["points"])
            assert (work / args[4] / "explore.png").read_bytes()[:4] == b"\x89PNG"
            assert not [p for p in os.listdir(work / args[4]) if ".pwas-tmp-" in p]

        check_promise(res, before, tree(work), ok, args)


SIM_SUMMARY = {"simulator": "icarus", "samples": 10, "mismatches": 0, "latency_cycles": {"measured_min": 3, "measured_max": 3},
               "ii": {"measured": 1.0}, "targets": {"z": {"reference_column": "z_true", "rmsee_hw": 1.0, "rmsee_float": 1.0,
                                                         "rmsee_increase_hw_vs_float_percent": 0.0}}}
SYNTH_RESULT = {"target": "ecp5", "part": "LFE5U-45F", "luts": 10, "ffs": 5, "fmax_mhz": 100.0}


@_settings("report")
@given(data=st.data())
def test_fuzz_report(base, data):
    k = Knobs(data)
    with scratch(base, ("d.csv",)) as work:
        _prepare(work)
        folder = _folder_variant(k, base, work)
        if folder == "g":
            if k.data.draw(st.booleans(), "with synth"):
                (work / "g" / "synth" / "ecp5").mkdir(parents=True)
                (work / "g" / "synth" / "ecp5" / "synth.json").write_bytes(k.json_doc(SYNTH_RESULT, "synth"))
            if k.data.draw(st.booleans(), "with sim"):
                (work / "g" / "sim").mkdir()
                (work / "g" / "sim" / "a.json").write_bytes(k.json_doc(SIM_SUMMARY, "sim"))
        args = ["report", folder]
        args += k.option("--json", [None, "r.json"], BAD_FILES)
        args += k.option("-o", [None, "r.md"], BAD_FILES + ["r.json"])
        args += k.option("--sim", [None], ["d.csv", "nope.json"])
        before = tree(work)
        res = run(args, work)

        def ok():
            assert res.stdout.startswith("# ") and "None" not in res.stdout
            if "-o" in args:
                assert (work / args[args.index("-o") + 1]).read_text().startswith("# ")
            if "--json" in args:
                assert json.loads((work / args[args.index("--json") + 1]).read_text())["format"] == "pwas-hdl-report"

        check_promise(res, before, tree(work), ok, args)


# ------------------------------------------------------------------------------------------------ make-data / bench
@_settings("make-data")
@given(data=st.data())
def test_fuzz_make_data(base, data):
    k = Knobs(data)
    args = ["make-data", "lorenz", "-o", k.out("a.csv")]
    args += ["--samples", k.choose("--samples", [1, 5, 300], [0, -1, 10**8, 10**20, "many", ""])]
    args += k.option("--test-out", [None, "b.csv"], ["a.csv", "./a.csv", "nodir/b.csv", "d.csv/b", ""])
    args += k.option("--test-samples", [None, 1, 50], [0, -3, MAX_SAMPLES])
    args += k.option("--seed", [None, 0, 7, 2**70], [-1])
    with scratch(base, ("d.csv",)) as work:
        _prepare(work)
        before = tree(work)
        res = run(args, work)

        def ok():
            n = int(args[args.index("--samples") + 1])
            lines = (work / args[3]).read_text().splitlines()
            assert lines[0] == "y,z,z_true" and len(lines) == n + 1
            if "--test-out" in args:
                m = int(args[args.index("--test-samples") + 1]) if "--test-samples" in args else 2000
                assert len((work / args[args.index("--test-out") + 1]).read_text().splitlines()) == m + 1

        check_promise(res, before, tree(work), ok, args)


@_settings("bench")
@given(data=st.data())
def test_fuzz_bench(base, data):
    k = Knobs(data)
    args = ["bench", "lorenz", "-o", k.out("b.json"), "--quick"]
    args += k.option("--md", [None, "b.md"], BAD_FILES + ["b.json"])
    args += ["--seeds", k.choose("--seeds", [1], [0, -1])]
    with scratch(base, ("d.csv",)) as work:
        _prepare(work)
        before = tree(work)
        res = run(args, work)

        def ok():
            r = json.loads((work / args[3]).read_text())
            assert r and "Table" in res.stdout or "|" in res.stdout

        check_promise(res, before, tree(work), ok, args)


# ------------------------------------------------------------------------------------------------ sizes, in a subprocess
def _limited() -> None:  # pragma: no cover - runs in the child
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


#: The child: runs ``pwas_hdl.cli.main`` once per request line (JSON: args, cwd) and answers with
#: one JSON line (exit code, what the run wrote to stderr). One interpreter start for all examples.
_CHILD = r"""
import io, json, os, sys
from contextlib import redirect_stderr, redirect_stdout
from pwas_hdl.cli import main
answer = sys.stdout
for line in sys.stdin:
    req = json.loads(line)
    os.chdir(req["cwd"])
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        try:
            code = main(req["args"])
        except SystemExit as e:
            code = e.code
        except BaseException as e:  # anything main() let through (a MemoryError, ...)
            code = "escaped"
            err.write(f"Traceback: {type(e).__name__}: {e}")
    answer.write(json.dumps({"code": code, "stderr": err.getvalue()}) + "\n")
    answer.flush()
"""


class LimitedCLI:
    """``pwas-hdl`` in one long-lived child process under ``RLIMIT_AS`` = :data:`MEMORY_LIMIT`.

    ``cli(args, cwd)`` -> ``(exit_code, stderr)``. A child killed by a signal (e.g. the kernel on
    an allocation) shows as exit code ``"died (<returncode>)"`` and is restarted for the next call.
    """

    def __init__(self, log: Path) -> None:
        self.log = log
        self.proc: subprocess.Popen | None = None

    def _start(self) -> subprocess.Popen:
        env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
        return subprocess.Popen([sys.executable, "-c", _CHILD], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                stderr=open(self.log, "ab"), text=True, preexec_fn=_limited, env=env)

    def __call__(self, args: list[Any], cwd: Path) -> tuple[Any, str]:
        if self.proc is None or self.proc.poll() is not None:
            self.proc = self._start()
        self.proc.stdin.write(json.dumps({"args": [str(a) for a in args], "cwd": str(cwd)}) + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            rc = self.proc.wait(timeout=60)
            self.proc = None
            return f"died ({rc})", self.log.read_text(errors="replace")[-2000:]
        ans = json.loads(line)
        return ans["code"], ans["stderr"]

    def close(self) -> None:
        if self.proc is not None:
            self.proc.stdin.close()
            self.proc.wait(timeout=60)
            self.proc = None


@pytest.fixture(scope="module")
def limited_cli(tmp_path_factory):
    cli = LimitedCLI(tmp_path_factory.mktemp("limited") / "child-stderr.log")
    yield cli
    cli.close()


LIMIT_KINDS = ["p", "my", "inputs", "sigma_grid", "samples", "model_p", "sweep"]


@pytest.mark.parametrize("kind", LIMIT_KINDS)
@settings(max_examples=examples("limits"), deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(size=st.integers(min_value=1, max_value=10**30))
def test_fuzz_sizes_refused_within_memory(base, limited_cli, kind, size):
    """Requests above a limit: exit 2, one error line naming the number and the limit, no MemoryError,
    no signal, under a 3 GiB address-space limit (every kind of limit, several sizes each)."""
    with scratch(base, ("d.csv", "t.csv", "m.json")) as work:
        if kind == "p":
            p = 1023 + size  # N = (p+1)^2 > 2^20
            args, limit = ["fit", "d.csv", "-o", "x.json", "-y", "y", "-z", "z", "--my", 2, "-p", p, "--sigma", 1], MAX_VERTICES
        elif kind == "my":
            args, limit = ["fit", "d.csv", "-o", "x.json", "-y", "y", "-z", "z", "--my", 20 + size, "--sigma", 1], 20
        elif kind == "inputs":
            k = 21 + size % 80
            rng = np.random.default_rng(size % 1000)
            cols = [f"y{i}" for i in range(k)]
            vals = rng.uniform(0, 1, (30, k + 1))
            (work / "w.csv").write_text(",".join(cols + ["z"]) + "\n" + "\n".join(",".join(repr(float(v)) for v in r) for r in vals) + "\n")
            args, limit = ["fit", "w.csv", "-o", "x.json", "--output", ",".join(cols), "--target", "z", "-p", 1, "--sigma", 1], 20
        elif kind == "sigma_grid":
            args, limit = ["fit", "d.csv", "-o", "x.json", "-y", "y", "-z", "z", "--sigma-grid",
                           f"logspace:-3:3:{MAX_SIGMA_CANDIDATES + size}"], MAX_SIGMA_CANDIDATES
        elif kind == "samples":
            args, limit = ["make-data", "lorenz", "-o", "x.csv", "--samples", MAX_SAMPLES + size], MAX_SAMPLES
        elif kind == "model_p":
            d = json.loads((work / "m.json").read_text())
            d["grid"]["partitions"] = [1023 + size, 1023 + size]
            (work / "m.json").write_text(json.dumps(d))
            args, limit = ["predict", "m.json", "t.csv", "-o", "x.csv"], MAX_VERTICES
        else:
            args, limit = ["explore", "m.json", "t.csv", "-o", "ex", "--input-bits", f"2:{10001 + size}"], 10000
        before = tree(work)
        code, stderr = limited_cli(args, work)
        assert code == 2, (args, code, stderr[-2000:])
        assert "Traceback" not in stderr and "MemoryError" not in stderr, stderr[-2000:]
        errors = [ln for ln in stderr.splitlines() if ln.startswith("error:")]
        assert len(errors) == 1 and f"limit of {limit}" in errors[0], stderr
        assert tree(work) == before
