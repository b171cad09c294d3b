"""RTL replay of a recurrent sensor top (issue 13) on Icarus or Verilator, against the bit-true
recurrence (:class:`pwas_hdl.fixedpoint.recurrence.RecurrentFixedPointModel`).

:func:`build_recurrent_design` turns a recurrent :class:`~pwas_hdl.fit.virtual_sensor.PWASVirtualSensor`
(``Mz >= 1``, initial-state rule "value") into its bit-true model, the Amaranth top and its
Verilog; :func:`replay` runs the cocotb bench ``sim/pwas_recurrent_tb.py`` (cached builds, as
:mod:`pwas_runner`) over runs of segments -- each segment after a reset -- and returns the output
codes the RTL produced together with the checks (exact match, latency, II, reset).
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from pwas_hdl.fixedpoint.bitfields import unpack_fields
from pwas_hdl.verify.segment_bench import TEST_MODULE, count_outputs, plan_job_runs, standard_segment_runs

if TYPE_CHECKING:
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.hdl.params import Pipeline

__all__ = ["RecurrentDesign", "build_recurrent_design", "replay", "standard_recurrent_runs"]


@dataclass
class RecurrentDesign:
    """A recurrent sensor ready to simulate: bit-true model, RTL component, Verilog text.

    Attributes
    ----------
    rmodel : RecurrentFixedPointModel
        The bit-true recurrence the RTL implements.
    top : PWASRecurrentTop
        The Amaranth top (``latency``, ``ii`` in cycles, ``warmup`` in samples).
    verilog : str
        Its Verilog text.
    name : str
        The Verilog module name.
    in_fields, out_fields : list of dict
        Bit fields (``name``, ``lsb``, ``width``, ``signed``) of the input payload (one code per
        measured signal) and of the output payload (one code per target, then ``out_of_range``).
    """

    rmodel: Any  # RecurrentFixedPointModel
    top: Any  # PWASRecurrentTop
    verilog: str
    name: str
    in_fields: list
    out_fields: list

    @property
    def latency(self) -> int:
        """Latency of the RTL top in cycles."""
        return int(self.top.latency)

    @property
    def ii(self) -> int:
        """Initiation interval of the RTL top in cycles."""
        return int(self.top.ii)

    def words(self, codes: np.ndarray) -> tuple[list[int], list[int], np.ndarray]:
        """Packed input words, the expected packed output words and the output codes (R, nz).

        Parameters
        ----------
        codes : ndarray of int, shape (T, S)
            Payload codes of one trajectory from reset, one row per input transfer
            (:meth:`RecurrentFixedPointModel.quantize_signals`).

        Returns
        -------
        ins : list of int
            ``T`` packed input words (``in_fields``).
        outs : list of int
            ``R`` packed expected output words (``out_fields``): ``R = T - M + 1`` rows, none during
            the warm-up (as :meth:`RecurrentFixedPointModel.run`).
        out : ndarray of int, shape (R, nz)
            The bit-true output codes.
        """
        from pwas_hdl.verify.recurrent_simulation import recurrence_words

        ins, outs, res = recurrence_words(self.rmodel, codes, self.in_fields, self.out_fields)
        return ins, outs, res["out"]


def build_recurrent_design(sensor: PWASVirtualSensor, *, input_bits: int = 16, pipeline: Pipeline | str | None = None,
                           name: str = "pwas_recurrent_sensor", architecture: str = "parallel",
                           **formats: Any) -> RecurrentDesign:
    """Bit-true model, RTL top and Verilog of a recurrent sensor (``sensor.lags_.mz >= 1``).

    Parameters
    ----------
    sensor : PWASVirtualSensor
        Recurrent, initial-state rule "value" (the reset values of the feedback registers). Fitted
        with power-of-two ``breakpoints`` (a non-uniform partition), its bit-true model is the
        :class:`~pwas_hdl.fixedpoint.warp.WarpedFixedPointModel` and the warp goes in front of the
        core (as ``generate`` builds it).
    input_bits : int
        ``B_in`` in bits of every regressor dimension (default 16: the fed-back state is re-quantised
        every step, see :mod:`pwas_hdl.fixedpoint.recurrence`).
    pipeline : Pipeline or str, optional
        Pipeline registers of the core, or a preset name (as :func:`pwas_hdl.hdl.api.build_sensor`).
    name : str
        Verilog module name.
    architecture : {"parallel", "serial"}
        The core inside the top (:class:`~pwas_hdl.hdl.recurrent_top.PWASRecurrentTop`).
    **formats
        More :class:`~pwas_hdl.fixedpoint.bittrue.FixedPointModel` options.

    Returns
    -------
    RecurrentDesign
        The bit-true recurrence, the top, its Verilog and the payload fields.

    Raises
    ------
    InputError
        Not recurrent, a measured initial state, or lags of one signal in different formats
        (:func:`pwas_hdl.design.recurrent.recurrent_model`, as ``generate``).
    """
    from pwas_hdl.design.recurrent import recurrent_model
    from pwas_hdl.fixedpoint.bittrue import FixedPointModel
    from pwas_hdl.hdl.emit import emit_verilog
    from pwas_hdl.hdl.recurrent_top import build_recurrent_sensor
    from pwas_hdl.hdl.sensor_top import sample_fields

    from pwas_hdl.fixedpoint.warp import WarpedFixedPointModel, is_warped

    model_class = WarpedFixedPointModel if is_warped(sensor) else FixedPointModel  # the one generate builds
    fxm = model_class.from_sensor(sensor, input_bits=input_bits, **formats)
    rm = recurrent_model(sensor, fxm)  # the recurrent hardware's conditions: Mz >= 1, constant initial states, one format per signal
    top = build_recurrent_sensor(rm, pipeline=pipeline, name=name, architecture=architecture)
    verilog = emit_verilog(top, name)
    b, ow = fxm.input_bits, fxm.output_format.bits
    in_fields = sample_fields(rm.signals, b)
    out_fields = [{"name": t, "lsb": i * ow, "width": ow, "signed": True} for i, t in enumerate(fxm.target_names)]
    out_fields.append({"name": "out_of_range", "lsb": fxm.nz * ow, "width": 1, "signed": False})
    return RecurrentDesign(rm, top, verilog, name, in_fields, out_fields)


def standard_recurrent_runs(n: int, seed: int = 0, stalls: tuple[float, float] = (0.7, 0.6)) -> list[dict]:
    """Run plans for ``n`` samples: full speed (checks II and latency), and random bubbles and
    stalls with a reset after about a third of the samples (then the whole trajectory again).

    Parameters
    ----------
    n : int
        Samples (rows) of the codes to replay.
    seed : int
        Seed of the full-speed run (the stall run uses ``seed + 1``).
    stalls : (float, float)
        ``p_valid``, ``p_ready`` of the stall run: per-cycle probabilities of input valid and output ready.

    Returns
    -------
    list of dict
        As :func:`~pwas_hdl.verify.segment_bench.standard_segment_runs`.
    """
    return standard_segment_runs(n, seed, stalls)


def replay(design: RecurrentDesign, codes: np.ndarray, simulator: str = "icarus", *, runs: Sequence[dict] | None = None,
           work_dir: str | Path | None = None, cache_dir: str | Path | None = None) -> dict:
    """Replay payload codes (T, S) through the RTL; every segment starts after a reset.

    Parameters
    ----------
    design : RecurrentDesign
    codes : ndarray (T, S) of int
        One row per input transfer (:meth:`RecurrentFixedPointModel.quantize_signals`).
    simulator : {"icarus", "verilator"}
    runs : list of dict, optional
        Plans as :func:`standard_recurrent_runs` (segments give ``rows`` = (start, stop) of
        ``codes``); default: the standard runs over all of ``codes``.
    work_dir : str or Path, optional
        Folder for the Verilog and the simulator run (kept); default: a temporary folder, removed.
    cache_dir : str or Path, optional
        Where simulator builds are cached (default: the runner's cache).

    Returns
    -------
    dict
        ``passed`` (the bench found no difference), ``failures``, ``runs`` (per segment: outputs,
        mismatches, latencies, spacings), ``rtl_out`` (R, nz) the output codes of the last segment
        of the first run as the RTL produced them (decoded), ``bittrue_out`` the model's,
        ``wall_s``, ``build_s``, ``simulator``.
    """
    import sys

    from pwas_hdl.hdl.emit import port_names
    from pwas_hdl.resources import sim_dir

    if str(sim_dir()) not in sys.path:
        sys.path.insert(0, str(sim_dir()))
    import pwas_runner  # noqa: E402 (sim/ on the path)

    codes = np.asarray(codes, dtype=np.int64)
    plans = list(runs) if runs is not None else standard_recurrent_runs(codes.shape[0])
    nm = port_names("axis")
    job: dict = {"ports": {"clock": nm["clock"], "reset": nm["reset"], "reset_on": 0, "in_valid": nm["in.valid"],
                           "in_ready": nm["in.ready"], "in_payload": nm["in.payload"], "out_valid": nm["out.valid"],
                           "out_ready": nm["out.ready"], "out_payload": nm["out.payload"], "warm": "warm"},
                 "latency": design.latency, "ii": design.ii, "warmup": int(design.top.warmup), "runs": []}
    job["runs"], cache = plan_job_runs(plans, lambda a, b: design.words(codes[a:b]))
    with tempfile.TemporaryDirectory(prefix="pwas-rec-") as tmp:
        wd = Path(work_dir) if work_dir is not None else Path(tmp)
        wd.mkdir(parents=True, exist_ok=True)
        vpath = wd / f"{design.name}.v"
        vpath.write_text(design.verilog, encoding="utf-8")
        bld = pwas_runner.build(vpath, design.name, simulator, cache_dir=cache_dir)
        res = pwas_runner.run_job(bld, job, wd / f"run-{simulator}", test_module=TEST_MODULE)
    first = plans[0]["segments"][-1]["rows"]
    seg0 = res["runs"][0]["segments"][-1] if res.get("runs") else None
    _, outs_exp, oc = cache[tuple(first)]
    res["bittrue_out"] = oc
    res["rtl_out"] = None
    if seg0 is not None and seg0.get("words") is not None:  # decoded output codes of the RTL (without the flag)
        res["rtl_out"] = np.array([unpack_fields(w, design.out_fields)[:-1] for w in seg0["words"]], dtype=np.int64)
    res["build_s"] = bld.build_seconds
    res["simulator"] = simulator
    res["n_samples"] = int(codes.shape[0])
    count_outputs(res)
    res["passed"] = bool(res.get("passed")) and not res.get("failures")
    return res
