"""Verilog export and port / resource description of the generated designs.

:func:`emit_verilog` converts a component with ``amaranth.back.verilog.convert(..., emit_src=False)``
(Amaranth's builtin Yosys) and applies one textual, semantics-preserving normalisation:

* Amaranth attaches an ``init`` attribute to every flip-flop and Yosys' ``write_verilog`` prints it
  as a declaration initialiser (``reg [5:0] x = 6'h00;``) of a variable that an ``always`` block
  then assigns, which ``verilator -Wall`` reports as PROCASSINIT. The initialiser is moved into an
  ``initial`` statement right after the declaration (``reg [5:0] x;`` / ``initial x = 6'h00;``);
  IEEE 1364-2005 §6.2.1 defines the declaration form as exactly that. Variables that no
  ``always`` block assigns (Yosys' time-zero trigger register) are left untouched.

The output is deterministic (no paths, no time stamps; the first line names the Yosys version).
"""

from __future__ import annotations

import re

from amaranth.back import verilog
from amaranth.lib import wiring

__all__ = ["emit_verilog", "port_list", "normalise_verilog", "memory_hex_files"]

_DECL = re.compile(
    r"^(?P<indent>[ \t]*)reg (?P<range>(?:signed )?(?:\[[0-9]+:[0-9]+\] )?)"
    r"(?P<name>\\\S+ |[A-Za-z_][A-Za-z0-9_$]*)(?P<sp> ?)= (?P<value>[^;]+);$",
    re.M,
)


def normalise_verilog(text: str) -> str:
    """Move the initialisers of procedurally assigned ``reg`` declarations to ``initial`` statements."""
    assigned = set()
    for mo in re.finditer(r"(?<![A-Za-z0-9_$\\])(\\\S+ |[A-Za-z_][A-Za-z0-9_$]*)\s*(?:\[[^\]]*\]\s*)?<=", text):
        assigned.add(mo.group(1).rstrip())

    def repl(mo: re.Match) -> str:
        name = mo.group("name")
        if name.rstrip() not in assigned:
            return mo.group(0)
        ind = mo.group("indent")
        return f"{ind}reg {mo.group('range')}{name.rstrip()}{' ' if name.startswith(chr(92)) else ''};\n" \
               f"{ind}initial {name}{mo.group('sp')}= {mo.group('value')};"

    return _DECL.sub(repl, text)


def emit_verilog(
    component: wiring.Component,
    name: str | None = None,
    *,
    memory_init: str = "inline",
    hex_prefix: str = "w",
) -> str:
    """Verilog-2005 text of ``component`` as a single module called ``name`` (default: the
    ``module_name`` given to :func:`~pwas_hdl.hdl.build_core`).

    The module has the ports listed by :func:`port_list` (``clk`` and ``rst`` for the ``sync``
    domain, then the flattened signature members). Deterministic: equal inputs give byte-identical
    text.

    ``memory_init``: ``"inline"`` (default; the weight memories ``wmem0 .. wmem<n>`` are initialised
    by assignments in ``initial`` blocks) or ``"readmemh"`` (``initial $readmemh("<hex_prefix>_b<b>.hex",
    wmem<b>);`` -- the files of :func:`memory_hex_files`, equal to
    ``memory_layout.hex_files(..., packed=True, prefix=hex_prefix)``, looked up relative to the
    simulator's / synthesiser's working directory).
    """
    if name is None:
        name = getattr(component, "module_name", None) or "top"
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
        raise ValueError(f"module name {name!r} is not a plain Verilog identifier")
    if memory_init not in ("inline", "readmemh"):
        raise ValueError(f"memory_init must be 'inline' or 'readmemh', got {memory_init!r}")
    text = normalise_verilog(verilog.convert(component, name=name, emit_src=False))
    if memory_init == "readmemh":
        text = _use_readmemh(text, component, hex_prefix)
    return text


def _plan(component):
    core = getattr(component, "core", component)
    return core.memory_plan


def memory_hex_files(component, prefix: str = "w") -> dict[str, str]:
    """``$readmemh`` files of the weight memories: ``<prefix>_b<bank>.hex``, one packed word per
    line (all targets, target 0 in the LSBs), ``ceil(word_bits/4)`` hex digits."""
    from pwas_hdl.fixedpoint.memory_layout import readmemh_text

    plan = _plan(component)
    return {f"{prefix}_b{b}.hex": readmemh_text(plan.contents[b], plan.word_bits) for b in range(plan.n_banks)}


_MEMINIT = re.compile(r"^(?P<ind>[ \t]*)initial begin\n(?P<body>(?:[ \t]*wmem(?P<bank>[0-9]+)\[[0-9]+\] = [^;\n]+;\n)+)[ \t]*end\n", re.M)
_MEMLINE = re.compile(r"wmem([0-9]+)\[([0-9]+)\] = (?:[0-9]+'([hdb])([0-9a-fA-F_]+)|([0-9]+));")


def _const_value(lm: re.Match) -> int:
    if lm.group(5) is not None:
        return int(lm.group(5))
    return int(lm.group(4).replace("_", ""), {"h": 16, "d": 10, "b": 2}[lm.group(3)])


def _use_readmemh(text: str, component, prefix: str) -> str:
    plan = _plan(component)
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", prefix):
        raise ValueError(f"hex_prefix {prefix!r} must be a plain file-name prefix")
    done = set()

    def repl(mo: re.Match) -> str:
        bank = int(mo.group("bank"))
        got = {}
        for lm in _MEMLINE.finditer(mo.group("body")):
            if int(lm.group(1)) != bank:
                raise RuntimeError("unexpected memory initialiser layout in the Yosys output")
            got[int(lm.group(2))] = _const_value(lm)
        want = {a: w for a, w in enumerate(plan.contents[bank])}
        if {a: w for a, w in got.items() if w} != {a: w for a, w in want.items() if w}:
            raise RuntimeError(f"memory wmem{bank}: the emitted contents differ from the memory plan")
        done.add(bank)
        return f'{mo.group("ind")}initial $readmemh("{prefix}_b{bank}.hex", wmem{bank});\n'

    out = _MEMINIT.sub(repl, text)
    if done != set(range(plan.n_banks)):
        raise RuntimeError(f"found initialisers of memories {sorted(done)}, expected 0..{plan.n_banks - 1}")
    return out


def port_list(component: wiring.Component) -> list[dict]:
    """Flattened Verilog ports of a component: ``[{name, direction, width, signed}]``.

    ``clk`` (rising edge) and ``rst`` (synchronous, active high) come first; then every signature
    member, named by joining its path with ``__`` (``in__valid``, ``in__ready``, ``in__payload``,
    ``out__valid``, ``out__ready``, ``out__payload``, ...), in signature order.
    """
    ports = [
        {"name": "clk", "direction": "input", "width": 1, "signed": False},
        {"name": "rst", "direction": "input", "width": 1, "signed": False},
    ]
    for path, member, value in component.signature.flatten(component):
        shape = value.shape() if hasattr(value, "shape") else None
        ports.append(
            {
                "name": "__".join(map(str, path)),
                "direction": "input" if member.flow == wiring.In else "output",
                "width": len(value.as_value()) if hasattr(value, "as_value") else len(value),
                "signed": bool(getattr(shape, "signed", False)),
            }
        )
    return ports
