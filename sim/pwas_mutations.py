"""Deliberate faults in generated Verilog, to show that the testbench fails when the RTL is wrong.

Each function takes the Verilog text and returns ``(new_text, description)``; it raises
ValueError when the generated code no longer has the construct it edits (then the mutation test
must be updated, not silently pass).

* :func:`flip_weight_bit` -- one bit of one word of a weight memory initialiser.
* :func:`round_constant_plus_one_lsb` -- the rounding constant of the output stage, so that every
  output comes out one LSB too high (a one-LSB change of the result).
* :func:`offset_constant_off_by_one` -- the constant that subtracts ``lo_code`` in the scale stage
  (``t_j = q_j - lo_code_j``), one input code off.
"""

from __future__ import annotations

import re

__all__ = ["flip_weight_bit", "round_constant_plus_one_lsb", "offset_constant_off_by_one"]


def flip_weight_bit(verilog: str, bank: int, addr: int, bit: int, *, part: int | None = None) -> tuple[str, str]:
    """Flip ``bit`` of ``wmem<bank>[<addr>]`` (the packed word: target 0 in the low bits); with
    ``part``, of ``part<part>_wmem<bank>[<addr>]`` (an additive design's part)."""
    from pwas_hdl.fixedpoint.memory_layout import weight_memory_name

    mem = weight_memory_name(bank, part)
    pat = re.compile(rf"^(\s*{mem}\[{addr}\] = )(\d+)'h([0-9a-fA-F]+);$", re.M)
    mo = pat.search(verilog)
    if not mo:
        raise ValueError(f"no initialiser of {mem}[{addr}] in the Verilog (inline memory init expected)")
    width = int(mo.group(2))
    if not 0 <= bit < width:
        raise ValueError(f"bit {bit} outside the {width}-bit word of {mem}[{addr}]")
    old = int(mo.group(3), 16)
    new = old ^ (1 << bit)
    digits = (width + 3) // 4
    text = verilog[: mo.start()] + f"{mo.group(1)}{width}'h{new:0{digits}x};" + verilog[mo.end():]
    return text, f"{mem}[{addr}]: {width}'h{old:0{digits}x} -> {width}'h{new:0{digits}x} (bit {bit} flipped)"


def _const_edit(verilog: str, name: str, delta: int, what: str) -> tuple[str, str]:
    """Add ``delta`` to the value that ``assign <name> = <expr> +/- W'hK;`` adds to ``expr``."""
    pat = re.compile(rf"^(\s*assign {re.escape(name)} = )(.+?) ([+-]) (\d+)'h([0-9a-fA-F]+);$", re.M)
    mo = pat.search(verilog)
    if not mo:
        raise ValueError(f"no 'assign {name} = <expr> +/- <constant>;' in the Verilog ({what})")
    width = int(mo.group(4))
    k = int(mo.group(5), 16)
    mask = (1 << width) - 1
    new = (k + delta) & mask if mo.group(3) == "+" else (k - delta) & mask
    digits = (width + 3) // 4
    line = f"{mo.group(1)}{mo.group(2)} {mo.group(3)} {width}'h{new:0{digits}x};"
    return verilog[: mo.start()] + line + verilog[mo.end():], f"{name}: {mo.group(0).strip()} -> {line.strip()} ({what})"


def round_constant_plus_one_lsb(verilog: str, shift: int, target: int = 0) -> tuple[str, str]:
    """Make output ``target`` one LSB larger: add ``2**shift`` to its rounding constant (``rnd<z>``)."""
    if shift <= 0:
        raise ValueError("the design has no rounding constant (output shift <= 0)")
    return _const_edit(verilog, f"rnd{target}", 1 << shift, "every output + 1 LSB")


def offset_constant_off_by_one(verilog: str, dim: int | None = None, delta: int = -1) -> tuple[str, str]:
    """Shift the ``lo_code`` subtraction of dimension ``dim`` (``t<dim>``) by ``delta`` input codes.

    ``dim=None``: the first dimension that has one (a dimension whose domain starts at the lowest
    input code needs no subtraction).
    """
    if dim is None:
        mo = re.search(r"^\s*assign t(\d+) = .+? [+-] \d+'h[0-9a-fA-F]+;$", verilog, re.M)
        if not mo:
            raise ValueError("no dimension subtracts a lo_code constant in this design")
        dim = int(mo.group(1))
    return _const_edit(verilog, f"t{dim}", delta, f"lo_code of dimension {dim} off by {-delta}")
