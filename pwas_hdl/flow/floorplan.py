"""Floorplan of the ECP5 hard blocks: fixed sites for the block RAMs and multipliers before nextpnr.

nextpnr's ECP5 placer puts the core's DP16KD block RAMs and MULT18X18D multipliers where its
analytic placement lands them (on the LFE5U-45F: the first EBR row Y10 and the DSP row Y22, with
the logic between them). In the latency-first build (``generate --goal latency``, the ``short``
pipeline: the block-RAM read feeds the multipliers' input registers in the same cycle as the
front's address logic) that puts the front (input -> comparators -> tables -> block-RAM address)
and the multiplier -> sum -> output logic into the same rows of fabric. Fixing the block RAMs to
the central EBR row and the multipliers to the DSP row below it (measured:
``benchmarks/results/hw_tables_latency_experiments.md``, sections "Floorplans of the hard blocks"
and hw14f) separates the two: 30.13 ns against 32.0 ns over nextpnr seeds 1-3 for
``short`` + ``counter_sum``.

:func:`apply_floorplan` runs between :func:`pwas_hdl.flow.hard_registers.pack_ecp5_registers` and
nextpnr (:func:`pwas_hdl.flow.synthesis.synthesize`): it gives every DP16KD and MULT18X18D cell of
the netlist a nextpnr ``BEL`` attribute, cell ``k`` (natural order of the cell names: bank 0, 1,
...; ``prod0_0``, ``prod0_1``, ...) on site ``k`` of the part's site table. The rule:

* ``floorplan="auto"`` plans only the structure it was measured on: a pipeline with the multiplier
  input register right after the read (``mul_in`` without ``mem_out``; ``short`` is the preset
  that has it) and the banked or replicated weight memory (manifest ``memory.kind``; the corner and
  serial layouts were not measured with a plan). The replicated memory's copies get the same rows,
  its DP16KD cells ``wmem<k>.0.<i>`` (copy ``k`` = vertex ``k``; 3 blocks of 4096 x 4 bits for a
  4096 x 11-bit copy) in natural order on the sites of :func:`replicated_sites`: the whole tile
  groups nearest the centre that hold them, left to right, so that each copy's blocks are adjacent
  and the copies whose addresses need the comparison bits (``1 .. n-1``) sit in the middle, between
  copy 0 (the cells alone) and copy ``n`` (cells + 1). hw14i, lorenz_my4_p7 ``short`` inline: 29.58 /
  29.54 ns over seeds 1-10 / 1-20 against 29.99 / 29.79 ns for hw14h's centre-outward order (which
  split copy 2 across the centre and put copy 4 at the far right); the front (input -> memory) then
  limits 2 of 20 seeds instead of 11. The multipliers keep the centre-outward order. Every other pipeline
  (``min``, ``balanced``, ``max``, ...) keeps nextpnr's free placement, so their netlists, and fmax,
  are unchanged. ``"none"``: never.
* Only parts with a site table (:data:`SITE_TABLES`: the LFE5U-45F, ``--device 45k``) get a plan;
  other parts: none, and the result says so.
* A design with more block RAMs or multipliers than the chosen row holds (36 each on the 45F) gets
  no plan (no second row was measured).

The site table of the 45F comes from the Project Trellis tile grid shipped with nextpnr (tiles
``MIB_EBR0..8`` and ``MIB_DSP0..8`` in groups of 9 columns; nextpnr names DP16KD ``k`` of a group
``X<c + 2k>/Y<row>/EBR<k>`` and its MULT18X18D ``X<c + j>/Y<row>/MULT18_<j>``, j = 0, 1, 4, 5). The
sites are listed from the central group (X42) outward, right side first; the first five of each
row were measured, the names of all 36 checked by nextpnr (``--pack-only``).

The result (``floorplan`` in ``synth.json``): ``mode``, ``applied``, ``part``, ``rows``
(resource -> row), ``cells`` (cell -> site) and ``reason`` (why no plan, else None).
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from typing import Any

from pwas_hdl.errors import InputError
from pwas_hdl.flow.netlist_json import read_top, write_netlist

__all__ = ["FLOORPLANS", "SITE_TABLES", "SiteTable", "check_floorplan", "plan_sites", "apply_floorplan",
           "applies_to_pipeline", "replicated_sites"]

#: ``synth --floorplan`` values: ``auto`` (the rule of this module) or ``none`` (never).
FLOORPLANS = ("auto", "none")

#: The weight-memory layouts (manifest ``memory.kind``) that ``auto`` plans (the measured ones).
PLANNED_MEMORIES = ("banked", "replicated")

#: The cell types that get sites.
HARD_BLOCKS = ("DP16KD", "MULT18X18D")


@dataclass(frozen=True)
class SiteTable:
    """The sites of one part for the plan: one row per hard-block type, in assignment order.

    Attributes
    ----------
    part
        The part's name (as :func:`pwas_hdl.flow.synthesis.synthesize` reports it, without package).
    rows
        Cell type -> the row's name (``"Y34"``), for the record.
    sites
        Cell type -> nextpnr BEL names, in the order cells are assigned to them (whole tile groups of
        ``group`` sites each, the central group first).
    columns
        BEL name -> its column (``X``), for :func:`replicated_sites`' left-to-right order.
    group
        Sites per tile group (consecutive in ``sites``).
    """

    part: str
    rows: dict[str, str]
    sites: dict[str, tuple[str, ...]]
    columns: dict[str, int]
    group: int = 4


def _ecp5_45f() -> SiteTable:
    groups = (42, 51, 31, 60, 22, 69, 13, 78, 4)  # first columns of the 9-column EBR / DSP groups, centre outward
    ebr_row, dsp_row = 34, 46
    ebr = tuple(f"X{c + 2 * k}/Y{ebr_row}/EBR{k}" for c in groups for k in range(4))
    mult = tuple(f"X{c + j}/Y{dsp_row}/MULT18_{j}" for c in groups for j in (0, 1, 4, 5))
    columns = {s: int(s[1:s.index("/")]) for s in ebr + mult}
    return SiteTable(part="LFE5U-45F", rows={"DP16KD": f"Y{ebr_row}", "MULT18X18D": f"Y{dsp_row}"},
                     sites={"DP16KD": ebr, "MULT18X18D": mult}, columns=columns)


#: nextpnr-ecp5 device option (``synthesize(device=...)``) -> its site table. Only the part measured.
SITE_TABLES: dict[str, SiteTable] = {"45k": _ecp5_45f()}


def check_floorplan(value: Any) -> str:
    """``value`` if it is one of :data:`FLOORPLANS`, else InputError (bad input: CLI exit 2).

    Parameters
    ----------
    value : Any
        The ``--floorplan`` value to check.

    Returns
    -------
    str
        ``value``.

    Raises
    ------
    InputError
        Not one of :data:`FLOORPLANS`.
    """
    if not isinstance(value, str) or value not in FLOORPLANS:
        raise InputError(f"--floorplan (floorplan) must be one of {', '.join(FLOORPLANS)}, got {value!r}")
    return value


def applies_to_pipeline(pipeline: dict[str, Any] | None) -> bool:
    """Whether ``auto`` plans a design of this manifest pipeline (``mul_in`` without ``mem_out``).

    Parameters
    ----------
    pipeline : dict, optional
        Register flags such as ``mul_in``, ``mem_out``: ``pwas-hdl synth`` passes those the design
        builds (:func:`pwas_hdl.design.manifest.built_pipeline_registers`; a serial core has no
        ``mul_in`` whatever its ``pipeline`` says); None: no flags.

    Returns
    -------
    bool
    """
    pl = pipeline or {}
    return bool(pl.get("mul_in")) and not pl.get("mem_out", True)


def _natural(name: str) -> tuple:
    return tuple(int(t) if t.isdigit() else t for t in re.split(r"(\d+)", name))


def replicated_sites(table: SiteTable, kind: str, count: int) -> tuple[str, ...]:
    """The sites of ``count`` cells of type ``kind`` for the replicated memory: the fewest whole tile
    groups of the table's centre-outward order that hold them, their sites left to right, the first
    ``count`` of those (for 15 DP16KD on the 45F: X31 .. X64 of row Y34, groups X31, X42, X51, X60).

    With the cells in natural order (copy 0's blocks, copy 1's, ...) each copy's blocks are adjacent
    and the copies run left to right, copy 0 and copy ``n`` at the ends.

    Parameters
    ----------
    table : SiteTable
        The part's sites.
    kind : str
        Cell type, one of :data:`HARD_BLOCKS`.
    count : int
        Cells of that type to place.

    Returns
    -------
    tuple of str
        ``count`` nextpnr BEL names, left to right.
    """
    sites = table.sites[kind]
    g = table.group
    chosen = sites[: -(-count // g) * g]
    return tuple(sorted(chosen, key=lambda s: table.columns[s]))[:count]


def plan_sites(cells: dict[str, str], device: str | None, *, mode: str = "auto",
               pipeline: dict[str, Any] | None = None, memory: str | None = "banked",
               part: str | None = None) -> dict[str, Any]:
    """The floorplan of a netlist's hard blocks (pure: no file, no tool).

    Parameters
    ----------
    cells
        Cell name -> cell type, of the netlist's top module (other types are ignored).
    device
        nextpnr-ecp5 device (``"45k"``, ...); None or a part without a site table: no plan.
    mode
        ``"auto"`` or ``"none"`` (:data:`FLOORPLANS`).
    pipeline
        The register flags of the design (:func:`applies_to_pipeline` decides for ``auto``).
    memory
        The manifest's ``memory.kind``; ``auto`` plans ``"banked"`` and ``"replicated"`` only.
    part
        The part's full name, for the record (default: the site table's).

    Returns
    -------
    dict
        ``mode``, ``applied`` (bool), ``part``, ``rows`` (cell type -> row, or None), ``cells``
        (cell name -> BEL, sorted by cell; empty without a plan), ``counts`` (cell type -> cells in
        the netlist) and ``reason`` (None when applied, else why not).
    """
    check_floorplan(mode)
    blocks = {t: sorted((n for n, ty in cells.items() if ty == t), key=_natural) for t in HARD_BLOCKS}
    table = SITE_TABLES.get(device or "")
    rec: dict[str, Any] = {"mode": mode, "applied": False, "part": part or (table.part if table else None),
                           "rows": None, "cells": {}, "counts": {t: len(v) for t, v in blocks.items()}, "reason": None}
    if mode == "none":
        rec["reason"] = "--floorplan none"
        return rec
    if not applies_to_pipeline(pipeline):
        rec["reason"] = ("auto: the pipeline does not read the block RAMs into the multipliers' input registers "
                         "(mul_in without mem_out, the short / latency-first structure); the plan was measured only there")
        return rec
    if memory not in PLANNED_MEMORIES:
        rec["reason"] = (f"auto: weight memory {memory!r}; the plan was measured only with the "
                         f"{' and '.join(PLANNED_MEMORIES)} layouts")
        return rec
    if table is None:
        known = ", ".join(f"{t.part} (--device {d})" for d, t in SITE_TABLES.items())
        rec["reason"] = f"auto: no site table for {part or device}; known: {known}"
        return rec
    if not any(blocks.values()):
        rec["reason"] = "auto: no DP16KD or MULT18X18D in the netlist"
        return rec
    for t, names in blocks.items():
        if len(names) > len(table.sites[t]):
            rec["reason"] = (f"auto: {len(names)} {t} cells, more than the {len(table.sites[t])} sites of row "
                             f"{table.rows[t]} on {table.part}")
            return rec
    order = {t: table.sites[t] for t in HARD_BLOCKS}
    if memory == "replicated":  # the copies left to right over the central groups (replicated_sites)
        order["DP16KD"] = replicated_sites(table, "DP16KD", len(blocks["DP16KD"]))
    plan = {n: order[t][k] for t, names in blocks.items() for k, n in enumerate(names)}
    rec.update(applied=True, rows={t: table.rows[t] for t, names in blocks.items() if names},
               cells=dict(sorted(plan.items(), key=lambda kv: _natural(kv[0]))))
    return rec


def apply_floorplan(netlist: str | os.PathLike, top: str, device: str | None, *, mode: str = "auto",
                    pipeline: dict[str, Any] | None = None, memory: str | None = "banked",
                    part: str | None = None) -> dict[str, Any]:
    """Give the hard blocks of a Yosys JSON netlist their sites (nextpnr ``BEL`` attributes), in place.

    The netlist is rewritten only when a plan applies.

    Parameters
    ----------
    netlist : str or os.PathLike
        The Yosys JSON netlist, after hard-register packing (rewritten in place).
    top : str
        Its top module.
    device, mode, pipeline, memory, part
        As in :func:`plan_sites`.

    Returns
    -------
    dict
        The record of :func:`plan_sites`.
    """
    data, mod = read_top(netlist, top)
    rec = plan_sites({n: c["type"] for n, c in mod["cells"].items()}, device, mode=mode, pipeline=pipeline, memory=memory,
                     part=part)
    if rec["applied"]:
        for name, bel in rec["cells"].items():
            mod["cells"][name].setdefault("attributes", {})["BEL"] = bel
        write_netlist(netlist, data)
    return rec
