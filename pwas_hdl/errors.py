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
:class:`CheckFailed`   a verification found a difference (RTL vs    ``error:`` line, exit 1
                       bit-true model, a failing testbench)
:class:`InternalError` a check inside pwas-hdl failed: a bug         traceback + "this is a
                                                                    bug", exit 3
anything else          a bug                                        traceback + "this is a
                                                                    bug", exit 3
=====================  ===========================================  ===========================
"""

from __future__ import annotations

__all__ = ["PwasError", "InputError", "ToolMissing", "CheckFailed", "InternalError", "ResourceLimit"]


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


class CheckFailed(PwasError):
    """A verification ran and found a difference (the result is written; the exit status is 1)."""


class InternalError(PwasError, RuntimeError):
    """A consistency check inside pwas-hdl failed: a bug, not bad input."""
