"""Native Verilator replay of a generated design: the C++ testbench ``pwas_native_tb.cpp``, built and cached.

The cocotb bench (:mod:`pwas_tb`) is the reference and the one with the debug trace; this engine
replays the same runs (stalls, backpressure, resets in the middle of a stream) at millions of
samples per second (``pwas-hdl simulate --engine native``).

* :func:`ports_header` writes ``pwas_ports.h`` from the manifest (port members of ``Vtop`` by role,
  widths in 32-bit words, reset level, latency, warm-up): the C++ names no port itself.
* :func:`build` compiles the design and the bench with ``verilator --cc --exe --build`` into a
  cache folder keyed by the SHA-256 of the Verilog, the header, the bench source, Verilator's
  version and the options (same cache root and file lock as :mod:`pwas_runner`).
* :func:`write_job` / :func:`run` write the binary job, run the binary, read its result.

Job file (little-endian ``uint32``): ``"PWJ1"``, ``reset_cycles``, ``n_runs``; per run
``pause_valid``, ``pause_ready`` (pause probability times 2**32), ``seed_lo``, ``seed_hi``,
``n_segments``; per segment ``n_in``, ``n_expected``, ``drain``, ``hold``, the input payload words
(``n_in * IN_WORDS``), the expected output payload words (``n_expected * OUT_WORDS``), and the
input index that completes each output (``n_expected``).
Result file: ``"PWR1"``, ``n_runs``; per run ``n_segments``, ``cycles`` (u64), wall ns (u64); per
segment ``accepted``, ``outputs``, ``mismatches``, ``problems`` (bits, :data:`PROBLEMS`),
``valid_after_reset``, then the cycles of the input transfers, of the output transfers, and the
output payload words.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import shutil
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from pwas_hdl.fixedpoint.bitfields import pack_fields_words, unpack_fields_words

try:  # loaded by pwas_hdl.verify.simulation.sim_module (which registers pwas_runner) or with sim/ on sys.path
    from pwas_runner import SIM_DIR, VERILATOR_MAKE_VARS, SimulationError, default_cache_dir, tool_versions
except ImportError:
    import sys

    from pwas_hdl.resources import sim_dir

    sys.path.insert(0, str(sim_dir()))
    from pwas_runner import SIM_DIR, VERILATOR_MAKE_VARS, SimulationError, default_cache_dir, tool_versions

__all__ = ["TB_SOURCE", "PROBLEMS", "NativeBuild", "ports_header", "verilator_member", "pack_words", "unpack_words",
           "build", "write_job", "run"]

TB_SOURCE = SIM_DIR / "pwas_native_tb.cpp"
#: Bumped when the way native builds are made changes (invalidates the cache).
NATIVE_RECIPE = 1
NATIVE_VERILATOR_ARGS = ("-O3", "-Wno-fatal", "--x-assign", "fast")
NATIVE_MAKE_VARS = (*VERILATOR_MAKE_VARS, "OPT_FAST=-O2", "OPT_SLOW=-O1")
JOB_MAGIC = 0x314A5750
RESULT_MAGIC = 0x31525750
#: Problem bits of the result file -> the message the cocotb bench gives for the same check.
PROBLEMS = {
    1: "not every input was accepted within the cycle limit (in.ready stuck low?)",
    2: "the number of outputs differs from the number expected",
    4: "more outputs before the reset than the inputs can give",
    8: "out.valid was high in the cycle after a reset",
    16: "a latency differs from the manifest's",
    32: "inputs were not accepted every II cycles (the manifest's ii)",
    64: "outputs did not come every II cycles",
    128: "warm differs from 'high from the transfer that yields the first output'",
}


@dataclass
class NativeBuild:
    top: str
    key: str
    build_dir: str
    executable: str
    build_seconds: float  # 0.0 when the cached build was reused
    reused: bool
    simulator: str = "verilator"
    waves: bool = False


def verilator_member(port: str) -> str:
    """The C++ member name Verilator gives a port (``__`` is escaped: ``in__payload`` -> ``in___05Fpayload``)."""
    if "___" in port:
        raise SimulationError(f"port name {port!r} has three underscores in a row; the native bench does not map it")
    return port.replace("__", "___05F")


def _port(man: dict, role: str) -> dict | None:
    return next((p for p in man["ports"] if p.get("role") == role), None)


def _words(width: int) -> int:
    return max(1, (int(width) + 31) // 32)


def ports_header(man: dict) -> str:
    """``pwas_ports.h`` of a manifest (deterministic text)."""
    def member(role: str) -> str:
        p = _port(man, role)
        if p is None:
            raise SimulationError(f"the manifest has no port with role {role!r}; regenerate the design")
        return verilator_member(p["name"])

    warm = _port(man, "warm")
    polarity = (man.get("reset") or {}).get("polarity", "high")
    warmup = int(man.get("lags", {}).get("warmup", {}).get("samples_without_output", 0)) if man["design"] == "sensor" else 0
    lines = [
        f"// pwas_ports.h: ports of {man['top']} for pwas_native_tb.cpp (written by sim/pwas_native.py from manifest.json)",
        "#pragma once",
        f"#define PWAS_CLK {member('clock')}",
        f"#define PWAS_RST {member('reset')}",
        f"#define PWAS_RST_ON {0 if polarity == 'low' else 1}",
        f"#define PWAS_IN_VALID {member('in.valid')}",
        f"#define PWAS_IN_READY {member('in.ready')}",
        f"#define PWAS_IN_DATA {member('in.payload')}",
        f"#define PWAS_OUT_VALID {member('out.valid')}",
        f"#define PWAS_OUT_READY {member('out.ready')}",
        f"#define PWAS_OUT_DATA {member('out.payload')}",
        f"#define PWAS_IN_WORDS {_words(_port(man, 'in.payload')['width'])}",
        f"#define PWAS_OUT_WORDS {_words(_port(man, 'out.payload')['width'])}",
        f"#define PWAS_LATENCY {int(man['latency_cycles'])}",
        f"#define PWAS_II {int(man['ii'])}",
        f"#define PWAS_WARMUP {warmup}",
        f"#define PWAS_HAS_WARM {1 if warm is not None else 0}",
    ]
    if warm is not None:
        lines.append(f"#define PWAS_WARM {verilator_member(warm['name'])}")
    return "\n".join(lines) + "\n"


def pack_words(values: np.ndarray, fields: Sequence[dict], n_words: int) -> np.ndarray:
    """Pack rows of integer codes into payload words by the manifest's bit fields:
    ``(m, len(fields))`` -> ``(m, n_words)`` uint32 (word 0 = bits 31..0).

    The one signed bit-field packer, :func:`pwas_hdl.fixedpoint.bitfields.pack_fields_words`, with
    32-bit words (Verilator's ``VlWide``); a code that does not fit its field is an error.
    """
    return pack_fields_words(values, fields, n_words, word_bits=32)


def unpack_words(words: np.ndarray, fields: Sequence[dict]) -> np.ndarray:
    """Inverse of :func:`pack_words`: ``(m, n_words)`` uint32 -> ``(m, len(fields))`` int64 (signed
    fields two's complement; :func:`pwas_hdl.fixedpoint.bitfields.unpack_fields_words`)."""
    return unpack_fields_words(words, fields, word_bits=32)


def _verilator() -> str:
    from pwas_hdl.flow.toolchain import require

    return require("verilator")  # ToolMissing with how to install it


def build(verilog: str | os.PathLike, man: dict, *, cache_dir: str | os.PathLike | None = None) -> NativeBuild:
    """Compile the design ``verilog`` (top ``man["top"]``) with the native bench, or reuse the cached build."""
    from pwas_hdl.flow.toolchain import tool_env

    top = man["top"]
    text = Path(verilog).read_text(encoding="utf-8")
    header = ports_header(man)
    tb = TB_SOURCE.read_text(encoding="utf-8")
    h = hashlib.sha256()
    for part in (text, header, tb, top, tool_versions("verilator"), str(NATIVE_RECIPE), " ".join(NATIVE_VERILATOR_ARGS),
                 " ".join(NATIVE_MAKE_VARS)):
        h.update(part.encode())
        h.update(b"\0")
    key = h.hexdigest()
    root = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    root.mkdir(parents=True, exist_ok=True)
    bdir = root / f"native-{top}-{key[:20]}"
    exe = bdir / "pwas_native_tb"
    stamp = bdir / "build.json"
    with open(root / f".{bdir.name}.lock", "w") as lockf:
        fcntl.flock(lockf, fcntl.LOCK_EX)
        if stamp.is_file() and json.loads(stamp.read_text()).get("key") == key and exe.is_file():
            return NativeBuild(top, key, str(bdir), str(exe), 0.0, True)
        if bdir.exists():
            shutil.rmtree(bdir)
        bdir.mkdir(parents=True)
        (bdir / f"{top}.v").write_text(text, encoding="utf-8")
        (bdir / "pwas_ports.h").write_text(header, encoding="utf-8")
        (bdir / "pwas_native_tb.cpp").write_text(tb, encoding="utf-8")
        cmd = [_verilator(), "--cc", "--exe", "--build", "-j", "2", *NATIVE_VERILATOR_ARGS, "--top-module", top, "--prefix", "Vtop",
               "-Mdir", str(bdir / "obj"), "-o", str(exe), "-CFLAGS", f"-I{bdir}"]
        for var in NATIVE_MAKE_VARS:
            cmd += ["-MAKEFLAGS", var]
        cmd += [str(bdir / "pwas_native_tb.cpp"), str(bdir / f"{top}.v")]
        log = bdir / "build.log"
        t0 = time.perf_counter()
        with open(log, "w", encoding="utf-8") as lf:
            r = subprocess.run(cmd, cwd=bdir, stdout=lf, stderr=subprocess.STDOUT, env=tool_env(), check=False)
        secs = time.perf_counter() - t0
        if r.returncode != 0 or not exe.is_file():
            tail = "\n".join(log.read_text(encoding="utf-8", errors="replace").splitlines()[-30:])
            raise SimulationError(f"native Verilator build of {top} failed (exit {r.returncode}); log {log}:\n{tail}")
        shutil.rmtree(bdir / "obj", ignore_errors=True)  # the objects are not reused; keep the cache small
        stamp.write_text(json.dumps({"key": key, "top": top, "seconds": secs, "tool": tool_versions("verilator")}))
        return NativeBuild(top, key, str(bdir), str(exe), secs, False)


def write_job(path: str | os.PathLike, man: dict, runs: Sequence[Any], *, reset_cycles: int = 2) -> None:
    """Write the binary job of ``runs`` (:class:`pwas_hdl.verify.simulation.Run` objects) for design ``man``."""
    pin, pout = _port(man, "in.payload"), _port(man, "out.payload")
    wi, wo = _words(pin["width"]), _words(pout["width"])
    parts: list[np.ndarray] = [np.array([JOB_MAGIC, reset_cycles, len(runs)], dtype=np.uint32)]

    def thr(p: float) -> int:
        return min(int(round((1.0 - float(p)) * 2**32)), 2**32 - 1) if p < 1.0 else 0

    for run in runs:
        seed = int(run.seed) & (2**64 - 1)
        parts.append(np.array([thr(run.p_valid), thr(run.p_ready), seed & 0xFFFFFFFF, seed >> 32, len(run.segments)], dtype=np.uint32))
        for seg in run.segments:
            exp = seg.rows()  # scores, out_of_range[, class_index]
            parts.append(np.array([len(seg.codes), len(exp), int(seg.drain), int(seg.hold)], dtype=np.uint32))
            parts.append(pack_words(seg.codes, pin["fields"], wi).ravel())
            parts.append(pack_words(exp, pout["fields"], wo).ravel())
            parts.append(np.asarray(seg.src, dtype=np.uint32))
    with open(path, "wb") as f:
        for p in parts:
            f.write(np.ascontiguousarray(p, dtype="<u4").tobytes())


def run(b: NativeBuild, man: dict, runs: Sequence[Any], work_dir: str | os.PathLike, *,
        files: dict[str, str | os.PathLike] | None = None, reset_cycles: int = 2, timeout: float | None = None) -> dict[str, Any]:
    """Replay ``runs`` on build ``b``; returns a result in the layout of the cocotb bench's
    (``runs`` -> ``segments`` with ``accepted_at``, ``produced_at``, ``latencies``, ``got``,
    ``mismatches``, ``problems``, ``first_mismatches``; ``failures``), arrays as numpy, plus
    ``wall_s``, ``log``, ``passed`` (the bench's exit status), ``build``."""
    from dataclasses import asdict

    wd = Path(work_dir)
    wd.mkdir(parents=True, exist_ok=True)
    for name, path in (files or {}).items():
        shutil.copyfile(path, wd / name)
    job, result, log = wd / "job.bin", wd / "result.bin", wd / "native.log"
    result.unlink(missing_ok=True)
    write_job(job, man, runs, reset_cycles=reset_cycles)
    t0 = time.perf_counter()
    with open(log, "w", encoding="utf-8") as lf:
        try:
            r = subprocess.run([b.executable, str(job), str(result)], cwd=wd, stdout=lf, stderr=subprocess.STDOUT, check=False,
                               timeout=timeout)
        except subprocess.TimeoutExpired:
            raise SimulationError(f"the native bench of {b.top} did not finish in {timeout} s; log {log}") from None
    wall = time.perf_counter() - t0
    if r.returncode not in (0, 1) or not result.is_file():
        raise SimulationError(f"the native bench of {b.top} failed (exit {r.returncode}); log {log}:\n"
                              + log.read_text(encoding="utf-8", errors="replace")[-2000:])
    pout = _port(man, "out.payload")
    wo = _words(pout["width"])
    data = np.fromfile(result, dtype="<u4")
    pos = 0

    def take(n: int) -> np.ndarray:
        nonlocal pos
        if pos + n > len(data):
            raise SimulationError(f"the native bench's result {result} is truncated")
        a = data[pos:pos + n]
        pos += n
        return a

    magic, n_runs = take(2)
    if magic != RESULT_MAGIC or n_runs != len(runs):
        raise SimulationError(f"{result} is not the result of this job")
    out_runs, failures = [], []
    for run_ in runs:
        n_seg, c_lo, c_hi, ns_lo, ns_hi = (int(v) for v in take(5))
        rr = {"name": run_.name, "cycles": c_lo | (c_hi << 32), "wall_s": (ns_lo | (ns_hi << 32)) * 1e-9, "segments": []}
        for si, seg in zip(range(n_seg), run_.segments):
            n_acc, n_got, mism, probs, valid_after = (int(v) for v in take(5))
            acc = take(n_acc).astype(np.int64)
            prod = take(n_got).astype(np.int64)
            got = unpack_words(take(n_got * wo).reshape(n_got, wo), pout["fields"])
            src = np.asarray(seg.src, dtype=np.int64)
            n_cmp = min(n_got, len(src))
            ok = src[:n_cmp] < n_acc
            lat = prod[:n_cmp][ok] - acc[src[:n_cmp][ok]]
            exp = seg.rows()
            bad = np.flatnonzero(np.any(got[:n_cmp] != exp[:n_cmp], axis=1))
            problems = [msg for bit, msg in PROBLEMS.items() if probs & bit]
            if len(bad) != mism:
                problems.append(f"the bench counted {mism} mismatches, the host {len(bad)}")
            rr["segments"].append({
                "accepted": n_acc, "outputs": n_got, "expected": len(src), "accepted_at": acc, "produced_at": prod,
                "latencies": lat, "got": got, "mismatches": int(len(bad)), "problems": problems,
                "first_mismatches": [
                    {"run": run_.name, "segment": si, "output": int(i), "input": int(src[i]), "input_codes": seg.codes[src[i]].tolist(),
                     "expected": exp[i].tolist(), "actual": got[i].tolist()} for i in bad[:20]
                ],
            })
            for prob in problems:
                failures.append(f"run {run_.name!r} segment {si}: {prob}")
            if len(bad):
                m = rr["segments"][-1]["first_mismatches"][0]
                failures.append(f"run {run_.name!r} segment {si}: {len(bad)} output(s) differ from the bit-true model; first: output "
                                f"{m['output']} (input transfer {m['input']}, codes {m['input_codes']}): expected {m['expected']}, "
                                f"RTL gave {m['actual']}")
        out_runs.append(rr)
    return {"top": b.top, "latency_cycles": int(man["latency_cycles"]), "runs": out_runs, "failures": failures,
            "wall_s": wall, "log": str(log), "waves": None, "passed": r.returncode == 0 and not failures, "build": asdict(b)}
