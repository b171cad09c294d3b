"""Verilog export and port / resource description of the generated designs.

:func:`emit_verilog` converts a component as ``amaranth.back.verilog.convert(..., emit_src=False)``
does (Amaranth's builtin Yosys, run in-process by :mod:`pwas_hdl.hdl.yosys_convert`) and applies one textual, semantics-preserving normalisation:

* Amaranth attaches an ``init`` attribute to every flip-flop and Yosys' ``write_verilog`` prints it
  as a declaration initialiser (``reg [5:0] x = 6'h00;``) of a variable that an ``always`` block
  then assigns, which ``verilator -Wall`` reports as PROCASSINIT. The initialiser is moved into an
  ``initial`` statement right after the declaration (``reg [5:0] x;`` / ``initial x = 6'h00;``);
  IEEE 1364-2005 §6.2.1 defines the declaration form as exactly that. Variables that no
  ``always`` block assigns (Yosys' time-zero trigger register) are left untouched.

The weight memories are elaborated as black boxes and written back last, as Yosys writes
memories (:mod:`pwas_hdl.hdl.weight_rom`): the passes above run on text without the weights, and a
million-word ROM costs well under a second instead of about a minute.

The output is deterministic (no paths, no time stamps; the first line names the Yosys version).
"""

from __future__ import annotations

import re

from amaranth.lib import wiring

from pwas_hdl.errors import InputError, InternalError, choice_text, option_text
from pwas_hdl.hdl.names import check_module_name
from pwas_hdl.fixedpoint.memory_layout import hex_file_name, weight_memory_name
from pwas_hdl.hdl.weight_rom import RomEmission, splice_roms
from pwas_hdl.hdl.yosys_convert import component_verilog_roms

__all__ = ["MEM_DIR_PARAMETER", "MEM_DIR_DEFAULT", "PORT_NAMINGS", "emit_verilog", "port_list", "port_names", "normalise_verilog",
           "memory_hex_files", "hex_file_name"]

#: Parameter of a ``memory_init="readmemh"`` design: the folder of its ``.hex`` files (with the
#: trailing ``/``), prefixed to every ``$readmemh`` file name; the default is the working directory.
MEM_DIR_PARAMETER = "MEM_DIR"
MEM_DIR_DEFAULT = "./"

#: Port naming schemes of the generated Verilog: ``"axis"`` (default; AXI4-Stream style, ``aclk``,
#: active-low ``aresetn``, ``s_axis_t*`` in, ``m_axis_t*`` out) or ``"amaranth"`` (Amaranth's
#: flattened names: ``clk``, active-high ``rst``, ``in__*``, ``out__*``).
PORT_NAMINGS = ("axis", "amaranth")

# Amaranth name -> (role, AXI-Stream name), in the port order of the module: clock, reset, input
# stream, output stream; other signature members (``warm``) follow, keeping their names.
_PORTS = (
    ("clk", "clock", "aclk"),
    ("rst", "reset", "aresetn"),
    ("in__valid", "in.valid", "s_axis_tvalid"),
    ("in__ready", "in.ready", "s_axis_tready"),
    ("in__payload", "in.payload", "s_axis_tdata"),
    ("out__valid", "out.valid", "m_axis_tvalid"),
    ("out__ready", "out.ready", "m_axis_tready"),
    ("out__payload", "out.payload", "m_axis_tdata"),
)
_ROLE = {a: r for a, r, _ in _PORTS}
_AXIS = {a: x for a, _, x in _PORTS}
_ORDER = {a: i for i, (a, _, _) in enumerate(_PORTS)}


def _check_naming(ports: str) -> None:
    if ports not in PORT_NAMINGS:
        raise InputError(f"--ports must be one of {', '.join(PORT_NAMINGS)}, got {ports!r}")


def port_names(ports: str = "axis") -> dict[str, str]:
    """Role -> Verilog port name of the clock, reset and stream ports under a naming scheme
    (roles ``clock``, ``reset``, ``in.valid``, ``in.ready``, ``in.payload``, ``out.valid``, ...).

    Parameters
    ----------
    ports : {"axis", "amaranth"}
        Port naming scheme (:data:`PORT_NAMINGS`).

    Returns
    -------
    dict of str to str
        Role -> Verilog port name.

    Raises
    ------
    InputError
        An unknown naming.
    """
    _check_naming(ports)
    return {r: (x if ports == "axis" else a) for a, r, x in _PORTS}

_DECL = re.compile(
    r"^(?P<indent>[ \t]*)reg (?P<range>(?:signed )?(?:\[[0-9]+:[0-9]+\] )?)"
    r"(?P<name>\\\S+ |[A-Za-z_][A-Za-z0-9_$]*)(?P<sp> ?)= (?P<value>[^;]+);$",
    re.M,
)


def normalise_verilog(text: str) -> str:
    """Move the initialisers of procedurally assigned ``reg`` declarations to ``initial`` statements.

    Parameters
    ----------
    text : str
        Verilog text as Yosys' ``write_verilog`` prints it.

    Returns
    -------
    str
        The same text with ``reg x = v;`` of every variable assigned with ``<=`` split into
        ``reg x;`` and ``initial x = v;``; other declarations unchanged.
    """
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
    ports: str = "axis",
) -> str:
    """Verilog-2005 text of ``component`` as a single module called ``name``.

    The module has the ports listed by :func:`port_list`, in that order (clock, reset, input
    stream, output stream, then ``warm`` of the sensor top). ``ports="axis"`` (default) names them
    ``aclk``, ``aresetn`` (synchronous, **active low**: the design's reset is ``~aresetn``),
    ``s_axis_tvalid/tready/tdata``, ``m_axis_tvalid/tready/tdata``; ``ports="amaranth"`` keeps
    Amaranth's ``clk``, ``rst`` (synchronous, active high), ``in__valid`` ... ``out__payload``.
    Deterministic: equal inputs give byte-identical text.

    Parameters
    ----------
    component : amaranth.lib.wiring.Component
        A core or top built by :mod:`pwas_hdl.hdl`.
    name : str, optional
        Module name; default the component's ``module_name`` (as given to
        :func:`~pwas_hdl.hdl.build_core`), else ``"top"``.
    memory_init : {"inline", "readmemh"}
        ``"inline"``: the weight memories ``wmem0 .. wmem<n>`` are initialised by assignments in
        ``initial`` blocks. ``"readmemh"``: ``initial $readmemh({MEM_DIR,
        "<hex_prefix>_b<b>.hex"}, wmem<b>);`` -- the files of :func:`memory_hex_files`, equal to
        ``memory_layout.hex_files(..., packed=True, prefix=hex_prefix)``; the module parameter
        ``MEM_DIR`` (default ``"./"``: the simulator's / synthesiser's working directory) is the
        folder that holds them, with its trailing ``/``.
    hex_prefix : str
        File-name prefix of the ``.hex`` files (``memory_init="readmemh"`` only).
    ports : {"axis", "amaranth"}
        Port naming.

    Returns
    -------
    str
        The Verilog text (first line: the Yosys version).

    Raises
    ------
    InputError
        ``name`` is not a plain Verilog identifier, an unknown ``memory_init`` or ``ports`` naming,
        or a ``hex_prefix`` that is not a plain file-name prefix.
    InternalError
        The Yosys output does not have the expected shape (ports, memory initialisers).
    """
    if name is None:
        name = getattr(component, "module_name", None) or "top"
    check_module_name(name, "module name")
    _check_memory_init(memory_init, hex_prefix)
    _check_naming(ports)
    text, roms = component_verilog_roms(component, name)  # the ROMs' words are written last
    text = _name_ports(normalise_verilog(text), name, component, ports)
    return _splice_weights(text, roms, component, memory_init, hex_prefix)


def _check_memory_init(memory_init: str, hex_prefix: str) -> None:
    """``memory_init`` is ``"inline"`` or ``"readmemh"``; for ``"readmemh"``, ``hex_prefix`` is a plain
    file-name prefix (it goes into a Verilog string literal)."""
    if memory_init not in ("inline", "readmemh"):
        raise InputError(choice_text(option_text("memory_init"), ("inline", "readmemh"), memory_init))
    if memory_init == "readmemh" and not re.fullmatch(r"[A-Za-z0-9_.-]+", hex_prefix):
        raise InputError(f"hex_prefix {hex_prefix!r} must be a plain file-name prefix")


def _splice_weights(text: str, roms: RomEmission, component, memory_init: str, hex_prefix: str) -> str:
    """The weight memories into ``text`` (:func:`~pwas_hdl.hdl.weight_rom.splice_roms`): inline, or
    ``$readmemh`` of the :func:`hex_file_name` files under the ``MEM_DIR`` parameter."""
    if memory_init == "readmemh":
        return _with_mem_dir(splice_roms(text, roms, _readmemh_files(component, roms, hex_prefix)))
    return splice_roms(text, roms)


def _token(name: str) -> re.Pattern:
    return re.compile(r"(?<![A-Za-z0-9_$\\])" + re.escape(name) + r"(?![A-Za-z0-9_$])")


def _name_ports(text: str, module: str, component, ports: str) -> str:
    """Put the module's port list in :func:`port_list` order and, for ``ports="axis"``, rename the
    ports (whole identifiers; Yosys writes them as plain names) and derive ``rst = ~aresetn``."""
    head = re.compile(r"^module " + re.escape(module) + r"\(([^)]*)\);$", re.M)
    mo = head.search(text)
    if mo is None:
        raise InternalError(f"no port list of module {module} in the Yosys output")
    amaranth = [p["name"] for p in port_list(component, "amaranth")]
    if sorted(n.strip() for n in mo.group(1).split(",")) != sorted(amaranth):
        raise InternalError(f"the ports of {module} in the Yosys output are not {amaranth}")
    if ports == "amaranth":
        return text[: mo.start(1)] + ", ".join(amaranth) + text[mo.end(1):]
    new = {a: _AXIS.get(a, a) for a in amaranth}
    for a, x in new.items():
        if a != x and _token(x).search(text):
            raise InternalError(f"cannot name port {a} {x}: the design already has a signal {x}")
    body = text[mo.end():]
    decl = re.compile(r"^(?P<ind>[ \t]*)input rst;\n", re.M)
    if len(decl.findall(body)) != 1:
        raise InternalError("expected one `input rst;` declaration in the Yosys output")
    body = decl.sub(lambda m: f"{m.group('ind')}input aresetn;\n{m.group('ind')}wire aresetn;\n", body, count=1)
    for a, x in new.items():
        if a not in ("rst",) and a != x:
            body = _token(a).sub(x, body)
    end = body.rindex("endmodule")
    body = body[:end] + "  assign rst = ~aresetn;\n" + body[end:]
    header = f"module {module}(" + ", ".join(new[a] for a in amaranth) + ");"
    return text[: mo.start()] + header + body


def _plans(component) -> dict:
    """The memory plans of a design's weight memories: ``{None: plan}`` (memories ``wmem<b>``), or for
    an additive design (:mod:`pwas_hdl.hdl.additive_top`, a core with ``parts``) ``{i: plan of part i}``
    (memories ``part<i>_wmem<b>`` once the parts are flattened)."""
    core = getattr(component, "core", component)
    parts = getattr(core, "parts", None)
    if parts is not None:
        return {i: c.memory_plan for i, c in enumerate(parts)}
    return {None: core.memory_plan}


def memory_hex_files(component: wiring.Component, prefix: str = "w") -> dict[str, str]:
    """``$readmemh`` files of the weight memories (:func:`hex_file_name`): ``<prefix>_b<bank>.hex``,
    or ``<prefix>_p<i>_b<bank>.hex`` per part of an additive design; one packed word per line (all
    targets, target 0 in the LSBs), ``ceil(word_bits/4)`` hex digits. The files
    ``memory_init="readmemh"`` makes the Verilog read.

    Parameters
    ----------
    component : amaranth.lib.wiring.Component
        A core, or a top with a ``core``; its ``memory_plan`` (an additive design: its parts') is read.
    prefix : str
        File-name prefix.

    Returns
    -------
    dict of str to str
        File name -> file text, one entry per memory bank (parts in order, then banks).
    """
    from pwas_hdl.fixedpoint.memory_layout import readmemh_text

    return {hex_file_name(prefix, b, part): readmemh_text(plan.contents[b], plan.word_bits)
            for part, plan in _plans(component).items() for b in range(plan.n_banks)}


def _readmemh_files(component, roms: RomEmission, prefix: str):
    """``(name, k) -> {MEM_DIR, "<file>"}`` (:func:`hex_file_name`) for the ROMs ``wmem<bank>`` of the
    component's memory plan, or ``part<i>_wmem<bank>`` of the plan of part ``i`` of an additive design
    (checked: the ROMs met in elaboration are the plans' memories and hold their words)."""
    plans = _plans(component)
    n_banks = sum(p.n_banks for p in plans.values())
    if len(roms.roms) != n_banks:
        raise InternalError(f"{len(roms.roms)} weight memories in the design, {n_banks} in its memory plan")
    names = {weight_memory_name(b, part): (part, b) for part, plan in plans.items() for b in range(plan.n_banks)}

    def file_of(name: str, k: int) -> str:
        if name not in names:
            raise InternalError(f"unexpected weight memory {name} in the design")
        part, bank = names[name]
        plan = plans[part]
        if roms.roms[k].contents != tuple(int(w) for w in plan.contents[bank]):
            raise InternalError(f"memory {name}: its contents differ from the memory plan")
        return f'{{{MEM_DIR_PARAMETER}, "{hex_file_name(prefix, bank, part)}"}}'

    return file_of


def _with_mem_dir(text: str) -> str:
    """Declare the ``MEM_DIR`` parameter right after the module header."""
    head = re.search(r"^module [A-Za-z_][A-Za-z0-9_]*\([^)]*\);\n", text, re.M)
    if head is None:
        raise InternalError("no module header in the Yosys output")
    decl = (f"  // Folder of the $readmemh files, with its trailing '/': set it where the module is instantiated\n"
            f"  // (#(.{MEM_DIR_PARAMETER}(\"path/to/hex/\"))) to run from any working directory.\n"
            f"  parameter {MEM_DIR_PARAMETER} = \"{MEM_DIR_DEFAULT}\";\n")
    return text[: head.end()] + decl + text[head.end():]


def port_list(component: wiring.Component, ports: str = "axis") -> list[dict]:
    """Verilog ports of a component, in module order: ``[{name, role, direction, width, signed}]``.

    Order: clock (rising edge), reset (synchronous), input stream (valid, ready, payload), output
    stream (valid, ready, payload), then the other signature members (``warm``) in signature
    order. Roles: ``clock``, ``reset``, ``in.valid``, ``in.ready``, ``in.payload``, ``out.valid``,
    ``out.ready``, ``out.payload``, else the member's name. Names: see :func:`emit_verilog`
    (``ports="axis"``: ``aclk``, ``aresetn`` active low, ``s_axis_t*``, ``m_axis_t*``;
    ``"amaranth"``: ``clk``, ``rst`` active high, the signature path joined with ``__``).

    Parameters
    ----------
    component : amaranth.lib.wiring.Component
        A core or top built by :mod:`pwas_hdl.hdl`; its ``signature`` gives the ports.
    ports : {"axis", "amaranth"}
        Port naming.

    Returns
    -------
    list of dict
        One per port: ``name``, ``role``, ``direction`` (``"input"`` / ``"output"``), ``width``
        (bits), ``signed``.

    Raises
    ------
    InputError
        An unknown ``ports`` naming.
    """
    _check_naming(ports)
    found = [
        {"name": "clk", "direction": "input", "width": 1, "signed": False},
        {"name": "rst", "direction": "input", "width": 1, "signed": False},
    ]
    for path, member, value in component.signature.flatten(component):
        shape = value.shape() if hasattr(value, "shape") else None
        found.append(
            {
                "name": "__".join(map(str, path)),
                "direction": "input" if member.flow == wiring.In else "output",
                "width": len(value.as_value()) if hasattr(value, "as_value") else len(value),
                "signed": bool(getattr(shape, "signed", False)),
            }
        )
    found.sort(key=lambda p: _ORDER.get(p["name"], len(_ORDER)))  # stable: extras keep signature order
    out = []
    for p in found:
        a = p["name"]
        out.append({"name": _AXIS.get(a, a) if ports == "axis" else a, "role": _ROLE.get(a, a.replace("__", ".")),
                    **{k: v for k, v in p.items() if k != "name"}})
    return out
