"""The error classes of pwas-hdl, and what the command line does with each.

=====================  ===========================================  ===========================
class                  meaning                                      CLI
=====================  ===========================================  ===========================
:class:`InputError`    bad input: a file, a value, an option, a     one ``error:`` line, exit 2
                       size that would exhaust memory (a
                       ``ValueError``, so ``except ValueError``
                       catches it)
``OSError``            a path that cannot be read or written        one ``error:`` line, exit 2
:class:`ToolMissing`   an external tool is not installed            ``error:`` line with the
                                                                    install step, exit 2
:class:`ToolFailed`    an external tool ran and failed (simulator   ``error:`` line naming the
                       build, Yosys, nextpnr); its log is kept      log, exit 2 (``-v``: the
                                                                    log's last lines too)
:class:`CheckFailed`   a verification found a difference (RTL vs    ``error:`` line, exit 1
                       bit-true model, a failing testbench)
:class:`InternalError` a check inside pwas-hdl failed: a bug         traceback + "this is a
                                                                    bug", exit 3
anything else          a bug                                        traceback + "this is a
                                                                    bug", exit 3
=====================  ===========================================  ===========================
"""

from __future__ import annotations

import os
from collections.abc import Iterable

__all__ = ["PwasError", "InputError", "ToolMissing", "ToolFailed", "CheckFailed", "InternalError", "ResourceLimit"]


class PwasError(Exception):
    """Base class of the errors raised on purpose by pwas-hdl."""


class InputError(PwasError, ValueError):
    """What the user gave is wrong (file contents, option values, sizes); the message says how to fix it."""


class ResourceLimit(InputError):
    """A request that would exceed a stated limit (memory, samples, weights); refused before allocating.

    The message names the requested size and the limit.
    """


class ToolMissing(PwasError, RuntimeError):
    """An external program (simulator, synthesis tool) is not installed.

    Parameters
    ----------
    tool : str
        The program's name.
    hint : str
        How to install it (one sentence).
    """

    def __init__(self, tool: str, hint: str) -> None:
        self.tool = tool
        self.hint = hint
        super().__init__(f"{tool} not found; {hint}")


class ToolFailed(PwasError, RuntimeError):
    """An external program ran and failed for a reason pwas-hdl could not check up front.

    Parameters
    ----------
    message : str
        What failed, in one line (the tool, its exit status, the design).
    log : str or os.PathLike, optional
        The tool's log file (kept for the user to read).
    tail : str, optional
        The last lines of that log (shown by ``pwas-hdl -v``).
    """

    def __init__(self, message: str, log: "str | os.PathLike[str] | None" = None, tail: str = "") -> None:
        self.message = message
        self.log = None if log is None else str(log)
        self.tail = tail
        super().__init__(message + (f"; log: {self.log}" if self.log else ""))


class CheckFailed(PwasError):
    """A verification ran and found a difference (the result is written; the exit status is 1)."""


class InternalError(PwasError, RuntimeError):
    """A consistency check inside pwas-hdl failed: a bug, not bad input."""


def option_text(param: str) -> str:
    """How an error names an API parameter that is also a command-line option.

    ``"weight_frac"`` -> ``"--weight-frac (weight_frac)"``: the option first, for the CLI user, the
    parameter in brackets for the API caller (who gets the same text).
    """
    return f"--{param.replace('_', '-')} ({param})"


def choice_text(option: str, choices: Iterable[object], value: object) -> str:
    """The message for a value that is not one of the allowed ``choices`` of ``option``.

    ``choice_text(option_text("memory"), ("banked", "replicated"), "dual")`` ->
    ``"--memory (memory) must be one of banked, replicated, got 'dual'"``.
    """
    return f"{option} must be one of {', '.join(map(str, choices))}, got {value!r}"


def fault_text(exc: BaseException) -> str:
    """What a ``KeyError`` / ``IndexError`` / ``TypeError`` met while reading a file says, in the file's terms.

    For messages about a corrupt or hand-edited file: the user needs the key that is missing, not the
    name of a Python exception class.
    """
    if isinstance(exc, KeyError):
        return f"the key {exc.args[0]!r} is missing" if exc.args else "a key is missing"
    if isinstance(exc, IndexError):
        return "a list has too few entries"
    return f"a value has the wrong type ({exc})"
