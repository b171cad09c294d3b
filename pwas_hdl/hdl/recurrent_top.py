"""Recurrent virtual-sensor top (issue 13): lag bank + PWAS core + a feedback path from the core
output back into the regressor.

The bit-true specification is :class:`pwas_hdl.fixedpoint.recurrence.RecurrentFixedPointModel`.

Input payload (``in__payload``, LSB first): one signed ``B_in``-bit code per *measured* signal,
as :class:`pwas_hdl.hdl.sensor_top.PWASSensorTop` (the u/y lag bank, its warm-up of ``M - 1``
transfers and the ``warm`` port are the same). The regressor of the core is the lag taps followed
by the ``nz * Mz`` fed-back estimates ``z_hat(t-Mz) .. z_hat(t-1)``, held in feedback registers.

Feedback: when an output is transferred (``out.valid & out.ready``) each target's output code is
requantised to the input code format of its fed-back dimension -- ``q = clip((o * K + C) >> S,
-2**(B_in-1), 2**(B_in-1) - 1)``: round half up, saturate (:class:`FeedbackRequant
<pwas_hdl.fixedpoint.recurrence.FeedbackRequant>`) -- and shifted into the feedback registers.
The reset values of the registers are the input codes of the model's initial state.

Non-uniform (power-of-two) partition: with ``warps`` the payload, the lag bank and the feedback
registers hold the ``B_in``-bit input codes ``q`` of the warped model
(:class:`~pwas_hdl.fixedpoint.warp.WarpedFixedPointModel`; the fed-back estimate is requantised
to the :class:`~pwas_hdl.fixedpoint.warp.WarpInputFormat` of its dimension) and the warp and its
register (:func:`pwas_hdl.hdl.warp.attach_warp`) are the core's first stage: one cycle more.

Serial core (``architecture="serial"``, :class:`~pwas_hdl.hdl.serial_core.SerialPWASCore`): the
same stream interface and bit-true model; its input throttle (one sample every ``n + 1`` cycles)
never bites here, since one sample in flight already spaces the samples by the core's latency
(``>= n + 1``; checked when the top is built); ``in.ready`` still includes it (``& advance``).

Flow control: one sample in flight. After a transfer that reaches the core, ``in.ready`` is low
until its output is transferred; in that cycle ``in.ready`` is high again and the requantised
output bypasses the feedback registers into the next regressor, so with a sink that never stalls
a new sample is accepted every ``L`` cycles (``II = latency = L``). During warm-up ``in.ready`` is
1. ``rst`` (synchronous) clears the pipeline, the warm-up and restores the initial state.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from amaranth.hdl import Cat, Const, Module, Signal, unsigned
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from pwas_hdl.errors import InputError, InternalError
from pwas_hdl.hdl._lintsafe import add_const_wrap, ge_const, sink_unused
from pwas_hdl.hdl.core import _not, core_output_layout
from pwas_hdl.hdl.params import CoreParams, Pipeline
from pwas_hdl.hdl.sensor_top import lag_bank, sample_fields

if TYPE_CHECKING:
    import numpy.typing as npt

    from pwas_hdl.fixedpoint.recurrence import FeedbackRequant, RecurrentFixedPointModel
    from pwas_hdl.fixedpoint.warp import Pow2Warp

__all__ = ["PWASRecurrentTop", "build_recurrent_sensor"]


class PWASRecurrentTop(wiring.Component):
    """Lag bank + PWAS core + feedback registers (see the module docstring).

    Parameters
    ----------
    params : CoreParams
        The core's parameters: ``n`` = lag dimensions + ``nz * Mz``.
    signals : list of (name, n_lags)
        The measured signals of the payload, payload order.
    io_dims : list of (signal index, lag)
        The first ``n - nz*Mz`` regressor dimensions, lag in samples (0: the current sample).
    mz : int
        ``Mz >= 1``: fed-back estimates per target.
    feedback : list of FeedbackRequant
        One per target: the requantisation of its output code (``B_out`` bits) to the input code
        (``B_in`` bits) of its fed-back dimensions.
    initial_codes : array_like (Mz, nz)
        Reset values of the feedback registers, input codes (oldest first).
    memory, pipeline : as :class:`~pwas_hdl.hdl.core.PWASCore`
    architecture : {"parallel", "serial"}
        The core (:func:`pwas_hdl.hdl.api._make_core`); ``"serial"`` ignores ``memory``.
    warps : list of Pow2Warp, optional
        A non-uniform (power-of-two) partition: one warp per regressor dimension in front of the
        core (:func:`~pwas_hdl.hdl.warp.attach_warp`, one register); the payload, the lag bank and
        the feedback registers then hold ``warps[0].input_bits``-bit codes.

    Attributes
    ----------
    latency : int
        Cycles from the transfer of a sample that reaches the core to its output (the warp
        register included).
    ii : int
        ``max(1, latency)``: cycles between accepted samples (sink never stalling).
    in_width : int
        Bits of one code in the payload, the lag bank and the feedback registers: the core's
        ``in_width``, or the warp's input width.
    warmup : int
        ``M - 1``: transfers after reset that produce no output.

    Raises
    ------
    InputError
        ``len(io_dims) + nz * mz != n``, ``len(feedback) != nz``, ``mz < 1``, a dimension the lag
        bank does not hold, a feedback requantisation whose product is narrower than ``B_in + S``
        (:meth:`~pwas_hdl.fixedpoint.recurrence.FeedbackRequant.check_top_product`), an unknown
        ``architecture``, warps that do not fit the core (:func:`~pwas_hdl.hdl.warp.attach_warp`),
        or as :class:`~pwas_hdl.hdl.core.PWASCore`.
    """

    kind = "recurrent-sensor"
    #: the manifest's warp entry of a warped top (:func:`build_recurrent_sensor`), else None
    warp_entry = None
    _warp_in_width = None

    @property
    def in_width(self) -> int:
        """Bits of one code in the payload, the lag bank and the feedback registers: the core's, or the warp's input."""
        return self._warp_in_width or self.params.in_width

    def __init__(self, params: CoreParams, signals: Sequence[tuple[str, int]], io_dims: Sequence[tuple[int, int]], mz: int,
                 feedback: Sequence[FeedbackRequant], initial_codes: npt.ArrayLike, *, memory: str = "banked",
                 pipeline: Pipeline | str | None = None, architecture: str = "parallel",
                 warps: Sequence[Pow2Warp] | None = None):
        from pwas_hdl.hdl.api import _make_core

        self._MustUse__silence = True
        nz = len(feedback)
        if len(io_dims) + nz * mz != params.n or nz != params.nz or mz < 1:
            raise InputError(f"{len(io_dims)} lag dimensions + {nz} x Mz = {mz} fed back do not make the core's n = {params.n}"
                             f" with nz = {params.nz}")
        for s, lag in io_dims:
            if not (0 <= s < len(signals) and 0 <= lag < signals[s][1]):
                raise InputError(f"dimension ({s}, {lag}) is not held by the lag bank {signals}")
        for c, fb in enumerate(feedback):  # the feedback product (_requant), refused before anything is built
            fb.check_top_product(c)
        self.core = _make_core(params, memory, pipeline, architecture)
        self.core._MustUse__silence = True
        if warps is not None:  # non-uniform partition: warp + register in front of the core (pwas_hdl.hdl.warp)
            from pwas_hdl.hdl.warp import attach_warp

            self._warp_in_width = attach_warp(self.core, warps)
        self.params = params
        self.signals = [(str(nm), int(k)) for nm, k in signals]
        self.dims = [(int(s), int(lag)) for s, lag in io_dims]
        self.mz = int(mz)
        self.feedback = list(feedback)
        self.initial_codes = [[int(v) for v in row] for row in initial_codes]
        self.latency = self.core.latency
        self.ii = max(1, self.latency)
        #: why II is not the core's (the manifest's architecture.meaning, pwas_hdl.hdl.serial_core.architecture_info)
        self.ii_meaning = "one sample in flight, the estimate fed back into the next regressor: II = latency"
        self.memory_plan = self.core.memory_plan
        self.pipeline = self.core.pipeline
        self.warmup = max([k for _, k in self.signals] + [1]) - 1
        self.serial = getattr(self.core, "architecture", "parallel") == "serial"
        # the serial throttle is free (gap == 0) from n + 1 cycles after a transfer; the next one comes >= latency after it
        if self.serial and self.latency < self.core.ii:
            raise InternalError(f"serial core latency {self.latency} < its II {self.core.ii}: one sample in flight would "
                                "not cover the throttle")
        super().__init__({
            "in": In(stream.Signature(unsigned(len(self.signals) * self.in_width))),
            "out": Out(stream.Signature(unsigned(core_output_layout(params).size))),
            "warm": Out(1),
        })
        self._MustUse__silence = False

    @property
    def input_fields(self) -> list[dict]:
        """Input payload fields, one signed ``in_width``-bit code per measured signal (:func:`sample_fields`)."""
        return sample_fields([nm for nm, _ in self.signals], self.in_width)

    @property
    def extra_info(self) -> dict:
        """Manifest entries of the top: ``lags`` (with the fed-back ``<target>_hat`` dimensions),
        ``warmup``, ``recurrence`` (Mz, II in cycles, feedback requantisation and initial codes),
        ``flow_control`` (replacing :func:`~pwas_hdl.hdl.api.design_info`'s generic rules, the serial
        core's throttle included) and, if warped, ``warp``."""
        tn = getattr(self.core, "target_names", [f"z{i}" for i in range(self.params.nz)])
        when = "low from a transfer that reaches the core until its output is transferred (1 during the warm-up)"
        ready = f"~busy | (out.valid & out.ready): {when}"
        if self.serial:
            ready = (f"(~busy | (out.valid & out.ready)) & advance: {when}; advance is the serial core's throttle "
                     f"(~out.valid | out.ready) & (gap == 0), 1 whenever the first term is (its {self.params.n + 1} cycles "
                     f"per sample are no more than the latency)")
        return {
            **({"warp": self.warp_entry} if self.warp_entry is not None else {}),
            "lags": {"signals": [{"name": nm, "lags": k} for nm, k in self.signals],
                     "regressor": [{"signal": self.signals[s][0], "lag": lag} for s, lag in self.dims]
                     + [{"signal": f"{tn[c]}_hat", "lag": lag} for lag in range(self.mz, 0, -1) for c in range(self.params.nz)]},
            "warmup": {"samples_without_output": self.warmup, "port": "warm",
                       "meaning": "warm = 1 once the lag bank holds M-1 samples since reset"},
            "recurrence": {"Mz": self.mz, "ii_cycles": self.ii,
                           "feedback": [{"target": tn[c], **fb.to_dict(), "initial_codes": [r[c] for r in self.initial_codes]}
                                        for c, fb in enumerate(self.feedback)],
                           "flow": "one sample in flight: in.ready is low from a transfer that reaches the core until its "
                                   "output is transferred; the requantised output bypasses into the next regressor"},
            # replaces design_info's generic entry (whose in.ready = advance holds for the feed-forward designs only)
            "flow_control": {
                "in.ready": ready,
                "ii": f"{self.ii} cycles between accepted samples when out.ready stays high (= latency)",
                "latency": f"the output of a transfer in cycle t is valid in cycle t + {self.latency} when out.ready stays high",
                "reset": "synchronous: clears the pipeline and the warm-up, restores the initial state codes",
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

    def _requant(self, m: Module, o, fb, c: int):
        """``clip((o * K + C) >> S)`` in lint-safe unsigned arithmetic (:mod:`pwas_hdl.hdl._lintsafe`).

        ``o`` (the raw ``B_out``-bit output field) is taken in offset binary ``ou = o + 2**(B_out-1)``,
        so ``o * K + C = ou * K + c1`` with ``c1 = C - 2**(B_out-1) K``. With ``P = ou * K`` (exact,
        unsigned) the clip limits are two comparisons of ``P`` with constants, and inside them
        ``q - qmin = (P + c1 - qmin 2**S) >> S`` lies in ``[0, 2**B_in)``: it is computed modulo
        ``2**(B_in + S)`` on the low bits of ``P``. Returns the input code (two's complement bits).
        """
        b, ow = self.in_width, len(o)
        k, sh = fb.mul, fb.shift
        pw = ow + k.bit_length()
        if (fb.in_bits, fb.out_bits) != (b, ow):
            raise InternalError(f"feedback requantisation of target {c} is for {fb.out_bits} -> {fb.in_bits} bits, the top "
                                f"has {ow} -> {b}")
        fb.check_top_product(c)  # also checked when the top is built (no half-built module on a refusal)
        c1 = fb.add - (1 << (ow - 1)) * k
        base = fb.qmin << sh  # (ou K + c1) >> S < qmin  <=>  ou K < qmin 2**S - c1
        lo_thr, hi_thr = base - c1, base + ((1 << b) << sh) - c1
        ou = Cat(o[: ow - 1], ~o[ow - 1])
        prod = Signal(unsigned(pw), name=f"fb{c}_prod")
        m.d.comb += prod.eq(ou * k)
        under = _not(ge_const(prod, lo_thr))
        over = ge_const(prod, hi_thr)
        low = add_const_wrap(m, prod[: b + sh], (c1 - base) % (1 << (b + sh)), f"fb{c}_sum")
        sink_unused(m, low[:sh], f"fb{c}_round")
        val = low[sh:]
        q = Signal(unsigned(b), name=f"fb{c}_code")
        mask = (1 << b) - 1
        if over is True:
            m.d.comb += q.eq(fb.qmax & mask)
            return q
        if under is True:
            m.d.comb += q.eq(fb.qmin & mask)
            return q
        with m.If(over if not isinstance(over, bool) else Const(0, 1)):
            m.d.comb += q.eq(fb.qmax & mask)
        with m.Elif(under if not isinstance(under, bool) else Const(0, 1)):
            m.d.comb += q.eq(fb.qmin & mask)
        with m.Else():
            m.d.comb += q.eq(Cat(val[: b - 1], ~val[b - 1]))
        return q

    def elaborate(self, platform: Any) -> Module:
        """The lag bank, PWAS core and feedback registers, connected.

        Parameters
        ----------
        platform : Any
            Amaranth build platform; not used.

        Returns
        -------
        Module
            One module: lag bank, warm-up thermometer, ``busy`` flag, feedback requantisation and
            registers, and the inlined core.

        Raises
        ------
        InputError
            A target's requantisation product ``B_out + bits(K)`` is narrower than ``B_in + S``
            (refused when the top is built already).
        """
        m = Module()
        p = self.params
        b = self.in_width
        inp = getattr(self, "in")
        cur = [inp.payload[i * b: (i + 1) * b] for i in range(len(self.signals))]
        advance = Signal(name="advance")  # driven by the core: ~out.valid | out.ready (serial: & its throttle)
        busy = Signal(name="busy")
        out_fire = Signal(name="out_fire")
        m.d.comb += out_fire.eq(self.out.valid & self.out.ready)
        if self.serial:  # the serial core's throttle (gap == 0): always 1 here, as its n + 1 cycles < the latency
            m.d.comb += inp.ready.eq((~busy | out_fire) & advance)
        else:
            m.d.comb += inp.ready.eq(~busy | out_fire)
        transfer = inp.valid & inp.ready
        if self.warmup:
            fill = [Signal(name=f"warmup{i + 1}") for i in range(self.warmup - 1)] + [self.warm]
            warm = self.warm
            with m.If(transfer):
                m.d.sync += [fill[0].eq(1)] + [fill[i].eq(fill[i - 1]) for i in range(1, len(fill))]
        else:
            warm = Const(1, 1)
            m.d.comb += self.warm.eq(1)
        core_valid = Signal(name="core_valid")
        m.d.comb += core_valid.eq(transfer & warm)
        hist = lag_bank(m, self.signals, cur, transfer, b)
        outw = p.out_width
        zin = {}
        for c, fb in enumerate(self.feedback):
            q = self._requant(m, self.out.payload[c * outw: (c + 1) * outw], fb, c)
            regs = {k: Signal(unsigned(b), name=f"fb{c}_z{k}", init=self.initial_codes[self.mz - k][c] % (1 << b))
                    for k in range(1, self.mz + 1)}
            with m.If(out_fire):
                m.d.sync += regs[1].eq(q)
                for k in range(2, self.mz + 1):
                    m.d.sync += regs[k].eq(regs[k - 1])
            for k in range(1, self.mz + 1):
                zk = Signal(unsigned(b), name=f"fb{c}_in{k}")
                with m.If(out_fire):
                    m.d.comb += zk.eq(q if k == 1 else regs[k - 1])
                with m.Else():
                    m.d.comb += zk.eq(regs[k])
                zin[(c, k)] = zk
        with m.If(core_valid):
            m.d.sync += busy.eq(1)
        with m.Elif(out_fire):
            m.d.sync += busy.eq(0)
        parts = [cur[s] if lag == 0 else hist[s][lag - 1] for s, lag in self.dims]
        parts += [zin[(c, k)] for k in range(self.mz, 0, -1) for c in range(p.nz)]
        self.core.build_into(m, Cat(*parts), core_valid, advance, self.out)
        return m


def build_recurrent_sensor(rmodel: RecurrentFixedPointModel, *, memory: str = "banked",
                           pipeline: Pipeline | str | None = None, name: str = "pwas_recurrent_sensor",
                           architecture: str = "parallel") -> PWASRecurrentTop:
    """The recurrent sensor top of a :class:`~pwas_hdl.fixedpoint.recurrence.RecurrentFixedPointModel`.

    Parameters
    ----------
    rmodel : RecurrentFixedPointModel
        ``.fxm`` (the core's ``FixedPointModel``, or a
        :class:`~pwas_hdl.fixedpoint.warp.WarpedFixedPointModel`: the warp goes in front of the
        core), ``.lags`` (with ``Mz``), ``.signals`` (measured signal names, payload order),
        ``.feedback``, ``.initial_codes``.
    memory, pipeline, architecture
        As :class:`PWASRecurrentTop`.
    name : str
        Verilog module name.

    Returns
    -------
    PWASRecurrentTop
        ``.latency`` (cycles), ``.ii`` (= latency), ``.warmup`` (samples), ``.signals``, ``.core``;
        a warped one has ``.warp_entry`` (the manifest's ``warp``, :func:`~pwas_hdl.hdl.warp.warp_hw_info`).

    Raises
    ------
    InputError
        ``name`` is not a plain Verilog identifier, or as :class:`PWASRecurrentTop`.
    """
    from pwas_hdl.hdl.api import _check_name

    name = _check_name(name)
    fxm, lags = rmodel.fxm, rmodel.lags
    warps = getattr(fxm, "warps", None)  # a WarpedFixedPointModel: its uniform core's parameters, the warps in front
    params = CoreParams.from_model(fxm.core if warps is not None else fxm)
    sod = lags.signal_of_dimension()
    sig_index = {s: i for i, s in enumerate(rmodel.signals)}
    counts = [0] * len(rmodel.signals)
    io_dims = []
    for j, (kind, _ch, lag) in enumerate(sod):
        if kind == "z":
            continue
        s = sig_index[fxm.regressor_signals[j][0]]
        io_dims.append((s, lag))
        counts[s] = max(counts[s], lag + 1)
    signals = list(zip(rmodel.signals, counts))
    top = PWASRecurrentTop(params, signals, io_dims, lags.mz, rmodel.feedback, rmodel.initial_codes, memory=memory,
                           pipeline=pipeline, architecture=architecture, warps=warps)
    top.module_name = name
    top._MustUse__silence = True
    if warps is not None:
        from pwas_hdl.hdl.warp import warp_hw_info

        top.warp_entry = warp_hw_info(fxm)
    top.core.input_names = list(fxm.regressor_names)
    top.core.target_names = list(fxm.target_names)
    return top
