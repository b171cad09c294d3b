"""Virtual-sensor top: one (u, y) sample per transfer -> lag bank -> PWAS core.

Input stream payload (``in__payload``, LSB first): one signed ``B_in``-bit code per *signal*, in
the order of :class:`pwas_hdl.fit.regressors.LagStructure` (inputs ``u0 .. u{nu-1}``, then outputs
``y0 .. y{ny-1}``; only signals that appear in the regressor). Each signal keeps its own format:
all lags of a signal share it (``FixedPointModel.signal_input_formats``).

Lag bank: per signal with ``L`` lags, ``L - 1`` registers holding the previous ``L - 1`` accepted
samples; the regressor is formed from them and the current sample, oldest first
(``u(t-Mu+1) .. u(t), y(t-My+1) .. y(t)``, channels within a time step), exactly as
:meth:`LagStructure.build`. The registers shift on every input transfer.

Warm-up: the first ``M - 1`` transfers after reset (``M = max(Mu, My)``) only fill the lag bank
and produce no output; the transfer of sample ``t >= M - 1`` produces one output, ``latency``
cycles later -- the rows of ``LagStructure.build``. The output port ``warm`` is high once the lag
bank is full (``M - 1`` samples held), i.e. when the next transfer yields an output; it is
constant 1 when ``M = 1``. During warm-up ``in.ready`` is 1 (the lag bank never waits for the
pipeline); afterwards ``in.ready = ~out.valid | out.ready``. ``rst`` restarts the warm-up.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import re

from amaranth.hdl import Cat, Const, Module, Signal, unsigned
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from pwas_hdl.errors import InputError
from pwas_hdl.fit.regressors import LagStructure
from pwas_hdl.hdl.classifier_top import argmax_extent, inline_core_and_argmax
from pwas_hdl.hdl.core import core_output_layout
from pwas_hdl.hdl.params import CoreParams, Pipeline

if TYPE_CHECKING:
    from amaranth.hdl import Value

    from pwas_hdl.fixedpoint.warp import Pow2Warp
    from pwas_hdl.hdl.argmax import ArgmaxStage

__all__ = ["PWASSensorTop", "lag_plan", "lag_bank"]


def lag_plan(model: Any, lags: LagStructure | None = None) -> tuple[list[tuple[str, int]], list[tuple[int, int]]]:
    """Signals and regressor dimensions of the lag bank.

    Parameters
    ----------
    model : FixedPointModel or CoreParams
        Gives ``n`` and, if set, ``regressor_signals`` (``(signal name, lag)`` per dimension).
    lags : LagStructure, optional
        The sensor's lag structure; default: derived from ``model.regressor_signals``.

    Returns
    -------
    signals : list of (name, n_lags)
        In payload order.
    dims : list of (signal index, lag)
        One per regressor dimension, ``lag = 0`` the current sample (lags in samples).

    Raises
    ------
    InputError
        ``lags`` is recurrent (``Mz > 0``); ``lags`` has another dimension than the model, or does not match its
        ``regressor_signals``; or neither ``lags`` nor ``regressor_signals`` is given.
    """
    n = model.n if isinstance(getattr(model, "n", None), int) else len(CoreParams.from_model(model).partitions)  # n: also additive models
    names = list(getattr(model, "regressor_signals", []) or [])
    if lags is not None and lags.recurrent:  # issue 13: the fed-back estimates need the feedback path
        raise InputError(
            f"the model is a recurrent (dynamical) sensor (Mz = {lags.mz}): the lag sensor top has no feedback path; "
            "build the recurrent top instead (generate --design sensor does; in Python "
            "pwas_hdl.verify.recurrent_replay.build_recurrent_design), or the bare core (generate --design core)"
        )
    if lags is not None:
        if lags.dimension != n:
            raise InputError(f"the lag structure has n = {lags.dimension} regressors, the model {n}")
        sod = lags.signal_of_dimension()
        seen: list[tuple[str, int]] = []  # (kind, channel) in first-appearance (= payload) order
        for kind, ch, _ in sod:
            if (kind, ch) not in seen:
                seen.append((kind, ch))
        dims = [(seen.index((kind, ch)), lag) for kind, ch, lag in sod]
        counts = [lags.mu if kind == "u" else lags.my for kind, _ in seen]
        sig_names = [f"{kind}{ch}" for kind, ch in seen]
        if names:
            for j, (s, _) in enumerate(dims):
                sig_names[s] = str(names[j][0])
            if [(sig_names[s], lag) for s, lag in dims] != [(str(a), int(b)) for a, b in names]:
                raise InputError("the lag structure does not match the model's regressor signals; pass the LagStructure the "
                                 "model was fitted with (sensor.lags_)")
        return list(zip(sig_names, counts)), dims
    if not names:
        raise InputError("the model has no regressor_signals; pass the LagStructure (sensor.lags_)")
    order: dict[str, int] = {}
    for s, _ in names:
        order.setdefault(s, len(order))
    dims = [(order[s], int(lag)) for s, lag in names]
    counts = [0] * len(order)
    for s, lag in dims:
        counts[s] = max(counts[s], lag + 1)
    return list(zip(order, counts)), dims


def sample_fields(names: Sequence[str], width: int) -> list[dict]:
    """Fields of a sensor top's input payload: one signed ``width``-bit code per signal, signal ``i``
    at bits ``[i*width, (i+1)*width)`` (the manifest's ``input.fields``).

    Parameters
    ----------
    names : sequence of str
        Signal names in payload order.
    width : int
        Bits per code.

    Returns
    -------
    list of dict
        ``{"name", "lsb", "width", "signed": True}`` per signal.
    """
    return [{"name": str(nm), "lsb": i * width, "width": width, "signed": True} for i, nm in enumerate(names)]


def _ident(name: str) -> str:
    s = re.sub(r"[^A-Za-z0-9_]", "_", name)
    return s if re.match(r"[A-Za-z_]", s) else f"s_{s}"


def lag_bank(m: Module, signals: Sequence[tuple[str, int]], cur: Sequence[Value], transfer: Value,
             width: int) -> list[list[Signal]]:
    """The lag bank of a sensor top: per signal ``(name, k)`` the ``k - 1`` registers
    ``lag_<name>_1 .. lag_<name>_{k-1}`` (``width`` bits, no reset), shifted on ``transfer``
    (after the transfer of sample ``t``, ``lag_<name>_d`` holds sample ``t - d``).

    Parameters
    ----------
    m : Module
        Module the registers are added to (``sync`` domain).
    signals : sequence of (name, n_lags)
        The signals in payload order; ``name`` is made a Verilog identifier for the register names.
    cur : sequence of Value
        ``cur[i]``: the current code of signal ``i``, ``width`` bits.
    transfer : Value
        1 bit; the registers shift when it is high.
    width : int
        Bits per code.

    Returns
    -------
    list of list of Signal
        The registers per signal: ``hist[i][d - 1]`` holds lag ``d`` of signal ``i`` (``k - 1``
        registers, empty for ``k = 1``).
    """
    hist = []
    for i, (nm, k) in enumerate(signals):
        regs = [Signal(width, name=f"lag_{_ident(nm)}_{lag}", reset_less=True) for lag in range(1, k)]
        with m.If(transfer):
            if regs:
                m.d.sync += regs[0].eq(cur[i])
            for lag in range(1, len(regs)):
                m.d.sync += regs[lag].eq(regs[lag - 1])
        hist.append(regs)
    return hist


class PWASSensorTop(wiring.Component):
    """Lag bank + PWAS core with one sample of every signal per input transfer.

    Parameters
    ----------
    params : CoreParams
        The core's parameters.
    signals : list of (name, n_lags)
        The signals of the input payload, payload order (:func:`lag_plan`).
    dims : list of (signal index, lag)
        One per regressor dimension, lag in samples (0: the current sample).
    memory, pipeline : as :class:`~pwas_hdl.hdl.core.PWASCore`
    argmax : ArgmaxStage, optional
        A classifier's decision stage after the core (:mod:`pwas_hdl.hdl.argmax`, ``C = nz``
        scores of ``B_out`` bits, ``out_of_range`` carried through): the output payload then ends
        with the class index and the latency grows by ``argmax.latency``.
    warps : list of Pow2Warp, optional
        A non-uniform (power-of-two) partition: the lag bank holds ``B_in``-bit input codes
        (``warps[0].input_bits``) and every regressor dimension is warped to the core's code in
        one more register (:func:`pwas_hdl.hdl.warp.attach_warp`; latency + 1).
    architecture : {"parallel", "serial"}
        ``"serial"``: :class:`~pwas_hdl.hdl.serial_core.SerialPWASCore` (II = n + 1; ``memory`` is
        then ignored), ``"parallel"``: :class:`~pwas_hdl.hdl.core.PWASCore`
        (:func:`pwas_hdl.hdl.api._make_core`). With ``argmax`` the stage follows either core.

    Ports: ``clk``, ``rst``, ``in__valid``, ``in__ready``, ``in__payload`` (``S*B_in`` bits, one code
    per signal), ``out__valid``, ``out__ready``, ``out__payload`` (as the core, then the class index
    with ``argmax``), ``warm``.

    Attributes
    ----------
    core : PWASCore or SerialPWASCore  (its logic is inlined; ``latency``, ``memory_plan``, ``params`` apply)
    latency, ii : int
        Cycles: the core's (from the transfer of a sample that completes a regressor), latency
        plus ``argmax.latency`` with an argmax stage.
    warmup : int
        ``M - 1``: transfers after reset that produce no output.

    Raises
    ------
    InputError
        ``dims`` not one per regressor, a dimension the lag bank does not hold, lags of one signal
        with different input formats (unwarped), an ``argmax`` whose ``index_lsb`` is not the
        core's output width, warps that do not fit (:func:`~pwas_hdl.hdl.warp.attach_warp`), an
        unknown ``architecture``, or as the core.
    """

    kind = "sensor"
    #: the manifest's warp entry of a warped top (pwas_hdl.hdl.warp.build_warped_sensor), else None
    warp_entry = None
    _warp_in_width = None

    @property
    def in_width(self) -> int:
        """Bits of one signal's code in the payload and the lag bank: the core's, or the warp's input."""
        return self._warp_in_width or self.params.in_width

    def __init__(self, params: CoreParams, signals: Sequence[tuple[str, int]], dims: Sequence[tuple[int, int]], *,
                 memory: str = "banked", pipeline: Pipeline | str | None = None, argmax: ArgmaxStage | None = None,
                 architecture: str = "parallel", warps: Sequence[Pow2Warp] | None = None):
        self._MustUse__silence = True  # see PWASCore.__init__
        if len(dims) != params.n:
            raise InputError(f"{len(dims)} lag-bank dimensions for a core with n = {params.n}")
        for s, lag in dims:
            if not (0 <= s < len(signals) and 0 <= lag < signals[s][1]):
                raise InputError(f"dimension ({s}, {lag}) is not held by the lag bank {signals}")
        for s, (nm, _) in enumerate(signals if warps is None else []):  # warped: the model checks its input codes
            fmt = {(params.lo_code[j], params.frac_bits[j], params.partitions[j]) for j, (sj, _) in enumerate(dims) if sj == s}
            if len(fmt) > 1:
                raise InputError(
                    f"the lags of signal {nm!r} have different input formats (lo_code, F, p) {sorted(fmt)}; "
                    "the lag bank feeds one code to all of them: fit without --separate-lag-domains (share_lag_domain=True) "
                    "and with one -p value for all lags of the signal, or generate --design core"
                )
        from pwas_hdl.hdl.api import _make_core

        # parallel, or serial: one multiplier per target, II = n + 1 (pwas_hdl.hdl.serial_core)
        self.core = _make_core(params, memory, pipeline, architecture)
        self.core._MustUse__silence = True  # its logic is inlined by elaborate(), never elaborated itself
        self.params = params
        if warps is not None:  # non-uniform partition: warp + register in front of the core (pwas_hdl.hdl.warp)
            from pwas_hdl.hdl.warp import attach_warp

            self._warp_in_width = attach_warp(self.core, warps)
        self.signals = [(str(nm), int(k)) for nm, k in signals]
        self.dims = [(int(s), int(lag)) for s, lag in dims]
        self.argmax = argmax
        cycles, index_bits = argmax_extent(argmax, core_output_layout(params).size)
        self.latency = self.core.latency + cycles
        self.ii = self.core.ii
        self.memory_plan = self.core.memory_plan
        self.pipeline = self.core.pipeline
        self.warmup = max(k for _, k in self.signals) - 1
        super().__init__(
            {
                "in": In(stream.Signature(unsigned(len(self.signals) * self.in_width))),
                "out": Out(stream.Signature(unsigned(core_output_layout(params).size + index_bits))),
                "warm": Out(1),
            }
        )
        self._MustUse__silence = False

    @property
    def input_fields(self) -> list[dict]:
        """Input payload fields, one signed ``in_width``-bit code per signal (:func:`sample_fields`)."""
        return sample_fields([nm for nm, _ in self.signals], self.in_width)

    @property
    def extra_info(self) -> dict:
        """Manifest entries of the top: ``lags`` (signals, regressor), ``warmup`` and, if warped, ``warp``."""
        return {
            **({"warp": self.warp_entry} if self.warp_entry is not None else {}),
            "lags": {
                "signals": [{"name": nm, "lags": k} for nm, k in self.signals],
                "regressor": [{"signal": self.signals[s][0], "lag": lag} for s, lag in self.dims],
            },
            "warmup": {
                "samples_without_output": self.warmup,
                "port": "warm",
                "meaning": "warm = 1 once the lag bank holds M-1 samples since reset; the first M-1 "
                "transfers after reset produce no output, every later transfer produces one",
            },
        }

    def expected_outputs(self, n_samples: int) -> int:
        """Outputs the top gives for ``n_samples`` input transfers after a reset.

        Parameters
        ----------
        n_samples : int
            Input transfers (samples) since the reset.

        Returns
        -------
        int
            ``max(0, n_samples - warmup)``: no output until the first regressor is complete.
        """
        return max(0, n_samples - self.warmup)

    def elaborate(self, platform: Any) -> Module:
        """The lag bank and the PWAS core (and argmax stage, if any), connected.

        Parameters
        ----------
        platform : Any
            Amaranth build platform; ignored.

        Returns
        -------
        Module
            One module: lag bank, warm-up thermometer and the inlined core.
        """
        m = Module()
        b = self.in_width
        inp = getattr(self, "in")
        cur = [inp.payload[i * b : (i + 1) * b] for i in range(len(self.signals))]
        if self.warmup:
            advance = Signal(name="advance")
            # thermometer of the samples held: fill[i] = i+1 samples; its last stage is `warm`
            fill = [Signal(name=f"warmup{i + 1}") for i in range(self.warmup - 1)] + [self.warm]
            warm = self.warm
            m.d.comb += inp.ready.eq(advance | ~warm)
        else:
            advance = inp.ready  # one net (a copy would be an unused alias wire)
            fill = []
            warm = Const(1, 1)
            m.d.comb += self.warm.eq(1)
        transfer = inp.valid & inp.ready
        hist = lag_bank(m, self.signals, cur, transfer, b)
        if fill:
            with m.If(transfer):
                m.d.sync += [fill[0].eq(1)] + [fill[i].eq(fill[i - 1]) for i in range(1, len(fill))]
        regressor = Cat(*[cur[s] if lag == 0 else hist[s][lag - 1] for s, lag in self.dims])
        # the core (after the warp, if any), then the argmax stage, if any: all inlined (one module)
        inline_core_and_argmax(m, self.core, self.argmax, regressor, inp.valid & warm, advance, self.out)
        return m
