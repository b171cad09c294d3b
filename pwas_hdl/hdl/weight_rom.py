"""The weight memories (ROMs) of the generated designs: one builder, two forms.

Every core reads its weights through :func:`weight_rom`: a read-only memory of ``depth`` words of
``width`` bits with one synchronous read port (``data <= mem[addr]`` on the rising clock edge
while ``en`` is high; the read register is not reset).

* Elaborated as usual (Amaranth's simulator, or any converter), it is an
  :class:`amaranth.lib.memory.Memory` with its contents as ``init``.
* While Verilog is being emitted (:func:`rom_emission`, entered by
  :func:`pwas_hdl.hdl.yosys_convert.component_verilog_roms`), it is a black-box instance, and
  :func:`splice_roms` -- after the text passes of :mod:`pwas_hdl.hdl.emit`, which so never see the
  weights -- replaces each instance in the Yosys output with the text Yosys itself
  writes for that memory: the array declaration, an ``initial`` block with one assignment a word,
  and the registered read. Amaranth's RTLIL back end spells a memory's initial contents bit by bit
  (``depth x width`` objects): for a million-word ROM that took ~60 s of the ~70 s ``generate``
  spent, and Yosys another ~15 s to print them. The spliced text is written from the contents
  directly, in well under a second, and has the same shape (``wmem<b>`` arrays, the same
  initialiser lines), so the ``$readmemh`` form, the simulators' memory checks and synthesis read
  it as before.
"""

from __future__ import annotations

import contextlib
import contextvars
import re
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

from amaranth.hdl import ClockSignal, Instance, Module, Signal, Value, unsigned
from amaranth.lib.memory import Memory

from pwas_hdl.errors import InternalError

__all__ = ["weight_rom", "rom_emission", "splice_roms", "inline_to_readmemh", "RomEmission", "BLACKBOX_PREFIX"]

#: Name prefix of the black-box modules that stand for the ROMs while Verilog is emitted; the
#: emitted text never contains it (:func:`splice_roms` refuses text that still does).
BLACKBOX_PREFIX = "pwas_hdl_weight_rom_"


@dataclass(frozen=True)
class _Rom:
    width: int
    depth: int
    contents: tuple[int, ...]  # depth words: the given ones, then zeros


class RomEmission:
    """The ROMs met while one design is elaborated for Verilog emission, in elaboration order."""

    def __init__(self) -> None:
        self.roms: list[_Rom] = []

    def add(self, width: int, depth: int, contents: Sequence[int]) -> str:
        """Register a ROM.

        Parameters
        ----------
        width : int
            Word width, bits.
        depth : int
            Number of words.
        contents : sequence of int
            The words, unsigned, address 0 first; at most ``depth`` (padded with zeros).

        Returns
        -------
        str
            The name of the black-box module that stands for it: ``BLACKBOX_PREFIX`` + its index.
        """
        words = tuple(int(w) for w in contents)
        self.roms.append(_Rom(int(width), int(depth), words + (0,) * (int(depth) - len(words))))
        return f"{BLACKBOX_PREFIX}{len(self.roms) - 1}"


_EMISSION: contextvars.ContextVar[RomEmission | None] = contextvars.ContextVar("pwas_hdl_rom_emission", default=None)


@contextlib.contextmanager
def rom_emission() -> Iterator[RomEmission]:
    """Elaborate the ROMs inside this block as black boxes, recorded in the yielded registry.

    Yields
    ------
    RomEmission
        The registry that :func:`splice_roms` needs to put the memories back into the text.
    """
    reg = RomEmission()
    token = _EMISSION.set(reg)
    try:
        yield reg
    finally:
        _EMISSION.reset(token)


def weight_rom(m: Module, name: str, width: int, depth: int, contents: Sequence[int],
               addr: Value | None, en: Value, domain: str = "sync") -> Value:
    """Add a ROM with one synchronous read port to ``m`` and return its read data.

    Parameters
    ----------
    m : Module
        Module the memory is added to, as the submodule ``name``.
    name : str
        Submodule name (``wmem<b>``): the memory array's name in the Verilog.
    width : int
        Word width, bits.
    depth : int
        Number of words (``len(contents)``).
    contents : sequence of int
        The words, unsigned, address 0 first; at most ``depth`` of them, the rest are 0 (as
        ``Memory(init=...)``).
    addr : Value or None
        Read address (``ceil(log2(depth))`` bits); ``None`` for a one-word memory.
    en : Value
        1-bit read enable: the read register loads ``mem[addr]`` at the clock edge while it is high.
    domain : str
        Clock domain of the read port.

    Returns
    -------
    Value
        The registered read data, ``width`` bits (not reset).

    Raises
    ------
    InternalError
        More than ``depth`` words in ``contents``.
    """
    if len(contents) > depth:
        raise InternalError(f"ROM {name}: {len(contents)} words for depth {depth}")
    reg = _EMISSION.get()
    if reg is None:
        mem = Memory(shape=unsigned(width), depth=depth, init=contents)
        m.submodules[name] = mem
        rp = mem.read_port(domain=domain)
        # Drive the port with our own nets instead of assigning to its addr/en signals (which
        # would leave those as unused alias wires); ReadPort does the same for its comb `en`.
        if addr is not None:
            rp.addr = addr
        rp.en = en
        return rp.data
    data = Signal(unsigned(width), name=f"{name}_data")
    # upper-case port names: never a token of the design's own names (the port renaming of
    # pwas_hdl.hdl.emit runs on the text before the splice and renames whole identifiers)
    ports = {"i_CLK": ClockSignal(domain), "i_EN": en, "o_DATA": data}
    if addr is not None:
        ports["i_ADDR"] = addr
    m.submodules[name] = Instance(reg.add(width, depth, contents), **ports)
    return data


# One instance as `write_verilog` prints it: `<module> <name> (` then `.port(expr),` lines, `);`.
_INSTANCE = re.compile(
    r"^(?P<ind>[ \t]*)" + re.escape(BLACKBOX_PREFIX) + r"(?P<k>[0-9]+) (?P<name>\\\S+ |[A-Za-z_][A-Za-z0-9_$]*) \(\n"
    r"(?P<conns>(?:[ \t]*\.[A-Z]+\(.*\),?\n)+)[ \t]*\);\n",
    re.M,
)
_CONN = re.compile(r"^[ \t]*\.(?P<port>[A-Z]+)\((?P<expr>.*)\),?$", re.M)


def splice_roms(text: str, reg: RomEmission, readmemh: Callable[[str, int], str] | None = None) -> str:
    """Replace each black-box ROM instance in Yosys' ``write_verilog`` text with the memory.

    Parameters
    ----------
    text : str
        The Verilog written for a design elaborated inside :func:`rom_emission` (possibly renamed
        since: the instance's name and its connections are read as they stand).
    reg : RomEmission
        The registry of that elaboration.
    readmemh : callable, optional
        ``readmemh(name, k) -> str``: the file-name expression of ROM ``k`` (instance ``name``) for
        ``$readmemh``. Default: the words are assigned inline.

    Returns
    -------
    str
        The text with, in place of each instance ``<name>``: ``reg [W-1:0] <name> [D-1:0];``, an
        ``initial`` block assigning every word (``<name>[a] = W'h..;``, as Yosys writes memory
        initialisers) or ``initial $readmemh(<file>, <name>, 0, D-1);``, a read register
        ``<name>_q`` loaded with ``<name>[addr]`` at the rising clock edge while ``en`` is high,
        and the instance's data net assigned from it.

    Raises
    ------
    InternalError
        An instance of an unknown ROM, a ROM without its instance, a port missing, or a read
        register name that is taken.
    """
    done: set[int] = set()

    def repl(mo: re.Match) -> str:
        k = int(mo.group("k"))
        if k >= len(reg.roms) or k in done:
            raise InternalError(f"unexpected ROM instance {BLACKBOX_PREFIX}{k} in the Yosys output")
        done.add(k)
        rom = reg.roms[k]
        conns = {c.group("port"): c.group("expr") for c in _CONN.finditer(mo.group("conns"))}
        if (not {"CLK", "EN", "DATA"} <= set(conns) or ("ADDR" in conns) != (rom.depth > 1)
                or not all(v.strip() for v in conns.values())):
            raise InternalError(f"ROM instance {mo.group('name').strip()}: ports {sorted(conns)}")
        ind, name = mo.group("ind"), mo.group("name").rstrip()
        esc = " " if name.startswith("\\") else ""  # an escaped identifier ends at white space
        q = f"{name}_q{esc}"
        if re.search(r"(?<![A-Za-z0-9_$\\])" + re.escape(q.rstrip()) + r"(?![A-Za-z0-9_$])", text):
            raise InternalError(f"cannot name the read register of ROM {name}: {q.strip()} is taken")
        w, depth = rom.width, rom.depth
        lines = [f"{ind}reg [{w - 1}:0] {name}{esc} [{depth - 1}:0];"]
        if readmemh is None:
            digits = (w + 3) // 4
            lines.append(f"{ind}initial begin")
            lines += [f"{ind}  {name}{esc}[{a}] = {w}'h{v:0{digits}x};" for a, v in enumerate(rom.contents)]
            lines.append(f"{ind}end")
        else:
            # explicit first and last address: with the descending range Yosys declares, IEEE
            # 1364-1995 loads a file without addresses from the left (highest) address and 1364-2005
            # from the lowest; with both given, every tool loads word a of the file into mem[a]
            lines.append(f"{ind}initial $readmemh({readmemh(name, k)}, {name}{esc}, 0, {depth - 1});")
        lines += [f"{ind}reg [{w - 1}:0] {q};", f"{ind}always @(posedge {conns['CLK']}) begin"]
        read = f"{q} <= {name}{esc}[{conns.get('ADDR', '0')}];"
        if conns["EN"] == "1'h1":
            lines.append(f"{ind}  {read}")
        else:
            lines += [f"{ind}  if ({conns['EN']}) begin", f"{ind}    {read}", f"{ind}  end"]
        lines += [f"{ind}end", f"{ind}assign {conns['DATA']} = {q};"]
        return "\n".join(lines) + "\n"

    out = _INSTANCE.sub(repl, text)
    if done != set(range(len(reg.roms))) or BLACKBOX_PREFIX in out:
        raise InternalError(f"found instances of ROMs {sorted(done)} in the Yosys output, expected 0..{len(reg.roms) - 1}")
    return out


# An inline initialiser block as splice_roms (and Yosys) write it: `initial begin`, one
# `<name>[a] = W'h..;` line a word, `end`.
_INIT_BLOCK = re.compile(
    r"^(?P<ind>[ \t]*)initial begin\n(?P<body>(?:[ \t]*(?P<name>[A-Za-z_][A-Za-z0-9_$]*)\[[0-9]+\] = [0-9]+'h[0-9a-fA-F]+;\n)+)"
    r"[ \t]*end\n",
    re.M,
)
_INIT_LINE = re.compile(r"^[ \t]*([A-Za-z_][A-Za-z0-9_$]*)\[([0-9]+)\] = [0-9]+'h([0-9a-fA-F]+);$", re.M)


def inline_to_readmemh(text: str, files: dict[str, tuple[str, Sequence[int]]]) -> str | None:
    """The Verilog ``text`` with each memory's inline initialiser replaced by ``$readmemh`` of a file
    that holds the same words, or None when that cannot be done exactly.

    Yosys reads a ``$readmemh`` memory in a fraction of the time it takes for one assignment a word
    (``synth`` at N = 65 536: 13 s against 328 s); the hardware is the same.

    Parameters
    ----------
    text : str
        Verilog with inline initialisers (the ``memory_init="inline"`` form of
        :func:`pwas_hdl.hdl.emit.emit_verilog`).
    files : dict of str to (str, sequence of int)
        Memory name (``wmem<b>``, ``part<i>_wmem<b>``) -> (the file name as ``$readmemh`` is to get
        it, a Verilog string literal's contents; the file's words, address 0 first).

    Returns
    -------
    str or None
        None when a memory of ``files`` has no inline initialiser or more than one, or its inline
        words differ from its file's (e.g. a hand-edited Verilog): then only the inline text is
        right.
    """
    blocks = [mo for mo in _INIT_BLOCK.finditer(text) if mo.group("name") in files]  # other arrays stay as they are
    if sorted(mo.group("name") for mo in blocks) != sorted(files):
        return None
    out, pos = [], 0
    for mo in blocks:
        name = mo.group("name")
        path, words = files[name]
        got = [(ln.group(1), int(ln.group(2)), int(ln.group(3), 16)) for ln in _INIT_LINE.finditer(mo.group("body"))]
        if [(n, a) for n, a, _ in got] != [(name, a) for a in range(len(words))] or any(
                v != int(w) for (_, _, v), w in zip(got, words)):
            return None
        out += [text[pos:mo.start()], f'{mo.group("ind")}initial $readmemh("{path}", {name}, 0, {len(words) - 1});\n']
        pos = mo.end()
    return "".join(out) + text[pos:]
