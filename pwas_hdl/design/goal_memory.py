"""The weight memory that ``generate --goal`` builds when ``--memory`` is not given (issue 14).

``--memory`` left out means "the goal's memory":

* ``--goal latency`` on ECP5 (``--fpga ecp5``): the replicated memory (``n + 1`` copies of the N
  words), when all of these hold, else the banked memory:

  - the design is a plain parallel PWAS core or sensor (no classifier, additive, non-uniform,
    observer-bank or recurrent model, ``--architecture parallel``): the structures measured;
  - the replicated address is a concatenation of bit fields
    (:meth:`pwas_hdl.fixedpoint.memory_layout.ReplicatedLayout.address_fields`: power-of-two
    strides, as p = 7, n > 1), so the latency-first front forms each copy's address with one table
    level and no adder (:meth:`pwas_hdl.hdl.core.PWASCore._vertex_direct`);
  - the copies' 18-kbit block RAMs and the multipliers fit the one row each that ``synth``'s
    floorplan places them in (:mod:`pwas_hdl.flow.floorplan`: 36 DP16KD and 36 MULT18X18D on the
    LFE5U-45F).

  Measured (Lorenz My = 4, p = 7, N = 4096, ECP5-45F speed 6, nextpnr seeds 1-3,
  ``benchmarks/results/hw_tables_latency_experiments.md`` sections hw14h, hw14i; ``hw_tables.md``):
  29.62 ns replicated with the floorplan's left-to-right copies (30.05 ns with hw14h's order)
  against 30.13 ns banked (seeds 1-20: 29.54 / 29.79 against 30.66 ns), 704 against 924 LUT4, 15
  against 5 DP16KD.
* every other goal, FPGA or design, and no goal: the banked memory (:data:`DEFAULT_MEMORY`).

The choice is recorded as the manifest's ``generator.options.memory`` (what rebuilds the design).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from pwas_hdl.fixedpoint.bittrue import FixedPointModel

__all__ = ["DEFAULT_MEMORY", "goal_memory"]

#: ``generate --memory`` when neither it nor a goal that chooses another is given.
DEFAULT_MEMORY = "banked"


def goal_memory(goal: str | None, fpga: str | None, fxm: "FixedPointModel", *, plain: bool) -> str:
    """The weight memory (``"banked"`` or ``"replicated"``) for ``goal`` on ``fpga`` (see the module notes).

    Parameters
    ----------
    goal : {"latency", "balanced", "throughput"} or None
        ``generate --goal``.
    fpga : {"ecp5", "ice40"} or None
        ``generate --fpga`` (None: ECP5).
    fxm : FixedPointModel
        The design's bit-true model (any layout): its grid, ``nz``, weight width and ``F`` size the copies.
    plain : bool
        True for a plain parallel PWAS core or sensor (the only designs the replicated choice is made for).

    Returns
    -------
    str
        ``"replicated"`` only for ``goal="latency"`` on ECP5, a plain design with ``n >= 2`` whose
        replicated banks fit the default part's block RAMs and multipliers; else ``"banked"``.
    """
    if goal != "latency" or (fpga or "ecp5") != "ecp5" or not plain or fxm.n < 2:
        return DEFAULT_MEMORY
    from pwas_hdl.fixedpoint.memory_layout import make_layout
    from pwas_hdl.flow.explore import bram18k_blocks, mult18_blocks
    from pwas_hdl.flow.floorplan import SITE_TABLES
    from pwas_hdl.flow.synthesis import DEFAULT_DEVICE

    layout = make_layout(fxm.grid, "replicated")
    if layout.address_fields() is None:
        return DEFAULT_MEMORY
    sites = SITE_TABLES[DEFAULT_DEVICE["ecp5"]].sites  # synth's default part, the one the floorplan knows
    bw = fxm.weight_format.bits
    brams = layout.n_banks * bram18k_blocks(layout.depth, fxm.nz * bw)
    mults = layout.n_banks * fxm.nz * mult18_blocks(fxm.F, bw)
    if brams > len(sites["DP16KD"]) or mults > len(sites["MULT18X18D"]):
        return DEFAULT_MEMORY
    return "replicated"
