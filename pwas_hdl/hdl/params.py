"""Parameters of the PWAS hardware core, pipeline options and the weight-memory plan.

:class:`CoreParams` is the integer description the RTL generator works from. It is filled from the
bit-true model (:class:`pwas_hdl.fixedpoint.bittrue.FixedPointModel`, see :meth:`CoreParams.from_model`); it
can also be built by hand (tests).

The arithmetic (the specification the RTL implements bit for bit, see ``ARCHITECTURE.md`` §1-2):

* input codes ``q_j``: signed ``in_width``-bit integers;
* ``t_j = q_j - lo_code_j``; clamped to ``[0, p_j * 2**F_j]`` (``out_of_range`` = some ``t_j`` was
  clamped); cell ``c_j = min(t_j >> F_j, p_j - 1)``; fraction ``d_j = t_j - c_j * 2**F_j``, aligned to
  ``F = max F_j`` by ``<< (F - F_j)`` (so ``0 <= d_j <= 2**F``);
* ``rank_j = #{i : d_i > d_j or (d_i == d_j and i < j)}``; vertex ``k`` has coordinates
  ``c_j + (rank_j < k)``;
* ``mu_0 = 2**F - d_(1)``, ``mu_k = d_(k) - d_(k+1)``, ``mu_n = d_(n)`` (``d_(k)`` = the ``d_j`` with
  ``rank_j == k - 1``);
* ``acc = sum_k mu_k * W[v_k]`` exact; ``out = (acc + 2**(sh-1)) >> sh`` (arithmetic, no rounding term
  when ``sh == 0``, ``acc << -sh`` when ``sh < 0``) with ``sh = F + Fw - Fo``; saturated to signed
  ``out_width`` bits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from pwas_hdl.errors import InputError
from pwas_hdl.fixedpoint.reduction import tree_depth

if TYPE_CHECKING:
    from pwas_hdl.fit.geometry import Grid
    from pwas_hdl.fixedpoint.bittrue import FixedPointModel
    from pwas_hdl.fixedpoint.memory_layout import BankedLayout, CornerLayout, ReplicatedLayout

__all__ = ["CoreParams", "Pipeline", "PipelineRefused", "MemoryPlan", "PIPELINE_PRESETS", "PIPELINE_REGISTERS", "GOALS", "GOALS_BY_FPGA",
           "goal_preset"]


class PipelineRefused(InputError):
    """A design cannot take this pipeline, though it takes others (e.g. an additive design whose parts
    cannot be given equal latencies with it): bad input (``--pipeline``), exit 2. The timing closure
    (:func:`pwas_hdl.flow.timing_closure.close_timing`) leaves such a candidate out; any other
    :class:`~pwas_hdl.errors.InputError` of a design is reported as it is."""


def _bits_for(v: int) -> int:
    """Width of an unsigned integer able to hold ``0 .. v`` (at least 1)."""
    return max(1, int(v).bit_length())


@dataclass(frozen=True, eq=False)
class CoreParams:
    """Integer description of one PWAS core.

    Attributes
    ----------
    partitions : tuple of int
        ``p_j >= 1`` intervals per dimension (``n = len(partitions)``).
    in_width : int
        Width ``B_in`` of the signed input codes in bits (all dimensions).
    lo_code : tuple of int
        Input code of the lower domain bound per dimension.
    frac_bits : tuple of int
        ``F_j >= 0`` bits: one grid interval of dimension ``j`` is ``2**F_j`` input codes.
    weight_width, weight_frac : int
        Signed weight codes ``B_w`` bits with ``Fw`` fractional bits.
    out_width, out_frac : int
        Signed output codes ``B_out`` bits with ``Fo`` fractional bits.
    weights : ndarray, shape (N, nz), int64
        Weight codes in the vertex order of :mod:`pwas_hdl.fit.geometry` (C order, last dimension fastest).
    rounding : {"half_up", "truncate"}
        Rounding of the output shift ``acc >> sh``: ``"half_up"`` adds ``2**(sh-1)`` first,
        ``"truncate"`` adds nothing (default ``"half_up"``).
    scaling : tuple
        One entry per ``input_scale="exact"`` dimension ``j``: ``(S_j, K_j, R_j)``, the input codes
        across the domain and the scale ``t' = (t * K_j) >> R_j`` (``R_j`` in bits); ``None`` for a
        pow2 dimension. Empty (default): every dimension pow2.
    """

    partitions: tuple[int, ...]
    in_width: int
    lo_code: tuple[int, ...]
    frac_bits: tuple[int, ...]
    weight_width: int
    weight_frac: int
    out_width: int
    out_frac: int
    weights: np.ndarray = field(repr=False)
    rounding: str = "half_up"
    #: ``input_scale="exact"`` dimensions: ``(S_j, K_j, R_j)`` (input codes across the domain, scale
    #: ``t' = (t * K_j) >> R_j``); ``None`` for a pow2 dimension. Empty: every dimension pow2.
    scaling: tuple = ()

    def __post_init__(self) -> None:
        n = len(self.partitions)
        if n < 1:
            raise InputError("a PWAS core needs at least one dimension")
        if len(self.lo_code) != n or len(self.frac_bits) != n:
            raise InputError(f"lo_code and frac_bits need {n} entries (one per dimension)")
        if any(int(p) < 1 for p in self.partitions):
            raise InputError(f"partitions must be >= 1, got {self.partitions}")
        if any(int(f) < 0 for f in self.frac_bits):
            raise InputError(f"frac_bits must be >= 0, got {self.frac_bits}")
        if self.in_width < 2 or self.weight_width < 1 or self.out_width < 1:
            raise InputError(f"widths must be >= 1 (inputs >= 2), got in_width = {self.in_width}, weight_width = {self.weight_width}, "
                             f"out_width = {self.out_width}")
        if self.rounding not in ("half_up", "truncate"):
            raise InputError(f"rounding must be 'half_up' or 'truncate', got {self.rounding!r}")
        w = np.asarray(self.weights, dtype=np.int64)
        if w.ndim == 1:
            w = w[:, None]
        if w.shape[0] != self.n_vertices or w.shape[1] < 1:
            raise InputError(f"weights must have shape (N={self.n_vertices}, nz>=1), got {w.shape}")
        lim = 1 << (self.weight_width - 1)
        if w.min() < -lim or w.max() >= lim:
            raise InputError(f"weight codes {int(w.min())}..{int(w.max())} do not fit signed {self.weight_width} bits "
                             f"[{-lim}, {lim - 1}]; give a wider weight_width or quantise the weights to it")
        object.__setattr__(self, "weights", w)
        object.__setattr__(self, "partitions", tuple(int(p) for p in self.partitions))
        object.__setattr__(self, "lo_code", tuple(int(v) for v in self.lo_code))
        object.__setattr__(self, "frac_bits", tuple(int(v) for v in self.frac_bits))
        sc = tuple(self.scaling) or (None,) * n
        if len(sc) != n:
            raise InputError(f"scaling needs {n} entries (one per dimension)")
        object.__setattr__(self, "scaling", tuple(None if v is None else tuple(int(x) for x in v) for v in sc))

    # ------------------------------------------------------------------ sizes
    @property
    def n(self) -> int:
        """Regressor dimension ``n = len(partitions)``."""
        return len(self.partitions)

    @property
    def nz(self) -> int:
        """Number of targets (columns of ``weights``)."""
        return int(self.weights.shape[1])

    @property
    def grid(self) -> "Grid":
        """The partition in grid units (``lo = 0``, ``hi = p``): the vertex numbering of
        :mod:`pwas_hdl.fit.geometry`, which the memory layouts and the addresses follow."""
        from pwas_hdl.fit.geometry import Grid

        parts = np.array(self.partitions, dtype=np.int64)
        return Grid(np.zeros(self.n), parts.astype(float), parts)

    @property
    def shape(self) -> tuple[int, ...]:
        """Vertices per dimension, ``p_j + 1``."""
        return tuple(p + 1 for p in self.partitions)

    @property
    def n_vertices(self) -> int:
        """Grid vertex count ``N = prod(p_j + 1)`` (rows of ``weights``)."""
        return int(np.prod(self.shape))

    @property
    def strides(self) -> tuple[int, ...]:
        """C-order vertex strides (last dimension fastest), as ``Grid.strides``."""
        return tuple(int(v) for v in self.grid.strides)

    @property
    def frac(self) -> int:
        """``F = max F_j`` (fractional bits of the aligned fractions and of ``mu``)."""
        return max(self.frac_bits)

    @property
    def shift(self) -> int:
        """``sh = F + Fw - Fo``."""
        return self.frac + self.weight_frac - self.out_frac

    @property
    def acc_width(self) -> int:
        """Width of products, partial sums and the accumulator: ``F + B_w`` (exact, see core)."""
        return self.frac + self.weight_width

    # ------------------------------------------------------------- builders
    @classmethod
    def from_model(cls, model: "FixedPointModel | CoreParams") -> "CoreParams":
        """Core parameters of a bit-true model (:class:`pwas_hdl.fixedpoint.bittrue.FixedPointModel`).

        Parameters
        ----------
        model : FixedPointModel or CoreParams
            A ``CoreParams`` is returned as it is.

        Returns
        -------
        CoreParams

        Raises
        ------
        TypeError
            ``model`` lacks an attribute of a bit-true model.
        InputError
            The model's values are invalid for a core (see the class checks).
        """
        return _params_from_model(cls, model)


def _params_from_model(cls, model) -> CoreParams:
    if isinstance(model, CoreParams):
        return model
    try:
        return cls(
            partitions=tuple(int(v) for v in model.grid.partitions),
            in_width=int(model.input_bits),
            lo_code=tuple(int(v) for v in model.lo_codes),
            frac_bits=tuple(int(v) for v in model.frac_bits),
            weight_width=int(model.weight_format.bits),
            weight_frac=int(model.weight_format.frac),
            out_width=int(model.output_format.bits),
            out_frac=int(model.output_format.frac),
            weights=np.asarray(model.weight_codes, dtype=np.int64),
            rounding=str(model.rounding),
            scaling=tuple((f.input_span, f.scale_mul, f.scale_shift) if getattr(f, "span", 0) else None
                          for f in getattr(model, "inputs", [])) or (),
        )
    except AttributeError as exc:
        raise TypeError(f"expected a pwas_hdl.fixedpoint.bittrue.FixedPointModel or CoreParams, got {type(model).__name__} ({exc})") from exc


# ---------------------------------------------------------------------------------------------
# Pipeline options
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Pipeline:
    """Which pipeline registers the core has.

    Stages (in order, ``*`` = always present):

    ============ ========================================================================
    ``split``    register after scale / clamp / cell-fraction split
    ``rank``     register after the rank extractor (and the address/bank precomputation; banked: the
                 bank rotation ``|c| mod (n+1)`` and the cells)
    ``offset``   register on the address offsets, the base address and the one-hot selected fractions
                 ``d_(k)``: before the address adders and the ``mu`` subtractions (it cuts the rank ->
                 address path between its tables and its carry chains). Banked memories: on bank
                 ``b``'s address pieces (bit fields ``c_j + [rank_j < (b - rot) mod (n+1)]``, or a
                 table of those step bits when the layout needs adders)
    ``addr``     register on the addresses (banked: already in bank order, no rotation follows them)
                 and ``mu`` (vertex order)
    ``bank``     register on the addresses and the bank-rotated ``mu`` (the memories' address pins then
                 come straight from flip-flops)
    ``mu_late``  (no register) banked: the sorted fractions ``d_(k)`` instead of ``mu`` go through the
                 registers up to the memory register; ``mu`` and its rotation are computed in the
                 memory-read cycle, beside the block RAM's clock-to-output (off the front's path).
                 Replicated memories (without ``offset``, n > 1, grid strides powers of two): the same,
                 and vertex ``k``'s address is bit fields ``c_j + [rank_j < k]``, each one case table of
                 ``c_j`` and dimension ``j``'s comparison bits (no adder; :meth:`PWASCore._vertex_direct`)
    ``raw_compare`` (no register; without ``split``) the rank comparators read the fractions as bit
                 fields of the input codes, when the domain's lower bound makes them so
                 (``L_j mod 2**F_j`` is 0 or ``2**(F_j-1)``, no exact scale), and the clamp enters
                 after their carry chains: ``d_i >= d_j = top_i | ~top_j & (under_j | (under_i ?
                 r_j == 0 : r_i >= r_j))`` (the same bits; the clamp / split LUTs leave the
                 comparators' path; other grids: plain comparators); the bank rotation
                 ``|c| mod (n+1)`` then comes from the cells' residue tables (no carry chain). No
                 effect for n = 1 and the corner memory (its comparators are off the address path)
    memory *     bank addresses + ``mu`` feed the synchronous read ports (one register)
    ``mem_out``  extra register on the memory read data (on ECP5 the DP16KD output register)
    ``mul_in``   register on the multiplier operands (``mu`` and the read data; on ECP5 the
                 MULT18X18D input registers)
    ``mul_halves`` each product as two half-width partial products (``mu`` times the weight's low and
                 high halves), registered, then added: multipliers built from LUTs (iCE40 HX, no DSP)
                 of half the depth per stage; on FPGAs with DSP blocks it takes twice as many
    ``product``  register after the ``mu_k * w`` multipliers (on ECP5 the MULT18X18D output register)
    ``tree``     a register after every ``tree_levels`` adder-tree levels (0: none)
    ``flat_sum`` (no register; needs ``tree_levels = 0``) the ``n + 1`` products and the rounding
                 constant ``2**(sh-1)`` as one modular sum in ``F + B_w + 1`` bits, each addition at
                 that full width, so that Yosys' ``alumacc`` merges them into one multi-operand
                 adder (one carry-save tree of full adders, one carry chain) instead of one carry
                 chain per tree level plus the rounding adder (:meth:`PWASCore._flat_sum`)
    ``counter_sum`` (no register; needs ``flat_sum``) the one sum's carry-save part as one level of
                 column counters: each bit column of the ``n + 1`` products (4 to 6; else no effect) and the rounding
                 constant counted by a case table (one wide LUT per count bit), then the 3 count words
                 in one sum (one full-adder level, one carry chain; :meth:`PWASCore._counter_sum`)
                 instead of Yosys' full-adder tree of 3 levels
    ``late_select`` (no register; banked bit-field addresses) each bank-address field bit as a case
                 table of dimension ``j``'s ``n - 1`` comparison bits selecting among ``n`` values
                 precomputed from ``(c_j, rot)`` (one per rank; :meth:`PWASCore._late_field`) instead of
                 rank table -> step table -> field table. Opt-in, in no preset: measured slower (hw14f)
    ``sort_late`` (no register; needs ``mu_late``, banked) the fractions in dimension order and the
                 ``n(n-1)/2`` comparison bits (instead of the sorted fractions) go through the
                 registers up to the memory register; the one-hot selection of the sorted fractions
                 ``d_(k)`` is made in the memory-read cycle, before ``mu`` (:meth:`PWASCore._sorted_fractions`):
                 the comparison bits then drive only the address tables in the front's cycle
    ``prune_sat`` (no register) leave out the saturation of a target whose weights cannot reach it
                 (the sum is a convex combination of the weights times ``2**F``, so its range is known
                 when the Verilog is generated; :meth:`PWASCore._sat_unreachable`): no saturation LUT
                 level after the last carry chain
    output *     rounding / saturation, then the output register (the stream's payload)
    ============ ========================================================================

    On ECP5, ``pwas-hdl synth`` moves the ``mem_out``, ``mul_in`` and ``product`` registers into the
    block RAMs and multipliers (:mod:`pwas_hdl.flow.hard_registers`); the generated Verilog is the
    same for every FPGA.

    Attributes
    ----------
    split, rank, offset, addr, bank, mem_out, mul_in, product : bool
        The register stages of the table above, each present when true (defaults: ``rank``,
        ``addr``, ``mem_out`` and ``product``).
    tree_levels : int
        Adder-tree levels between two ``tree`` registers (default 3; 0: no adder-tree register).
    mu_late, raw_compare, mul_halves, flat_sum, counter_sum, late_select, sort_late, prune_sat : bool
        The structural options of the table above, each on when true (default: all off).
    """

    split: bool = False
    rank: bool = True
    mem_out: bool = True
    product: bool = True
    tree_levels: int = 3
    addr: bool = True
    mul_in: bool = False
    offset: bool = False
    bank: bool = False
    mul_halves: bool = False
    mu_late: bool = False
    flat_sum: bool = False
    prune_sat: bool = False
    raw_compare: bool = False
    counter_sum: bool = False
    late_select: bool = False
    sort_late: bool = False

    def __post_init__(self) -> None:
        if self.tree_levels < 0:
            raise InputError("tree_levels must be >= 0 (0 = no adder-tree registers)")
        if self.flat_sum and self.tree_levels:
            raise InputError("flat_sum needs tree_levels = 0 (one sum without adder-tree registers)")
        if self.counter_sum and not self.flat_sum:
            raise InputError("counter_sum needs flat_sum (it is a way of adding the one sum)")
        if self.sort_late and not self.mu_late:
            raise InputError("sort_late needs mu_late (the sort moves into the memory-read cycle beside mu)")

    @staticmethod
    def tree_depth(n: int) -> int:
        """Adder-tree levels to sum ``n + 1`` products (:func:`pwas_hdl.fixedpoint.reduction.tree_depth`).

        Parameters
        ----------
        n : int
            Regressor dimension.

        Returns
        -------
        int
            Adder levels, at least 1.
        """
        return max(1, tree_depth(n + 1))

    def tree_registers(self, n: int) -> int:
        """Register stages in the adder tree of ``n + 1`` products.

        Parameters
        ----------
        n : int
            Regressor dimension.

        Returns
        -------
        int
            0 with ``tree_levels = 0``, else ``ceil(tree_depth(n) / tree_levels)`` (a register every
            ``tree_levels`` adder levels).
        """
        if self.tree_levels == 0:
            return 0
        return math.ceil(self.tree_depth(n) / self.tree_levels)

    def latency(self, n: int) -> int:
        """Cycles from an input transfer to the matching output (without backpressure).

        Parameters
        ----------
        n : int
            Regressor dimension (sets the adder-tree depth).

        Returns
        -------
        int
            Latency in clock cycles: the enabled optional stages, one memory read, the
            :meth:`tree_registers` and one output register.
        """
        return (
            int(self.split)
            + int(self.rank)
            + int(self.offset)
            + int(self.addr)
            + int(self.bank)
            + 1
            + int(self.mem_out)
            + int(self.mul_in)
            + int(self.mul_halves)
            + int(self.product)
            + self.tree_registers(n)
            + 1
        )

    @classmethod
    def cast(cls, value: "Pipeline | str | dict | None") -> "Pipeline":
        """A pipeline from any of the forms the API and the manifest use.

        Parameters
        ----------
        value : Pipeline, str, dict or None
            A pipeline (returned as is), a preset name of :data:`PIPELINE_PRESETS`, the options as
            :meth:`to_dict` writes them, or None (the default ``Pipeline()``).

        Returns
        -------
        Pipeline

        Raises
        ------
        InputError
            An unknown preset or option, or options that contradict each other.
        TypeError
            ``value`` is of another type.
        """
        if value is None:
            return cls()
        if isinstance(value, Pipeline):
            return value
        if isinstance(value, dict):  # as written by to_dict() (a manifest's "pipeline")
            known = {"split", "rank", "mem_out", "product", "tree_levels", "addr", "mul_in", "offset", "bank", "mul_halves",
                     "mu_late", "flat_sum", "prune_sat", "raw_compare", "counter_sum", "late_select",
                     "sort_late"}
            bad = set(value) - known
            if bad:
                raise InputError(f"unknown pipeline option(s) {sorted(bad)}; known: {', '.join(sorted(known))}")
            return cls(**value)
        if isinstance(value, str):
            try:
                return PIPELINE_PRESETS[value]
            except KeyError:
                raise InputError(
                    f"unknown pipeline preset {value!r} (--pipeline); choose one of {', '.join(PIPELINE_PRESETS)}"
                ) from None
        raise TypeError(f"pipeline must be a Pipeline, a preset name, a dict of its options or None, not {value!r}")

    def to_dict(self) -> dict:
        """The options as a JSON-ready dict (a manifest's ``pipeline``; :meth:`cast` reads it back).

        Returns
        -------
        dict
            ``split``, ``rank``, ``mem_out``, ``product``, ``tree_levels``, ``addr``, ``mul_in``,
            ``offset``, ``bank``, ``mul_halves``, ``mu_late``, and each of ``flat_sum``,
            ``prune_sat``, ``raw_compare``, ``counter_sum``, ``late_select``, ``sort_late`` only
            when it is set.
        """
        return {
            "split": self.split,
            "rank": self.rank,
            "mem_out": self.mem_out,
            "product": self.product,
            "tree_levels": self.tree_levels,
            "addr": self.addr,
            "mul_in": self.mul_in,
            "offset": self.offset,
            "bank": self.bank,
            "mul_halves": self.mul_halves,
            "mu_late": self.mu_late,
            # only when set: the manifests of the pipelines without it stay as they were
            **({"flat_sum": True} if self.flat_sum else {}),
            **({"prune_sat": True} if self.prune_sat else {}),
            **({"raw_compare": True} if self.raw_compare else {}),
            **({"counter_sum": True} if self.counter_sum else {}),
            **({"late_select": True} if self.late_select else {}),
            **({"sort_late": True} if self.sort_late else {}),
        }


#: The options of :class:`Pipeline` that are register stages (each adds a cycle where a design builds
#: it), in stage order; ``tree_levels`` stands for its adder-tree (or argmax compare-tree) registers.
#: The parallel core builds every one; a design may build fewer (``pipeline_registers`` of its cores
#: and stages: the serial core's :data:`~pwas_hdl.hdl.serial_core.SERIAL_REGISTERS`).
PIPELINE_REGISTERS = ("split", "rank", "offset", "addr", "bank", "mem_out", "mul_in", "mul_halves", "product", "tree_levels")


#: Named pipelines (measured on the Lorenz core n = 4, N = 4096, ECP5-45F speed 6, nextpnr, timing
#: harness, hard-block registers packed; benchmarks/hw_tables.py has the current figures):
#:
#: * ``min``: 2 registers (memory + output), the fewest cycles;
#: * ``short``: ``min`` + one multiplier register + ``mu_late`` (3 cycles for every n). The rule behind
#:   it: a register pays only where it costs no fabric (the MULT18X18D output register) and cuts the
#:   longest stage of ``min`` (memory -> multipliers -> adder tree -> output) into two parts that are
#:   each shorter than the front (input -> scale / rank / address -> memory), which no hard-block
#:   register can cut; logic that does not feed the addresses (``mu``) moves out of the front into
#:   the memory-read cycle; every further register adds a cycle of at least the front's length.
#:   Seed 1, rotation-free banked core (issue 14): 33.8 ns = 3 x 11.3 ns (the front: input ->
#:   clamp / split -> comparators -> step tables -> bit-field address -> memory), with the memory ->
#:   multiplier stage at 11.0 ns (DP16KD clock-to-output 5.6 ns + routing 1.9 + MULT18X18D setup
#:   3.5), which bounds every 3-cycle structure at 33 ns; before: 40.6 ns (3 seeds, 3 x 13.5 ns)
#:   against 43.1 ns for ``min`` (2 x 21.7 ns); rank + product 44.0 ns, mem_out + product 52.5 ns,
#:   mem_out alone 51.9 ns (seed 1). The product -> output stage is one multi-operand sum with the
#:   rounding constant (``flat_sum``: one carry-save tree, one carry chain) without the saturation
#:   the weights cannot reach (``prune_sat``): 7.7 ns alone (10.7 ns as a pairwise tree + rounding
#:   adder + saturation; measured with every other stage cut by registers, seed 1), 3 seeds 33.7 ns
#:   (34.1 before), the memory -> multiplier stage now the critical one on every seed. Now the one
#:   register after the read is the multipliers' input register (``mul_in``; ``synth`` packs it into the
#:   MULT18X18D input registers, :mod:`pwas_hdl.flow.hard_registers` ``mult_first``) instead of their
#:   output register: memory -> multiplier ~8 ns (setup 0.08 ns instead of 3.5), the multiplier's
#:   clock-to-output (3.86 ns) joins the one-sum stage (10.4-11.0 ns), and the front, then the longest
#:   stage, is trimmed by ``raw_compare`` (comparators on the input bits, the rotation from residue
#:   tables: 11.5 -> 10.2 ns alone): 3 seeds 31.8 ns (33.7 before), the front and the sum stage both
#:   at 10.4-10.9 ns (``benchmarks/results/hw_tables_latency_experiments.md``, c9'). The sum is
#:   counted by column counters (``counter_sum``: the multiplier -> output stage 10.4-10.5 -> 9.9 ns),
#:   and ``pwas-hdl synth`` fixes this structure's block RAMs to the central EBR row and its
#:   multipliers to the DSP row below (:mod:`pwas_hdl.flow.floorplan`, ``--floorplan auto``): 3 seeds
#:   30.13 ns (31.98 ns with counter_sum and no plan, 31.65 ns with the plan and no counter_sum);
#:   seeds 1-5 30.50 ns (hw14f);
#: * ``balanced`` (default, ``Pipeline()``): rank, addr, mem_out, product and one adder-tree register
#:   every 3 levels (7 cycles for n = 4): >= 100 MHz and <= 65 ns;
#: * ``max``: every register (13 cycles for n = 4): each stage holds at most one carry chain or a
#:   few LUT levels -- the highest clock;
#: * ``max-lut``: ``max`` with the products split into half-width partial products (``mul_halves``,
#:   14 cycles for n = 4): the highest clock where the multipliers are LUTs (iCE40 HX); on an FPGA
#:   with DSP blocks it takes twice as many.
PIPELINE_PRESETS: dict[str, Pipeline] = {
    "min": Pipeline(split=False, rank=False, addr=False, mem_out=False, mul_in=False, product=False, tree_levels=0),
    "short": Pipeline(split=False, rank=False, addr=False, mem_out=False, mul_in=True, product=False, tree_levels=0,
                      mu_late=True, flat_sum=True, prune_sat=True, raw_compare=True, counter_sum=True),
    "balanced": Pipeline(),
    "max": Pipeline(split=True, rank=True, addr=True, mem_out=True, mul_in=True, product=True, tree_levels=1,
                    offset=True, bank=True),
    "max-lut": Pipeline(split=True, rank=True, addr=True, mem_out=True, mul_in=True, product=True, tree_levels=1,
                        offset=True, bank=True, mul_halves=True),
}

#: ``generate --goal``: what matters -> the pipeline preset that gives it (see PIPELINE_PRESETS):
#: ``latency`` -> ``short`` (the fewest nanoseconds, by the rule above), ``balanced`` -> ``balanced``,
#: ``throughput`` -> ``max`` (the highest clock).
GOALS: dict[str, str] = {"latency": "short", "balanced": "balanced", "throughput": "max"}

#: FPGA families whose goals differ from :data:`GOALS`: iCE40 HX has no DSP blocks, so the
#: throughput build splits its LUT multipliers (``max-lut``).
GOALS_BY_FPGA: dict[str, dict[str, str]] = {"ice40": {"throughput": "max-lut"}}


def goal_preset(goal: str, fpga: str | None = None) -> str:
    """The pipeline preset of ``generate --goal goal`` for the FPGA family ``fpga`` (None: ECP5's).

    Parameters
    ----------
    goal : str
        One of :data:`GOALS`.
    fpga : {"ecp5", "ice40"}, optional
        FPGA family; None: ``ecp5``.

    Returns
    -------
    str
        A preset name of :data:`PIPELINE_PRESETS`.

    Raises
    ------
    InputError
        ``goal`` is not one of :data:`GOALS`, or ``fpga`` is not ``ecp5`` / ``ice40``.
    """
    if goal not in GOALS:
        raise InputError(f"unknown goal {goal!r} (--goal); choose one of {', '.join(GOALS)}")
    if fpga is not None and fpga not in ("ecp5", "ice40"):
        raise InputError(f"unknown FPGA family {fpga!r} for the goal; choose ecp5 or ice40")
    return GOALS_BY_FPGA.get(fpga or "", {}).get(goal, GOALS[goal])


# ---------------------------------------------------------------------------------------------
# Weight memory plan
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MemoryPlan:
    """The weight memories of the core: a view of a layout of :mod:`pwas_hdl.fixedpoint.memory_layout`.

    The geometry (banks, depth, which vertex sits at which bank and address, the address weights
    ``row_strides`` that the core's address logic adds) is the layout's; this class only adds the
    packed contents: one word per bank and address holds all ``nz`` targets, target 0 in the LSBs
    (:func:`pwas_hdl.fixedpoint.bitfields.pack_rows`). Padding words are 0.

    Attributes
    ----------
    layout : BankedLayout or ReplicatedLayout or CornerLayout
        The layout the bit-true model reads through (built by :meth:`build`).
    word_bits : int
        Bits of one packed word, ``nz * B_w``.
    contents : tuple of tuple of int
        Per bank, ``depth`` packed words.
    """

    layout: "BankedLayout | ReplicatedLayout | CornerLayout"
    word_bits: int
    contents: tuple[tuple[int, ...], ...]

    @property
    def kind(self) -> str:
        """Layout name: ``"banked"``, ``"replicated"`` or ``"corner"``."""
        return self.layout.kind

    @property
    def n_banks(self) -> int:
        """Number of weight memories (banks)."""
        return self.layout.n_banks

    @property
    def depth(self) -> int:
        """Words per memory."""
        return self.layout.depth

    @property
    def words(self) -> int:
        """Words in all memories together (padding included)."""
        return self.layout.total_words

    @property
    def bits(self) -> int:
        """Memory bits in all: ``words * word_bits``."""
        return self.words * self.word_bits

    @property
    def addr_width(self) -> int:
        """Address bits of one memory (0 when it has one word: the core then drives no address)."""
        return self.layout.addr_bits if self.depth > 1 else 0

    def to_dict(self) -> dict:
        """JSON-ready summary of the memories (for the manifest and the report).

        Returns
        -------
        dict
            ``kind``, ``memories`` (banks), ``depth`` (words per memory), ``word_bits``, ``words``
            (all memories) and ``bits`` (all memories).
        """
        return {
            "kind": self.kind,
            "memories": self.n_banks,
            "depth": self.depth,
            "word_bits": self.word_bits,
            "words": self.words,
            "bits": self.bits,
        }

    @classmethod
    def build(cls, p: CoreParams, kind: str = "banked") -> "MemoryPlan":
        """The plan of the layout ``kind`` of ``p``'s grid, its words packed from ``p.weights``.

        Parameters
        ----------
        p : CoreParams
            Grid, weight codes ``(N, nz)`` and weight width ``B_w``.
        kind : {"banked", "replicated", "corner"}
            Layout name (:func:`pwas_hdl.fixedpoint.memory_layout.make_layout`).

        Returns
        -------
        MemoryPlan

        Raises
        ------
        InputError
            An unknown ``kind``.
        """
        from pwas_hdl.fixedpoint.bitfields import pack_rows
        from pwas_hdl.fixedpoint.memory_layout import make_layout

        layout = make_layout(p.grid, kind)
        rom = layout.contents(p.weights)  # (n_banks, depth, nz)
        contents = tuple(tuple(pack_rows(rom[b], p.weight_width)) for b in range(layout.n_banks))
        return cls(layout, p.nz * p.weight_width, contents)
