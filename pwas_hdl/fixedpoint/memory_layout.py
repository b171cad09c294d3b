"""Weight memory layouts: where each vertex weight lives in the ROM banks.

This module is the single source of truth for the ROM layout: the generator writes the memory
contents with :meth:`BankedLayout.contents` / :func:`hex_files`, and the bit-true model
(:mod:`pwas_hdl.fixedpoint.bittrue`) reads the weights back through the same layout, so a layout bug shows
up as a bit-true mismatch against the float model.

Both layouts give ``n + 1`` banks (one read port each, all read in the same cycle) and have the
same interface: ``n_banks``, ``depth``, ``total_words``, ``bank_addr``, ``simplex_bank_addr``,
``contents``, ``to_dict``.

Banked layout (default, :class:`BankedLayout`)
----------------------------------------------
Vertex ``v = (v_0 .. v_{n-1})`` (coordinates of :mod:`pwas_hdl.fit.geometry`, last dimension has
stride 1) goes to

* bank ``b(v) = (v_0 + ... + v_{n-1}) mod (n + 1)``;
* address ``a(v) = r * (P' / (n+1)) + v_{n-1} // (n+1)``, where ``r`` is the C-order index of
  ``(v_0 .. v_{n-2})`` (``r = linear_index // (p_{n-1} + 1)``; ``r = 0`` when ``n = 1``) and
  ``P' = ceil((p_{n-1} + 1) / (n+1)) * (n+1)`` is the last dimension padded to a multiple of
  ``n + 1``.

Depth ``D = R * P' / (n+1)`` with ``R = N / (p_{n-1} + 1)`` rows; total ``(n+1) * D = R * P'``
words, i.e. ``N`` plus the padding of each row (``N * P' / (p_{n-1}+1)``; 1.25 N for n = 4,
p = 7). Slots that hold no vertex contain 0.

*Uniqueness.* Given ``(b, a)``: ``r = a // (P'/(n+1))`` and the block ``g = a mod (P'/(n+1))``
fix ``v_0 .. v_{n-2}`` (so their sum ``S``) and ``v_{n-1} in {g(n+1), .., g(n+1) + n}``; these
``n + 1`` candidates have distinct residues mod ``n + 1``, so ``b = (S + v_{n-1}) mod (n+1)``
selects exactly one. Hence no two vertices share ``(bank, addr)``.

*One read per bank.* The vertices of a Kuhn simplex are ``v_k = c + e_perm[0] + .. +
e_perm[k-1]``, whose coordinate sums are ``|c| + k``: vertex ``k`` is in bank
``(|c| + k) mod (n+1)`` -- the ``n + 1`` vertices hit the ``n + 1`` banks once each (a rotation
by ``|c| mod (n+1)``).

Corner layout (:class:`CornerLayout`, comparator-free addresses)
-----------------------------------------------------------------
``2**n`` banks, one per cube corner ``s`` (bit ``j`` of ``s`` = the offset ``0 / 1`` in dimension
``j``), all addressed by the cell alone: bank ``s`` holds ``W[c + s]`` at address
``a(c) = sum_j c_j * 2**e_j``, the concatenation of the cells' bit fields (``width(p_j - 1)`` bits
each, the last dimension in the least significant bits; ``e_{n-1} = 0``,
``e_j = e_{j+1} + width(p_{j+1} - 1)``). Vertex ``k`` of the Kuhn simplex of cell ``c`` is corner
``s_k = sum_j [rank_j < k] 2**j``, read from bank ``s_k`` at ``a(c)``: the address needs no
comparison of the fractions (those only choose, after the read, which of the ``C(n, k)`` corner
words with ``k`` set bits vertex ``k`` takes). Depth ``2**sum_j width(p_j - 1)`` (addresses with a
``c_j >= p_j`` hold 0), ``2**n * depth`` words: e.g. 16 x 4096 x 11 bits for n = 4, p = 7 against
5 x 1024 for the banked layout.

Replicated layout (:class:`ReplicatedLayout`, for comparison)
-------------------------------------------------------------
``n + 1`` identical copies of the whole weight vector (depth ``N``, address = linear vertex
index); vertex ``k`` of a simplex is read from copy ``k``. ``(n+1) * N`` words.

``$readmemh`` files
-------------------
:func:`readmemh_text` writes one word per line, two's complement, lower-case hex with a fixed
number of digits ``ceil(bits / 4)``, no comments, no address markers: line ``a`` is address ``a``.
:func:`hex_files` chooses **one file per bank per target** by default (``<prefix>_b<bank>_z<target>.hex``,
each word ``B_w`` bits wide), so every memory is a plain signed ROM of one weight. With
``packed=True`` it writes one file per bank whose words hold all targets, target 0 in the least
significant ``B_w`` bits (``<prefix>_b<bank>.hex``, ``nz * B_w`` bits).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from pwas_hdl.errors import InputError
from pwas_hdl.fit.geometry import Grid
from pwas_hdl.fixedpoint.bitfields import check_codes, int64_codes, pack_rows, to_unsigned
from pwas_hdl.limits import MAX_MEMORY_WORDS, check_limit

__all__ = ["BankedLayout", "ReplicatedLayout", "CornerLayout", "make_layout", "readmemh_text", "pack_words", "hex_files", "LAYOUT_KINDS",
           "weight_memory_name", "hex_file_name", "WEIGHT_MEMORY_PATTERN", "SINGLE_MEMORY", "model_layout"]

LAYOUT_KINDS = ("banked", "replicated", "corner")

#: The serial core's weight memory (``generate --architecture serial``,
#: :class:`pwas_hdl.hdl.serial_core.SingleMemoryPlan`): one memory of ``N`` words addressed by the
#: linear vertex index, which is copy 0 of the replicated layout. The manifest's ``memory.kind`` and
#: ``generator.options.memory`` of a serial design.
SINGLE_MEMORY = "single"


def model_layout(memory: str) -> str:
    """The bit-true model's layout of a design's weight memory (``generate``'s ``memory``, the
    manifest's ``generator.options.memory``).

    Parameters
    ----------
    memory : {"banked", "replicated", "corner", "single"}

    Returns
    -------
    str
        ``memory`` itself, or ``"replicated"`` for the serial core's :data:`SINGLE_MEMORY` (its one
        memory is the replicated layout's copy 0: the same address of every vertex).
    """
    return "replicated" if memory == SINGLE_MEMORY else memory


def _as_weight_matrix(weight_codes, n_vertices: int) -> np.ndarray:
    w = np.asarray(weight_codes)
    if w.dtype.kind not in "iu":
        if not np.all(w == np.floor(w)):
            raise InputError("weight codes must be integers (quantize the weights first)")
    w = w.astype(np.int64)
    if w.ndim == 1:
        w = w[:, None]
    if w.ndim != 2 or w.shape[0] != n_vertices:
        raise InputError(f"weight codes must have shape (N, nz) with N = {n_vertices}, got {np.shape(weight_codes)}")
    return w


class _LayoutBase:
    kind = ""

    def __init__(self, grid: Grid):
        if not isinstance(grid, Grid):
            raise TypeError(f"expected a pwas_hdl.fit.geometry.Grid, got {type(grid).__name__}")
        self.grid = grid
        self.n = grid.n
        self.n_banks = grid.n + 1

    @property
    def total_words(self) -> int:
        """Words over all banks, ``n_banks * depth``."""
        return self.n_banks * self.depth

    @property
    def addr_bits(self) -> int:
        """Address width of one bank, ``max(1, ceil(log2(depth)))``."""
        return max(1, (self.depth - 1).bit_length())

    def _index(self, vertex) -> np.ndarray:
        if isinstance(vertex, tuple):
            return self.grid.vertex_index(np.asarray(vertex, dtype=np.int64))
        idx = np.asarray(vertex)
        if idx.dtype.kind not in "iu":
            raise InputError(f"vertex indices must be integers, got dtype {idx.dtype}; pass linear indices 0..N-1 or a tuple of coordinates")
        idx = idx.astype(np.int64)
        if idx.size and (idx.min() < 0 or idx.max() >= self.grid.n_vertices):
            raise InputError(f"vertex index {int(idx.min()) if idx.min() < 0 else int(idx.max())} is out of range [0, {self.grid.n_vertices}) "
                             f"(N = {self.grid.n_vertices} vertices)")
        return idx

    def contents(self, weight_codes) -> np.ndarray:
        """ROM contents.

        Parameters
        ----------
        weight_codes : array_like of int, shape (N, nz) or (N,)
            Weight codes in vertex order.

        Returns
        -------
        ndarray of int64, shape (n_banks, depth, nz)
            ``out[b, a, t]`` is the word at address ``a`` of bank ``b`` for target ``t``; unused
            slots are 0.
        """
        w = _as_weight_matrix(weight_codes, self.grid.n_vertices)
        out = np.zeros((self.n_banks, self.depth, w.shape[1]), dtype=np.int64)
        idx = np.arange(self.grid.n_vertices, dtype=np.int64)
        for slot in range(self.n_banks) if self.kind == "replicated" else (None,):
            b, a = self.bank_addr(idx, slot) if slot is not None else self.bank_addr(idx)
            out[b, a, :] = w
        return out

    def product_slots(self, bank: np.ndarray) -> np.ndarray:
        """Position of each product in the adder tree (:mod:`pwas_hdl.fixedpoint.reduction`): the
        bank that read its word (each bank multiplies its own word)."""
        return bank

    def used_mask(self) -> np.ndarray:
        """Boolean ``(n_banks, depth)``: True where a vertex is stored."""
        return self.contents(np.ones(self.grid.n_vertices, dtype=np.int64))[:, :, 0] != 0

    def to_dict(self) -> dict:
        """JSON-ready description for the manifest."""
        return {
            "kind": self.kind,
            "n_banks": self.n_banks,
            "depth": self.depth,
            "addr_bits": self.addr_bits,
            "total_words": self.total_words,
            "n_vertices": self.grid.n_vertices,
            "words_per_vertex": self.total_words / self.grid.n_vertices,
        }


class BankedLayout(_LayoutBase):
    """``n + 1`` banks by coordinate sum mod ``n + 1`` (see the module docstring).

    Parameters
    ----------
    grid : Grid

    Attributes
    ----------
    n_banks : int
        ``n + 1``.
    n_rows : int
        ``R = N / (p_{n-1} + 1)``.
    padded_last : int
        ``P'``, the last dimension padded to a multiple of ``n + 1``.
    row_words : int
        ``P' / (n + 1)``: addresses per row in each bank.
    row_strides : tuple of int
        Address weight of the coordinates ``v_0 .. v_{n-2}``: ``row_words`` times their C-order
        strides over the first ``n - 1`` dimensions, so that
        ``addr(v) = sum_{j<n-1} v_j * row_strides[j] + v_{n-1} // (n+1)`` (what the RTL adds).
    depth : int
        ``R * P' / (n + 1)``.
    """

    kind = "banked"

    def __init__(self, grid: Grid):
        super().__init__(grid)
        last = int(grid.partitions[-1]) + 1
        self.n_rows = grid.n_vertices // last
        self.padded_last = -(-last // self.n_banks) * self.n_banks
        self.row_words = self.padded_last // self.n_banks
        self.depth = self.n_rows * self.row_words
        self.row_strides = tuple(int(s) * self.row_words for s in grid.strides[:-1] // last)

    def bank_addr(self, vertex: int | np.ndarray | tuple[int, ...],
                  slot: int | np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Bank and address of vertices.

        Parameters
        ----------
        vertex : int, array of int (linear indices, any shape) or tuple of n ints (coordinates)
        slot : int or array of int, any shape, optional
            Ignored (the position in the simplex; only :class:`ReplicatedLayout` and
            :class:`CornerLayout` need it).

        Returns
        -------
        bank, addr : ndarray of int64, shape of the indices
        """
        return self.bank_addr_coords(self.grid.vertex_coords(self._index(vertex)))

    def bank_addr_coords(self, coords: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Bank and address from integer coordinates, shape ``(..., n)``.

        Parameters
        ----------
        coords : array_like of int, shape (..., n)
            Vertex coordinates, ``0 <= v_j <= p_j``.

        Returns
        -------
        bank, addr : ndarray of int64, shape (...)
            ``bank = sum(v) mod (n + 1)``, ``addr = v[:-1] @ row_strides + v[-1] // (n + 1)``.

        Raises
        ------
        InputError
            The last axis is not ``n`` long, or a coordinate is outside the grid.
        """
        c = np.asarray(coords, dtype=np.int64)
        if c.shape[-1:] != (self.n,):
            raise InputError(f"vertex coordinates must have shape (..., {self.n}), got {c.shape}")
        if c.size and (np.any(c < 0) or np.any(c > self.grid.partitions)):
            raise InputError(f"vertex coordinates outside the grid: coordinate j must be in 0..p_j, p = {tuple(self.grid.partitions)}")
        bank = c.sum(axis=-1) % self.n_banks
        addr = c[..., :-1] @ np.array(self.row_strides, dtype=np.int64) + c[..., -1] // self.n_banks
        return bank.astype(np.int64), np.asarray(addr, dtype=np.int64)

    def simplex_bank_addr(self, vertices: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Bank and address of each vertex of simplices.

        Parameters
        ----------
        vertices : ndarray of int, shape (m, n + 1)
            Linear indices, ``vertices[:, k]`` = vertex ``k`` (as :meth:`Grid.simplex_vertices`).

        Returns
        -------
        bank, addr : ndarray of int64, shape (m, n + 1)
            For the banked layout ``bank[:, k] = (|cell| + k) mod (n + 1)``.
        """
        return self.bank_addr(np.asarray(vertices, dtype=np.int64))

    def to_dict(self) -> dict:
        """JSON-ready description for the manifest.

        Returns
        -------
        dict
            The common keys (``kind``, ``n_banks``, ``depth``, ``addr_bits``, ...) and
            ``n_rows``, ``padded_last``, ``row_words`` and the ``bank`` / ``addr`` rules as text.
        """
        d = super().to_dict()
        d.update(
            {
                "n_rows": self.n_rows,
                "padded_last": self.padded_last,
                "row_words": self.row_words,
                "bank": "(v_0 + ... + v_{n-1}) mod (n+1)",
                "addr": "r * row_words + v_{n-1} // (n+1), r = C-order index of (v_0..v_{n-2})",
            }
        )
        return d


class ReplicatedLayout(_LayoutBase):
    """``n + 1`` full copies of the weights (the MOBY-DIC "fast" circuit), for comparison.

    Copy ``k`` serves vertex ``k`` of the simplex; address = linear vertex index.

    Parameters
    ----------
    grid : Grid
        The simplicial grid (``N`` vertices: every copy is ``N`` words deep).
    """

    kind = "replicated"

    def __init__(self, grid: Grid):
        super().__init__(grid)
        self.depth = grid.n_vertices

    def bank_addr(self, vertex: int | np.ndarray | tuple[int, ...],
                  slot: int | np.ndarray | None = 0) -> tuple[np.ndarray, np.ndarray]:
        """Bank (= ``slot``, the vertex's position ``k`` in its simplex; default 0) and address
        (= linear index) of vertices. Every copy holds every vertex.

        Parameters
        ----------
        vertex : int, array of int (linear indices, any shape) or tuple of n ints (coordinates)
        slot : int or array of int, optional
            The copy to read, broadcast to the shape of the indices (None: 0).

        Returns
        -------
        bank, addr : ndarray of int64, shape of the indices

        Raises
        ------
        InputError
            A vertex index that is not an integer or is outside ``[0, N)``.
        """
        idx = self._index(vertex)
        slot = 0 if slot is None else slot
        bank = np.broadcast_to(np.asarray(slot, dtype=np.int64), idx.shape).copy()
        return bank, idx.copy()

    def simplex_bank_addr(self, vertices: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Vertex ``k`` from copy ``k``; see :meth:`BankedLayout.simplex_bank_addr`.

        Parameters
        ----------
        vertices : array_like of int, shape (m, n + 1)
            Linear vertex indices (as :meth:`Grid.simplex_vertices`).

        Returns
        -------
        bank, addr : ndarray of int64, shape (m, n + 1)
            ``bank[:, k] = k``, ``addr`` = the linear index.
        """
        v = np.asarray(vertices, dtype=np.int64)
        return self.bank_addr(v, np.arange(v.shape[-1], dtype=np.int64))

    def address_fields(self) -> list[tuple[int, int, int]] | None:
        """The address (linear vertex index) as a concatenation of bit fields, or None.

        The address of vertex ``v`` is ``sum_j v_j * strides[j]``. When every stride is a power of
        two ``2**e_j`` and the fields ``[e_j, e_j + w_j)`` (``w_j`` the bits of ``0 .. p_j``) are
        disjoint inside :attr:`addr_bits` (``p_j + 1`` a power of two for ``j > 0``, as p = 7), the sum
        is their concatenation: no adder (what the latency-first core's front uses,
        :meth:`pwas_hdl.hdl.core.PWASCore._vertex_fields`).

        Returns
        -------
        list of (e_j, w_j, j) in dimension order, or None
        """
        spans, used, aw = [], 0, self.addr_bits if self.depth > 1 else 0
        for j, s in enumerate(int(v) for v in self.grid.strides):
            if s < 1 or s & (s - 1):
                return None
            e, w = s.bit_length() - 1, max(1, int(self.grid.partitions[j]).bit_length())
            mask = ((1 << w) - 1) << e
            if used & mask or e + w > aw:
                return None
            used |= mask
            spans.append((e, w, j))
        return spans


class CornerLayout(_LayoutBase):
    """``2**n`` corner banks addressed by the cell's bit fields (see the module docstring).

    Parameters
    ----------
    grid : Grid

    Attributes
    ----------
    n_banks : int
        ``2**n``: bank ``s`` holds the corner ``c + s`` of every cell ``c`` (bit ``j`` of ``s`` is
        the offset in dimension ``j``).
    cell_bits : tuple of int
        ``width(p_j - 1)`` (0 when ``p_j = 1``): the bits of cell coordinate ``j`` in the address.
    field_shifts : tuple of int
        ``e_j``: cell coordinate ``j`` sits at address bits ``[e_j, e_j + cell_bits[j])``.
    depth : int
        ``2**sum(cell_bits)`` (at least 1).
    """

    kind = "corner"

    def __init__(self, grid: Grid):
        super().__init__(grid)
        self.n_banks = 1 << self.n
        parts = [int(v) for v in grid.partitions]
        self.cell_bits = tuple((pj - 1).bit_length() for pj in parts)
        shifts, pos = [0] * self.n, 0
        for j in reversed(range(self.n)):
            shifts[j] = pos
            pos += self.cell_bits[j]
        self.field_shifts = tuple(shifts)
        # refused before any table or content of 2**n x 2**pos words is built
        check_limit("the corner memory's words (2**n banks x 2**(cell address bits))", self.n_banks << pos,
                    MAX_MEMORY_WORDS, "use the banked memory (--memory banked) for this grid")
        self.depth = 1 << pos

    def cell_addr(self, cells: ArrayLike) -> np.ndarray:
        """Address of cells (integer coordinates ``0 <= c_j < p_j``, shape ``(..., n)``).

        Parameters
        ----------
        cells : array_like of int, shape (..., n)
            Cell coordinates.

        Returns
        -------
        ndarray of int64, shape (...)
            ``sum_j c_j * 2**field_shifts[j]``.

        Raises
        ------
        InputError
            The last axis is not ``n`` long, or a coordinate is outside ``[0, p_j)``.
        """
        c = np.asarray(cells, dtype=np.int64)
        if c.shape[-1:] != (self.n,):
            raise InputError(f"cell coordinates must have shape (..., {self.n}), got {c.shape}")
        if c.size and (np.any(c < 0) or np.any(c >= self.grid.partitions)):
            raise InputError(f"cell coordinates outside the grid: coordinate j must be in 0..p_j - 1, p = {tuple(self.grid.partitions)}")
        return np.asarray(c @ (np.int64(1) << np.array(self.field_shifts, dtype=np.int64)), dtype=np.int64)

    def bank_addr(self, vertex: int | np.ndarray | tuple[int, ...],
                  slot: int | np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Bank and address of vertices as corner ``slot`` (a bank number ``s``) of a cell.

        Parameters
        ----------
        vertex : int, array of int (linear indices, any shape) or tuple of n ints (coordinates)
        slot : int or array of int, optional
            The corner ``s`` the vertex is read as, broadcast to the shape of the indices (default 0:
            the vertex as its own cell's corner 0, valid for vertices with every ``v_j < p_j``); the
            cell is ``v - s``.

        Returns
        -------
        bank, addr : ndarray of int64, shape of the indices
        """
        v = self.grid.vertex_coords(self._index(vertex))
        s = np.asarray(0 if slot is None else slot, dtype=np.int64)
        bits = (s[..., None] >> np.arange(self.n)) & 1
        bank = np.broadcast_to(s, v.shape[:-1]).copy()
        return bank, self.cell_addr(v - bits)

    def simplex_bank_addr(self, vertices: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Bank (the corner ``s_k``) and address (the cell's) of each vertex of simplices.

        Parameters
        ----------
        vertices : ndarray of int, shape (m, n + 1)
            Linear indices, ``vertices[:, 0]`` the cell's corner 0 (as :meth:`Grid.simplex_vertices`).

        Returns
        -------
        bank, addr : ndarray of int64, shape (m, n + 1)
        """
        v = np.asarray(vertices, dtype=np.int64)
        coords = self.grid.vertex_coords(self._index(v))  # (m, n+1, n)
        off = coords - coords[:, :1, :]
        bank = off @ (np.int64(1) << np.arange(self.n, dtype=np.int64))
        addr = np.broadcast_to(self.cell_addr(coords[:, 0, :])[:, None], bank.shape).copy()
        return bank.astype(np.int64), addr

    def product_slots(self, bank: np.ndarray) -> np.ndarray:
        """Position of each product in the adder tree: vertex order (the RTL selects vertex ``k``'s
        word among the corners, then multiplies and adds in vertex order).

        Parameters
        ----------
        bank : ndarray of int, shape (m, n + 1)
            The banks of :meth:`simplex_bank_addr` (only the shape is used).

        Returns
        -------
        ndarray of int64, shape of ``bank``
            ``k`` at column ``k`` (a read-only broadcast view).
        """
        return np.broadcast_to(np.arange(bank.shape[-1], dtype=np.int64), bank.shape)

    def contents(self, weight_codes: ArrayLike) -> np.ndarray:
        """ROM contents, shape ``(2**n, depth, nz)``: ``out[s, a(c), t] = W[c + s, t]``, 0 elsewhere.

        Parameters
        ----------
        weight_codes : array_like of int, shape (N, nz) or (N,)
            Weight codes in vertex order.

        Returns
        -------
        ndarray of int64, shape (2**n, depth, nz)

        Raises
        ------
        InputError
            Non-integer codes, or not ``N`` rows.
        """
        w = _as_weight_matrix(weight_codes, self.grid.n_vertices)
        out = np.zeros((self.n_banks, self.depth, w.shape[1]), dtype=np.int64)
        parts = np.asarray(self.grid.partitions, dtype=np.int64)
        cells = np.stack(np.meshgrid(*[np.arange(pj) for pj in parts], indexing="ij"), axis=-1).reshape(-1, self.n)
        a = self.cell_addr(cells)
        for s in range(self.n_banks):
            bits = (s >> np.arange(self.n)) & 1
            out[s, a, :] = w[self.grid.vertex_index(cells + bits)]
        return out

    def to_dict(self) -> dict:
        """JSON-ready description for the manifest.

        Returns
        -------
        dict
            The common keys (``kind``, ``n_banks``, ``depth``, ``addr_bits``, ...) and
            ``cell_bits``, ``field_shifts`` and the ``bank`` / ``addr`` rules as text.
        """
        d = super().to_dict()
        d.update({"cell_bits": list(self.cell_bits), "field_shifts": list(self.field_shifts),
                  "bank": "corner s of the cell (bit j of s: offset in dimension j)",
                  "addr": "sum_j c_j * 2**field_shifts[j] (the cell's bit fields)"})
        return d


def make_layout(grid: Grid, kind: str = "banked") -> BankedLayout | ReplicatedLayout | CornerLayout:
    """Layout by name: ``"banked"`` (default), ``"replicated"`` or ``"corner"``.

    Parameters
    ----------
    grid : Grid
    kind : {"banked", "replicated", "corner"}

    Returns
    -------
    BankedLayout or ReplicatedLayout or CornerLayout

    Raises
    ------
    InputError
        An unknown ``kind``.
    """
    if kind == "banked":
        return BankedLayout(grid)
    if kind == "replicated":
        return ReplicatedLayout(grid)
    if kind == "corner":
        return CornerLayout(grid)
    raise InputError(f"memory layout must be one of {LAYOUT_KINDS}, got {kind!r}")


#: A weight memory's name in the generated Verilog (:func:`weight_memory_name`), as a regular
#: expression without groups: ``wmem<b>``, or ``part<i>_wmem<b>`` in an additive design's part ``i``.
WEIGHT_MEMORY_PATTERN = r"(?:part[0-9]+_)?wmem[0-9]+"


def weight_memory_name(bank: int, part: int | None = None) -> str:
    """The name of weight memory ``bank`` in the generated Verilog: ``wmem<bank>``, or
    ``part<part>_wmem<bank>`` in part ``part`` of an additive design (its parts flattened into the
    top, :mod:`pwas_hdl.hdl.additive_top`). The one place these names are made; the cores name
    their ROMs with it, and synthesis and ``$readmemh`` read them back
    (:data:`WEIGHT_MEMORY_PATTERN`).

    Parameters
    ----------
    bank : int
        Memory bank of the core (``0 .. n_banks - 1``).
    part : int, optional
        Additive part; None for a design with one core (or inside a part, before flattening).

    Returns
    -------
    str
    """
    return f"{'' if part is None else f'part{int(part)}_'}wmem{int(bank)}"


def hex_file_name(prefix: str, bank: int, part: int | None = None, target: int | None = None) -> str:
    """Name of the ``$readmemh`` file of weight memory ``bank``: ``<prefix>_b<bank>.hex``, or of bank
    ``bank`` of additive part ``part``: ``<prefix>_p<part>_b<bank>.hex``; with ``target``, the file of
    that target's words alone (:func:`hex_files`): ``..._z<target>.hex``. The one place these names are
    made (:func:`hex_files`, :func:`pwas_hdl.hdl.emit.memory_hex_files` and the ``$readmemh`` calls
    of the Verilog).

    Parameters
    ----------
    prefix : str
        File-name prefix.
    bank : int
        Memory bank (``wmem<bank>``).
    part : int, optional
        Additive part (``part<part>_wmem<bank>``); None for a design with one core.
    target : int, optional
        One target's file (``hex_files(..., packed=False)``); None: the packed word of all targets.

    Returns
    -------
    str
    """
    return f"{prefix}{'' if part is None else f'_p{int(part)}'}_b{int(bank)}{'' if target is None else f'_z{int(target)}'}.hex"


def readmemh_text(words: ArrayLike, bits: int) -> str:
    """``$readmemh`` text: one word per line, two's complement, ``ceil(bits/4)`` lower-case hex digits.

    Parameters
    ----------
    words : sequence of int, shape (depth,)
        Signed or unsigned integers that fit ``bits`` bits (two's complement for negatives).
    bits : int
        Word width in bits, ``>= 1``.

    Returns
    -------
    str
        Ends with a newline (empty string for no words).

    Raises
    ------
    InputError
        ``bits`` is not an integer ``>= 1``.
    """
    if not isinstance(bits, (int, np.integer)) or bits < 1:
        raise InputError(f"word width must be an integer >= 1, got {bits!r}")
    bits = int(bits)
    digits = -(-bits // 4)
    if bits <= 63:
        arr = int64_codes(words)  # None: not integers an int64 holds exactly (the loop below refuses or converts them)
        if arr is not None and arr.ndim == 1:
            check_codes(arr, bits)
            # the hex digits of every word at once: nibbles, most significant first, through a table
            u = arr & ((1 << bits) - 1)  # two's complement in `bits` bits
            nibbles = (u[:, None] >> (4 * np.arange(digits - 1, -1, -1))) & 0xF
            text = np.empty((len(arr), digits + 1), dtype=np.uint8)
            text[:, :digits] = _HEX_DIGITS[nibbles]
            text[:, digits] = ord("\n")
            return text.tobytes().decode("ascii")
    return "".join(format(to_unsigned(w, bits), f"0{digits}x") + "\n" for w in words)


_HEX_DIGITS = np.frombuffer(b"0123456789abcdef", dtype=np.uint8)


#: Packed words of one bank, target 0 in the least significant bits (:func:`pwas_hdl.fixedpoint.bitfields.pack_rows`).
pack_words = pack_rows


def hex_files(layout: BankedLayout | ReplicatedLayout | CornerLayout, weight_codes: ArrayLike, bits: int,
              packed: bool = False, prefix: str = "w") -> dict[str, str]:
    """``$readmemh`` files of all banks.

    Parameters
    ----------
    layout : BankedLayout, ReplicatedLayout or CornerLayout
        Where each vertex's weights go (banks and addresses).
    weight_codes : array_like of int, shape (N, nz)
        Weight codes (LSB of the weight format), one row per vertex.
    bits : int
        Weight width ``B_w`` in bits.
    packed : bool
        False (default): one file per bank per target, ``<prefix>_b<bank>_z<target>.hex``.
        True: one file per bank, ``<prefix>_b<bank>.hex``, ``nz * bits``-bit words with target 0
        in the least significant bits.
    prefix : str
        Start of the file names.

    Returns
    -------
    dict
        File name -> text, in bank (then target) order.
    """
    rom = layout.contents(weight_codes)
    files: dict[str, str] = {}
    for b in range(layout.n_banks):
        if packed:
            files[hex_file_name(prefix, b)] = readmemh_text(pack_words(rom[b], bits), bits * rom.shape[2])
        else:
            for t in range(rom.shape[2]):
                files[hex_file_name(prefix, b, target=t)] = readmemh_text(rom[b, :, t], bits)
    return files
