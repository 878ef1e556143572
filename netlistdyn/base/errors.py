"""Error types and source coordinates shared by every pipeline stage.

Every error a user can provoke with a bad netlist is a :class:`NetlistError`
carrying the :class:`SourceLocation` of the offending line, so the command
line can print one ``file:line: message`` and exit non-zero.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class SourceLocation:
    """Where a netlist element or directive came from.

    Attributes
    ----------
    path : str
        File name as given by the user (or ``"<string>"``).
    line : int
        1-based physical line number of the start of the logical line; 0 for the
        file as a whole (printed as ``path`` alone, not ``path:0``).
    """

    path: str
    line: int

    def __str__(self) -> str:
        return f"{self.path}:{self.line}" if self.line > 0 else self.path


UNKNOWN_LOCATION = SourceLocation("<netlist>", 0)


class NetlistError(ValueError):
    """A netlist that cannot be compiled, with the location that caused it.

    Parameters
    ----------
    message : str
        One-line description naming the offending element.
    loc : SourceLocation, optional
        Where the problem is; defaults to the whole netlist.
    """

    def __init__(self, message: str, loc: SourceLocation | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.loc = loc if loc is not None else UNKNOWN_LOCATION

    def __str__(self) -> str:
        return f"{self.loc}: {self.message}"


class TopologyError(NetlistError):
    """The circuit graph is inconsistent (source loops/cutsets, floating nodes...)."""


class SingularCircuitError(NetlistError):
    """The circuit equations have no unique solution for the given values."""


class ControlDimension(ValueError):
    """Matrix dimensions that do not agree, as in python-control.

    The message states what was expected and what was found.
    """


class UsageError(ValueError):
    """A bad command-line request (unknown output, unknown parameter...)."""
