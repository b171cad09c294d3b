"""The one bit-field packing (fixedpoint/bitfields.py) and the one reduction-tree order (fixedpoint/reduction.py)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from pwas_hdl.errors import InputError
from pwas_hdl.fixedpoint.bitfields import (pack, pack_fields, pack_fields_words, pack_rows, to_signed, to_unsigned, unpack,
                                           unpack_fields)
from pwas_hdl.fixedpoint.reduction import tree_depth, tree_level, tree_levels, tree_reduce


@st.composite
def _codes(draw):
    width = draw(st.integers(1, 40))
    vals = draw(st.lists(st.integers(-(1 << (width - 1)), (1 << (width - 1)) - 1), min_size=1, max_size=6))
    return width, vals


@given(_codes())
def test_pack_unpack_round_trip(wv):
    width, vals = wv
    word = pack(vals, width)
    assert 0 <= word < 1 << (width * len(vals))
    assert unpack(word, width, len(vals)) == vals
    # field i sits at bits [i*width +: width], two's complement
    for i, v in enumerate(vals):
        assert (word >> (i * width)) & ((1 << width) - 1) == v % (1 << width)
    fields = [{"lsb": i * width, "width": width, "signed": True} for i in range(len(vals))]
    assert pack_fields(vals, fields) == word and unpack_fields(word, fields) == vals


def test_explicit_fields_mixed_signedness():
    fields = [{"lsb": 0, "width": 5, "signed": True}, {"lsb": 5, "width": 3, "signed": False}, {"lsb": 8, "width": 1}]
    word = pack_fields([-3, 6, 1], fields)
    assert word == (29 | 6 << 5 | 1 << 8)
    assert unpack_fields(word, fields) == [-3, 6, 1]
    assert unpack(word, 5, 1, signed=False) == [29]


@pytest.mark.parametrize("value, width", [(8, 3), (-5, 3), (2, 1), (-2, 1)])
def test_values_that_do_not_fit_are_refused(value, width):
    assert to_signed(to_unsigned(-1, width), width) == -1
    with pytest.raises(InputError, match=f"code {value} does not fit {width} bits"):
        pack([0, value], width)


def test_pack_rows_is_one_word_per_row():
    codes = np.array([[1, -1], [-2, 3], [0, 0]])
    assert pack_rows(codes, 4) == [1 | 15 << 4, 14 | 3 << 4, 0]
    assert pack_rows(np.array([-1, 2]), 4) == [15, 2]


def test_tree_order_pairs_neighbours_and_passes_the_odd_one():
    seen = []
    levels = tree_levels(list("abcde"), lambda a, b, lvl, i: seen.append((lvl, i, a, b)) or f"({a}{b})")
    assert levels == [["(ab)", "(cd)", "e"], ["((ab)(cd))", "e"], ["(((ab)(cd))e)"]]
    assert seen[0] == (0, 0, "a", "b") and seen[1] == (0, 1, "c", "d") and seen[-1][:2] == (2, 0)
    assert tree_reduce(list("abcde"), lambda a, b, *_: a + b) == "abcde"
    assert tree_reduce(["x"], lambda a, b, *_: a + b) == "x" and tree_levels(["x"], lambda *a: None) == []
    assert tree_level([1, 2, 3], lambda a, b, *_: a + b, 4) == [3, 3]
    assert [tree_depth(k) for k in range(1, 10)] == [0, 1, 2, 2, 3, 3, 3, 3, 4]
    with pytest.raises(ValueError):
        tree_depth(0)


@given(st.lists(st.integers(-(2**40), 2**40), min_size=1, max_size=9))
def test_tree_sum_is_the_sum_and_has_depth_levels(values):
    levels = tree_levels(values, lambda a, b, *_: a + b)
    assert len(levels) == tree_depth(len(values))
    assert tree_reduce(values, lambda a, b, *_: a + b) == sum(values)


def test_core_adder_tree_and_probes_use_the_same_order():
    """The partial sums the debug probes expect are the levels of the same tree (bank order)."""
    from pwas_hdl.verify.simulation import _tree_levels

    products = np.array([[1, 10], [2, 20], [3, 30], [4, 40], [5, 50]])
    levels = _tree_levels(products)
    assert levels == [[[3, 7, 5], [30, 70, 50]], [[10, 5], [100, 50]], [[15], [150]]]


@given(st.data())
def test_array_packing_into_32_bit_words_matches_the_scalar_one(data):
    from pwas_hdl.fixedpoint.bitfields import pack_fields_words, unpack_fields_words

    widths = data.draw(st.lists(st.integers(1, 62), min_size=1, max_size=5))
    signed = data.draw(st.lists(st.booleans(), min_size=len(widths), max_size=len(widths)))
    fields, lsb = [], 0
    for w, sg in zip(widths, signed):
        fields.append({"name": f"f{len(fields)}", "lsb": lsb, "width": w, "signed": sg})
        lsb += w
    n_words = -(-lsb // 32)
    rows = [[data.draw(st.integers(-(1 << (w - 1)) if sg else 0, (1 << (w - 1)) - 1 if sg else (1 << w) - 1))
             for w, sg in zip(widths, signed)] for _ in range(3)]
    words = pack_fields_words(np.array(rows), fields, n_words)
    assert words.dtype == np.uint32 and words.shape == (3, n_words)
    for r, row in enumerate(rows):
        assert sum(int(x) << (32 * i) for i, x in enumerate(words[r])) == pack_fields(row, fields)
    assert unpack_fields_words(words, fields).tolist() == rows


def test_array_packing_refuses_what_does_not_fit():
    from pwas_hdl.fixedpoint.bitfields import pack_fields_words

    fields = [{"name": "a", "lsb": 0, "width": 4}, {"name": "b", "lsb": 4, "width": 40}]
    with pytest.raises(InputError, match="code 16 does not fit 4 bits"):
        pack_fields_words(np.array([[16, 0]]), fields, 2)
    with pytest.raises(InputError, match="ends past"):
        pack_fields_words(np.array([[1, 1]]), fields, 1)


@given(st.data())
def test_native_bench_words_are_the_bitfields_packing(data):
    """sim/pwas_native.py packs the native bench's payload words with the one packer (bitfields):
    fields crossing 32-bit word boundaries, signed and unsigned, round-trip exactly."""
    from pwas_hdl.sim import pwas_native as native

    widths = data.draw(st.lists(st.integers(1, 40), min_size=1, max_size=5), "widths")
    signed = data.draw(st.lists(st.booleans(), min_size=len(widths), max_size=len(widths)), "signed")
    fields, lsb = [], 0
    for k, (w, sg) in enumerate(zip(widths, signed)):
        fields.append({"name": f"f{k}", "lsb": lsb, "width": w, "signed": sg})
        lsb += w
    n_words = (lsb + 31) // 32
    rows = data.draw(st.integers(1, 4), "rows")
    codes = np.array([[data.draw(st.integers(-(1 << (f["width"] - 1)), (1 << (f["width"] - 1)) - 1) if f["signed"]
                                 else st.integers(0, (1 << f["width"]) - 1)) for f in fields] for _ in range(rows)],
                     dtype=np.int64)
    words = native.pack_words(codes, fields, n_words)
    assert words.dtype == np.uint32 and words.shape == (rows, n_words)
    assert np.array_equal(words, pack_fields_words(codes, fields, n_words))
    assert np.array_equal(native.unpack_words(words, fields), codes)
    # the same bits as the scalar packer, word by word (word 0 = bits 31..0)
    for r in range(rows):
        big = pack_fields(codes[r].tolist(), fields)
        assert [int(x) for x in words[r]] == [(big >> (32 * i)) & 0xFFFFFFFF for i in range(n_words)]


@given(st.data())
def test_array_forms_of_pack_rows_and_readmemh_match_the_scalar_ones(data):
    """pack_rows and readmemh_text pack and print whole ROM images with numpy up to 63 bits a word
    (a 10^6-weight generate spent ~5 s in their per-word Python loops); they must give exactly what
    pack / to_unsigned / format give word by word, and refuse the same codes."""
    from pwas_hdl.fixedpoint.memory_layout import readmemh_text

    width = data.draw(st.integers(1, 40), label="width")
    fields = data.draw(st.integers(1, 4), label="fields")
    # mostly codes that fit (signed or unsigned), sometimes one just outside
    code = st.integers(-(1 << (width - 1)) - 1, (1 << width))
    rows = data.draw(st.lists(st.lists(code, min_size=fields, max_size=fields), min_size=0, max_size=12), label="rows")
    codes = np.array(rows, dtype=np.int64).reshape(len(rows), fields)
    fits = all(-(1 << (width - 1)) <= v < (1 << width) for r in rows for v in r)
    bits = width * fields
    digits = -(-bits // 4)
    if fits:
        words = pack_rows(codes, width)
        assert words == [pack(r, width) for r in rows] and all(type(w) is int for w in words)
        assert readmemh_text(words, bits) == "".join(format(w, f"0{digits}x") + "\n" for w in words)
        flat = codes[:, 0].tolist()
        assert readmemh_text(flat, width) == "".join(format(to_unsigned(v, width), f"0{-(-width // 4)}x") + "\n" for v in flat)
    else:
        with pytest.raises(InputError, match="does not fit"):
            pack_rows(codes, width)
        with pytest.raises(InputError, match="does not fit"):
            readmemh_text(codes.ravel().tolist(), width)


def test_array_forms_refuse_unsigned_64_bit_codes_an_int64_would_wrap():
    """readmemh_text / pack_rows convert to int64 for numpy: a uint64 word of 2**63 or more wrapped
    to a negative that fits (2**64 - 1 became -1 and was written as "ff" in 8 bits, or packed as
    2**70 - 1 in a 70-bit field). The module refuses codes that do not fit rather than wrapping
    them, and a 70-bit field holds 2**64 - 1 as it is."""
    from pwas_hdl.fixedpoint.memory_layout import readmemh_text

    big = np.array([2**64 - 1, 5], dtype=np.uint64)
    with pytest.raises(InputError, match="code 18446744073709551615 does not fit 8 bits"):
        readmemh_text(big, 8)
    with pytest.raises(InputError, match="code 9223372036854775808 does not fit 63 bits"):
        readmemh_text(np.array([2**63], dtype=np.uint64), 63)
    with pytest.raises(InputError, match="code 18446744073709551615 does not fit 8 bits"):
        pack_rows(big[:, None], 8)
    assert pack_rows(np.array([2**64 - 1], dtype=np.uint64), 70) == [2**64 - 1]
    # unsigned codes an int64 holds stay on the array path, and give what the scalar path gives
    assert readmemh_text(np.array([2**63 - 1, 0], dtype=np.uint64), 63) == format(2**63 - 1, "016x") + "\n" + "0" * 16 + "\n"
    assert pack_rows(np.array([[255, 1]], dtype=np.uint64), 8) == [pack([255, 1], 8)]


def test_readmemh_of_floats_is_the_per_word_conversion():
    """numpy casts NaN and floats beyond int64 to -2**63 (with a RuntimeWarning): readmemh_text named
    that code instead of the word's (1e30), and refused a NaN as a code that does not fit, where
    the per-word int() keeps the value or refuses the NaN as not a number."""
    import warnings

    from pwas_hdl.fixedpoint.memory_layout import readmemh_text

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(InputError, match=f"code {int(1e30)} does not fit 8 bits"):
            readmemh_text(np.array([1e30]), 8)
        with pytest.raises(ValueError, match="NaN"):
            readmemh_text(np.array([np.nan]), 8)
        assert readmemh_text(np.array([-1.5, 2.7]), 8) == "ff\n02\n"
