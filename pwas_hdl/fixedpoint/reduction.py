"""The pairwise reduction tree: the one definition of the order in which the circuit adds.

Level ``l`` combines items ``2i`` and ``2i + 1`` of level ``l - 1`` into item ``i``; an odd last item
passes to the next level unchanged. ``k`` items take ``ceil(log2 k)`` levels. The same order is used
by

* the bit-true model (:mod:`pwas_hdl.fixedpoint.bittrue`: the accumulator is the tree sum of the
  products in memory-bank order),
* the RTL generator (:mod:`pwas_hdl.hdl.core`: the adder tree and its pipeline registers;
  :mod:`pwas_hdl.hdl._lintsafe`: modular address sums; the bank rotation's residue sum),
* the debug probes of the RTL replay (:mod:`pwas_hdl.verify.simulation`: the expected partial sums
  held by the ``s_tree<l>`` registers).

``combine(a, b, level, index)`` gets the level number (0 for the first) and the index of the new
item within its level, so that a hardware builder can name the net it creates.
"""

from __future__ import annotations

from typing import Callable, Sequence, TypeVar

from pwas_hdl.errors import InputError

__all__ = ["tree_depth", "tree_level", "tree_levels", "tree_reduce"]

T = TypeVar("T")


def tree_depth(n_items: int) -> int:
    """Levels of the tree over ``n_items >= 1`` items: ``ceil(log2(n_items))`` (0 for one item).

    Parameters
    ----------
    n_items : int
        Leaves of the tree, ``>= 1``.

    Returns
    -------
    int
        Levels of pairwise combinations (not cycles).

    Raises
    ------
    InputError
        ``n_items < 1``.
    """
    if n_items < 1:
        raise InputError(f"a reduction needs at least one item, got {n_items}")
    return (int(n_items) - 1).bit_length()


def tree_level(items: Sequence[T], combine: Callable[[T, T, int, int], T], level: int = 0) -> list[T]:
    """One level: ``combine(items[2i], items[2i+1], level, i)``; an odd last item passes.

    Parameters
    ----------
    items : sequence
        The items entering this level, lowest index first.
    combine : callable(a, b, level, index) -> item
        Combines two items of level ``level`` into the ``index``-th item of the next level.
    level : int
        This level's number (0: the leaves' level), passed to ``combine``.

    Returns
    -------
    list
        ``ceil(len(items) / 2)`` items.
    """
    return [
        combine(items[i], items[i + 1], level, i // 2) if i + 1 < len(items) else items[i]
        for i in range(0, len(items), 2)
    ]


def tree_levels(items: Sequence[T], combine: Callable[[T, T, int, int], T]) -> list[list[T]]:
    """Every level of the tree: ``out[l]`` are the items after level ``l``; ``out[-1]`` has one item.

    Empty for a single item (nothing to add).

    Parameters
    ----------
    items : sequence
        The leaves, lowest index first (at least one).
    combine : callable(a, b, level, index) -> item
        Combines two items of level ``level`` into the ``index``-th item of the next level.

    Returns
    -------
    list of list
        ``tree_depth(len(items))`` levels.

    Raises
    ------
    InputError
        No item.
    """
    cur = list(items)
    if not cur:
        raise InputError("a reduction needs at least one item")
    levels = []
    while len(cur) > 1:
        cur = tree_level(cur, combine, len(levels))
        levels.append(cur)
    return levels


def tree_reduce(items: Sequence[T], combine: Callable[[T, T, int, int], T]) -> T:
    """The root of the tree (``items[0]`` for a single item).

    Parameters
    ----------
    items : sequence
        The leaves, lowest index first (at least one).
    combine : callable(a, b, level, index) -> item
        Combines two items of level ``level`` into the ``index``-th item of the next level.

    Returns
    -------
    item
        What the last ``combine`` returned.

    Raises
    ------
    InputError
        No item.
    """
    levels = tree_levels(items, combine)
    return levels[-1][0] if levels else list(items)[0]
