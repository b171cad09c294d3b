"""Recurrent sensors (issue 13) in the three-tank bench: rows for the dynamical PWAS and the PWAS
approximations of the observer maps (27)/(28) run recurrently (float, bit-true, RTL), and the
Lorenz sensor with Mz = 1, 2 beside the plain one.

Protocol (every choice is written into the result file's ``config.recurrent``):

* *map sensors* ``pwas-map-27`` / ``pwas-map-28``: :func:`pwas_hdl.fit.map_approximation.fit_map`
  of the one-step maps over the admissible levels of the training runs, ``[0, 25]`` for ``y`` and
  the state, ``[0, 2]`` for ``u1`` (27 is affine in ``u1``: one interval); ``p = 32`` per level
  (``--quick``: 16); run from the paper's initial states ``z(0) = (5, 2)`` (A4); the estimate of
  ``x(t)`` is the state after ``t`` steps, as for the paper's sensors;
* *dynamical PWAS* ``pwas-dyn``: the lag-window configuration chosen for the target plus
  ``Mz = 1``, fitted series-parallel on the training runs and refined on the closed-loop error
  (``refine = 3``), started from the same ``z(0)`` as the paper's sensors;
* *bit-true* of a recurrent sensor: 16-bit inputs (the fed-back state is requantised every
  step; 12 bits are reported too for the map-28 sensor), other formats by default;
* *RTL*: Icarus replay (cocotb, ``sim/pwas_recurrent_tb.py``) of the noise-free run 0, the RTL's
  own output codes (the bench also checks them against the bit-true model: ``rtl_mismatches``);
  ``--quick``: the map sensors only;
* *Lorenz*: the data of eq. (18) (6000 training samples, 2000 test samples after them, seed =
  run), RMSEE against the noise-free ``z``: plain ``My = 4, p = 7`` (Table II), plain ``My = 2``,
  and ``My = 2`` with ``Mz = 1, 2`` (``p = 7``, sigma by 5-fold CV, refine 3, initial state the
  training mean).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from pwas_hdl import bench_results as br
from pwas_hdl.benchmarks.bench_common import QUICK_SIGMA_GRID, rmse
from pwas_hdl.fit.map_approximation import fit_map, recurrent_sensor_from_map
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
from pwas_hdl.systems.decoupled_observer import observer_map_27, observer_map_28
from pwas_hdl.systems.three_tank import three_tank_paper_run, three_tank_training_runs

__all__ = ["map_sensors", "recurrent_rows", "lorenz_rows", "Z0"]

Z0 = {"x1": 5.0, "x3": 2.0}
LEVELS = (0.0, 25.0)
REC_BITS = 16


def map_sensors(p: int = 32) -> dict:
    """The recurrent PWAS sensors of maps (27) (x1) and (28) (x3), with their approximation errors."""
    a27 = fit_map(lambda x: observer_map_27(x[:, 0], x[:, 1], x[:, 2]), ([0.0, LEVELS[0], LEVELS[0]], [2.0, LEVELS[1], LEVELS[1]]),
                  [1, p, p])
    a28 = fit_map(lambda x: observer_map_28(x[:, 0], x[:, 1]), ([LEVELS[0]] * 2, [LEVELS[1]] * 2), p)
    return {"x1": (recurrent_sensor_from_map(a27, ["u1"], ["y"], ["x1"], [Z0["x1"]]), a27.errors, "pwas-map-27", f"[1, {p}, {p}]"),
            "x3": (recurrent_sensor_from_map(a28, [], ["y"], ["x3"], [Z0["x3"]]), a28.errors, "pwas-map-28", f"[{p}, {p}]")}


def _lead_trace(zrows: np.ndarray, z0: float, T: int) -> np.ndarray:
    """Estimates of x(0..T-1) from a lead-1 sensor: z0, then row t-1 for x(t)."""
    out = np.empty(T)
    out[0] = z0
    out[1:] = zrows[: T - 1]
    return out


def _pad(zrows: np.ndarray, start: int, T: int) -> np.ndarray:
    out = np.full(T, np.nan)
    out[start:] = zrows
    return out


def recurrent_rows(runs: int, quick: bool, train_runs: int, samples: int, chosen: dict, windows: dict,
                   say: Callable[[str], None], simulator: str = "icarus") -> tuple[list[dict], dict, dict]:
    """Rows of the recurrent sensors of x1 and x3 on the noise-free paper run; also traces and config."""
    from pwas_hdl.verify.recurrent_replay import build_recurrent_design, replay

    p = 16 if quick else 32
    maps = map_sensors(p)
    designs = {t: build_recurrent_design(s, input_bits=REC_BITS, name=f"rec_{t}") for t, (s, *_r) in maps.items()}
    design12 = build_recurrent_design(maps["x3"][0], input_bits=12, name="rec_x3_12")
    vals: dict[tuple, list[float]] = {}
    extra: dict = {"rtl": {}}
    traces: dict = {}
    grid = QUICK_SIGMA_GRID if quick else None
    for r in range(runs):
        say(f"recurrent sensors: run {r + 1}/{runs}")
        test = three_tank_paper_run(samples, seed=r, noise=0.0)
        train = three_tank_training_runs(train_runs, samples, seed=1000 * (r + 1), noise=0.0).runs()
        for tgt, col in (("x1", 0), ("x3", 1)):
            truth = test.z_true[:, col]
            s, _err, name, _ = maps[tgt]
            u = test.u[:, :1] if s.lags_.nu else None
            est = {(name, "float"): _lead_trace(s.predict(u, test.y)[:, 0], Z0[tgt], samples),
                   (name, "bittrue"): _lead_trace(designs[tgt].rmodel.predict(u, test.y)[:, 0], Z0[tgt], samples)}
            if tgt == "x3":
                est[(name + "-12bit", "bittrue")] = _lead_trace(design12.rmodel.predict(None, test.y)[:, 0], Z0[tgt], samples)
            cfg = chosen[tgt]
            dyn = PWASVirtualSensor(mu=cfg.mu, my=cfg.my, partitions=cfg.p, gamma=cfg.gamma, mz=1, refine=3,
                                    initial_state=[Z0[tgt]], sigma_grid=grid, input_names=["u1"] if cfg.mu else None,
                                    output_names=["y"], target_names=[tgt])
            dyn.fit([d.u[:, :1] for d in train] if cfg.mu else None, [d.y for d in train], [d.z[:, col:col + 1] for d in train])
            start = dyn.lags_.memory - 1
            du = test.u[:, :1] if cfg.mu else None
            ddes = build_recurrent_design(dyn, input_bits=REC_BITS, name=f"dyn_{tgt}")
            est[("pwas-dyn", "float")] = _pad(dyn.predict(du, test.y)[:, 0], start, samples)
            est[("pwas-dyn", "bittrue")] = _pad(ddes.rmodel.predict(du, test.y)[:, 0], start, samples)
            extra.setdefault(("pwas-dyn", tgt, "fit"), []).append(dyn.recurrence_fit_)
            if r == 0:
                for nm, des, lead in ((name, designs[tgt], True),) + ((("pwas-dyn", ddes, False),) if not quick else ()):
                    uu = du if nm == "pwas-dyn" else u
                    codes = des.rmodel.quantize_signals(uu, test.y)
                    rr = replay(des, codes, simulator, runs=[{"name": "paper-run", "p_valid": 1.0, "p_ready": 1.0, "seed": 0,
                                                              "segments": [{"rows": (0, codes.shape[0]), "record": True}]}])
                    zr = des.rmodel.fxm.to_physical_output(rr["rtl_out"])[:, 0] if rr["rtl_out"] is not None else None
                    extra["rtl"][f"{tgt}/{nm}"] = {"passed": rr["passed"], "mismatches": rr["mismatches"],
                                                   "outputs": int(len(rr["rtl_out"]) if rr["rtl_out"] is not None else 0),
                                                   "latency": des.latency, "ii": des.ii, "simulator": simulator,
                                                   "wall_s": rr["wall_s"]}
                    if zr is not None and len(zr) == codes.shape[0] - des.top.warmup:
                        est[(nm, "rtl")] = _lead_trace(zr, Z0[tgt], samples) if lead else _pad(zr, start, samples)
                traces[tgt] = {k[0] + ("" if k[1] == "float" else "_" + k[1]): v for k, v in est.items()}
            for (nm, stage), z in est.items():
                for wname, w in windows.items():
                    vals.setdefault((tgt, nm, stage, wname), []).append(rmse(z - truth, w & np.isfinite(z)))
    rows = []
    for (tgt, nm, stage, wname), v in vals.items():
        cfg = {"window": wname, "noise_y": 0.0, "test": "paper run (x0 = (8, 2, 1), rho from t = 100, T = 1000)", "z0": Z0[tgt]}
        if nm.startswith("pwas-map"):
            s, err, _, parts = maps[tgt]
            cfg |= {"map": "eq. 27" if tgt == "x1" else "eq. 28", "partitions": parts, "box": "levels [0, 25], u1 [0, 2]",
                    "map_max_error": err["max"][0], "map_rms_error": err["rms"][0], "Mz": 1}
        else:
            c = chosen[tgt]
            cfg |= {"Mu": c.mu, "My": c.my, "Mz": 1, "p": c.p, "refine": 3, "train_runs": train_runs}
        if stage != "float":
            cfg["input_bits"] = 12 if nm.endswith("12bit") else REC_BITS
        if stage == "rtl":
            info = extra["rtl"][f"{tgt}/{nm}"]
            cfg |= {"simulator": info["simulator"], "rtl_mismatches": info["mismatches"], "latency": info["latency"],
                    "ii": info["ii"], "run": 0}
        rows.append(br.row_from_values("three-tank", tgt, nm, stage, "rmse", v, None, cfg))
    conf = {"map_partitions": p, "rec_input_bits": REC_BITS, "rtl": extra["rtl"],
            "dyn_fit": {t: [{k: (np.asarray(v).tolist() if k in ("closed_loop_rmse", "series_parallel_rmse",
                                                                   "series_parallel_closed_loop_rmse") else v)
                             for k, v in f.items() if k != "refine"} for f in extra[("pwas-dyn", t, "fit")]]
                        for t in ("x1", "x3")}}
    return rows, traces, conf


def lorenz_rows(runs: int, quick: bool, say: Callable[[str], None]) -> tuple[list[dict], dict]:
    """Lorenz (eq. 18): the plain sensor beside Mz = 1, 2 (float and bit-true RMSEE)."""
    from pwas_hdl.fixedpoint.bittrue import FixedPointModel
    from pwas_hdl.fixedpoint.recurrence import RecurrentFixedPointModel
    from pwas_hdl.systems.lorenz import lorenz

    n_train, n_test = (2000, 1000) if quick else (6000, 2000)
    configs = [("plain My=4", 4, 0), ("plain My=2", 2, 0), ("dyn My=2 Mz=1", 2, 1), ("dyn My=2 Mz=2", 2, 2)]
    if quick:
        configs = [configs[1], configs[2]]
    grid = QUICK_SIGMA_GRID if quick else None
    vals: dict[tuple, list[float]] = {}
    fits: dict[str, list] = {}
    for r in range(runs):
        say(f"lorenz Mz: run {r + 1}/{runs}")
        d = lorenz(n_train + n_test, seed=r)
        tr_y, tr_z, te_y, te_z = d.y[:n_train], d.z[:n_train], d.y[n_train:], d.z_true[n_train:]
        for label, my, mz in configs:
            m = PWASVirtualSensor(my=my, partitions=7, gamma=1.2, mz=mz, refine=3 if mz else 0, sigma_grid=grid,
                                  output_names=["y"], target_names=["z"])
            m.fit(None, tr_y, tr_z)
            start = m.lags_.memory - 1
            zf = m.predict(None, te_y)[:, 0]
            if mz:
                zb = RecurrentFixedPointModel(FixedPointModel.from_sensor(m, input_bits=REC_BITS), m.lags_,
                                              m.initial_values_).predict(None, te_y)[:, 0]
                fits.setdefault(label, []).append({"closed_loop_rmse_train": float(m.recurrence_fit_["closed_loop_rmse"][0]),
                                                   "series_parallel_rmse_train": float(m.recurrence_fit_["series_parallel_rmse"][0]),
                                                   "refinements_kept": int(m.recurrence_fit_["iterations_used"])})
            else:
                xi, _ = m.regressors(None, te_y)
                zb = FixedPointModel.from_sensor(m).predict(xi)[:, 0]
            truth = te_z[start:, 0]
            vals.setdefault((label, "float", my, mz), []).append(rmse(zf - truth))
            vals.setdefault((label, "bittrue", my, mz), []).append(rmse(zb - truth))
    rows = [br.row_from_values("lorenz", "z", "pwas" if mz == 0 else "pwas-dyn", stage, "rmse", v, None,
                               {"label": label, "My": my, "Mz": mz, "p": 7, "gamma": 1.2, "train": n_train, "test": n_test,
                                "refine": 3 if mz else 0, **({"input_bits": REC_BITS if mz else 12} if stage == "bittrue" else {})})
            for (label, stage, my, mz), v in vals.items()]
    return rows, {"lorenz_fits": fits, "lorenz_samples": [n_train, n_test]}
