"""Seed 003's virtual estimator on the FPGA: per-mode observer bank, argmin detector, switched observer.

Bit for bit :class:`pwas_hdl.fixedpoint.observer_bank.FixedPointSwitchedEstimator`, built from the
same pieces as the observer-bank sensor (:func:`pwas_hdl.hdl.observer_bank.const_product`,
``saturate``, the window sums of :mod:`pwas_hdl.hdl.residual_features`) and cls10's compare tree
(:class:`pwas_hdl.hdl.argmax.ArgmaxStage`, ``select="min"``, combinational: preset ``min``).

One (u, y) sample per input transfer; per transfer (one clock, II = 1): the residuals of the
bank, their window sums, the detected mode (argmin, ties to the lowest mode), the switched
observer's output for the sample (``x_hat``, ``y_hat`` from its state before the update) and the
updates of every state. The output register holds ``x_hat`` (``n`` codes ``s<B_s>.<F_s>``),
``y_hat`` (``F_s`` fraction bits, :func:`estimator_widths`), the mode index (``theta - 1``, ``index_width`` bits)
and ``state_saturated`` (1 bit: a state of the bank or of the switched observer saturated in this
sample's update, the bit-true trace's ``state_saturated``), LSB first;
latency 1 cycle, one output per transfer, no warm-up (the estimator starts at 0, A6).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from amaranth.hdl import Cat, Const, Module, Mux, Signal, signed, unsigned
from amaranth.lib.memory import Memory
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from pwas_hdl.errors import InputError
from pwas_hdl.fixedpoint.argmax import index_width
from pwas_hdl.hdl._lintsafe import sink_unused
from pwas_hdl.hdl.argmax import ArgmaxStage, inner_stream
from pwas_hdl.hdl.observer_bank import _sum, add_const_signed, const_product, saturate
from pwas_hdl.hdl.residual_features import sub_wrap
from pwas_hdl.hdl._lintsafe import add_wrap  # noqa: E402

if TYPE_CHECKING:
    import numpy.typing as npt

    from pwas_hdl.fixedpoint.observer_bank import FixedPointSwitchedEstimator

__all__ = ["SwitchedEstimatorTop", "SerialSwitchedEstimatorTop", "serial_estimator_schedule", "estimator_widths",
           "simulate_estimator"]


def estimator_widths(est: FixedPointSwitchedEstimator) -> dict[str, int]:
    """Widths of the datapath of :class:`SwitchedEstimatorTop` (all exact).

    Parameters
    ----------
    est : FixedPointSwitchedEstimator
        The bit-true estimator: coefficient codes, formats, window.

    Returns
    -------
    dict of str to int
        Bits: ``acc`` (state-update accumulator), ``racc`` (residual / output accumulator, widened
        so that a residual's square holds the window sum), ``residual`` (``racc - F_c``), ``sum``
        (window sum, ``2 * residual``) and ``y_hat`` (= ``residual``).
    """
    fc, bs, b_in = est.coef_frac, est.state_bits, est.input_bits
    sh = est.state_frac - est.input_frac
    lw = max(1, (est.window - 1).bit_length()) if est.window > 1 else 0
    amax = int(abs(est.f_codes).max()) * (1 << (bs - 1)) * est.n
    bmax = (int(abs(est.g_codes).max()) + int(abs(est.l_codes).max())) * (1 << (b_in - 1)) << sh
    acc = (amax + bmax + (1 << fc)).bit_length() + 2
    hmax = int(abs(est.h_codes).max()) * (1 << (bs - 1)) * est.n + ((1 << (b_in - 1)) << (sh + fc)) + (1 << fc)
    racc = hmax.bit_length() + 2
    racc = max(racc, bs + 2, b_in + sh + fc + 2) + (lw + 1) // 2  # widened so that r * r holds the window sum
    rb = racc - fc  # the residual after rounding
    return {"acc": max(acc, bs + 2, b_in + sh + fc + 2), "racc": racc, "residual": rb, "sum": 2 * rb, "y_hat": rb}


def _estimator_ports(top: wiring.Component, est) -> None:
    """The output fields and the stream ports shared by both estimator tops (called last in ``__init__``).

    ``out_fields``: ``x<i>_hat`` (``state_bits`` each), ``y_hat``, ``mode_index``, ``state_saturated``,
    LSB first; ``unsigned_fields`` the unsigned ones (the others are signed codes); ``in`` one (u, y)
    code pair per transfer (``2 input_bits``).
    """
    top.out_fields = ([(f"x{i + 1}_hat", est.state_bits) for i in range(est.n)] + [("y_hat", top.widths["y_hat"])]
                      + [("mode_index", top.index_width), ("state_saturated", 1)])
    top.unsigned_fields = ("mode_index", "state_saturated")
    wiring.Component.__init__(top, {
        "in": In(stream.Signature(unsigned(2 * est.input_bits))),
        "out": Out(stream.Signature(unsigned(sum(w for _, w in top.out_fields)))),
    })
    top._MustUse__silence = False


class SwitchedEstimatorTop(wiring.Component):
    """The estimator of seed 003 as one stream component (see the module docstring).

    Parameters
    ----------
    est : FixedPointSwitchedEstimator
        The bit-true estimator (``n`` states, ``n_modes`` modes, formats and coefficient codes).

    Ports: ``in`` (stream of ``2 * input_bits``: the u code, then the y code), ``out`` (stream of
    the fields ``out_fields``, LSB first: ``x<i>_hat``, ``y_hat``, ``mode_index``, ``state_saturated``).

    Attributes
    ----------
    widths : dict of str to int
        :func:`estimator_widths`.
    index_width : int
        Bits of ``mode_index``.
    latency, ii : int
        1 cycle each.
    out_fields : list of (name, bits)
        The output payload fields, LSB first.
    """

    kind = "switched-estimator"

    def __init__(self, est: FixedPointSwitchedEstimator):
        self._MustUse__silence = True
        self.est = est
        self.widths = estimator_widths(est)
        self.index_width = index_width(est.n_modes)
        self.latency = 1
        self.ii = 1
        _estimator_ports(self, est)

    def _update(self, m, fc_rows, gc, lc, x, qu, qy, name):
        """``sat((F x + (G qu + L qy) << sh + 2**(F_c-1)) >> F_c)`` per state; returns (next states, saturation flags)."""
        est, wd = self.est, self.widths
        sh, fcb = est.state_frac - est.input_frac, est.coef_frac
        nxt, flags = [], []
        for i in range(est.n):
            terms = [const_product(m, int(fc_rows[i][k]) << 0, x[k], wd["acc"], f"{name}_f{i}{k}")
                     for k in range(est.n) if int(fc_rows[i][k])]
            if int(gc[i]):
                terms.append(const_product(m, int(gc[i]) << sh, qu, wd["acc"], f"{name}_g{i}"))
            if int(lc[i]):
                terms.append(const_product(m, int(lc[i]) << sh, qy, wd["acc"], f"{name}_l{i}"))
            acc = add_const_signed(m, _sum(m, terms, wd["acc"], f"{name}_acc{i}"), 1 << (fcb - 1), f"{name}_rnd{i}")
            sink_unused(m, acc[:fcb], f"{name}_acc{i}_frac")
            v, f = saturate(m, acc[fcb:].as_signed(), est.state_bits, f"{name}_next{i}")
            nxt.append(v)
            flags.append(f)
        return nxt, flags

    def _output_of(self, m, hc, x, qy_al, name):
        """``(qy_al - H x + 2**(F_c-1)) >> F_c`` (the residual; ``qy_al`` the aligned ``qy << (sh + F_c)``
        product net) or, with ``qy_al = None``, ``(H x + 2**(F_c-1)) >> F_c`` (``y_hat``)."""
        est, wd = self.est, self.widths
        sign = -1 if qy_al is not None else 1
        terms = [const_product(m, sign * int(hc[k]), x[k], wd["racc"], f"{name}_h{k}") for k in range(est.n) if int(hc[k])]
        if qy_al is not None:
            terms.append(qy_al)
        acc = add_const_signed(m, _sum(m, terms, wd["racc"], f"{name}_acc"), 1 << (est.coef_frac - 1), f"{name}_rnd")
        sink_unused(m, acc[: est.coef_frac], f"{name}_frac")
        return acc[est.coef_frac :].as_signed()

    def elaborate(self, platform: Any) -> Module:
        """The estimator's logic: the per-mode observers, the residual detector and the switched output.

        Parameters
        ----------
        platform : Any
            Amaranth build platform; not used.

        Returns
        -------
        Module
            One module: bank, window sums, argmin detector, switched observer and output register.
        """
        m = Module()
        est, wd = self.est, self.widths
        b = est.input_bits
        inp = getattr(self, "in")
        qu = inp.payload[:b].as_signed()
        qy = inp.payload[b : 2 * b].as_signed()
        advance = inp.ready
        m.d.comb += advance.eq(~self.out.valid | self.out.ready)
        transfer = Signal(name="transfer")
        m.d.comb += transfer.eq(inp.valid & advance)
        sh = est.state_frac - est.input_frac
        s, n = est.n_modes, est.n
        bank = [[Signal(signed(est.state_bits), name=f"bank{j}_x{i}") for i in range(n)] for j in range(s)]
        xo = [Signal(signed(est.state_bits), name=f"obs_x{i}") for i in range(n)]
        qy_al = const_product(m, 1 << (sh + est.coef_frac), qy, wd["racc"], "y_aligned")
        # ---- bank residuals, squares, window sums
        rb, sw = wd["residual"], wd["sum"]
        sums = []
        for j in range(s):
            r = self._output_of(m, est.h_codes[j], bank[j], qy_al, f"bank{j}_res")
            assert len(r) == rb
            sq = Signal(signed(2 * rb), name=f"bank{j}_sq")
            m.d.comb += sq.eq(r * r)
            if est.window == 1:
                sums.append(sq.as_unsigned())
                continue
            dl = [Signal(unsigned(sw), name=f"bank{j}_dl{i}") for i in range(est.window)]
            acc = Signal(unsigned(sw), name=f"bank{j}_sum")
            tot = sub_wrap(m, add_wrap(m, acc, sq.as_unsigned(), f"bank{j}_sum_add"), dl[-1], f"bank{j}_sum_next")
            with m.If(transfer):
                m.d.sync += [dl[0].eq(sq.as_unsigned()), acc.eq(tot)] + [dl[i].eq(dl[i - 1]) for i in range(1, est.window)]
            sums.append(tot)
        # ---- detector: argmin by the shared compare tree (combinational preset "min")
        det = ArgmaxStage(s, sw, signed=False, pipeline="min", select="min")
        det._MustUse__silence = True
        # the stage's handshake and its copy of the scores are not needed here (every transfer is
        # decided in its own cycle): its link wires are aliases, named as deliberately unused
        link = inner_stream(s * sw + self.index_width, "unused_detector")
        det_adv = Signal(name="unused_detector_advance")
        m.d.comb += link.ready.eq(1)
        det.build_into(m, Cat(*sums), Const(1, 1), det_adv, link)
        theta = link.payload[s * sw :]
        # ---- switched observer: the candidates of every mode, selected by theta
        yh = Signal(signed(wd["y_hat"]), name="y_hat")
        nxt = [Signal(signed(est.state_bits), name=f"obs_next{i}") for i in range(n)]
        cands = [self._output_of(m, est.h_codes[j], xo, None, f"obs_y{j}") for j in range(s)]
        updates, sat_flags = [], []
        for j in range(s):
            nx, fl = self._update(m, est.f_codes[j], est.g_codes[j], est.l_codes[j], xo, qu, qy, f"obs_m{j}")
            updates.append(nx)
            sat_flags.append(Cat(*fl).any())
        obs_sat = Signal(name="obs_saturated")  # the selected mode's update saturated
        with m.Switch(theta):
            for j in range(s):
                with m.Case(j):
                    m.d.comb += [d.eq(v) for d, v in zip(nxt, updates[j])]
                    m.d.comb += [yh.eq(cands[j]), obs_sat.eq(sat_flags[j])]
            with m.Default():
                m.d.comb += [d.eq(x) for d, x in zip(nxt, xo)]
                m.d.comb += [yh.eq(0), obs_sat.eq(0)]
        bank_flags = []
        for j in range(s):
            nb, fl = self._update(m, est.f_codes[j], est.g_codes[j], est.l_codes[j], bank[j], qu, qy, f"bank{j}")
            bank_flags += fl
            with m.If(transfer):
                m.d.sync += [d.eq(v) for d, v in zip(bank[j], nb)]
        sat = Signal(name="state_saturated")
        m.d.comb += sat.eq(obs_sat | Cat(*bank_flags).any())
        with m.If(transfer):
            m.d.sync += [d.eq(v) for d, v in zip(xo, nxt)]
        with m.If(advance):
            m.d.sync += [self.out.valid.eq(inp.valid), self.out.payload.eq(Cat(*xo, yh, theta, sat))]
        return m


def simulate_estimator(top: SwitchedEstimatorTop | SerialSwitchedEstimatorTop, codes: npt.ArrayLike, *,
                       p_valid: float = 1.0, p_ready: float = 1.0, seed: int = 0) -> dict:
    """Replay (u, y) codes (T, 2) through ``top`` in Amaranth's simulator (the netlist the Verilog is
    emitted from), with random bubbles (``p_valid``) and backpressure (``p_ready``).

    Parameters
    ----------
    top : SwitchedEstimatorTop or SerialSwitchedEstimatorTop
        The estimator top.
    codes : array_like of int, shape (T, 2)
        Signed ``input_bits`` codes per sample: column 0 the u code, column 1 the y code.
    p_valid, p_ready : float
        Probability that the source offers a sample / the sink accepts in a cycle.
    seed : int
        Seed of the random bubbles and backpressure.

    Returns
    -------
    dict
        ``x_hat`` (T, n), ``y_hat`` (T,), ``theta`` (T,) 1-based, ``state_saturated`` (T,) bool, as
        the bit-true :meth:`~pwas_hdl.fixedpoint.observer_bank.FixedPointSwitchedEstimator.trace`,
        and ``cycles`` (clock cycles simulated). The run has no cycle limit: it ends when ``T``
        outputs have come.
    """
    import numpy as np
    from amaranth.sim import Simulator

    codes = np.asarray(codes, dtype=np.int64)
    b = top.est.input_bits
    mask = (1 << b) - 1
    rng = np.random.default_rng(seed)
    got: list[int] = []
    cycles = [0]

    async def bench(ctx):
        inp = getattr(top, "in")
        k = 0
        while len(got) < len(codes):
            if k < len(codes):
                ctx.set(inp.payload, (int(codes[k, 0]) & mask) | ((int(codes[k, 1]) & mask) << b))
            ctx.set(inp.valid, int(k < len(codes) and rng.random() < p_valid))
            ctx.set(top.out.ready, int(rng.random() < p_ready))
            await ctx.delay(1e-9)
            took = bool(ctx.get(inp.valid) and ctx.get(inp.ready))
            if ctx.get(top.out.valid) and ctx.get(top.out.ready):
                got.append(int(ctx.get(top.out.payload)))
            await ctx.tick()
            k += int(took)
            cycles[0] += 1

    sim = Simulator(top)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    rows = []
    for v in got:
        out, lsb = [], 0
        for nm, w in top.out_fields:
            x = (v >> lsb) & ((1 << w) - 1)
            if nm not in top.unsigned_fields and x >> (w - 1):
                x -= 1 << w
            out.append(x)
            lsb += w
        rows.append(out)
    a = np.array(rows, dtype=np.int64).reshape(-1, len(top.out_fields))
    n = top.est.n
    return {"x_hat": a[:, :n], "y_hat": a[:, n], "theta": a[:, n + 1] + 1, "state_saturated": a[:, n + 2].astype(bool),
            "cycles": cycles[0]}


# ---------------------------------------------------------------------------------------------
# time-multiplexed ("serial") estimator: ``generate EST.json --architecture serial``


def default_mac_pipeline(est: FixedPointSwitchedEstimator) -> int:
    """1 (a register after the row units' multipliers) where the schedule allows it (``n >= 2``), else 0.

    Parameters
    ----------
    est : FixedPointSwitchedEstimator
        Its ``n`` (states) is read.

    Returns
    -------
    int
        The default ``mac_pipeline`` (0 or 1) of :func:`serial_estimator_schedule`.
    """
    return 1 if est.n >= 2 else 0


def serial_estimator_schedule(est: FixedPointSwitchedEstimator, mac_pipeline: int | None = None, lanes: int = 1) -> dict:
    """The step schedule of :class:`SerialSwitchedEstimatorTop` (counts in clock cycles).

    The ``s`` modes of the bank are split into ``lanes`` contiguous groups
    (:func:`pwas_hdl.hdl.serial_observer_bank.lane_groups`; ``s_0`` modes in the first, the longest),
    one row unit per group; the switched observer's rows run on lane 0. A row is *issued* in a step
    (its operands and coefficients enter the multipliers) and its result (sum, rounding,
    saturation) is written ``d = mac_pipeline`` steps later. Lane issue steps ``0 .. s_l-1``: the
    residual rows of the lane's modes; ``s_l .. s_l + s_l n - 1``: their state-update rows; lane 0
    also ``P``: the switched observer's ``y_hat`` row with the coefficients of the detected mode,
    ``P + 1 .. P + n``: its state-update rows. The residual of a lane's ``k``-th mode is registered in
    step ``k + d``, its square in step ``k + d + 1``, the window sum and the running argmin (over the
    lanes: smaller sum, or equal sum and lower mode) in step ``k + d + 2``; the detected mode is
    final after step ``s_0 + d + 1``, before the table of step ``P`` is read in step ``P - 1``:
    ``P = max(s_0 + s_0 n, s_0 + d + 3)``. ``cycles_per_sample = P + 1 + n + d`` (= II); latency
    ``cycles_per_sample + 1`` (the input is latched in the transfer cycle, the output register is
    written in the last step).

    Parameters
    ----------
    est : FixedPointSwitchedEstimator
        Gives ``s`` (``n_modes``) and ``n`` (states).
    mac_pipeline : int, optional
        ``d``: 0 or 1 steps between a row's issue and its result; default
        :func:`default_mac_pipeline`.
    lanes : int
        Row units for the bank, ``1 .. s``.

    Returns
    -------
    dict
        ``lanes``, ``modes_per_lane``, ``row_unit_multipliers`` (``n + 2``), ``multipliers``,
        ``squarers``, ``mac_pipeline``, ``rows`` (row counts by kind), ``bank_end_step``,
        ``observer_first_step`` (``P``), ``cycles_per_sample`` and ``latency`` (clock cycles).

    Raises
    ------
    InputError
        ``lanes`` not an integer in ``1 .. s``.
        ``mac_pipeline`` not 0 / 1 (1 needs ``n >= 2``).
    """
    from pwas_hdl.hdl.serial_observer_bank import lane_groups

    s, n = est.n_modes, est.n
    if isinstance(lanes, bool) or not isinstance(lanes, int) or not 1 <= lanes <= s:
        raise InputError(f"--bank-lanes must be an integer in 1 .. {s} (the number of modes) for this estimator, got {lanes!r}")
    d = default_mac_pipeline(est) if mac_pipeline is None else int(mac_pipeline)
    if d not in (0, 1) or (d == 1 and n < 2):
        raise InputError(f"mac_pipeline must be 0 or 1 (1 needs n >= 2 states), got {mac_pipeline!r} with n = {n}")
    groups = lane_groups(s, lanes)
    s0 = len(groups[0])
    p0 = max(s0 + s0 * n, s0 + d + 3)  # idle steps before P only where the detector is not final yet
    cps = p0 + 1 + n + d
    return {"lanes": len(groups), "modes_per_lane": [list(g) for g in groups], "row_unit_multipliers": n + 2,
            "multipliers": len(groups) * (n + 2), "squarers": len(groups), "mac_pipeline": d,
            "rows": {"residual": s, "bank_update": s * n, "y_hat": 1, "observer_update": n},
            "bank_end_step": s0 + s0 * n, "observer_first_step": p0, "cycles_per_sample": cps, "latency": cps + 1}


class SerialSwitchedEstimatorTop(wiring.Component):
    """Seed 003's estimator time-multiplexed over a few row units (``--architecture serial [--bank-lanes L]``).

    Bit for bit :class:`~pwas_hdl.fixedpoint.observer_bank.FixedPointSwitchedEstimator`, as
    :class:`SwitchedEstimatorTop` (the same ports, payload fields and widths), but every affine row
    of the estimator -- the residual ``(qy << (sh + F_c)) - H_j x_j``, the bank update
    ``F_j x_j + (G_j qu + L_j qy) << sh``, the switched observer's ``H_theta x`` and its update
    -- runs on a row unit of ``n + 2`` variable multipliers whose coefficients come from tables
    indexed by the step (and, for the switched observer's rows, the detected mode):
    :func:`pwas_hdl.hdl.serial_observer_bank.table_mac` (coefficients registered from the next
    step's index; with ``mac_pipeline = 1`` the products registered too). ``lanes`` row units share
    the bank's modes (:func:`serial_estimator_schedule`); lane 0 also runs the switched observer.
    Each row adds ``2**(F_c-1)`` and takes ``>> F_c`` exactly as the bit-true model (the state rows
    saturate); the sum is exact in the accumulator width ``max(acc, racc)``
    (:func:`estimator_widths`), so the result does not depend on the sharing.

    A lane's states are one rotating chain of its modes' state vectors (the head feeds the unit: no
    mode multiplexer); new states go to row registers and the whole vector to the tail when its
    last row is issued (with ``mac_pipeline = 1`` the last state is written into the tail one
    step later), so every row of a mode reads the states before the update. One squarer per lane,
    the window sums as a rotating chain and (window > 1) one delay-line memory per lane (word
    (mode, slot), read one step ahead, 0 until ``window`` samples since reset, as the serial
    observer bank); the detector is a running argmin over the lanes' window sums (a candidate
    replaces the best if its sum is smaller, or equal with a lower mode: ties to the lowest mode, as
    ``numpy.argmin``).

    Handshake: ``in.ready`` is high when the units are idle, or in their last step when the output
    register can take the result (``~out.valid | out.ready``); otherwise the last step (which
    issues no row) waits. II = ``cycles_per_sample``, latency ``cycles_per_sample + 1``.

    Parameters
    ----------
    est : FixedPointSwitchedEstimator
        The bit-true estimator.
    mac_pipeline : int, optional
        0 or 1: the products registered (:func:`serial_estimator_schedule`); default
        :func:`default_mac_pipeline`.
    lanes : int
        Row units for the bank's modes, ``1 .. n_modes``.

    Raises
    ------
    InputError
        ``lanes`` out of range (:func:`serial_estimator_schedule`).
        ``mac_pipeline`` not 0 / 1, or 1 with ``n < 2``.
    """

    kind = "switched-estimator"
    architecture = "serial"

    def __init__(self, est: FixedPointSwitchedEstimator, mac_pipeline: int | None = None, lanes: int = 1):
        self._MustUse__silence = True
        self.est = est
        self.widths = estimator_widths(est)
        self.index_width = index_width(est.n_modes)
        self.schedule = serial_estimator_schedule(est, mac_pipeline, lanes)
        self.mac_pipeline = self.schedule["mac_pipeline"]
        self.lanes = self.schedule["lanes"]
        self.ii = self.schedule["cycles_per_sample"]
        self.latency = self.schedule["latency"]
        _estimator_ports(self, est)

    def _columns(self, group, observer: bool, stw: int, ib: int):
        """Coefficient columns (state 0..n-1, qu, qy) of the lane of modes ``group`` indexed by
        ``Cat(issue step, theta)`` (``ib`` theta bits; the switched observer's rows if ``observer``);
        the qu and qy columns without the alignment ``<< sh`` (the unit shifts those products)."""
        est = self.est
        n, fc = est.n, est.coef_frac
        sl = len(group)
        p0 = self.schedule["observer_first_step"]

        def row(step: int, th: int):
            z = [0] * n
            if step < sl:  # residual of mode group[step]: (qy << (sh + F_c)) - H x
                return [-int(v) for v in est.h_codes[group[step]]], 0, 1 << fc
            if step < sl + sl * n:
                jl, i = divmod(step - sl, n)
                j = group[jl]
                return [int(v) for v in est.f_codes[j][i]], int(est.g_codes[j][i]), int(est.l_codes[j][i])
            if not observer or th >= est.n_modes or step > p0 + n or step < p0:
                return z, 0, 0
            if step == p0:  # y_hat = H_theta x
                return [int(v) for v in est.h_codes[th]], 0, 0
            i = step - p0 - 1
            return [int(v) for v in est.f_codes[th][i]], int(est.g_codes[th][i]), int(est.l_codes[th][i])

        cols = [[] for _ in range(n + 2)]
        for th in range(1 << ib):
            for step in range(1 << stw):
                xs, gu, ly = row(step, th)
                for k in range(n):
                    cols[k].append(xs[k])
                cols[n].append(gu)
                cols[n + 1].append(ly)
        return cols

    def elaborate(self, platform: Any) -> Module:
        """The time-multiplexed estimator's logic: row units, schedule and memories.

        Parameters
        ----------
        platform : Any
            Amaranth build platform; not used.

        Returns
        -------
        Module
            One module: step counter and handshake, the lanes' row units, state chains, window
            sums and delay-line memories, the running argmin and the output register.
        """
        from pwas_hdl.hdl._lintsafe import add_const_wrap, bits_for, ge_const, rom
        from pwas_hdl.hdl.serial_observer_bank import eq_const, table_mac, var_product

        m = Module()
        est, wd = self.est, self.widths
        s, n, b, fc, bs = est.n_modes, est.n, est.input_bits, est.coef_frac, est.state_bits
        rb, sw = wd["residual"], wd["sum"]
        accw = max(wd["acc"], wd["racc"])
        cps, dly = self.ii, self.mac_pipeline
        sh_in = est.state_frac - est.input_frac
        p0 = self.schedule["observer_first_step"]
        groups = self.schedule["modes_per_lane"]
        iw = self.index_width
        inp = getattr(self, "in")

        # ---- handshake and step counter (steps 0 .. cps-1 in the cycles after the transfer)
        stw = bits_for(cps - 1)
        st = Signal(unsigned(stw), name="step")
        busy = Signal(name="busy")
        last = Signal(name="last_step")
        m.d.comb += last.eq(busy & eq_const(st, cps - 1))
        out_free = Signal(name="out_free")
        m.d.comb += out_free.eq(~self.out.valid | self.out.ready)
        go = Signal(name="step_go")  # the current step takes effect (only the last one, which issues no row, can wait)
        m.d.comb += go.eq(busy & (~last | out_free))
        m.d.comb += inp.ready.eq(~busy | (last & out_free))
        transfer = Signal(name="transfer")
        m.d.comb += transfer.eq(inp.valid & inp.ready)
        st_next = Signal(unsigned(stw), name="step_next")  # the step of the next cycle (indexes the registered tables)
        with m.If(transfer):
            m.d.comb += st_next.eq(0)
        with m.Elif(go & ~last):
            m.d.comb += st_next.eq(add_const_wrap(m, st, 1, "step_next_inc"))
        with m.Else():
            m.d.comb += st_next.eq(st)
        qu = Signal(signed(b), name="in_u", reset_less=True)
        qy = Signal(signed(b), name="in_y", reset_less=True)
        with m.If(transfer):
            m.d.sync += [qu.eq(inp.payload[:b].as_signed()), qy.eq(inp.payload[b : 2 * b].as_signed()), st.eq(0), busy.eq(1)]
        with m.Elif(go):
            with m.If(last):
                m.d.sync += busy.eq(0)
            with m.Else():
                m.d.sync += st.eq(st_next)

        steps = range(cps)

        def flag(values, name, result=True):
            """Registered decode of the issue step (loaded from the next step's index) and, with
            ``mac_pipeline``, its copy for the row's result step (advanced with ``go`` only)."""
            v = rom(m, st_next, [int(x) for x in values] + [0] * ((1 << stw) - len(values)), 1, f"{name}_next")
            if isinstance(v, int):
                c = Const(int(v), 1)
                return c, c
            r = Signal(name=f"{name}_issue")
            m.d.sync += r.eq(v)
            if not dly or not result:
                return r, r
            q = Signal(name=f"{name}_result")
            with m.If(go):
                m.d.sync += q.eq(r)
            return r, q

        theta = Signal(unsigned(iw), name="theta")
        best = Signal(unsigned(sw), name="det_best", reset_less=True)
        sat_terms = []
        cands = []  # per lane: (valid, window sum, global mode)
        lane0 = {}
        for ln, group in enumerate(groups):
            pre = "" if len(groups) == 1 else f"lane{ln}_"
            sl = len(group)
            pb = sl + sl * n
            obs = ln == 0
            res_i, res_r = flag([k < sl for k in steps], f"{pre}row_residual")
            bank_i, bank_r = flag([sl <= k < pb for k in steps], f"{pre}row_bank")
            blast_i, blast_r = flag([sl <= k < pb and (k - sl) % n == n - 1 for k in steps], f"{pre}row_bank_last")
            row_is = [flag([(sl <= k < pb and (k - sl) % n == i) or (obs and p0 < k <= p0 + n and k - p0 - 1 == i) for k in steps],
                           f"{pre}row_state{i}")[1] for i in range(n - 1)]
            # ---- the lane's modes as a rotating chain of state vectors
            chain = [[Signal(signed(bs), name=f"bank{j}_x{i}") for i in range(n)] for j in group]
            tmp = [Signal(signed(bs), name=f"{pre}row_x{i}", reset_less=True) for i in range(n - 1)]
            if obs:
                _, y_r = flag([k == p0 for k in steps], "row_y_hat")
                _, obs_r = flag([p0 < k <= p0 + n for k in steps], "row_observer")
                obs_all_i, _ = flag([p0 <= k <= p0 + n for k in steps], "row_uses_observer", result=False)
                _, olast_r = flag([k == p0 + n for k in steps], "row_observer_last")
                xo = [Signal(signed(bs), name=f"obs_x{i}") for i in range(n)]
                vec = [Signal(signed(bs), name=f"unit_x{i}") for i in range(n)]
                m.d.comb += [v.eq(Mux(obs_all_i, o, h)) for v, o, h in zip(vec, xo, chain[0])]
                sel, ib = Cat(st_next, theta), max(1, iw)  # theta is final from step s_0 + d + 2 <= P - 1
            else:
                obs_r = Const(0, 1)
                vec, sel, ib = chain[0], st_next, 0
            # ---- the row unit
            acc0 = table_mac(m, sel, self._columns(group, obs, stw, ib), vec + [qu, qy], accw, f"{pre}unit", registered=True,
                             product_enable=go if dly else None, shifts=[0] * n + [sh_in, sh_in])
            acc = add_const_signed(m, acc0, 1 << (fc - 1), f"{pre}unit_rnd")
            sink_unused(m, acc[:fc], f"{pre}unit_frac")
            hi = acc[fc:].as_signed()
            low = hi[:rb]  # residual / y_hat rows: exact in rb bits
            if len(hi) > rb:
                sink_unused(m, hi[rb:], f"{pre}unit_out_top")
            new, row_sat = saturate(m, hi, bs, f"{pre}unit_next")
            sat_terms.append(go & (bank_r | obs_r) & row_sat)
            with m.If(go & (bank_r | obs_r)):
                for i in range(n - 1):
                    with m.If(row_is[i]):
                        m.d.sync += tmp[i].eq(new)
            # rotate (residual rows) / push the mode's new vector when its last row is issued
            if dly:  # the last row's result is written into the tail in the next step; row n-2's result is `new` now
                tail = tmp[: n - 2] + [new, chain[0][n - 1]]
                with m.If(go & bank_r & blast_r):
                    m.d.sync += chain[-1][n - 1].eq(new)
            else:
                tail = tmp + [new]
            with m.If(go & (res_i | (bank_i & blast_i))):
                for j in range(sl - 1):
                    m.d.sync += [d.eq(v) for d, v in zip(chain[j], chain[j + 1])]
                with m.If(res_i):
                    m.d.sync += [d.eq(v) for d, v in zip(chain[-1], chain[0])]
                with m.Else():
                    m.d.sync += [d.eq(v) for d, v in zip(chain[-1], tail)]

            # ---- residual register (step k + d) -> square register -> window sum (step k + d + 2)
            mw = bits_for(sl - 1)
            if sl == 1:  # one mode in the lane: its index is 0
                r_mode = Const(0, 1)
            elif dly:
                r_mode = Signal(unsigned(mw), name=f"{pre}row_mode_result")
                with m.If(go):
                    m.d.sync += r_mode.eq(st[:mw])
            else:
                r_mode = st[:mw]
            res = Signal(signed(rb), name=f"{pre}res_reg", reset_less=True)
            wtok = Signal(name=f"{pre}win_tok")
            wj = Signal(unsigned(mw), name=f"{pre}win_mode") if sl > 1 else Const(0, 1)
            m.d.sync += wtok.eq(go & res_r)
            if sl > 1:
                m.d.sync += wj.eq(r_mode)
            with m.If(go & res_r):
                m.d.sync += res.eq(low)
            sqs = var_product(m, res, res, sw, f"{pre}win_sq")
            sq = Signal(unsigned(sw), name=f"{pre}win_sq_reg", reset_less=True)  # the square stage
            wtok2 = Signal(name=f"{pre}win_sum_tok")
            wj2 = Signal(unsigned(mw), name=f"{pre}win_sum_mode") if sl > 1 else Const(0, 1)
            m.d.sync += wtok2.eq(wtok)
            if sl > 1:
                m.d.sync += wj2.eq(wj)
            with m.If(wtok):
                m.d.sync += sq.eq(sqs.as_unsigned())
            sums = [Signal(unsigned(sw), name=f"win_sum{j}") for j in group]
            if est.window == 1:
                s_new = sq
            else:
                s_new = self._window_sum(m, sq, sums[0], wj, wj2, wtok2, transfer, mw, pre)
            with m.If(wtok2):
                m.d.sync += [sums[j].eq(sums[j + 1]) for j in range(sl - 1)] + [sums[-1].eq(s_new)]
            if est.window == 1:
                for j, sm in zip(group, sums):  # the sums are not needed with a window of one sample
                    sink_unused(m, sm, f"win_sum{j}")
            gm = rom(m, wj2, [group[0] + k for k in range(sl)], iw, f"{pre}win_global_mode")
            if ln == 0 and sl > 1:  # a later window step of the sample (lane 0 has the most modes: its first step is the sample's)
                later = Signal(name="det_later_step")
                m.d.comb += later.eq(wj2.any())
            elif ln == 0:
                later = Const(0, 1)
            cands.append((wtok2, s_new, Const(gm, iw) if isinstance(gm, int) else gm))
            if obs:
                lane0 = {"y_r": y_r, "olast_r": olast_r, "xo": xo, "tmp": tmp, "new": new, "low": low, "row_sat": row_sat}

        # ---- detector: running argmin over the lanes (smaller sum, or equal sum and lower mode)
        cur_b, cur_t, have = best, theta, later
        for ln, (v, sn, gmode) in enumerate(cands):
            if ln == 0 and len(groups[0]) == 1:  # one mode per lane: lane 0's only window step is the sample's first
                take = v
            elif len(cands) == 1:  # one lane: the best so far is from a lower mode, a tie keeps it
                take = v & (~have | (sn < cur_b))
            else:  # the best so far may be another lane's higher mode of an earlier step
                lower = (gmode < cur_t) if not isinstance(gmode, Const) else ge_const(cur_t, gmode.value + 1)
                if isinstance(lower, bool):  # no mode above this constant one: a tie keeps the best
                    take = v & (~have | (sn < cur_b))
                else:
                    take = v & (~have | (sn < cur_b) | ((sn == cur_b) & lower))
            nb = Signal(unsigned(sw), name=f"det_best_{ln}")
            nt = Signal(unsigned(iw), name=f"det_theta_{ln}")
            nh = Signal(name=f"det_have_{ln}")
            m.d.comb += [nb.eq(Mux(take, sn, cur_b)), nt.eq(Mux(take, gmode, cur_t)), nh.eq(have | take)]
            cur_b, cur_t, have = nb, nt, nh
        sink_unused(m, have, "det_have")
        with m.If(cands[0][0]):
            m.d.sync += [best.eq(cur_b), theta.eq(cur_t)]

        # ---- saturation, y_hat, the switched observer's commit and the output register (in the last step)
        sat_acc = Signal(name="sat_acc")
        any_sat = Signal(name="row_saturated")
        m.d.comb += any_sat.eq(Cat(*sat_terms).any())
        with m.If(transfer):
            m.d.sync += sat_acc.eq(0)
        with m.Elif(any_sat):
            m.d.sync += sat_acc.eq(1)
        yh = Signal(signed(wd["y_hat"]), name="y_hat_reg", reset_less=True)
        with m.If(go & lane0["y_r"]):
            m.d.sync += yh.eq(lane0["low"])
        with m.If(self.out.ready):
            m.d.sync += self.out.valid.eq(0)
        with m.If(go & last):
            m.d.sync += [d.eq(v) for d, v in zip(lane0["xo"], lane0["tmp"] + [lane0["new"]])]
            m.d.sync += [self.out.valid.eq(1),
                         self.out.payload.eq(Cat(*lane0["xo"], yh, theta, sat_acc | (lane0["row_sat"] & lane0["olast_r"])))]
        return m

    def _window_sum(self, m, sq, head, wj, wj2, wtok2, transfer, mw: int, pre: str):
        """Delay line (one memory per lane, word (mode, slot)) and the running window sum ``S + sq - oldest``."""
        from pwas_hdl.hdl._lintsafe import add_const_wrap, bits_for, ge_const
        from pwas_hdl.hdl.serial_observer_bank import eq_const

        sw = len(sq)
        lw = self.est.window
        slw = bits_for(lw - 1)
        wptr = Signal(unsigned(slw), name=f"{pre}dl_next_slot")
        slot = Signal(unsigned(slw), name=f"{pre}dl_slot")
        cnt = Signal(unsigned(bits_for(lw)), name=f"{pre}dl_count")
        old_valid = Signal(name=f"{pre}dl_old_valid")
        with m.If(transfer):
            m.d.sync += [slot.eq(wptr), wptr.eq(Mux(eq_const(wptr, lw - 1), 0, add_const_wrap(m, wptr, 1, f"{pre}dl_slot_inc"))),
                         old_valid.eq(ge_const(cnt, lw))]
            with m.If(~ge_const(cnt, lw)):
                m.d.sync += cnt.eq(add_const_wrap(m, cnt, 1, f"{pre}dl_count_inc"))
        mem = Memory(shape=unsigned(sw), depth=(1 << mw) * lw, init=[])
        m.submodules[f"{pre}dlmem"] = mem
        rp = mem.read_port(domain="sync")
        rp.addr = Cat(wj, slot)  # the mode's oldest square, read in its square step (used in the next one)
        wp = mem.write_port()
        wp.addr = Cat(wj2, slot)
        wp.data = sq
        wp.en = wtok2
        oldest = Signal(unsigned(sw), name=f"{pre}dl_oldest")
        m.d.comb += oldest.eq(Mux(old_valid, rp.data, 0))
        return sub_wrap(m, add_wrap(m, head, sq, f"{pre}win_sum_add"), oldest, f"{pre}win_sum_next")
