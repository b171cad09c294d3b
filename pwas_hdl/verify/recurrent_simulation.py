"""``pwas-hdl simulate`` of a recurrent design (issue 13): the CSV replay through the recurrent top.

A folder that ``generate --design sensor`` wrote for a recurrent model (manifest ``design`` =
``"recurrent"``, see :mod:`pwas_hdl.design.recurrent`) is replayed by the cocotb bench
``sim/pwas_recurrent_tb.py`` on Icarus or Verilator, driven from the manifest (ports, reset
polarity, latency, II, warm-up, bit fields). Each trajectory of the data is one segment after a
reset (the feedback registers restart from the reset state codes). Expected words come from the
bit-true recurrence (:class:`~pwas_hdl.fixedpoint.recurrence.RecurrentFixedPointModel`,
rebuilt from ``model.json`` and the generate options); the float column is the model's own
recurrence (:meth:`PWASVirtualSensor.predict <pwas_hdl.fit.virtual_sensor.PWASVirtualSensor.predict>`).

Checks (``summary["checks"]``; the CLI exits with status 1 when one fails): every output word
equals the bit-true recurrence's (exact), none missing or extra, ``out.valid`` low after a reset,
and at full speed (``--stall 0``) every latency equals the manifest's and samples are accepted
exactly every II cycles. The deviation from the float recurrence is measured and reported, not
checked: the per-step error bound of the manifest does not bound a recurrence (the errors of
each step are fed back; :mod:`pwas_hdl.fixedpoint.recurrence`).

The native Verilator engine (``--engine native``) drives the feed-forward designs only; it is
refused here with a plain message.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Callable

import numpy as np

from pwas_hdl.errors import InputError
from pwas_hdl.fixedpoint.bitfields import pack_fields, unpack_fields
from pwas_hdl.verify.segment_bench import replay_segments, replay_summary, rmse, segment_job_ports

__all__ = ["recurrent_job_ports", "recurrence_words", "simulate_recurrent"]


def recurrence_words(rmodel: Any, codes: np.ndarray, in_fields: list[dict],
                     out_fields: list[dict]) -> tuple[list[int], list[int], dict]:
    """Packed input words, the expected packed output words and the bit-true run of one trajectory
    of a recurrent top from reset (the one packing of ``simulate``, the replay API and
    ``export-testbench``).

    Parameters
    ----------
    rmodel : RecurrentFixedPointModel
        The bit-true recurrence (:func:`pwas_hdl.design.recurrent.recurrent_model`).
    codes : ndarray of int, shape (T, S)
        Payload codes, one row per input transfer (:meth:`RecurrentFixedPointModel.quantize_signals`).
    in_fields, out_fields : list of dict
        Bit fields of the input payload (one code per signal) and of the output payload (one code
        per target, then ``out_of_range``).

    Returns
    -------
    ins : list of int
        ``T`` packed input words.
    outs : list of int
        ``T - M + 1`` packed expected output words (none during the warm-up).
    run : dict
        :meth:`RecurrentFixedPointModel.run`'s result (``out`` (R, nz), ``out_of_range`` (R,)).
    """
    run = rmodel.run(codes)
    ins = [pack_fields([int(v) for v in row], in_fields) for row in np.asarray(codes)]
    outs = [pack_fields([int(v) for v in o] + [int(f)], out_fields) for o, f in zip(run["out"], run["out_of_range"])]
    return ins, outs, run


def recurrent_job_ports(manifest: dict) -> dict:
    """The port names of the recurrent bench's job, from the manifest's roles and reset polarity.

    Parameters
    ----------
    manifest : dict
        The recurrent design's manifest.

    Returns
    -------
    dict
        As :func:`~pwas_hdl.verify.segment_bench.segment_job_ports` with ``warm``.
    """
    return segment_job_ports(manifest, warm=True)


def simulate_recurrent(design: Any, table: Any, output: str | Path, spath: Path, outset: Any, *, simulator: str,
                       engine: str, traj_col: str | None, stall: float, seed: int, cache_dir: Any, waves: bool,
                       say: Callable[[str], None]) -> dict:
    """Replay ``table`` through the recurrent design (called by :func:`pwas_hdl.verify.simulation.simulate_data`).

    Parameters
    ----------
    design : pwas_hdl.verify.simulation.Design
        A folder whose manifest's design is ``"recurrent"``.
    table : pwas_hdl.io.csv_table.Table
        The data (the model's input/output columns; a ``TARGET_true`` or ``TARGET`` column is the
        reference of the RMSEE, compared ``lead`` rows later).
    output, spath : paths of the CSV and the JSON summary (registered in ``outset``)
    outset : pwas_hdl.io.atomic.OutputSet
        Both files are written together, or neither.
    simulator, engine, traj_col, stall, seed, cache_dir, waves, say : as ``simulate_data``

    Returns
    -------
    dict
        As :func:`~pwas_hdl.verify.simulation.simulate_data`: ``summary``, ``summary_path``,
        ``output``, ``result`` (the bench's raw result), ``rows`` (m,), ``estimates`` (m, nz).

    Raises
    ------
    InputError
        ``--engine native``, or a trajectory shorter than the lags.
    CheckFailed
        The RTL did not produce every output (nothing is written).
    """
    from pwas_hdl.design.recurrent import estimate_rows, recurrent_model
    from pwas_hdl.io.csv_table import check_trajectory_column, format_csv, split_trajectories
    from pwas_hdl.verify.simulation import _checks, _json_default

    if engine != "cocotb":
        raise InputError("--engine native drives the feed-forward designs only; simulate a recurrent design with "
                         "--engine cocotb (the recurrent bench sim/pwas_recurrent_tb.py)")
    man, sensor, fxm = design.manifest, design.sensor, design.model
    rm = recurrent_model(sensor, fxm)
    ins, outs, tgts = sensor.signal_names()
    lags = sensor.lags_
    lead = int(man["recurrence"]["lead"])
    in_fields, out_fields = design.in_fields, design.out_fields
    if [f["name"] for f in in_fields] != list(rm.signals):
        raise InputError(f"{design.outdir}: the input fields {[f['name'] for f in in_fields]} are not the model's signals "
                         f"{rm.signals}; regenerate the folder with `pwas-hdl generate`")
    check_trajectory_column(table, traj_col, [*ins, *outs], tgts)
    u_all = table.numeric(ins) if lags.nu and lags.mu else None
    y_all = table.numeric(outs) if lags.ny and lags.my else None
    m_hist = max(lags.memory, 1)
    segs = []  # per trajectory: words, expected words, bit-true codes, flags, float, data rows
    for sl in split_trajectories(table, traj_col):
        if sl.stop - sl.start < m_hist:
            raise table.short_trajectory(sl, m_hist, "the lags need", traj_col)
        u = u_all[sl] if u_all is not None else None
        y = y_all[sl] if y_all is not None else None
        codes = rm.quantize_signals(u, y)
        words, exp, res = recurrence_words(rm, codes, in_fields, out_fields)
        zf = np.asarray(sensor.predict(u, y), dtype=float).reshape(-1, len(tgts))
        rows, has_ref = estimate_rows(sl.start, sl.stop, lags, lead)
        segs.append({"words": words, "expected": exp, "bt": res["out"], "bt_oor": res["out_of_range"], "float": zf,
                     "rows": rows, "has_reference": has_ref, "stop": sl.stop})
    n = int(sum(len(s["expected"]) for s in segs))
    say(f"simulating {n} samples of {table.path} through the recurrent {design.top} on {simulator} (cocotb) ...")
    rep = replay_segments(design.verilog_path, design.top,
                          [{"words": s["words"], "expected": s["expected"], "drain": True, "hold": 0, "record": True} for s in segs],
                          ports=recurrent_job_ports(man), latency=design.latency, ii=int(man["ii"]), warmup=design.warmup,
                          simulator=simulator, stall=stall, seed=seed, cache_dir=cache_dir, waves=waves, output=output,
                          outset=outset, files=design.runtime_files, prefix="pwas-rsim")
    raw, rsegs = rep.raw, rep.segments
    nz = fxm.nz
    dec = [np.array([unpack_fields(w, out_fields) for w in r["words"]], dtype=np.int64).reshape(-1, nz + 1) for r in rsegs]
    hw = np.concatenate([d[:, :nz] for d in dec]) if dec else np.empty((0, nz), dtype=np.int64)
    oor = np.concatenate([d[:, nz] for d in dec]).astype(bool) if dec else np.empty(0, dtype=bool)
    bt = np.concatenate([s["bt"] for s in segs])
    bt_oor = np.concatenate([s["bt_oor"] for s in segs]).astype(bool)
    zf = np.concatenate([s["float"] for s in segs])
    row = np.concatenate([s["rows"] for s in segs])
    mism = np.any(hw != bt, axis=1) | (oor != bt_oor)
    zhw, zbt = fxm.to_physical_output(hw), fxm.to_physical_output(bt)
    cols: dict[str, Any] = {"row": row, "estimate_of_row": row + lead}
    for i, t in enumerate(tgts):
        cols[f"{t}_hw"], cols[f"{t}_bittrue"], cols[f"{t}_float"] = zhw[:, i], zbt[:, i], zf[:, i]
    cols["out_of_range"] = oor
    cols["mismatch"] = mism
    e_float = np.abs(zhw - zf)
    targets = {}
    for i, t in enumerate(tgts):
        entry: dict[str, Any] = {"max_error_vs_float_recurrence": float(e_float[:, i].max(initial=0.0)),
                                 "rms_error_vs_float_recurrence": rmse(zhw[:, i], zf[:, i])}
        ref = table.reference_column(t)
        if ref is not None:
            zt = table.numeric([ref])[:, 0]
            ok = np.concatenate([s["has_reference"] for s in segs])  # the reference row exists
            r_ok = row[ok] + lead
            entry.update(reference_column=ref, reference_rows=int(ok.sum()),
                         rmsee_hw=rmse(zhw[ok, i], zt[r_ok]), rmsee_bittrue=rmse(zbt[ok, i], zt[r_ok]),
                         rmsee_float=rmse(zf[ok, i], zt[r_ok]))
            if entry["rmsee_hw"] is not None and entry["rmsee_float"]:
                entry["rmsee_increase_hw_vs_float_percent"] = 100.0 * (entry["rmsee_hw"] / entry["rmsee_float"] - 1.0)
        targets[t] = entry
    first = None
    if mism.any():
        k = int(np.flatnonzero(mism)[0])
        first = {"row": int(row[k]), "expected": bt[k].tolist() + [int(bt_oor[k])], "actual": hw[k].tolist() + [int(oor[k])]}
    lsb = 2.0 ** -fxm.output_format.frac
    head, tail = replay_summary(rep, design=design, kind=design.kind, table=table, simulator=simulator, engine=engine,
                                samples=n, input_transfers=int(sum(len(s["words"]) for s in segs)), latency=design.latency,
                                ii=int(man["ii"]), stall=stall, process_seconds=True,
                                ii_note="cycles between accepted samples at full speed (one sample in flight: II = latency)")
    summary = {
        **head,
        "mismatches": int(mism.sum()),
        "first_mismatch": first,
        "out_of_range": int(oor.sum()),
        "output_lsb": lsb,
        "error_bound": float(man["error_bound"]["physical"]),
        "error_bound_lsb": float(man["error_bound"]["lsb"]),
        "error_bound_note": "per step of the circuit; not a bound over the recurrence (the deviation from the float "
                            "recurrence is measured: max_error_vs_float)",
        # what _checks reads: the recurrence has no bound against the float model, so none is checked
        "within_error_bound": True,
        "max_error_vs_float": float(e_float.max(initial=0.0)),
        "max_error_vs_float_lsb": float(e_float.max(initial=0.0) / lsb),
        "targets": targets,
        "recurrence": {"Mz": int(man["recurrence"]["Mz"]), "lead": lead,
                       "note": f"row t estimates z(t + {lead}); each trajectory starts after a reset from the reset state codes"},
        **tail,
    }
    summary["checks"] = _checks(summary, stall)
    outset.write_text(output, format_csv(cols))
    outset.write_text(spath, json.dumps(summary, indent=2, allow_nan=False, default=_json_default) + "\n")
    outset.commit()
    return {"summary": summary, "summary_path": str(spath), "output": str(output), "result": raw, "rows": row,
            "estimates": zhw}
