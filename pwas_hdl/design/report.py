"""One report of a generated design: fit, formats, latency, simulation and synthesis results.

:func:`collect_report` reads what the other commands left in a generated folder --
``manifest.json`` and ``model.json`` (``generate``), ``sim/*.json`` (``simulate --json``, or any
summary passed explicitly) and ``synth/<target>/synth.json`` (``synth``) -- and puts the numbers
side by side; :func:`report_markdown` renders them.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any, Sequence

from pwas_hdl.design.manifest import load_manifest
from pwas_hdl.errors import InputError, fault_text
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

__all__ = ["collect_report", "report_markdown", "stale_results", "STALE_NOTE", "SIM_RESULTS"]

#: What the report says of a result made for another design than the folder's.
STALE_NOTE = "stale: made for an earlier design"
#: The subfolder of a design folder whose ``*.json`` simulation summaries ``report`` reads (where
#: ``simulate`` writes by default: ``OUTDIR/sim/SIMULATOR.csv`` and ``.json``).
SIM_RESULTS = "sim"


def _is_stale(result: dict[str, Any], manifest: dict[str, Any]) -> bool:
    """A result is stale when the folder's manifest has a design hash and the result another (or none)."""
    current = manifest.get("design_hash")
    return current is not None and result.get("design_hash") != current


def stale_results(outdir: str | os.PathLike) -> list[str]:
    """Results in ``outdir/sim/*.json`` and ``outdir/synth/*/synth.json`` made for an earlier design.

    Parameters
    ----------
    outdir : path
        A design folder (its manifest is loaded and validated).

    Returns
    -------
    list of str
        Their paths relative to ``outdir`` (sorted); empty when every result matches the
        manifest's ``design_hash``. Files that are not JSON objects are skipped.

    Raises
    ------
    FileNotFoundError, InputError
        As :func:`~pwas_hdl.design.manifest.load_manifest`.
    """
    out = Path(outdir)
    man = load_manifest(out)
    stale = []
    for p in sorted(out.glob("sim/*.json")) + sorted(out.glob("synth/*/synth.json")):
        try:
            r = json.loads(p.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        if isinstance(r, dict) and _is_stale(r, man):
            stale.append(p.relative_to(out).as_posix())
    return stale


def report_inputs(outdir: str | os.PathLike, sims: list[str | os.PathLike] = ()) -> list[tuple[Path, str]]:
    """Every file :func:`collect_report` reads, for the ``inputs`` of the report's
    :class:`~pwas_hdl.io.atomic.OutputSet` (``--json`` / ``-o`` never replace one).

    Parameters
    ----------
    outdir : path
        The design folder.
    sims : list of path
        Extra simulation summaries (``--sim``).

    Returns
    -------
    list of (Path, str)
        The folder's files (:func:`~pwas_hdl.design.manifest.folder_inputs`), its ``sim/*.json``
        and ``synth/*/synth.json``, then ``sims``, each with a description for messages.
    """
    from pwas_hdl.design.manifest import folder_inputs

    out = Path(outdir)
    res = folder_inputs(out)
    res += [(p, "a simulation summary of the design") for p in sorted(out.glob("sim/*.json"))]
    res += [(p, "a synthesis result of the design") for p in sorted(out.glob("synth/*/synth.json"))]
    return res + [(Path(p), "--sim") for p in sims]


def _read_json(path: Path) -> dict[str, Any]:
    if path.is_dir():
        raise InputError(f"{path} is a folder; give the JSON summary that `pwas-hdl simulate` wrote (OUTDIR/sim/*.json "
                         "are read without --sim)")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{path} is not valid JSON ({exc}); re-run the command that wrote it") from exc
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror or exc}") from exc


#: Keys a result file must have, by the command that writes it (the report reads them).
_SIM_KEYS = {"simulator": str, "samples": int, "mismatches": int, "latency_cycles": dict, "ii": dict}
_SYNTH_KEYS = {"target": str, "luts": int, "ffs": int, "fmax_mhz": (int, float, type(None))}

_NUM = (int, float, type(None))
#: The values the report shows, by path in the result file: (types, smallest value, whether the
#: smallest is excluded). Absent keys of the optional ones are shown as "-"; null is allowed where the
#: types say so; numbers must be finite (JSON's Infinity / NaN are refused).
_SIM_VALUES = {
    ("samples",): (int, 1, False), ("mismatches",): (int, 0, False),
    ("latency_cycles", "measured_min"): ((int, type(None)), 0, False),
    ("latency_cycles", "measured_max"): ((int, type(None)), 0, False),
    ("ii", "measured"): (_NUM, 0, True), ("max_error_vs_float_lsb",): (_NUM, 0, False),
    ("samples_per_second",): (_NUM, 0, False), ("out_of_range",): ((int, type(None)), 0, False),
}
_SIM_TARGET_VALUES = {"rmsee_float": (_NUM, 0, False), "rmsee_hw": (_NUM, 0, False),
                      "rmsee_increase_hw_vs_float_percent": (_NUM, None, False)}
_SYNTH_VALUES = {
    ("luts",): (int, 0, False), ("ffs",): (int, 0, False), ("carry",): ((int, type(None)), 0, False),
    ("dsp",): ((int, type(None)), 0, False), ("bram",): ((int, type(None)), 0, False),
    ("bram_bits",): ((int, type(None)), 0, False), ("fmax_mhz",): (_NUM, 0, True),
    ("latency_ns",): (_NUM, 0, True), ("throughput_msps",): (_NUM, 0, True),
}


def _check_values(d: dict[str, Any], spec: dict[tuple[str, ...], tuple], path: Path, command: str, where: str = "") -> None:
    """Refuse a value of the wrong type or out of range (a negative count, zero samples, an infinite
    or non-positive fmax) rather than print it."""
    for keys, (types, lo, strict) in spec.items():
        v: Any = d
        for k in keys:
            v = v.get(k) if isinstance(v, dict) else None
        name = where + ".".join(keys)
        if isinstance(v, bool) or not isinstance(v, types):
            raise InputError(f"{path}: {name} = {json.dumps(v)} has the wrong type; re-run `pwas-hdl {command}`")
        if v is None:
            continue
        if isinstance(v, float) and not math.isfinite(v):
            raise InputError(f"{path}: {name} = {v} is not a finite number; re-run `pwas-hdl {command}`")
        if lo is not None and (v <= lo if strict else v < lo):
            raise InputError(f"{path}: {name} = {json.dumps(v)} is out of range (must be {'>' if strict else '>='} {lo}); "
                             f"re-run `pwas-hdl {command}`")


def _require(d: Any, keys: dict[str, Any], path: Path, command: str) -> dict[str, Any]:
    """Refuse a result file that lacks what the report shows (instead of printing ``None`` rows),
    or holds a value of the wrong type or out of range."""
    noun = "summary" if command == "simulate" else "result"
    if not isinstance(d, dict):
        raise InputError(f"{path} is not a `pwas-hdl {command}` {noun} (not a JSON object); re-run `pwas-hdl {command}`")
    missing = [k for k in keys if k not in d]
    if missing:
        raise InputError(
            f"{path} is not a `pwas-hdl {command}` {noun} (missing {', '.join(missing)}); "
            f"re-run `pwas-hdl {command}` or remove the file"
        )
    bad = [k for k, t in keys.items() if not isinstance(d[k], t) or isinstance(d[k], bool)]
    if bad:
        raise InputError(f"{path}: {', '.join(f'{k} = {json.dumps(d[k])}' for k in bad)} has the wrong type; re-run `pwas-hdl {command}`")
    if command == "simulate":
        _check_values(d, _SIM_VALUES, path, command)
        if d["mismatches"] > d["samples"]:
            raise InputError(f"{path}: mismatches = {d['mismatches']} is more than samples = {d['samples']}; re-run `pwas-hdl {command}`")
        targets = d.get("targets", {})
        if isinstance(targets, dict):
            for t, v in targets.items():
                if isinstance(v, dict):
                    _check_values(v, {(k,): spec for k, spec in _SIM_TARGET_VALUES.items()}, path, command, f"targets.{t}.")
    else:
        _check_values(d, _SYNTH_VALUES, path, command)
        from pwas_hdl.flow.synthesis import TARGETS

        if d["target"] not in TARGETS:
            raise InputError(f"{path}: target = {json.dumps(d['target'])} is not one of {', '.join(TARGETS)}; re-run `pwas-hdl {command}`")
    return d


def _check_top(r: dict[str, Any], key: str, man: dict[str, Any], path: Path, command: str, given: bool = False) -> None:
    """A result for another top level than the folder's (and not marked stale: same design hash or
    none) belongs to another design: refused, not shown as this one's. A file ``given`` by ``--sim``
    (not in the folder, so not left there by an earlier ``generate``) is refused for another top
    even with another hash: it is another design's, not "made for an earlier design"."""
    top = r.get(key)
    if top is not None and top != man["top"] and (given or not _is_stale(r, man)):
        raise InputError(f"{path} is a result for the top {json.dumps(top)}, not this folder's {man['top']}; "
                         f"re-run `pwas-hdl {command}` on this folder or "
                         + ("leave it out of --sim" if given else "remove the file"))


def collect_report(outdir: str | os.PathLike, sim_summaries: Sequence[str | os.PathLike] = ()) -> dict[str, Any]:
    """Gather the results of a generated folder.

    Parameters
    ----------
    outdir : path
        Folder written by ``pwas-hdl generate``.
    sim_summaries : sequence of paths
        JSON summaries of ``pwas-hdl simulate`` (in addition to ``outdir/sim/*.json``).

    Returns
    -------
    dict
        ``design`` (top, kind, latency, II, memory, formats, error bound), ``fit`` (model
        summary), ``simulation`` (one entry per summary), ``synthesis`` (one entry per target).
    """
    out = Path(outdir)
    man = load_manifest(out)
    try:
        design, fit = _design_summary(out, man)
    except (KeyError, TypeError, AttributeError, IndexError) as exc:
        raise InputError(
            f"{out / 'manifest.json'} is incomplete or corrupt ({fault_text(exc)}); "
            "regenerate the folder with `pwas-hdl generate`"
        ) from exc
    rep = _collect_results(out, man, design, fit, sim_summaries)
    try:
        report_markdown(rep)  # every value the rendering needs is there and of the right kind
    except (KeyError, TypeError, AttributeError, IndexError, ValueError) as exc:
        raise InputError(
            f"{out}: the manifest or a simulate/synth result holds a value of the wrong kind ({fault_text(exc)}); "
            "regenerate the folder or re-run the command that wrote the result"
        ) from exc
    return rep


def _estimator_summary(out: Path, man: dict[str, Any]) -> tuple[dict[str, Any], None]:
    """The design summary of an estimator folder (seed 003's switched observer: no PWAS fit)."""
    from pwas_hdl.fit.estimator_file import read_estimator

    cfg = read_estimator(out / man["files"]["model"])  # the configuration must still be readable
    e = man["estimator"]
    f = e["formats"]
    return {"top": man["top"], "kind": "estimator", "modes": e["modes"], "states": e["states"], "window": e["window"],
            "signals": e["signals"], "latency_cycles": man["latency_cycles"], "ii": man["ii"],
            "formats": f"inputs s{f['input_bits']}.{f['input_frac']}, states s{f['state_bits']}.{f['state_frac']}, "
                       f"coefficients {f['coef_frac']} fraction bits",
            "error_bound": e["error_bound"], "source": cfg.source}, None


def _architecture_text(d: dict[str, Any]) -> str:
    """`` (serial architecture)`` and a classifier's argmax stage, for the report's latency line
    (nothing for a parallel design without a classifier, whose line stays as it was)."""
    words = ["serial architecture"] if d.get("architecture") == "serial" else []
    c = d.get("classifier")
    if c is not None:
        cyc = c["stage_latency_cycles"]
        words.append(f"classifier of {c['target']} ({c['n_classes']} classes): argmax stage {cyc} cycle"
                     f"{'' if cyc == 1 else 's'} of the latency")
    return f" ({'; '.join(words)})" if words else ""


def _design_summary(out: Path, man: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any] | None]:
    if man["design"] == "estimator":
        return _estimator_summary(out, man)
    model = PWASVirtualSensor.load(out / man["files"]["model"])
    fit = model.to_dict()["fit"]
    fmt = man["formats"]
    design = {
        "top": man["top"],
        "kind": man["design"],
        "n": len(man["lags"]["regressors"]),
        "N": man["domain"]["n_vertices"],
        "regressors": man["lags"]["regressors"],
        "latency_cycles": man["latency_cycles"],
        "ii": man["ii"],
        "memory": {k: man["memory"][k] for k in ("kind", "memories", "depth", "word_bits", "words", "bits")},
        "input_formats": sorted({str(i["format"]) for i in fmt["inputs"]}),
        "weight_format": f"s{fmt['weight']['bits']}.{fmt['weight']['frac']}",
        "output_format": f"s{fmt['output']['bits']}.{fmt['output']['frac']}",
        "output_lsb": 2.0 ** -fmt["output"]["frac"],
        "error_bound_lsb": man["error_bound"]["lsb"],
        "error_bound": man["error_bound"]["physical"],
        "architecture": man.get("architecture", {}).get("kind", "parallel"),
    }
    if "classifier" in man:  # the argmax stage after the core (parallel or serial)
        c = man["classifier"]
        design["classifier"] = {"target": c["target"], "n_classes": c["n_classes"],
                                "stage_latency_cycles": c["stage_latency_cycles"]}
    return design, fit


def _collect_results(out: Path, man: dict[str, Any], design: dict[str, Any], fit: dict[str, Any],
                     sim_summaries: Sequence[str | os.PathLike]) -> dict[str, Any]:
    paths = sorted((out / SIM_RESULTS).glob("*.json")) if (out / SIM_RESULTS).is_dir() else []
    n_folder = len(paths)
    paths += [Path(p) for p in sim_summaries]
    sims = []
    for i, p in enumerate(paths):
        s = _require(_read_json(p), _SIM_KEYS, p, "simulate")
        _check_top(s, "design", man, p, "simulate", given=i >= n_folder)
        if not isinstance(s.get("targets", {}), dict) or not all(isinstance(v, dict) for v in s.get("targets", {}).values()):
            raise InputError(f"{p}: \"targets\" is not an object of objects; re-run `pwas-hdl simulate`")
        sims.append(
            {
                "file": p.name,
                "simulator": s["simulator"],
                "samples": s["samples"],
                "mismatches": s["mismatches"],
                "latency_measured": [s["latency_cycles"].get("measured_min"), s["latency_cycles"].get("measured_max")],
                "ii_measured": s["ii"].get("measured"),
                "max_error_vs_float_lsb": s.get("max_error_vs_float_lsb"),
                "within_error_bound": s.get("within_error_bound"),
                "samples_per_second": s.get("samples_per_second"),
                "out_of_range": s.get("out_of_range"),
                "stale": _is_stale(s, man),
                **({"modes": s.get("modes"), "metrics": s.get("metrics")} if man["design"] == "estimator" else {}),
                **({"classifier": _classifier_result(s["classifier"])}
                   if man.get("classifier") is not None and isinstance(s.get("classifier"), dict) else {}),
                "targets": {
                    t: {k: v.get(k) for k in ("reference_column", "rmsee_float", "rmsee_hw", "rmsee_increase_hw_vs_float_percent")}
                    for t, v in s.get("targets", {}).items()
                },
            }
        )
    synth = []
    for p in sorted(out.glob("synth/*/synth.json")):
        r = _require(_read_json(p), _SYNTH_KEYS, p, "synth")
        _check_top(r, "top", man, p, "synth")
        synth.append({k: r.get(k) for k in ("target", "part", "luts", "ffs", "carry", "dsp", "bram", "bram_bits",
                                             "fmax_mhz", "latency_ns", "throughput_msps", "timing_met")})
        synth[-1].update(file=p.relative_to(out).as_posix(), stale=_is_stale(r, man))
        fp = r.get("floorplan")  # ECP5: the hard-block sites of pwas_hdl.flow.floorplan (None before hw14f / other targets)
        synth[-1]["floorplan"] = ({"applied": bool(fp.get("applied")),
                                   "rows": fp.get("rows") if isinstance(fp.get("rows"), dict) else None,
                                   "reason": fp.get("reason")} if isinstance(fp, dict) else None)
    return {
        "format": "pwas-hdl-report",
        "version": 1,
        "design": design,
        "fit": ({**{k: fit[k] for k in ("sigma", "tikhonov_order", "gamma", "n_train", "train_rmse")},
                 "solve": fit.get("solve")} if fit is not None else None),
        "simulation": sims,
        "synthesis": synth,
    }


def _classifier_result(c: dict[str, Any]) -> dict[str, Any]:
    """What the report keeps of a classifier simulation (``simulate``'s ``classifier`` entry): the class
    mismatches against the bit-true argmax, the accuracy of the RTL and of the float classifier against
    the label column, and the agreement with the float argmax; a value of another type is ``None``."""

    def num(*keys: str) -> float | None:
        v: Any = c
        for k in keys:
            v = v.get(k) if isinstance(v, dict) else None
        return v if isinstance(v, (int, float)) and not isinstance(v, bool) else None

    ref = c.get("reference_column")
    return {"class_mismatches": num("class_mismatches"), "accuracy_hw": num("scores_hw", "accuracy"),
            "accuracy_float": num("scores_float", "accuracy"), "reference_column": ref if isinstance(ref, str) else None,
            "agreement_float": num("agreement_float", "agreement")}


def _fmt(v: Any, spec: str = ".4g") -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return format(v, spec)
    return str(v)


def _solve_sentence(solve: dict[str, Any] | None) -> str:
    """The fit's solve (model file ``fit.solve``) in a sentence: only when a solve did not converge."""
    if not solve:
        return ""
    out = ""
    if not solve.get("converged", True):
        bound = solve.get("weight_bound")
        out += (f" **The weights did not converge**: relative residual {_fmt(solve.get('rel_residual'), '.3g')}"
                + (f", within {_fmt(bound, '.3g')} (2-norm) of the exact solution." if bound is not None else "."))
    if solve.get("cv_unconverged"):
        out += (f" {solve['cv_unconverged']} of {solve.get('cv_solves')} CV solves stopped unconverged (the choice "
                "of sigma is approximate).")
    return out


def _estimator_lines(rep: dict[str, Any]) -> list[str]:
    """Design and simulation lines of an estimator folder (seed 003's switched observer)."""
    d = rep["design"]
    eb = d["error_bound"]
    lines = [f"# {d['top']} (estimator): accuracy, latency, resources", "",
             f"Seed 003's switched-observer estimator: {d['modes']} modes, {d['states']} states "
             f"({', '.join(d['signals']['states'])}), detector window {d['window']}; {d['formats']}. Latency "
             f"{d['latency_cycles']} cycle{'' if d['latency_cycles'] == 1 else 's'}, II {d['ii']}. Bounds against the float estimator: modes equal where the float margin "
             f"exceeds {_fmt(2 * eb['window_sum'])}; then |x_hat - float| <= {_fmt(eb['state'])}, |y_hat - float| <= "
             f"{_fmt(eb['y_hat'])}.", ""]
    if rep["simulation"]:
        lines += ["## Simulation (RTL against the bit-true and float estimators)", "",
                  "| simulator | samples | mismatches | latency (meas.) | II (meas.) | modes differing from float (beyond bound) | "
                  "mode accuracy hw / float | output MSE hw / float |", "|---|---:|---:|---:|---:|---:|---|---|"]
        for s in rep["simulation"]:
            lat, mo, me = s["latency_measured"], s.get("modes") or {}, s.get("metrics") or {}
            yn = d["signals"]["output"]
            lines.append(f"| {s['simulator']} | {s['samples']} | {s['mismatches']} | {lat[0]}..{lat[1]} | {_fmt(s['ii_measured'])} | "
                         f"{_fmt(mo.get('differ_from_float'))} ({_fmt(mo.get('differ_beyond_bound'))}) | "
                         f"{_fmt(me.get('mode_accuracy_hw'))} / {_fmt(me.get('mode_accuracy_float'))} | "
                         f"{_fmt(me.get(f'{yn}_mse_hw'))} / {_fmt(me.get(f'{yn}_mse_float'))} |")
        lines += _stale_lines(rep["simulation"], "simulate")
        lines.append("")
    return lines


def report_markdown(rep: dict[str, Any]) -> str:
    """Markdown rendering of :func:`collect_report`.

    Parameters
    ----------
    rep : dict
        What :func:`collect_report` returns.

    Returns
    -------
    str
        The report text (as in ``report.md``): accuracy, latency, resources.
    """
    if rep["design"]["kind"] == "estimator":
        lines = _estimator_lines(rep)
        lines += _synth_lines(rep)
        return "\n".join(lines)
    d, f = rep["design"], rep["fit"]
    lines = [
        f"# {d['top']} ({d['kind']}): accuracy, latency, resources",
        "",
        f"Model: n = {d['n']} ({', '.join(d['regressors'])}), N = {d['N']}, sigma = {_fmt(f['sigma'], '.3g')}, "
        f"Tikhonov order {f['tikhonov_order']}, gamma = {f['gamma']}, train RMSE "
        + ", ".join(f"{t} {_fmt(v)}" for t, v in (f.get("train_rmse") or {}).items())
        + "."
        + _solve_sentence(f.get("solve")),
        "",
        f"Formats: inputs {', '.join(d['input_formats'])}, weights {d['weight_format']}, output {d['output_format']} "
        f"(LSB {_fmt(d['output_lsb'])}); error bound vs float {_fmt(d['error_bound_lsb'])} LSB = {_fmt(d['error_bound'])}.",
        f"Latency {d['latency_cycles']} cycles, II {d['ii']}{_architecture_text(d)}; weight memory {d['memory']['words']} words x "
        f"{d['memory']['word_bits']} bits ({d['memory']['kind']}, {d['memory']['memories']} memories).",
        "",
    ]
    if rep["simulation"]:
        lines += ["## Simulation (RTL against the bit-true and float models)", "",
                  "| simulator | samples | mismatches | latency (meas.) | II (meas.) | max err vs float (LSB) | target | RMSEE float | RMSEE hardware | increase |",
                  "|---|---:|---:|---:|---:|---:|---|---:|---:|---:|"]
        for s in rep["simulation"]:
            lat = s["latency_measured"]
            for t, v in s["targets"].items():
                lines.append(
                    f"| {s['simulator']} | {s['samples']} | {s['mismatches']} | {lat[0]}..{lat[1]} | {_fmt(s['ii_measured'])} | "
                    f"{_fmt(s['max_error_vs_float_lsb'], '.3f')} | {t} (vs {_fmt(v.get('reference_column'))}) | {_fmt(v['rmsee_float'])} | "
                    f"{_fmt(v['rmsee_hw'])} | {_fmt(v['rmsee_increase_hw_vs_float_percent'], '.3f')} % |"
                )
        for s in rep["simulation"]:  # clamped estimates: their errors are in the RMSEE above
            if s.get("out_of_range"):
                lines += ["", f"{s['simulator']} ({s['file']}): {s['out_of_range']} of {s['samples']} estimates had a "
                              "regressor outside the domain (clamped to its edge; column out_of_range): the RMSEE "
                              "includes the sensor's extrapolation there."]
        lines += _stale_lines(rep["simulation"], "simulate")
        lines.append("")
        clf = [s for s in rep["simulation"] if s.get("classifier")]
        if clf:  # a classifier design: the class of the RTL (the score rows above have no reference)
            lines += ["## Classifier (class index of the RTL against the bit-true and float argmax)", "",
                      "| simulator | samples | class mismatches | accuracy hardware | accuracy float | reference | "
                      "agreement with float argmax |", "|---|---:|---:|---:|---:|---|---:|"]
            for s in clf:
                c = s["classifier"]
                lines.append(f"| {s['simulator']} | {s['samples']} | {_fmt(c['class_mismatches'])} | {_fmt(c['accuracy_hw'])} | "
                             f"{_fmt(c['accuracy_float'])} | {_fmt(c['reference_column'])} | {_fmt(c['agreement_float'])} |")
            lines.append("")
    lines += _synth_lines(rep)
    return "\n".join(lines)


def _synth_lines(rep: dict[str, Any]) -> list[str]:
    lines: list[str] = []
    if rep["synthesis"]:
        lines += ["## Synthesis (Yosys + nextpnr)", "",
                  "| target | part | LUT | FF | carry | DSP | BRAM (bits) | fmax (MHz) | latency (ns) | Msamples/s |",
                  "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for s in rep["synthesis"]:
            lines.append(
                f"| {s['target']} | {_fmt(s['part'])} | {_fmt(s['luts'])} | {_fmt(s['ffs'])} | {_fmt(s['carry'])} | {_fmt(s['dsp'])} | "
                f"{_fmt(s['bram'])} ({_fmt(s['bram_bits'])}) | {_fmt(s['fmax_mhz'], '.1f')} | {_fmt(s['latency_ns'], '.1f')} | "
                f"{_fmt(s['throughput_msps'], '.1f')} |"
            )
        for s in rep["synthesis"]:
            fp = s.get("floorplan")
            if fp and fp.get("applied"):
                rows = ", ".join(f"{t} in row {y}" for t, y in (fp.get("rows") or {}).items())
                lines.append(f"Floorplan ({s['target']}): block RAMs and multipliers on fixed sites ({rows}; `synth --floorplan`).")
        lines += _stale_lines(rep["synthesis"], "synth")
        lines.append("")
    return lines


def _stale_lines(entries: list[dict[str, Any]], command: str) -> list[str]:
    stale = [e.get("file", "?") for e in entries if e.get("stale")]
    if not stale:
        return []
    return ["", f"{STALE_NOTE} (the design was regenerated since): {', '.join(stale)}; re-run `pwas-hdl {command}`."]
