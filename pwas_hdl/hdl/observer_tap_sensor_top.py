"""Observer-bank sensor top with u/y taps (issue 12): bank features and lag taps side by side into the core.

Bit for bit :class:`pwas_hdl.fixedpoint.bank_taps.TappedObserverBankSensorModel`. The same front
end as :class:`pwas_hdl.hdl.observer_sensor_top.ObserverSensorTop` (built from the same pieces:
:func:`~pwas_hdl.hdl.observer_bank.build_observer_bank`, the window sums, the integer square
root, the feature codes), plus a lag bank of the input codes (payload fields
:func:`pwas_hdl.hdl.sensor_top.sample_fields`, the bank's normalised ``s<B_in>.<F_in>`` codes):

* per tapped signal with largest lag ``L``, ``L + 1`` registers shifted on every input transfer
  (after the transfer of sample ``k`` register ``d`` holds sample ``k - d``; 0 after reset) -- in
  step with the bank's first input stage ``s_in``;
* the tap's affine map to the core's input code (``sat((qn * K + C) >> R)``, constants of
  :class:`~pwas_hdl.fixedpoint.bank_taps.BankTaps`), registered (beside ``s_in2``), then ``R + 7`` more registers beside
  the features' (``stages_before_core - 2``: the residual, square and sum stages, the ``R`` inside
  the square root, the root register, the affine map's two and the code register);
* the core takes ``Cat(feature codes, tap codes)``, the regressor order of the model.

``latency = 9 + R + core latency``, II 1, one cycle per sample; warm-up ``max(M + l, memory - 1)``
transfers (output ``warm``).

``architecture="serial"`` (``generate --architecture serial [--bank-lanes L]``): the serial
observer-sensor top's body (:func:`pwas_hdl.hdl.observer_bank_top.serial_sensor_path`: the
time-multiplexed bank, the pending feature codes, the serial core) with the same lag registers
(shifted on the input transfer, so in step with the serial schedule: they hold sample ``k`` from
the cycle after its transfer until the next transfer, which waits for the core to take sample
``k``'s inputs) and the tap codes registered in the cycle the bank writes its last feature code
(``bank_features_done``), held with the feature codes until the core takes them. II =
``cycles_per_sample`` of the schedule (the serial core now has ``N_theta + taps + 1`` cycles per
sample), ``latency = stages_before_core + core latency``. The bit-true model is the same.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from amaranth.hdl import Cat, Module, Signal, signed

from pwas_hdl.errors import InputError
from pwas_hdl.hdl._lintsafe import sink_unused
from pwas_hdl.hdl.observer_bank import add_const_signed, const_product, saturate
from pwas_hdl.hdl.observer_bank_top import (
    ObserverBankTopBase,
    build_observer_bank_top,
    advance_registers,
    inputs_and_warmup,
    parallel_feature_codes,
    serial_sensor_path,
)
from pwas_hdl.hdl.params import CoreParams, Pipeline
from pwas_hdl.hdl.serial_observer_bank import DEFAULT_ISQRT_EVERY

if TYPE_CHECKING:
    from pwas_hdl.fixedpoint.bank_taps import TappedObserverBankSensorModel
    from pwas_hdl.fixedpoint.warp import Pow2Warp

__all__ = ["ObserverTapSensorTop", "build_tapped_observer_sensor"]


class ObserverTapSensorTop(ObserverBankTopBase):
    """Observer bank + residual features + u/y taps + PWAS core (ports as :class:`ObserverSensorTop`).

    Parameters
    ----------
    model : TappedObserverBankSensorModel
        The bit-true model: ``.bank``, ``.taps`` (:class:`~pwas_hdl.fixedpoint.bank_taps.BankTaps`),
        ``.first_output``.
    params : CoreParams
        The core on ``[features, taps]``: ``n = N_theta + len(taps.dims)`` inputs.
    memory, pipeline : as :class:`~pwas_hdl.hdl.core.PWASCore`
    architecture, lanes, isqrt_every : as :class:`~pwas_hdl.hdl.observer_sensor_top.ObserverSensorTop`
        (serial: single-buffered feature codes).
    warps : sequence of Pow2Warp, optional
        A non-uniform partition: the warp stage in front of the core (features and taps are the
        warps' ``B_in``-bit input codes; ``params`` the uniform core's).

    The constructor and the manifest parts are :class:`~pwas_hdl.hdl.observer_bank_top.ObserverBankTopBase`'s;
    this top adds the taps (``front_end.taps``, their error bound) and its warm-up
    ``max(M + l, memory - 1)`` samples.

    Raises
    ------
    InputError
        As :class:`~pwas_hdl.hdl.observer_bank_top.ObserverBankTopBase` (serial ``lanes``,
        ``isqrt_every``).
        ``params.n`` is not the bank's features plus the taps, or as
        :class:`~pwas_hdl.hdl.observer_bank_top.ObserverBankTopBase`.
    """

    def __init__(self, model: TappedObserverBankSensorModel, params: CoreParams, *, memory: str = "banked", pipeline: Pipeline | str | None = None,
                 architecture: str = "parallel", lanes: int = 1, isqrt_every: int | None = DEFAULT_ISQRT_EVERY,
                 warps: Sequence[Pow2Warp] | None = None):
        self._MustUse__silence = True  # no UnusedElaboratable warning when the check refuses
        bank, taps = model.bank, model.taps
        if params.n != bank.n_models + len(taps.dims):
            raise InputError(f"the core has n = {params.n} inputs, the bank {bank.n_models} features and {len(taps.dims)} taps")
        self.model = model
        self.taps = taps
        super().__init__(bank, params, memory=memory, pipeline=pipeline, architecture=architecture, lanes=lanes,
                         isqrt_every=isqrt_every, warmup=int(model.first_output), warps=warps)

    def _architecture_more(self) -> str:
        return "u/y taps from a lag bank of the input codes, requantised to the core's tap inputs"

    def _front_end_more(self) -> dict:
        return {"taps": self.taps.to_dict()}

    def _error_bound_more(self) -> dict:
        return {"taps": list(self.taps.error_bound)}

    def _warmup_meaning(self) -> str:
        return (f"warm = 1 once max(M + l, memory - 1) = {self.warmup} samples have been taken since reset; the first "
                f"{self.warmup} transfers after reset produce no output, every later transfer produces one")

    def _tap_codes(self, m: Module, cur: list, transfer, advance, delay: int = 0) -> list:
        """Lag registers of the tapped signals (shift on transfer) and the tap codes, registered when
        ``advance`` (``delay`` more such registers: the parallel bank's stages after its root register)."""
        taps, b = self.taps, self.bank.input_bits
        depth: dict[int, int] = {}
        for s, lag in taps.dims:
            depth[s] = max(depth.get(s, 0), lag)
        regs = {s: [Signal(signed(b), name=f"tap_{self.signals[s]}_d{d}") for d in range(n + 1)] for s, n in depth.items()}
        with m.If(transfer):
            for s, rr in regs.items():
                m.d.sync += rr[0].eq(cur[s])
                m.d.sync += [rr[d].eq(rr[d - 1]) for d in range(1, len(rr))]
        out = []
        for j, ((s, lag), k, c) in enumerate(zip(taps.dims, taps.mul, taps.add)):
            prod = const_product(m, int(k), regs[s][lag], taps.product_bits, f"tap{j}_prod")
            tot = add_const_signed(m, prod, int(c), f"tap{j}_affine")
            sink_unused(m, tot[: taps.shift], f"tap{j}_affine_frac")
            q, _ = saturate(m, tot[taps.shift :].as_signed(), taps.core_bits, f"tap{j}_q", flag=False)
            reg = Signal(signed(taps.core_bits), name=f"s_root_tap{j}", reset_less=True)
            with m.If(advance):
                m.d.sync += reg.eq(q)
            out.append(advance_registers(m, reg, delay, advance, f"s_code_tap{j}"))
        return out

    def elaborate(self, platform: Any) -> Module:
        """The observer bank, residual features, u/y taps and PWAS core, connected.

        Parameters
        ----------
        platform : Any
            Amaranth build platform; not used.

        Returns
        -------
        Module
            One module: input side and warm-up counter, bank and feature unit, tap lag registers
            and codes, and the inlined core.
        """
        m = Module()
        cur, inp, advance, transfer = inputs_and_warmup(m, self)
        if self.plan is not None:  # serial bank: the tap codes registered with the last feature code (done)
            serial_sensor_path(m, self, cur, inp, transfer, lambda done: self._tap_codes(m, cur, transfer, done))
            return m
        codes, valid = parallel_feature_codes(m, self.bank, cur, transfer, advance, self.warm, self.isqrt_every)
        # the taps wait beside the bank's stages (their lag and code registers stand for s_in and s_in2,
        # the stages_before_core - 2 more for s_res .. s_code)
        taps = self._tap_codes(m, cur, transfer, advance, self.stages_before_core - 2)
        self.core.build_into(m, Cat(*codes, *taps), valid, advance, self.out)
        return m


def build_tapped_observer_sensor(model: TappedObserverBankSensorModel, *, memory: str = "banked", pipeline: Pipeline | str | None = None,
                                 name: str = "pwas_sensor", architecture: str = "parallel", lanes: int = 1,
                                 isqrt_every: int | None = DEFAULT_ISQRT_EVERY) -> ObserverTapSensorTop:
    """The top of a bit-true :class:`~pwas_hdl.fixedpoint.bank_taps.TappedObserverBankSensorModel`
    (``architecture="serial"``: the time-multiplexed bank with ``lanes`` state-update units).

    Parameters
    ----------
    model : TappedObserverBankSensorModel
        ``.bank``, ``.taps``, ``.core`` (the core's ``FixedPointModel``), ``.error_bound``,
        ``.lipschitz``.
    memory, pipeline, architecture, lanes, isqrt_every
        As :class:`ObserverTapSensorTop`.
    name : str
        Verilog module name.

    Returns
    -------
    ObserverTapSensorTop
        ``.latency`` and ``.ii`` (cycles), ``.cycles_per_sample``, ``.warmup`` (samples),
        ``.core``, ``.estimate_bound``.

    Raises
    ------
    InputError
        As :class:`ObserverTapSensorTop`.
        ``name`` is not a plain Verilog identifier, or as :class:`ObserverTapSensorTop`.
    """
    return build_observer_bank_top(
        ObserverTapSensorTop, model, model, memory=memory, pipeline=pipeline, name=name, architecture=architecture,
        lanes=lanes, isqrt_every=isqrt_every,
        bound_rule="core bound + sum_j G_j * (feature or tap) bound_j (G_j: largest edge slope along j)",
        bound_against="float sensor (front end + taps + PWAS) at the physical signals the input codes represent")
