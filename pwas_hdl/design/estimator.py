"""The estimator design of ``pwas-hdl generate`` (issue 12): seed 003's switched observer as a folder.

``pwas-hdl generate EST.json -o DIR`` on an estimator file (:mod:`pwas_hdl.fit.estimator_file`,
written by ``pwas-hdl make-data switched-linear --estimator-out EST.json``) writes the same kind
of folder as for a PWAS model: ``<top>.v`` (:class:`pwas_hdl.hdl.switched_estimator_top.SwitchedEstimatorTop`,
one synthesizable module, ``verilator --lint-only -Wall`` clean), ``manifest.json`` (design
``"estimator"``, its ``estimator`` block: formats, coefficient codes, widths, bounds, detector),
``report.md``, ``estimator.json`` (the configuration: the float reference of the testbench, in the
``files.model`` slot), ``<top>_inst.v`` and ``<top>.core``. No weight memories (``files.hex`` is
empty). Same inputs give byte-identical files.

The bit-true model is :class:`pwas_hdl.fixedpoint.observer_bank.FixedPointSwitchedEstimator`; its
format options (``input_bits``, ``input_headroom``, ``state_bits``, ``state_frac``, ``coef_frac``)
are recorded in ``generator.options`` so that :func:`fixed_point_estimator` rebuilds it exactly.

``--architecture serial`` builds :class:`~pwas_hdl.hdl.switched_estimator_top.SerialSwitchedEstimatorTop`
instead (the same ports and fields; II = ``manifest.estimator.cycles_per_sample``, latency II + 1).

Ports (one (u, y) sample per input transfer, parallel: latency 1, II 1, no warm-up): input payload fields
``u`` (the input signal's name) and ``y`` (``s<B_in>.<F_in>`` of the physical value), output
payload fields ``<state>_hat`` (``s<B_s>.<F_s>``), ``y_hat`` (``F_s`` fraction bits),
``mode_index`` (the detected mode minus 1; physical mode = 1 + code) and ``state_saturated``.
"""

from __future__ import annotations

import hashlib
import os
from typing import TYPE_CHECKING, Any

from pwas_hdl import __version__
from pwas_hdl.errors import InputError, choice_text, option_text
from pwas_hdl.fit.estimator_file import SwitchedEstimatorConfig, estimator_text, is_estimator_file, read_estimator
from pwas_hdl.fixedpoint.formats import FixedFormat, PortFormat, SignalScaling

if TYPE_CHECKING:
    from pwas_hdl.design.generate import GeneratedDesign
    from pwas_hdl.fixedpoint.observer_bank import FixedPointSwitchedEstimator

__all__ = ["ESTIMATOR_OPTIONS", "ESTIMATOR_FILE", "fixed_point_estimator", "build_estimator_design", "is_estimator",
           "estimator_info", "load_estimator_config"]

#: Format options of the estimator design (None: the default of the noise budget).
ESTIMATOR_OPTIONS = ("input_bits", "input_headroom", "state_bits", "state_frac", "coef_frac")
#: Architectures of the estimator design (``generate --architecture``).
ESTIMATOR_ARCHITECTURES = ("parallel", "serial")
#: Name of the configuration inside the generated folder.
ESTIMATOR_FILE = "estimator.json"
#: generate options that belong to the PWAS designs, with the value that means "not given".
_PWAS_DEFAULTS = {"memory": "banked", "pipeline": None, "memory_init": "inline", "goal": None, "target_mhz": None,
                  "input_fill": 0.9, "input_scale": "pow2", "weight_bits": None,
                  "weight_frac": None, "output_bits": None, "output_frac": None, "overflow": "error", "rounding": "half_up"}


def is_estimator(model: Any) -> bool:
    """True for a :class:`SwitchedEstimatorConfig` or the path of an estimator file.

    Parameters
    ----------
    model : Any
        What ``generate`` was given (a sensor, a path, a config).

    Returns
    -------
    bool
        A path counts when its JSON ``format`` is ``pwas-hdl-estimator``
        (:func:`~pwas_hdl.fit.estimator_file.is_estimator_file`, no validation).
    """
    if isinstance(model, SwitchedEstimatorConfig):
        return True
    return isinstance(model, (str, os.PathLike)) and is_estimator_file(model)


def load_estimator_config(model: SwitchedEstimatorConfig | str | os.PathLike) -> SwitchedEstimatorConfig:
    """The estimator configuration itself, or the one read from an estimator file.

    Parameters
    ----------
    model : SwitchedEstimatorConfig, str or os.PathLike
        A configuration (returned as is) or the path of an estimator file.

    Returns
    -------
    SwitchedEstimatorConfig

    Raises
    ------
    FileNotFoundError
        No such file.
    InputError
        Not a valid estimator file (:func:`~pwas_hdl.fit.estimator_file.read_estimator`).
    """
    return model if isinstance(model, SwitchedEstimatorConfig) else read_estimator(model)


def _check_int(name: str, v: Any, lo: int, hi: int) -> None:
    if v is None:
        return
    if not isinstance(v, int) or isinstance(v, bool) or not lo <= v <= hi:
        raise InputError(f"{option_text(name)} must be an integer in {lo}..{hi}, got {v!r}")


def fixed_point_estimator(config: SwitchedEstimatorConfig, *, input_bits: int | None = None, input_headroom: float | None = None,
                          state_bits: int | None = None, state_frac: int | None = None,
                          coef_frac: int | None = None) -> FixedPointSwitchedEstimator:
    """The bit-true estimator (:class:`~pwas_hdl.fixedpoint.observer_bank.FixedPointSwitchedEstimator`) of ``config``.

    Parameters
    ----------
    config : SwitchedEstimatorConfig
        The float estimator (observer bank and switching rule).
    input_bits : int, optional
        ``B_in``: width in bits of the u and y codes (default 12; 4..24).
    input_headroom : float, optional
        ``H``: physical |u|, |y| < H are representable (the signals' physical units; default 8).
    state_bits, state_frac, coef_frac : int, optional
        ``B_s`` (2..48 bits), ``F_s`` (fraction bits, >= the input fraction bits, <= 40), ``F_c`` (fraction
        bits, 1..40); default from the noise budget and the l1 state bound (no saturation for inputs within
        the code range).

    Returns
    -------
    FixedPointSwitchedEstimator

    Raises
    ------
    InputError
        An option out of range (also ``F_s`` below the input fraction bits) or an unstable observer (``A_i - K_i C_i`` with a pole on or outside
        the unit circle).
    """
    import numpy as np

    from pwas_hdl.fixedpoint.observer_bank import FixedPointSwitchedEstimator

    _check_int("input_bits", input_bits, 4, 24)
    _check_int("state_bits", state_bits, 2, 48)
    _check_int("state_frac", state_frac, 0, 40)
    _check_int("coef_frac", coef_frac, 1, 40)
    if input_headroom is not None and not (isinstance(input_headroom, (int, float)) and not isinstance(input_headroom, bool)
                                           and 0 < float(input_headroom) < 1e6):
        raise InputError(f"{option_text('input_headroom')} must be a positive number below 1e6, got {input_headroom!r}")
    for i, (a, k, c) in enumerate(zip(config.A, config.K, config.C)):
        rho = float(np.max(np.abs(np.linalg.eigvals(a - np.outer(k, c)))))
        if not rho < 1.0:
            raise InputError(f"the observer of mode {i + 1} is not stable (A - K C has a pole of modulus {rho:.4g} >= 1); "
                             "choose gains K that place the poles inside the unit circle")
    est = FixedPointSwitchedEstimator(config.A, config.B, config.C, config.K, window=config.window,
                                      input_bits=12 if input_bits is None else input_bits,
                                      input_headroom=8.0 if input_headroom is None else float(input_headroom),
                                      coef_frac=coef_frac, state_frac=state_frac, state_bits=state_bits)
    if est.state_frac < est.input_frac:
        raise InputError(f"{option_text('state_frac')} = {est.state_frac} must be >= the input fraction bits {est.input_frac}")
    return est


def _fmt(bits: int, frac: int, signed: bool = True, scale: float = 1.0, offset: float = 0.0) -> dict:
    return PortFormat(FixedFormat(bits, frac, signed, "half_up", "saturate"), SignalScaling(scale, offset)).to_dict()


def estimator_info(top: Any, config: SwitchedEstimatorConfig, ports: str) -> dict:
    """Ports (with their payload fields), clock, reset, latency, II and flow control of the built top.

    Parameters
    ----------
    top : SwitchedEstimatorTop or SerialSwitchedEstimatorTop
        The built top (:mod:`pwas_hdl.hdl.switched_estimator_top`).
    config : SwitchedEstimatorConfig
        Gives the signal and state names of the fields.
    ports : {"axis", "amaranth"}
        Port naming.

    Returns
    -------
    dict
        ``ports`` (payload ports with ``fields``: bit positions, formats, meanings), ``clock``,
        ``reset``, ``latency`` and ``ii`` (cycles), ``flow_control``: the ``info`` of
        :func:`~pwas_hdl.design.manifest.build_estimator_manifest`.
    """
    from pwas_hdl.hdl.emit import port_list, port_names

    est = top.est
    nm = port_names(ports)
    b = est.input_bits
    in_fields = [{"name": config.input_name, "lsb": 0, "width": b, "signed": True, "signal": config.input_name,
                  "format": est.input_port.to_dict()},
                 {"name": config.output_name, "lsb": b, "width": b, "signed": True, "signal": config.output_name,
                  "format": est.input_port.to_dict()}]
    out_fields, lsb = [], 0
    state_of = {f"x{i + 1}_hat": config.state_names[i] for i in range(est.n)}
    for fname, w in top.out_fields:
        f: dict[str, Any] = {"name": fname, "lsb": lsb, "width": w, "signed": fname not in top.unsigned_fields}
        if fname in state_of:
            f.update(name=f"{state_of[fname]}_hat", target=state_of[fname], format=_fmt(w, est.state_frac),
                     meaning=f"the switched observer's estimate of {state_of[fname]} for this sample (its state before the update)")
        elif fname == "y_hat":
            f.update(name=f"{config.output_name}_hat", target=f"{config.output_name}_hat", format=_fmt(w, est.state_frac),
                     meaning=f"C(mode) x_hat: the estimated output {config.output_name}")
        elif fname == "mode_index":
            f.update(target="mode", format=_fmt(w, 0, False, 1.0, 1.0),
                     meaning="the detected mode minus 1: argmin over the modes of the window sum of squared residuals, "
                             "ties to the lowest mode (numpy.argmin); physical mode = 1 + code")
        else:
            f["meaning"] = ("1: a state of the bank or of the switched observer saturated in this sample's update "
                            "(the error bound does not hold from then on)")
        out_fields.append(f)
        lsb += w
    plist = port_list(top, ports)
    for p in plist:
        if p["role"] == "in.payload":
            p["fields"] = in_fields
        elif p["role"] == "out.payload":
            p["fields"] = out_fields
    rst = f"~{nm['reset']}" if ports == "axis" else nm["reset"]
    serial = getattr(top, "architecture", "parallel") == "serial"
    flow = {
        "advance": f"~{nm['out.valid']} | {nm['out.ready']}",
        nm["in.ready"]: "advance",
    }
    if serial:
        cps = int(top.ii)
        flow = {
            "advance": f"~{nm['out.valid']} | {nm['out.ready']} (the output register can take a result)",
            nm["in.ready"]: f"the row unit is idle, or in its last step ({cps - 1}) and advance holds: one transfer every "
                            f"{cps} clocks at most (II = cycles_per_sample = {cps}); the last step waits while advance is low",
        }
    return {
        "ports": plist,
        "clock": {"port": nm["clock"], "edge": "rising"},
        "reset": {"port": nm["reset"], "polarity": "low" if ports == "axis" else "high", "kind": "synchronous"},
        "latency": int(top.latency), "ii": int(top.ii),
        "flow_control": {
            **flow,
            "reset": f"{nm['reset']}: synchronous, active {'low' if ports == 'axis' else 'high'} (the design resets while "
                     f"{rst} is 1); clears the valid bit, every observer state and the window sums (the estimator starts at 0)",
            "latency": f"a transfer on the input stream in cycle t gives {nm['out.valid']} with its result in cycle t + {int(top.latency)} "
                       f"when {nm['out.ready']} stays high; every transfer yields one output (no warm-up)",
        },
    }


def _estimator_block(est, config: SwitchedEstimatorConfig, top) -> dict:
    d = est.to_dict()
    return {
        **{k: d[k] for k in ("kind", "modes", "states", "window", "formats", "state_bound", "residual_gain",
                             "contraction_inf_norm", "error_bound")},
        "input_headroom": float(2 ** (est.input_bits - 1) * 2.0 ** -est.input_frac),
        "state_may_saturate": bool(est.state_may_saturate),
        "signals": {"input": config.input_name, "output": config.output_name, "states": list(config.state_names)},
        "coefficients": {"frac": int(est.coef_frac), "F": est.f_codes.tolist(), "G": est.g_codes.tolist(),
                         "L": est.l_codes.tolist(), "H": est.h_codes.tolist(),
                         "meaning": "codes with frac fraction bits (half up) of F_i = A_i - K_i C_i, G_i = B_i, L_i = K_i, H_i = C_i"},
        "widths": {k: int(v) for k, v in top.widths.items()},
        "cycles_per_sample": int(top.ii), "ii": int(top.ii), "warmup_samples": 0,
        "architecture": getattr(top, "architecture", "parallel"),
        **({"schedule": top.schedule} if hasattr(top, "schedule") else {}),
        "detector": {"select": "min", "tie_rule": "lowest mode (numpy.argmin)", "compare_tree": "pwas_hdl.hdl.argmax.ArgmaxStage",
                     "scores": "window sums of the squared residuals r_i = y - C_i x_i of the bank"},
        "bit_true": "pwas_hdl.fixedpoint.observer_bank.FixedPointSwitchedEstimator",
        "float_reference": "pwas_hdl.systems.switched_observer.run_switched_observer (bank 'practical') at the represented signals",
    }


def _rate(man: dict) -> str:
    if man["ii"] == 1:
        return "one sample per clock"
    sch = man["estimator"]["schedule"]
    units = "one unit" if sch["lanes"] == 1 else f"{sch['lanes']} units (lanes)"
    return (f"one sample every {man['ii']} clocks: serial architecture, every row of the estimator on {units} of "
            f"{sch['row_unit_multipliers']} variable multipliers")


def _header(man: dict, config_sha: str) -> str:
    from pwas_hdl.design.generate import _port_meaning  # what each port does, as in the PWAS designs' header

    e = man["estimator"]
    f, eb = e["formats"], e["error_bound"]
    lines = [f"{man['top']}: seed 003 switched-observer estimator generated by pwas-hdl {__version__} -- do not edit, regenerate",
             f"estimator.json SHA-256 {config_sha}",
             f"{e['modes']} modes, {e['states']} states ({', '.join(e['signals']['states'])}), detector window {e['window']}: "
             "bank of per-mode observers with output injection, argmin of the residual window sums (ties to the lowest mode), "
             "switched observer",
             f"latency {man['latency_cycles']} cycle{'s' if man['latency_cycles'] != 1 else ''}, II {man['ii']} "
             f"({_rate(man)}), no warm-up",
             f"inputs s{f['input_bits']}.{f['input_frac']} (physical), states s{f['state_bits']}.{f['state_frac']} (saturating), "
             f"coefficients {f['coef_frac']} fraction bits",
             f"|x_hat - float| <= {eb['state']!r}, |y_hat - float| <= {eb['y_hat']!r} where the modes agree; the modes agree "
             f"wherever the float detector's margin exceeds 2 * {eb['window_sum']!r}",
             "ports:"]
    for prt in man["ports"]:
        d = "in " if prt["direction"] == "input" else "out"
        lines.append(f"  {prt['name']:<14} {d} {prt['width']:>4}  {_port_meaning(man, prt['role'])}")
        for fl in prt.get("fields", []):
            what = fl.get("meaning") or ""
            fm = fl.get("format")
            if fm is not None:
                what = f"{fm['str']}" + (f", physical = {fm['offset']!r} + code" if fm.get("offset") else "") + (f"; {what}" if what else "")
            lines.append(f"      [{fl['lsb'] + fl['width'] - 1}:{fl['lsb']}] {fl['name']}: {what}".rstrip())
    return "".join(f"// {ln}".rstrip() + "\n" for ln in lines) + "\n"


def _bound_text(v) -> str:
    """A state / y_hat bound, or why there is none (``max_i ||A_i - K_i C_i||_inf >= 1``: no contraction to sum)."""
    return f"{v:.4g}" if v is not None else "(no bound: max_i ||A_i - K_i C_i||_inf >= 1)"


def _report(man: dict) -> str:
    e = man["estimator"]
    f, eb = e["formats"], e["error_bound"]
    rows = []
    for p in man["ports"]:
        fl = ", ".join(f"{x['name']} [{x['lsb'] + x['width'] - 1}:{x['lsb']}]" for x in p.get("fields", [])) or "-"
        rows.append(f"| `{p['name']}` | {p['direction']} | {p['width']} | {fl} |")
    return "\n".join([
        f"# {man['top']}: seed 003 switched-observer estimator generated by pwas-hdl {__version__}", "",
        f"{e['modes']} modes, {e['states']} states ({', '.join(e['signals']['states'])}), input `{e['signals']['input']}`, "
        f"output `{e['signals']['output']}`, detector window {e['window']}.", "",
        "## Interface", "",
        f"- Clock `{man['clock']['port']}` (rising edge), reset `{man['reset']['port']}` ({man['reset']['kind']}, active "
        f"{man['reset']['polarity']}); the reset clears every observer state and window sum.",
        f"- Latency **{man['latency_cycles']} cycle{'s' if man['latency_cycles'] != 1 else ''}**, II **{man['ii']}** "
        f"({_rate(man)}), one output per input "
        "transfer, valid/ready backpressure on both streams.", "",
        "| port | dir | width | fields (LSB first) |", "|---|---|---|---|", *rows, "",
        "## Formats and bounds", "",
        f"Inputs s{f['input_bits']}.{f['input_frac']} (physical u, y; saturated), states s{f['state_bits']}.{f['state_frac']} "
        f"(saturating; flagged by `state_saturated`), coefficients with {f['coef_frac']} fraction bits.", "",
        f"Against the float estimator at the represented inputs: residuals within {eb['residual']:.4g}, window sums within "
        f"{eb['window_sum']:.4g}; the detected mode equals the float one wherever the float margin exceeds "
        f"{2 * eb['window_sum']:.4g}; with equal modes |x_hat - float| <= {_bound_text(eb['state'])} and |y_hat - float| <= "
        f"{_bound_text(eb['y_hat'])} (unless a state saturates).", "",
        (f"States within +-{e['state_bound']:.4g} for every input code and every sequence of detected modes (invariant box of "
         "the quantised arithmetic): the states never saturate." if not e["state_may_saturate"] else
         f"**The states may saturate** (`estimator.state_may_saturate`): s{f['state_bits']}.{f['state_frac']} does not hold "
         "a proven bound of the switched observer's states (narrower than the bound, or no invariant box: the modes' |F_i| "
         "have no common contraction); `state_saturated` flags each sample where one did."), "",
        "## Files", "", *[f"- `{v}`" for k, v in sorted(man["files"].items()) if isinstance(v, str)], ""])


def build_estimator_design(model: SwitchedEstimatorConfig | str | os.PathLike, *, design: str = "core", name: str | None = None,
                           ports: str = "axis", progress: Any = None, executor: Any = None, timing_seed: int = 1,
                           prescreen: bool = True, fpga_target: str = "ecp5", architecture: str = "parallel",
                           bank_lanes: int | None = None, **options: Any) -> GeneratedDesign:
    """Build the estimator's folder in memory (called by :func:`pwas_hdl.design.generate.build_design`).

    Parameters
    ----------
    model : SwitchedEstimatorConfig or the path of an estimator file
    design : str
        Any of ``generate``'s default values or ``"estimator"``: the file has one design.
    name : str, optional
        Verilog module name (default ``pwas_estimator``).
    ports : {"axis", "amaranth"}
    progress, executor, timing_seed, prescreen, fpga_target
        Accepted and ignored (the estimator design has no timing closure).
    architecture : {"parallel", "serial"}
        ``parallel`` (default): :class:`~pwas_hdl.hdl.switched_estimator_top.SwitchedEstimatorTop`, every
        row its own constant multipliers, one sample per clock (II 1, latency 1). ``serial``:
        :class:`~pwas_hdl.hdl.switched_estimator_top.SerialSwitchedEstimatorTop`, every row on one unit
        of ``n + 2`` variable multipliers and a squarer (per lane), II = ``s + s n + 2 + n`` clocks (one lane), latency II + 1;
        bit-exact with parallel, for FPGAs without enough multipliers (LFE5U-45F, iCE40).
    bank_lanes : int, optional
        Serial only: row units ``1 .. s`` sharing the bank's modes (default 1); lane 0 also runs the
        switched observer. II = ``max(s_0 + s_0 n, s_0 + d + 3) + 1 + n + d`` with ``s_0 = ceil(s / L)``.
    **options
        :data:`ESTIMATOR_OPTIONS`; the PWAS options of ``generate`` are refused unless they have
        their default value (they have no meaning here).

    Returns
    -------
    pwas_hdl.design.generate.GeneratedDesign
        ``model`` is the bit-true estimator, ``component`` the Amaranth top.

    Raises
    ------
    InputError
        A ``design`` other than ``core`` / ``sensor`` / ``estimator``, a PWAS option with a
        non-default value, an unknown option, ``ports`` or ``architecture``, ``bank_lanes``
        without ``serial`` or out of range, a bad module name, or as :func:`fixed_point_estimator`.
    """
    from pwas_hdl.design.generate import GeneratedDesign, _fusesoc, _instance, design_hash
    from pwas_hdl.design.manifest import build_estimator_manifest, manifest_text
    from pwas_hdl.hdl.names import check_module_name
    from pwas_hdl.hdl.emit import emit_verilog
    from pwas_hdl.hdl.switched_estimator_top import SerialSwitchedEstimatorTop, SwitchedEstimatorTop

    if design not in ("core", "sensor", "estimator"):
        raise InputError(f"an estimator file has one design (the estimator top); --design {design} does not apply")
    given = {k: v for k, v in options.items() if k in _PWAS_DEFAULTS and v != _PWAS_DEFAULTS[k]}
    if given:
        k = sorted(given)[0]
        opt = "--clock-mhz" if k == "target_mhz" else "--" + k.replace("_", "-")  # the generate option of API name k
        takes = ["--name", "--ports", "--architecture", "--bank-lanes"] + ["--" + o.replace("_", "-") for o in ESTIMATOR_OPTIONS]
        raise InputError(f"{opt} {given[k]!r} belongs to the PWAS designs; the estimator file takes "
                         f"{', '.join(takes[:-1])} and {takes[-1]} only")
    unknown = set(options) - set(_PWAS_DEFAULTS) - set(ESTIMATOR_OPTIONS)
    if unknown:
        raise InputError(f"unknown option(s) {sorted(unknown)} for an estimator design; known: {', '.join(ESTIMATOR_OPTIONS)}")
    if ports not in ("axis", "amaranth"):
        raise InputError(choice_text(option_text("ports"), ("axis", "amaranth"), ports))
    if architecture not in ESTIMATOR_ARCHITECTURES:
        raise InputError(choice_text(option_text("architecture"), ESTIMATOR_ARCHITECTURES, architecture))
    if bank_lanes is not None and architecture != "serial":
        raise InputError("--bank-lanes applies to --architecture serial only")
    if name is not None:
        check_module_name(name)
    config = load_estimator_config(model)
    top_name = name or "pwas_estimator"
    est_opts = {k: options.get(k) for k in ESTIMATOR_OPTIONS}
    est = fixed_point_estimator(config, **est_opts)
    comp = (SwitchedEstimatorTop(est) if architecture == "parallel"
            else SerialSwitchedEstimatorTop(est, lanes=1 if bank_lanes is None else bank_lanes))  # InputError: lanes out of range
    info = estimator_info(comp, config, ports)
    files = {"verilog": f"{top_name}.v", "model": ESTIMATOR_FILE, "manifest": "manifest.json", "report": "report.md",
             "instance_template": f"{top_name}_inst.v", "fusesoc_core": f"{top_name}.core", "hex": []}
    gen_opts = {"design": "estimator", "ports": ports, **est_opts}
    if architecture != "parallel":  # the parallel folder's options are unchanged (byte-identical reruns of old folders)
        gen_opts["architecture"] = architecture
    if bank_lanes is not None:
        gen_opts["bank_lanes"] = bank_lanes
    man = build_estimator_manifest(top_name, info, files, gen_opts, _estimator_block(est, config, comp))
    cfg_text = estimator_text(config)
    cfg_sha = hashlib.sha256(cfg_text.encode("utf-8")).hexdigest()
    verilog = _header(man, cfg_sha) + emit_verilog(comp, top_name, ports=ports)
    man["design_hash"] = design_hash({files["verilog"]: verilog, ESTIMATOR_FILE: cfg_text})
    texts = {files["verilog"]: verilog, ESTIMATOR_FILE: cfg_text, "manifest.json": manifest_text(man), "report.md": _report(man),
             files["instance_template"]: _instance({**man, "memory": {}}, f"{ESTIMATOR_FILE} SHA-256 {cfg_sha}"), files["fusesoc_core"]: _fusesoc(man, "inline")}
    return GeneratedDesign(top_name, texts, man, est, comp)
