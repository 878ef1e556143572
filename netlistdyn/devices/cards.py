"""What a device's card builder gets from the parser, and the small syntax helpers builders share.

The parser (:mod:`netlistdyn.frontend.parser`) reads logical lines, parameters, subcircuits
and models; an element line it hands to the builder its device family registered for the
line's first letter (:attr:`~netlistdyn.devices.traits.Family.cards`), with a
:class:`CardContext` that evaluates values and splits fields as ngspice does. The builder
returns the line's elements (one, or several for LTspice's parasitics, a K of three inductors,
a linear behavioural source as a sum of controlled sources).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from typing import Protocol

from netlistdyn.base.errors import NetlistError, SourceLocation
from netlistdyn.base.values import read_number
from netlistdyn.circuit.expressions import Expression
from netlistdyn.circuit.netlist import GROUND, Diagnostic, Element, TranSpec
from netlistdyn.circuit.waveforms import Waveform


class CardLine(Protocol):
    """One logical netlist line: its text (continuations joined) and where it starts."""

    @property
    def text(self) -> str: ...

    @property
    def loc(self) -> SourceLocation: ...


class CardValues(Protocol):
    """Evaluates value fields against the parameters in scope."""

    @property
    def params(self) -> Mapping[str, float]: ...

    @property
    def functions(self) -> Mapping[str, tuple[tuple[str, ...], Expression]]: ...

    def number(self, token: str, loc: SourceLocation, what: str) -> float:
        """The value of a number, parameter name or ``{expression}`` (``what`` names it in messages)."""
        ...

    def is_value(self, token: str) -> bool:
        """True when ``token`` reads as a value."""
        ...


class CardContext(Protocol):
    """What element builders need besides the line."""

    @property
    def values(self) -> CardValues: ...

    @property
    def warnings(self) -> list[Diagnostic]: ...

    @property
    def models(self) -> dict[str, tuple[str, dict[str, str], SourceLocation]]: ...

    @property
    def temp(self) -> float | None: ...

    @property
    def tran(self) -> TranSpec | None: ...

    @property
    def tnom(self) -> float: ...

    def fields(self, line: CardLine, keep_parens: bool = False) -> list[str]:
        """The line's fields, split as ngspice splits them (``keep_parens``: keep ``(`` and ``)``)."""
        ...

    def split(self, text: str) -> list[str]:
        """Fields of a piece of text (an expression's rest of line)."""
        ...

    def source(
        self, fields: list[str], loc: SourceLocation, name: str
    ) -> tuple[float, Waveform | None, float | None]:
        """An independent source's value fields: DC value (V or A), waveform, port impedance (Ω) or None."""
        ...


#: ``build(line, ctx)``: the elements of one netlist line.
CardBuilder = Callable[[CardLine, CardContext], list[Element]]


def canonical_node(name: str) -> str:
    """The canonical name of a node: lower case, ``0`` for ground (``0``, ``gnd``)."""
    low = name.lower()
    return GROUND if low in ("0", "gnd") else low


def short(text: str, limit: int = 40) -> str:
    """``text`` cut to ``limit`` characters for a one-line message."""
    return text if len(text) <= limit else f"{text[: limit - 3]}..."


def is_expr(token: str) -> bool:
    """True for a ``{...}`` or ``'...'`` expression."""
    return bool(token) and token[0] in "{'"


def unwrap(token: str) -> str:
    """An expression without its braces or quotes."""
    if len(token) >= 2 and ((token[0] == "{" and token[-1] == "}") or (token[0] == "'" and token[-1] == "'")):
        return token[1:-1]
    return token


def split_keywords(
    fields: list[str], start: int, name: str, loc: SourceLocation
) -> tuple[list[str], dict[str, str]]:
    """Positional fields and ``key=value`` pairs after index ``start``."""
    positional: list[str] = []
    keywords: dict[str, str] = {}
    i = start
    while i < len(fields):
        if i + 1 < len(fields) and fields[i + 1] == "=":
            if i + 2 >= len(fields):
                raise NetlistError(f"{name}: {fields[i]}= has no value", loc)
            key = fields[i].lower()
            if key in keywords:
                raise NetlistError(f"{name}: {fields[i]}= given twice", loc)
            keywords[key] = _braced_if_expression(fields[i + 2])
            i += 3
            continue
        if fields[i] == "=":
            raise NetlistError(f"{name}: '=' without a name", loc)
        positional.append(fields[i])
        i += 1
    return positional, keywords


def _braced_if_expression(token: str) -> str:
    """A ``key=value`` value as ngspice's numparam reads it: ``R=VAL1+VAL2`` (no blanks) is the
    expression ``{VAL1+VAL2}`` (measured: 5 with VAL1=2, VAL2=3), while a positional ``VAL1*VAL2``
    stays an error, as in ngspice."""
    if is_expr(token) or read_number(token) is not None or not re.search(r"[-+*/^]", token[1:]):
        return token
    return "{" + token + "}"


def check_value(element: Element, warnings: list[Diagnostic]) -> None:
    """Refuse a zero value; warn of a negative one."""
    if element.value == 0:
        raise NetlistError(f"{element.label}: value is zero", element.loc)
    if element.value < 0:
        warnings.append(Diagnostic(element.loc, f"{element.label} has a negative value ({element.value:g})"))
