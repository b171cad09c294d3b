"""Observer-bank virtual-sensor top: one (u, y) sample per transfer -> bank -> features -> PWAS core.

Input stream payload (``in__payload``, LSB first): one signed ``B_in``-bit code per signal,
``u0 .. u{nu-1}`` then ``y0``; the code is the *normalised* signal in ``s<B_in>.<F_in>``
(``physical = mean + std * code * 2**-F_in``, :class:`pwas_hdl.fixedpoint.observer_bank.FixedPointObserverBank`).

Pipeline (one global enable ``advance = ~out.valid | out.ready``, ``in.ready = advance``):

* stage ``s_in`` (the transfer of sample ``k``): the input products, and the aligned output code,
  registered; stage ``s_in2``: per observer and state their sum and the rounding constant;
* the next enabled cycle: residuals ``e_j = yhat_j - y`` from the states, registered (stage
  ``s_res``), and the observer updates from ``s_in2`` and the states only (the input products
  are out of the recurrence's path); then the squares ``e_j^2`` registered (stage ``s_sq``);
* stage ``s_sum``: the delay lines and the running sums ``S_j`` (registers);
* ``R`` registers inside each square root ``r_j = isqrt(S_j)`` (11b; one every ``isqrt_every``
  digit steps, :func:`~pwas_hdl.hdl.serial_observer_bank.isqrt_registers`; none for 11b-sq);
* stage ``s_root``: ``r_j`` (11b) or ``S_j`` (11b-sq) registered;
* the affine map to the feature codes: the capped root and the product registered, then the code
  (stage ``s_code``); they feed the PWAS core
  (:meth:`pwas_hdl.hdl.core.PWASCore.build_into`), whose latency follows.

``latency = 9 + R + core latency`` cycles (:data:`~pwas_hdl.hdl.observer_bank_top.FRONT_END_STAGES` + R), II = 1,
one cycle per sample (parallel multipliers).

``architecture="serial"`` (``generate --architecture serial [--bank-lanes L]``): the
time-multiplexed bank and feature unit of :mod:`pwas_hdl.hdl.serial_observer_bank` (``L``
state-update units, rotating state chains, pipelined square root) and the serial core
(:class:`pwas_hdl.hdl.serial_core.SerialPWASCore`); the feature codes double-buffered (staging
registers, then the core's buffer), ``in.ready`` = bank idle or in its last cycle, and fewer than
2 warm samples between the input and the core's take (``features_outstanding``); II =
``cycles_per_sample`` (manifest ``front_end.cycles_per_sample`` / ``ii`` / ``schedule``),
``latency = stages_before_core + core latency``. The same bit-true model, bit for bit.
Warm-up: the first ``M + l`` transfers after reset produce no output (their windows hold observer
start-up residuals; the float front end has no features for them either); ``warm`` is 1 once they
have been taken. ``rst`` (synchronous) clears states, delay lines, sums, the warm-up counter and
the valid bits: the stream restarts as from power-up. The bank's saturation flag
(``state_saturated``, 1 in the cycle where a state saturates, combinational) is not a port: it is
kept for debug as the wires ``unused_state_saturated_flag*``.

The constructor, the manifest parts and the RTL pieces this top shares with the tapped one
(:mod:`pwas_hdl.hdl.observer_tap_sensor_top`) are in :mod:`pwas_hdl.hdl.observer_bank_top`; their
names (:func:`inputs_and_warmup`, :func:`serial_sensor_path`, ...) stay importable from here.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from amaranth.hdl import Cat, Module

from pwas_hdl.errors import InputError
from pwas_hdl.hdl.observer_bank_top import (  # noqa: F401 (public names of this module since issue 12)
    FRONT_END_STAGES,
    ObserverBankTopBase,
    attach_core_and_schedule,
    build_observer_bank_top,
    inputs_and_warmup,
    parallel_feature_codes,
    serial_flow_control,
    serial_sensor_path,
)
from pwas_hdl.hdl.params import CoreParams, Pipeline
from pwas_hdl.hdl.serial_observer_bank import DEFAULT_ISQRT_EVERY

if TYPE_CHECKING:
    from pwas_hdl.fixedpoint.observer_bank import FixedPointObserverBank, ObserverBankSensorModel
    from pwas_hdl.fixedpoint.warp import Pow2Warp

__all__ = ["ObserverSensorTop", "FRONT_END_STAGES", "build_observer_sensor", "attach_core_and_schedule",
           "serial_flow_control", "serial_sensor_path", "inputs_and_warmup", "parallel_feature_codes"]


class ObserverSensorTop(ObserverBankTopBase):
    """Observer bank + residual features + PWAS core.

    Parameters
    ----------
    bank : FixedPointObserverBank
        The bit-true bank and feature unit.
    params : CoreParams
        The PWAS core on the features (``n = N_theta`` inputs of ``bank.input_bits_core`` bits).
    memory, pipeline : as :class:`~pwas_hdl.hdl.core.PWASCore`
    architecture : {"parallel", "serial"}
        Parallel constant-multiplier bank + parallel core (II 1), or the time-multiplexed bank
        + serial core (feature codes double-buffered).
    lanes : int
        Serial bank: state-update units (1 .. N_theta).
    isqrt_every : int or None
        Serial bank: digit steps of the square root between pipeline registers.
    warps : sequence of Pow2Warp, optional
        A non-uniform partition (``breakpoints="quantile-pow2"``): the warp stage in front of the
        core (one more cycle); ``params`` are then the uniform core's and the warps' input width is
        the feature code width.

    Ports: ``clk``, ``rst``, ``in__valid/ready/payload`` (``(nu+1) B_in`` bits), ``out__valid/ready/payload``
    (as the core), ``warm``.

    Attributes: ``core``, ``latency``, ``ii`` and ``cycles_per_sample`` (1 parallel, the schedule's
    serial), ``plan`` (:class:`~pwas_hdl.hdl.serial_observer_bank.SerialBankPlan` or None), ``warmup`` (``M + l``);
    the constructor and the manifest parts are :class:`~pwas_hdl.hdl.observer_bank_top.ObserverBankTopBase`'s.

    Raises
    ------
    InputError
        As :class:`~pwas_hdl.hdl.observer_bank_top.ObserverBankTopBase` (serial ``lanes``,
        ``isqrt_every``).
        ``params.n`` differs from the bank's number of features, ``params.in_width`` from the
        feature code width; or as :class:`~pwas_hdl.hdl.observer_bank_top.ObserverBankTopBase`.
    """

    def __init__(self, bank: FixedPointObserverBank, params: CoreParams, *, memory: str = "banked", pipeline: Pipeline | str | None = None,
                 architecture: str = "parallel", lanes: int = 1, isqrt_every: int | None = DEFAULT_ISQRT_EVERY,
                 warps: Sequence[Pow2Warp] | None = None):
        self._MustUse__silence = True  # no UnusedElaboratable warning when a check refuses
        if params.n != bank.n_models:
            raise InputError(f"the core has n = {params.n} inputs, the bank {bank.n_models} features")
        width = params.in_width if warps is None else warps[0].input_bits  # a warp's input codes are the features'
        if width != bank.input_bits_core:
            raise InputError(f"the core's input width ({width} bits) differs from the feature code width "
                             f"({bank.input_bits_core} bits); build the core from the same observer-bank model")
        super().__init__(bank, params, memory=memory, pipeline=pipeline, architecture=architecture, lanes=lanes,
                         isqrt_every=isqrt_every, warmup=bank.first_output, double_buffered=True, warps=warps)

    def elaborate(self, platform: Any) -> Module:
        """The observer bank, residual features and PWAS core, connected.

        Parameters
        ----------
        platform : Any
            Amaranth build platform; not used.

        Returns
        -------
        Module
            One module: input side and warm-up counter, the bank and feature unit (parallel or
            serial) and the inlined core.
        """
        m = Module()
        cur, inp, advance, transfer = inputs_and_warmup(m, self)
        if self.plan is not None:
            serial_sensor_path(m, self, cur, inp, transfer)
            return m
        codes, valid = parallel_feature_codes(m, self.bank, cur, transfer, advance, self.warm, self.isqrt_every)
        self.core.build_into(m, Cat(*codes), valid, advance, self.out)
        return m


def build_observer_sensor(model: ObserverBankSensorModel, *, memory: str = "banked", pipeline: Pipeline | str | None = None,
                          name: str = "pwas_sensor", architecture: str = "parallel", lanes: int = 1,
                          isqrt_every: int | None = DEFAULT_ISQRT_EVERY) -> ObserverSensorTop:
    """The observer-bank sensor top of a bit-true :class:`~pwas_hdl.fixedpoint.observer_bank.ObserverBankSensorModel`.

    Parameters
    ----------
    model : ObserverBankSensorModel
        ``.bank`` (the front end), ``.core`` (the core's ``FixedPointModel``), ``.error_bound``,
        ``.lipschitz``.
    memory, pipeline, architecture, lanes, isqrt_every
        As :class:`ObserverSensorTop`.
    name : str
        Verilog module name.

    Returns
    -------
    ObserverSensorTop
        ``.latency`` and ``.ii`` (cycles), ``.cycles_per_sample``, ``.warmup`` (= M + l samples),
        ``.core``.

    Raises
    ------
    InputError
        As :class:`ObserverSensorTop`.
        ``name`` is not a plain Verilog identifier, or as :class:`ObserverSensorTop`.
    """
    return build_observer_bank_top(
        ObserverSensorTop, model.bank, model, memory=memory, pipeline=pipeline, name=name, architecture=architecture,
        lanes=lanes, isqrt_every=isqrt_every,
        bound_rule="core bound + sum_j G_j * feature bound_j (G_j: largest edge slope along j)",
        bound_against="float sensor (front end + PWAS) at the physical signals the input codes represent")
