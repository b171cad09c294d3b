"""Banked weight memory: uniqueness, one read per bank per simplex, size, ROM image, $readmemh."""

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pwas_hdl.fit.geometry import Grid
from pwas_hdl.fixedpoint.memory_layout import BankedLayout, ReplicatedLayout, hex_files, make_layout, pack_words, readmemh_text

GRIDS = [
    [1], [2], [7], [8],
    [1, 1], [3, 2], [2, 5], [4, 4], [7, 1],
    [1, 1, 1], [2, 3, 4], [5, 1, 3], [3, 3, 3],
    [1, 1, 1, 1], [2, 2, 2, 3], [3, 1, 2, 4], [7, 7, 7, 7],
    [1, 1, 1, 1, 1], [2, 1, 2, 1, 3], [2, 2, 2, 2, 2],
    [1, 1, 1, 1, 1, 1], [2, 1, 1, 2, 1, 4], [2, 2, 2, 2, 2, 2],
]


def _grid(parts):
    n = len(parts)
    return Grid(np.zeros(n), np.arange(1, n + 1, dtype=float), parts)


def _simplices(grid, limit, rng):
    """All (cell, perm) pairs when there are at most ``limit`` simplices, else a random sample."""
    n = grid.n
    perms = np.array(list(itertools.permutations(range(n))), dtype=np.int64)
    cells = np.stack(np.unravel_index(np.arange(int(np.prod(grid.partitions))), tuple(grid.partitions)), axis=1).astype(np.int64)
    if len(cells) * len(perms) <= limit:
        c = np.repeat(cells, len(perms), axis=0)
        p = np.tile(perms, (len(cells), 1))
    else:
        c = cells[rng.integers(0, len(cells), limit)]
        p = perms[rng.integers(0, len(perms), limit)]
    return c, p


@pytest.mark.parametrize("parts", GRIDS, ids=lambda p: "x".join(map(str, p)))
def test_banked_unique_and_in_range(parts):
    g = _grid(parts)
    lay = BankedLayout(g)
    n = g.n
    assert lay.n_banks == n + 1
    last = parts[-1] + 1
    pp = math.ceil(last / (n + 1)) * (n + 1)
    assert lay.padded_last == pp
    assert lay.depth == (g.n_vertices // last) * pp // (n + 1)
    assert lay.total_words == lay.n_banks * lay.depth
    assert lay.total_words - g.n_vertices == (g.n_vertices // last) * (pp - last)  # only the row padding
    idx = np.arange(g.n_vertices)
    bank, addr = lay.bank_addr(idx)
    coords = g.vertex_coords(idx)
    assert np.array_equal(bank, coords.sum(axis=1) % (n + 1))
    assert bank.min() >= 0 and bank.max() < lay.n_banks
    assert addr.min() >= 0 and addr.max() < lay.depth
    slots = bank * lay.depth + addr
    assert np.unique(slots).size == g.n_vertices  # no two vertices share (bank, addr)
    # tuple of coordinates and coordinate arrays give the same answer
    b0, a0 = lay.bank_addr(tuple(int(c) for c in coords[-1]))
    assert (int(b0), int(a0)) == (int(bank[-1]), int(addr[-1]))
    b1, a1 = lay.bank_addr_coords(coords)
    assert np.array_equal(b1, bank) and np.array_equal(a1, addr)


@pytest.mark.parametrize("parts", GRIDS, ids=lambda p: "x".join(map(str, p)))
def test_simplex_vertices_hit_every_bank_once(parts):
    g = _grid(parts)
    lay = BankedLayout(g)
    n = g.n
    cell, perm = _simplices(g, 4000, np.random.default_rng(len(parts) * 100 + sum(parts)))
    verts = g.simplex_vertices(cell, perm)
    bank, addr = lay.simplex_bank_addr(verts)
    assert np.array_equal(np.sort(bank, axis=1), np.broadcast_to(np.arange(n + 1), bank.shape))
    expect = (cell.sum(axis=1)[:, None] + np.arange(n + 1)[None, :]) % (n + 1)
    assert np.array_equal(bank, expect)  # vertex k in bank (|c| + k) mod (n+1)
    # addresses agree with the single-vertex mapping
    b2, a2 = lay.bank_addr(verts)
    assert np.array_equal(addr, a2) and np.array_equal(bank, b2)


def test_lorenz_size():
    g = _grid([7, 7, 7, 7])
    lay = BankedLayout(g)
    assert g.n_vertices == 4096
    assert lay.total_words == 5120 == 1.25 * g.n_vertices
    assert lay.total_words <= 1.3 * g.n_vertices
    assert lay.depth == 1024 and lay.addr_bits == 10
    rep = ReplicatedLayout(g)
    assert rep.total_words == 5 * 4096 and rep.depth == 4096


@pytest.mark.parametrize("parts", [[3], [2, 3], [3, 1, 2], [2, 2, 1, 3]])
@pytest.mark.parametrize("kind", ["banked", "replicated"])
def test_contents_read_back(parts, kind):
    g = _grid(parts)
    lay = make_layout(g, kind)
    rng = np.random.default_rng(7)
    codes = rng.integers(1, 1000, (g.n_vertices, 2)) * rng.choice([-1, 1], (g.n_vertices, 2))
    rom = lay.contents(codes)
    assert rom.shape == (lay.n_banks, lay.depth, 2) and rom.dtype == np.int64
    cell, perm = _simplices(g, 10_000, rng)
    verts = g.simplex_vertices(cell, perm)
    bank, addr = lay.simplex_bank_addr(verts)
    assert np.array_equal(rom[bank, addr, :], codes[verts])
    used = lay.used_mask()
    # every non-zero word is a weight, unused slots are 0
    assert np.all(rom[~used] == 0)
    per_bank = g.n_vertices if kind == "replicated" else None
    if per_bank:
        assert np.all(used.sum(axis=1) == per_bank)
        assert np.array_equal(bank, np.broadcast_to(np.arange(g.n + 1), bank.shape))
        assert np.array_equal(addr, verts)
    else:
        assert used.sum() == g.n_vertices
    # 1-D weight vector
    assert lay.contents(codes[:, 0]).shape == (lay.n_banks, lay.depth, 1)
    with pytest.raises(ValueError, match="shape"):
        lay.contents(codes[:-1])


@pytest.mark.parametrize("parts", [[3], [2, 3], [3, 1, 2], [2, 2, 1, 3]])
def test_corner_bank_addr_is_where_contents_put_the_vertex(parts):
    """CornerLayout.bank_addr(v, s) (v as corner s of cell v - s) names the word that holds W[v]."""
    g = _grid(parts)
    lay = make_layout(g, "corner")
    codes = np.arange(1, g.n_vertices + 1)
    rom = lay.contents(codes)
    coords = g.vertex_coords()
    for s in range(lay.n_banks):
        bits = (s >> np.arange(g.n)) & 1
        ok = np.all(coords - bits >= 0, axis=1) & np.all(coords - bits < g.partitions, axis=1)  # cell v - s exists
        v = np.flatnonzero(ok)
        bank, addr = lay.bank_addr(v, s)
        assert np.all(bank == s)
        assert np.array_equal(rom[bank, addr, 0], codes[v])


def test_layout_errors():
    g = _grid([2, 2])
    with pytest.raises(ValueError, match="memory layout"):
        make_layout(g, "diagonal")
    with pytest.raises(ValueError, match="out of range"):
        BankedLayout(g).bank_addr(np.array([9]))
    with pytest.raises(ValueError, match="outside the grid"):
        BankedLayout(g).bank_addr_coords(np.array([[3, 0]]))
    d = BankedLayout(g).to_dict()
    assert d["kind"] == "banked" and d["n_banks"] == 3 and d["total_words"] == 9


def test_readmemh_text():
    txt = readmemh_text([0, 1, -1, -32768, 32767, 255], 16)
    assert txt == "0000\n0001\nffff\n8000\n7fff\n00ff\n"
    assert readmemh_text([-1, 3], 5) == "1f\n03\n"  # ceil(5/4) = 2 digits
    assert readmemh_text([], 8) == ""
    with pytest.raises(ValueError, match="does not fit"):
        readmemh_text([128 + 256], 8)
    with pytest.raises(ValueError, match="does not fit"):
        readmemh_text([-129], 8)
    # parse back as two's complement
    words = np.random.default_rng(0).integers(-(2**11), 2**11, 200)
    back = [int(s, 16) for s in readmemh_text(words, 12).split()]
    back = [b - (1 << 12) if b >= 1 << 11 else b for b in back]
    assert back == words.tolist()


def test_hex_files_and_packing():
    g = _grid([2, 3])
    lay = BankedLayout(g)
    codes = np.arange(g.n_vertices * 2).reshape(-1, 2) - 6
    files = hex_files(lay, codes, 6)
    assert sorted(files) == sorted(f"w_b{b}_z{t}.hex" for b in range(3) for t in range(2))
    rom = lay.contents(codes)
    for b in range(3):
        for t in range(2):
            lines = files[f"w_b{b}_z{t}.hex"].split("\n")[:-1]
            assert len(lines) == lay.depth and all(len(s) == 2 for s in lines)
            vals = [int(s, 16) - 64 if int(s, 16) >= 32 else int(s, 16) for s in lines]
            assert vals == rom[b, :, t].tolist()
    packed = hex_files(lay, codes, 6, packed=True, prefix="rom")
    assert sorted(packed) == ["rom_b0.hex", "rom_b1.hex", "rom_b2.hex"]
    words = [int(s, 16) for s in packed["rom_b1.hex"].split()]
    assert words == pack_words(rom[1], 6)
    assert all(len(s) == 3 for s in packed["rom_b1.hex"].split())  # 12 bits -> 3 digits
    lo = [(w & 63) - 64 if (w & 63) >= 32 else (w & 63) for w in words]
    hi = [(w >> 6) - 64 if (w >> 6) >= 32 else (w >> 6) for w in words]
    assert lo == rom[1, :, 0].tolist() and hi == rom[1, :, 1].tolist()


@settings(deadline=None)
@given(parts=st.lists(st.integers(1, 17), min_size=1, max_size=4), seed=st.integers(0, 2**16))
def test_replicated_address_fields_concatenate_to_the_linear_index(parts, seed):
    """Where ReplicatedLayout.address_fields exists, OR-ing each coordinate into its field is the
    layout's address (the linear vertex index) of every vertex; where it is None, some stride is not a
    power of two or two fields would overlap."""
    lay = ReplicatedLayout(Grid([0.0] * len(parts), [1.0] * len(parts), parts))
    fields = lay.address_fields()
    strides = [int(s) for s in lay.grid.strides]
    if fields is None:
        pow2 = all(s & (s - 1) == 0 for s in strides)
        spans = [(s.bit_length() - 1, max(1, p.bit_length())) for s, p in zip(strides, parts)]
        overlap = any(a < c + d and c < a + b for i, (a, b) in enumerate(spans) for c, d in spans[i + 1:])
        assert not pow2 or overlap or any(e + w > lay.addr_bits for e, w in spans)
        return
    assert [j for _, _, j in fields] == list(range(len(parts)))
    rng = np.random.default_rng(seed)
    coords = np.stack([rng.integers(0, p + 1, size=64) for p in parts], axis=1)
    word = np.zeros(64, dtype=np.int64)
    for e, w, j in fields:
        assert int(coords[:, j].max()) < (1 << w)
        word |= coords[:, j] << e
    _, addr = lay.bank_addr(lay.grid.vertex_index(coords))
    np.testing.assert_array_equal(word, addr)
    assert int(word.max()) < (1 << lay.addr_bits)
