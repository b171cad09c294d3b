"""The shared part of the observer-bank sensor tops (seed 004 front end + PWAS core).

Two tops use it: :class:`pwas_hdl.hdl.observer_sensor_top.ObserverSensorTop` (the bank's residual
features into the core, "P-feat") and :class:`pwas_hdl.hdl.observer_tap_sensor_top.ObserverTapSensorTop`
(the features and u/y lag taps side by side, issue 12). What they share lives here, once:

* :class:`ObserverBankTopBase`: the component's constructor (core and schedule, latency, ports
  ``in`` / ``out`` / ``warm``), its payload fields, the manifest parts (``front_end``, ``warmup``),
  the flow-control words and the number of outputs a stream produces;
* :func:`build_observer_bank_top`: the builder's common steps (module name, core names, the
  estimate's error bound);
* the RTL pieces of :meth:`elaborate`: :func:`inputs_and_warmup` (payload codes, handshake, the
  warm-up counter), :func:`parallel_feature_codes` (the parallel bank's :data:`FRONT_END_STAGES`
  registers), :func:`attach_core_and_schedule` (parallel core, or the serial core behind the
  time-multiplexed bank), :func:`serial_sensor_path` and :func:`serial_flow_control` (the serial
  bank's body and its ``in.ready`` rule).

The names stay importable from :mod:`pwas_hdl.hdl.observer_sensor_top`, where they were first.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from amaranth.hdl import Cat, Module, Signal, Value, unsigned
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from pwas_hdl.errors import InputError, InternalError, choice_text, option_text
from pwas_hdl.hdl._lintsafe import add_const_wrap, ge_const, sink_unused
from pwas_hdl.hdl.core import PWASCore, core_output_layout
from pwas_hdl.hdl.observer_bank import INPUT_STAGES, advance_registers, build_observer_bank
from pwas_hdl.hdl.params import CoreParams, Pipeline
from pwas_hdl.hdl.residual_features import build_feature_codes, build_window_sums
from pwas_hdl.hdl.sensor_top import sample_fields
from pwas_hdl.hdl.serial_observer_bank import (AFFINE_REGS, DEFAULT_ISQRT_EVERY, build_isqrt_pipelined, build_serial_front_end,
                                               check_isqrt_every, isqrt_registers, plan_serial_bank)

if TYPE_CHECKING:
    from pwas_hdl.fixedpoint.observer_bank import FixedPointObserverBank

__all__ = ["ObserverBankTopBase", "build_observer_bank_top", "FRONT_END_STAGES", "BANK_INPUT_STAGES", "attach_core_and_schedule",
           "serial_flow_control", "serial_sensor_path", "inputs_and_warmup", "parallel_feature_codes", "advance_registers"]

#: Of the parallel bank's stages, those in front of the window sums: the input stages in front of the
#: state update (``s_in``, ``s_in2``, :data:`~pwas_hdl.hdl.observer_bank.INPUT_STAGES`), the residual
#: register ``s_res`` and the square register ``s_sq``.
BANK_INPUT_STAGES = INPUT_STAGES + 2
#: Pipeline stages in front of the core of the parallel bank (:data:`BANK_INPUT_STAGES`, the sum
#: registers, the root register, the affine map's registers -- the capped root and the product,
#: :data:`~pwas_hdl.hdl.serial_observer_bank.AFFINE_REGS` as in the serial bank -- and the
#: feature-code register), besides the registers inside the square root
#: (:func:`~pwas_hdl.hdl.serial_observer_bank.isqrt_registers`).
FRONT_END_STAGES = BANK_INPUT_STAGES + 3 + AFFINE_REGS


class ObserverBankTopBase(wiring.Component):
    """What every observer-bank sensor top has: bank, core, schedule, ports, manifest parts.

    Parameters
    ----------
    bank : FixedPointObserverBank
        The bit-true bank (its ``signal_names`` and ``input_bits`` give the input payload).
    params : CoreParams
        The PWAS core's parameters.
    memory, pipeline : as :class:`~pwas_hdl.hdl.core.PWASCore`
    architecture : {"parallel", "serial"}
        Parallel constant-multiplier bank + parallel core (II 1), or the time-multiplexed bank
        + serial core (:func:`attach_core_and_schedule`).
    lanes : int
        Serial bank: state-update units (1 .. N_theta).
    isqrt_every : int or None
        Digit steps of each feature's square root between pipeline registers (map 11b; serial and
        parallel bank); None: the root in one cycle.
    warmup : int
        Transfers after reset that produce no output (``warm`` is 1 once they have been taken).
    double_buffered : bool
        Serial bank: the feature codes double-buffered (:func:`serial_sensor_path`).
    warps : sequence of Pow2Warp, optional
        A non-uniform partition's warps, one per core input (:func:`pwas_hdl.hdl.warp.attach_warp`):
        the warp and its register go in front of the core (one more cycle of latency), whose
        ``params`` are then the uniform core's; the feature codes are the warps' ``B_in``-bit inputs.

    Ports: ``clk``, ``rst``, ``in__valid/ready/payload`` (``(nu+1) B_in`` bits), ``out__valid/ready/payload``
    (as the core), ``warm``.

    Attributes: ``bank``, ``core``, ``params``, ``latency``, ``ii`` and ``cycles_per_sample`` (1
    parallel, the schedule's serial), ``plan`` (:class:`~pwas_hdl.hdl.serial_observer_bank.SerialBankPlan`
    or None), ``warmup``, ``signals`` (payload signal names), ``estimate_bound`` (set by
    :func:`build_observer_bank_top`).

    A subclass checks its core's inputs, then calls this constructor; it may add to the manifest
    with :meth:`_architecture_more`, :meth:`_front_end_more`, :meth:`_error_bound_more` and
    :meth:`_warmup_meaning`, and writes :meth:`elaborate`.

    Raises
    ------
    InputError
        Serial: ``lanes`` or ``isqrt_every`` out of range
        (:func:`~pwas_hdl.hdl.serial_observer_bank.plan_serial_bank`).
        An unknown ``architecture``, or parameters the core refuses.
    """

    kind = "observer-sensor"
    #: the manifest's ``warp`` entry of a non-uniform partition (:func:`pwas_hdl.hdl.warp.warp_hw_info`),
    #: set by :func:`build_observer_bank_top`
    warp_entry = None

    def __init__(self, bank: FixedPointObserverBank, params: CoreParams, *, memory: str = "banked",
                 pipeline: Pipeline | str | None = None, architecture: str = "parallel", lanes: int = 1,
                 isqrt_every: int | None = DEFAULT_ISQRT_EVERY, warmup: int, double_buffered: bool = False,
                 warps: Sequence[Any] | None = None):
        self._MustUse__silence = True
        self.bank = bank
        attach_core_and_schedule(self, bank, params, memory=memory, pipeline=pipeline, architecture=architecture,
                                 lanes=lanes, isqrt_every=isqrt_every, double_buffered=double_buffered)
        self.warps = None
        if warps is not None:  # non-uniform partition: the warp stage in front of the core (pwas_hdl.hdl.warp)
            from pwas_hdl.hdl.warp import attach_warp

            self.warps = list(warps)
            attach_warp(self.core, self.warps)
        self.params = params
        self.latency = self.stages_before_core + self.core.latency
        self.memory_plan = self.core.memory_plan
        self.pipeline = self.core.pipeline
        self.warmup = warmup
        self.signals = list(bank.signal_names)
        #: per target |estimate - float sensor| bound (physical), set by build_observer_bank_top
        self.estimate_bound = None
        super().__init__(
            {
                "in": In(stream.Signature(unsigned(len(self.signals) * bank.input_bits))),
                "out": Out(stream.Signature(unsigned(core_output_layout(params).size))),
                "warm": Out(1),
            }
        )
        self._MustUse__silence = False

    @property
    def input_fields(self) -> list[dict]:
        """Input payload fields, one signed ``bank.input_bits``-bit code per signal (:func:`sample_fields`)."""
        return sample_fields(self.signals, self.bank.input_bits)

    # --- what a subclass adds to the manifest
    def _architecture_more(self) -> str | None:
        """Words appended (after ``"; "``) to the front end's ``architecture``."""
        return None

    def _front_end_more(self) -> dict:
        """Entries of ``front_end`` after the bank's own."""
        return {}

    def _error_bound_more(self) -> dict:
        """Entries of ``front_end.error_bound`` between the bank's and ``estimate``."""
        return {}

    def _warmup_meaning(self) -> str:
        """``warmup.meaning`` of the manifest."""
        return ("warm = 1 once M + l samples have been taken since reset; the first M + l transfers "
                "after reset produce no output, every later transfer produces one")

    @property
    def extra_info(self) -> dict:
        """The manifest's ``front_end`` (schedule, bank, error bounds) and ``warmup``."""
        arch = ("parallel constant multipliers, one state update of every observer per input transfer"
                if self.plan is None else
                f"time-multiplexed: {len(self.plan.lanes)} state-update unit(s) (lanes), one state update per lane "
                "per clock, rotating state chains, one squarer / square root / code multiplier per lane")
        more = self._architecture_more()
        fe = {
            "kind": "observer-bank",
            "architecture": arch if more is None else f"{arch}; {more}",
            "bank": self.architecture,
            "cycles_per_sample": self.cycles_per_sample,
            "ii": self.ii,
            "stages_before_core": self.stages_before_core,
            **({"schedule": self.plan.to_dict()} if self.plan is not None else
               {"isqrt_every": self.isqrt_every, "isqrt_registers": self.isqrt_regs}),
            **self.bank.to_dict(),
            **self._front_end_more(),
        }
        fe["first_output_sample"] = self.warmup
        fe["error_bound"] = {**fe["error_bound"], **self._error_bound_more(), "estimate": self.estimate_bound}
        return {
            "front_end": fe,
            "warmup": {"samples_without_output": self.warmup, "port": "warm", "meaning": self._warmup_meaning()},
            **({"warp": self.warp_entry} if self.warp_entry is not None else {}),
        }

    def flow_control(self, names: dict) -> dict:
        """The handshake rules in words; the serial bank throttles the input.

        Parameters
        ----------
        names : dict of str to str
            Port name by role (:func:`~pwas_hdl.hdl.emit.port_names`).

        Returns
        -------
        dict of str to str
            As :func:`serial_flow_control`: ``{in.ready port: rule}``, empty for the parallel bank.
        """
        return serial_flow_control(self, names)

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


def build_observer_bank_top(cls: type[ObserverBankTopBase], first: Any, model: Any, *, memory: str = "banked",
                            pipeline: Pipeline | str | None = None, name: str = "pwas_sensor",
                            architecture: str = "parallel", lanes: int = 1,
                            isqrt_every: int | None = DEFAULT_ISQRT_EVERY, bound_rule: str,
                            bound_against: str) -> ObserverBankTopBase:
    """An observer-bank top ``cls(first, CoreParams.from_model(model.core), ...)`` of a bit-true sensor model.

    Parameters
    ----------
    cls : type
        A subclass of :class:`ObserverBankTopBase`.
    first : object
        The top's first constructor argument (the bank, or the whole model).
    model : ObserverBankSensorModel or TappedObserverBankSensorModel
        Bit-true sensor model: ``.core`` (the core's ``FixedPointModel``), ``.error_bound``
        (``nz`` values, physical units), ``.lipschitz`` (ndarray ``(n,)``).
    memory, pipeline, architecture, lanes, isqrt_every
        As the top's constructor.
    name : str
        Verilog module name (checked).
    bound_rule, bound_against : str
        The words of ``estimate_bound`` (how the bound adds up, against what).

    Returns
    -------
    ObserverBankTopBase
        The ``cls`` instance with ``module_name``, the core's ``input_names`` / ``target_names``
        and ``estimate_bound`` (``physical``, ``lipschitz``, ``rule``, ``against``) set.

    Raises
    ------
    InputError
        ``name`` is not a plain Verilog identifier, or as the top's constructor.
    """
    from pwas_hdl.hdl.api import _check_name

    name = _check_name(name)
    warps = getattr(model.core, "warps", None)  # a WarpedFixedPointModel: the warp, then its uniform core
    uniform = model.core.core if warps is not None else model.core
    top = cls(first, CoreParams.from_model(uniform), memory=memory, pipeline=pipeline,
              architecture=architecture, lanes=lanes, isqrt_every=isqrt_every,
              **({"warps": warps} if warps is not None else {}))
    if warps is not None:
        from pwas_hdl.hdl.warp import warp_hw_info

        top.warp_entry = warp_hw_info(model.core)
    top.module_name = name
    top._MustUse__silence = True
    top.core.input_names = list(model.core.regressor_names)
    top.core.target_names = list(model.core.target_names)
    top.estimate_bound = {"physical": list(model.error_bound), "lipschitz": model.lipschitz.tolist(),
                          "rule": bound_rule, "against": bound_against}
    return top


def inputs_and_warmup(m: Module, top: ObserverBankTopBase) -> tuple[list[Value], Any, Signal, Signal]:
    """The input side shared by the observer-bank tops: the payload's signed sample codes ``cur``
    (one per signal of ``top.signals``, ``top.bank.input_bits`` each), ``advance`` (= ``in.ready``,
    driven by the core), ``transfer`` (``in.valid & advance``) and the saturating warm-up counter
    0 .. ``top.warmup`` that drives ``top.warm``.

    Parameters
    ----------
    m : Module
        Module the logic is added to (the counter ``warmup_count`` in ``sync``).
    top : ObserverBankTopBase
        The top being elaborated (its ``in`` stream, ``warm`` port, ``signals``, ``warmup``).

    Returns
    -------
    cur : list of Value
        Signed ``top.bank.input_bits``-bit codes, one per signal, payload order.
    in : stream interface
        The top's input stream (``getattr(top, "in")``).
    advance : Signal
        ``in.ready`` itself (not driven here).
    transfer : Signal
        1 bit, ``in.valid & advance``.
    """
    b = top.bank.input_bits
    inp = getattr(top, "in")
    cur = [inp.payload[i * b : (i + 1) * b].as_signed() for i in range(len(top.signals))]
    advance = inp.ready  # the core drives it: ~out.valid | out.ready (one net, no alias)
    transfer = Signal(name="transfer")
    m.d.comb += transfer.eq(inp.valid & advance)

    # warm-up counter 0 .. M + l (saturating)
    wu = top.warmup
    cw = max(1, wu.bit_length())
    cnt = Signal(unsigned(cw), name="warmup_count")
    full = ge_const(cnt, wu)
    m.d.comb += top.warm.eq(full)
    inc = add_const_wrap(m, cnt, 1, "warmup_inc")
    with m.If(transfer & ~top.warm):
        m.d.sync += cnt.eq(inc)
    return cur, inp, advance, transfer


def parallel_feature_codes(m: Module, bank: FixedPointObserverBank, cur: list, transfer: Value, advance: Value,
                           warm: Value, isqrt_every: int | None = DEFAULT_ISQRT_EVERY) -> tuple[list, Signal]:
    """The parallel bank's feature path (:data:`FRONT_END_STAGES` registers + those inside the square
    root, all loading with ``advance``): the input stages and the observer bank (stages ``s_in`` and
    ``s_in2``: the input products and their sum registered in front of the state update), the
    residuals (stage ``s_res``) and their squares (stage ``s_sq``),
    window sums (stage ``s_sum``), square root or not (map 11b: a register after every
    ``isqrt_every`` digit steps) and its register (stage ``s_root``), the affine map with its capped
    root and product registered (``s_code_cap<j>``, ``s_code_prod<j>``), feature codes (``s_code``).

    Parameters
    ----------
    m : Module
        Module the logic is added to.
    bank : FixedPointObserverBank
        The bit-true bank.
    cur : list of Value
        Signed ``bank.input_bits``-bit codes ``u0 .. u{nu-1}, y0`` (:func:`inputs_and_warmup`).
    transfer : Value
        1 bit, the input transfer (the sample enters stage ``s_in``).
    advance : Value
        1 bit, the core's enable: every register of the path loads when it is high (the states,
        delay lines and sums when a valid sample leaves the stage in front of them).
    warm : Value
        1 bit: a transfer while it is high yields an output (its ``warm`` bit travels with it).
    isqrt_every : int or None
        Digit steps of the square root between registers (None: combinational, one cycle).

    Returns
    -------
    codes : list of Signal
        ``N`` feature codes, signed ``bank.input_bits_core`` bits: the core's inputs.
    valid : Signal
        Their valid bit (``s_code_valid``), :data:`FRONT_END_STAGES` + :func:`isqrt_registers`
        (enabled) cycles after the transfer.
    """
    residuals, _sat, _states, update = build_observer_bank(m, bank, cur[: bank.nu], cur[bank.nu], transfer, advance)
    sink_unused(m, _sat, "state_saturated_flag")
    # update = s_in2_valid & advance; the residuals and their squares registered (s_res, s_sq)
    sq_valid = advance_registers(m, advance_registers(m, update, 1, advance, "s_res_valid"), 1, advance, "s_sq_valid")
    sum_update = Signal(name="sum_update")
    m.d.comb += sum_update.eq(sq_valid & advance)
    sums = build_window_sums(m, bank, residuals, sum_update, stage_enable=advance)
    # the sample's warm bit (at its transfer) beside it through s_in and s_sq, then stage s_sum
    v1 = advance_registers(m, advance_registers(m, transfer & warm, BANK_INPUT_STAGES, advance, "s_in_warm"),
                           1, advance, "s_sum_valid")
    # the square root (its registers load with the core's enable, as every stage here) and stage s_root
    nreg = isqrt_registers(bank, isqrt_every)
    roots = []
    for j, s in enumerate(sums):
        if bank.feature_map == "11b":
            r, got = build_isqrt_pipelined(m, s, f"feat{j}_isqrt", isqrt_every, enable=advance)
            if got != nreg:
                raise InternalError(f"the square root has {got} registers, the schedule counted {nreg}")
        else:
            r = s
        reg = Signal(unsigned(len(r)), name=f"s_root_r{j}", reset_less=True)
        with m.If(advance):
            m.d.sync += reg.eq(r)
        roots.append(reg)
    v = advance_registers(m, v1, nreg, advance, "s_isqrt_valid")  # the valid bit beside the root's registers
    v2 = Signal(name="s_root_valid")
    with m.If(advance):
        m.d.sync += v2.eq(v)
    # stage s_code: the feature codes (the affine map's product and saturation) registered
    qs = build_feature_codes(m, bank, roots, stage_enable=advance)  # the capped root and the product registered
    codes = [advance_registers(m, q, 1, advance, f"s_code_q{j}") for j, q in enumerate(qs)]
    return codes, advance_registers(m, v2, 1 + AFFINE_REGS, advance, "s_code_valid")


def attach_core_and_schedule(top: Any, bank: FixedPointObserverBank, params: CoreParams, *, memory: str,
                             pipeline: Pipeline | str | None, architecture: str, lanes: int,
                             isqrt_every: int | None, double_buffered: bool = False) -> None:
    """Set the core and the schedule of an observer-bank top (``top.architecture``, ``core``, ``plan``,
    ``stages_before_core``, ``ii``, ``cycles_per_sample``): the parallel core behind the
    :data:`FRONT_END_STAGES` registers (II 1), or the serial core behind the time-multiplexed bank
    (:func:`~pwas_hdl.hdl.serial_observer_bank.plan_serial_bank`: II = cycles_per_sample;
    ``double_buffered``: the feature codes double-buffered, :func:`serial_sensor_path`).

    Parameters
    ----------
    top : ObserverBankTopBase
        The top under construction; the attributes above are set on it.
    bank : FixedPointObserverBank
        The bit-true bank (for the serial schedule).
    params : CoreParams
        The core's parameters.
    memory : {"banked", "replicated", "corner"}
        Weight memory layout of the parallel core (the serial core has its own).
    pipeline : Pipeline, preset name or None
        The core's pipeline.
    architecture : {"parallel", "serial"}
        Parallel bank and core, or serial bank and core.
    lanes : int
        Serial: state-update units, ``1 .. N_theta``.
    isqrt_every : int or None
        Digit steps of the square root between registers (serial and parallel bank).
    double_buffered : bool
        Serial: double-buffered feature codes.

    Raises
    ------
    InputError
        ``isqrt_every`` not a positive integer or None; serial: ``lanes`` out of range
        (:func:`plan_serial_bank`).
        An unknown ``architecture``, or what the core refuses.
    """
    if architecture not in ("parallel", "serial"):
        raise InputError(choice_text(option_text("architecture"), ("parallel", "serial"), architecture))
    top.architecture = architecture
    check_isqrt_every(isqrt_every)
    top.isqrt_every = isqrt_every if bank.feature_map == "11b" else None
    top.isqrt_regs = isqrt_registers(bank, isqrt_every)  # inside each square root (the serial plan counts the same)
    if architecture == "serial":  # time-multiplexed bank + serial core (pwas_hdl.hdl.serial_observer_bank)
        from pwas_hdl.hdl.serial_core import SerialPWASCore

        top.core = SerialPWASCore(params, pipeline=pipeline)
        top.core._MustUse__silence = True
        top.plan = plan_serial_bank(bank, lanes, isqrt_every, top.core.ii, double_buffered=double_buffered)
        top.stages_before_core = top.plan.stages_before_core
        top.ii = top.cycles_per_sample = top.plan.cycles_per_sample
        # why II is not the serial core's (the manifest's architecture.meaning, serial_core.architecture_info)
        top.ii_meaning = "the time-multiplexed observer bank's cycles per sample (front_end.cycles_per_sample)"
    else:
        top.core = PWASCore(params, memory=memory, pipeline=pipeline)
        top.plan = None
        top.stages_before_core = FRONT_END_STAGES + top.isqrt_regs
        top.ii = top.cycles_per_sample = 1
    top.core._MustUse__silence = True


def serial_flow_control(top: ObserverBankTopBase, names: dict) -> dict:
    """``in.ready``'s rule in words for a top with the serial bank (``{}`` for the parallel one).

    Parameters
    ----------
    top : ObserverBankTopBase
        Its ``plan`` (None: parallel) and ``ii`` (cycles) are read.
    names : dict of str to str
        Port name by role (``in.ready``, ``out.valid``, ``out.ready``; :func:`~pwas_hdl.hdl.emit.port_names`).

    Returns
    -------
    dict of str to str
        ``{in.ready port name: rule}``, or ``{}`` for the parallel bank.
    """
    if top.plan is None:
        return {}
    ir, ov, orr = names["in.ready"], names["out.valid"], names["out.ready"]
    return {ir: f"bank idle or in its last cycle, and the previous sample's feature codes taken by the core: one transfer "
                f"every {top.ii} cycles at most (II = cycles_per_sample); low while the bank is busy or while "
                f"{ov} & ~{orr} holds the core"}


def serial_sensor_path(m: Module, top: ObserverBankTopBase, cur: list, inp: Any, transfer: Value,
                       extra_codes: Callable[[Signal], Sequence[Value]] | None = None) -> None:
    """The serial top's body: time-multiplexed bank (:func:`build_serial_front_end`), the pending
    feature codes and the serial core; ``in.ready`` = bank free & (no pending codes | the core takes
    them now).

    ``extra_codes(done)``, if given, returns more core inputs (after the feature codes, in the
    core's input order) that must be valid from the cycle after ``done`` (the last feature code of
    a warm sample written) until the core takes them: e.g. the u/y tap codes registered on ``done``
    (single-buffered plans only).

    Double-buffered plan (``top.plan.double_buffered``): the core reads a second set of code
    registers, loaded at ``done`` when it is free (or taken in that cycle), else held in the
    staging registers (``features_held``) and loaded in the cycle the core takes the previous
    codes; ``in.ready`` = bank free & (fewer than 2 warm samples between the input and the core's
    take | the core takes one now), so no sample's codes are overwritten under backpressure.

    Parameters
    ----------
    m : Module
        Module the logic is added to.
    top : ObserverBankTopBase
        A top with the serial bank (``top.plan`` set); its core, ``warm``, ``out`` are used.
    cur : list of Value
        Signed ``bank.input_bits``-bit codes ``u0 .. y0`` (:func:`inputs_and_warmup`).
    inp : stream interface
        The top's input stream (``in.ready`` driven here).
    transfer : Value
        1 bit, the input transfer.
    extra_codes : callable, optional
        ``extra_codes(done) -> sequence of Value`` (see above).

    Raises
    ------
    InputError
        ``extra_codes`` with a double-buffered plan; or ``buffer_load`` / plan mismatch in
        :func:`build_serial_front_end`.
    """
    sample_warm = Signal(name="bank_sample_warm")
    with m.If(transfer):
        m.d.sync += sample_warm.eq(top.warm)
    db = top.plan.double_buffered
    if db and extra_codes is not None:
        raise InternalError("extra core inputs need the single-buffered serial plan")
    load = Signal(name="features_load") if db else None
    codes, done, free = build_serial_front_end(m, top.bank, top.plan, cur, transfer, sample_warm, buffer_load=load)
    if db:
        _double_buffer_control(m, top, inp, transfer, codes, done, free, load)
        return
    extra = list(extra_codes(done)) if extra_codes is not None else []
    pending = Signal(name="features_valid")
    core_adv = Signal(name="core_advance")
    take = Signal(name="features_taken")
    m.d.comb += take.eq(pending & core_adv)
    with m.If(take):
        m.d.sync += pending.eq(0)
    with m.If(done):
        m.d.sync += pending.eq(1)
    m.d.comb += inp.ready.eq(free & (~pending | take))
    top.core.build_into(m, Cat(*codes, *extra), pending, core_adv, top.out)


def _double_buffer_control(m: Module, top, inp, transfer, codes: list, done, free, load) -> None:
    """Flow control of the double-buffered codes (:func:`serial_sensor_path`): ``features_valid``
    (the buffer holds codes the core has not taken), ``features_held`` (a sample's complete codes
    wait in the staging registers), ``features_outstanding`` (warm samples transferred and not yet
    taken, 0 .. 2)."""
    pending = Signal(name="features_valid")
    held = Signal(name="features_held")
    core_adv = Signal(name="core_advance")
    take = Signal(name="features_taken")
    m.d.comb += take.eq(pending & core_adv)
    m.d.comb += load.eq((done & (~pending | take)) | (held & take))
    with m.If(load):
        m.d.sync += pending.eq(1)
    with m.Elif(take):
        m.d.sync += pending.eq(0)
    with m.If(held & take):
        m.d.sync += held.eq(0)
    with m.Elif(done & pending & ~take):
        m.d.sync += held.eq(1)
    out_n = Signal(unsigned(2), name="features_outstanding")
    enter = Signal(name="warm_transfer")
    m.d.comb += enter.eq(transfer & top.warm)
    with m.If(enter & ~take):
        m.d.sync += out_n.eq(add_const_wrap(m, out_n, 1, "features_outstanding_inc"))
    with m.Elif(take & ~enter):
        m.d.sync += out_n.eq(add_const_wrap(m, out_n, -1, "features_outstanding_dec"))
    m.d.comb += inp.ready.eq(free & (~out_n[1] | take))
    top.core.build_into(m, Cat(*codes), pending, core_adv, top.out)
