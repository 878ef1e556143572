"""Nonlinear capacitors and inductors: ngspice's ``C={C(v)}``, ``Q={Q(v)}`` and ``L={L(i)}``.

Their law has the form of a linear capacitor's or inductor's (i = C(v)·v', v = L(i)·i'); its
derivative term never enters the nonlinear equations (the operating point drops it, the state
equations replace the law by the state).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from netlistdyn.base.errors import NetlistError, SourceLocation
from netlistdyn.circuit.expressions import ExpressionError, parse
from netlistdyn.circuit.netlist import Element, Kind
from netlistdyn.devices.cards import CardContext, unwrap
from netlistdyn.devices.models import Behaviour, fold
from netlistdyn.devices.traits import DeviceKind, ElementLaws, Family, SpiceText

#: The keyword of each kind on its ngspice card.
_KEYWORD = {Kind.CAPACITANCE: "C", Kind.CHARGE: "Q", Kind.INDUCTANCE: "L"}


def reads_solution(token: str) -> bool:
    """True when a value reads the circuit's solution (``v()``, ``i()``) or ``time``."""
    try:
        expr = parse(unwrap(token))
    except ExpressionError:
        return False
    return expr.refs or "time" in expr.names


def nonlinear_storage(
    name: str,
    letter: str,
    nodes: tuple[str, str],
    positional: list[str],
    keywords: dict[str, str],
    ctx: CardContext,
    loc: SourceLocation,
) -> Element | None:
    """ngspice's nonlinear ``C={expr}``, ``Q={expr}`` and ``L={expr}`` (None: an ordinary value)."""
    key = "q" if letter == "c" and "q" in keywords else letter
    text = keywords.get(key)
    if any(reads_solution(t) for t in positional):
        raise NetlistError(
            f"{name}: a value that reads v(), i() or time is written {letter.upper()}={{...}}"
            + (" or Q={...}" if letter == "c" else ""),
            loc,
        )
    if key != "q" and (text is None or not reads_solution(text)):
        return None
    assert text is not None
    others = sorted(set(keywords) - {key})
    if others or positional:
        what = f"{others[0]}=" if others else repr(positional[0])
        raise NetlistError(f"{name}: {what} beside a nonlinear {key.upper()}= is not supported", loc)
    try:
        folded = fold(unwrap(text), ctx.values.params, ctx.values.functions)
        Behaviour.from_text(folded)
    except ExpressionError as exc:
        raise NetlistError(f"{name}: {exc}", loc) from None
    kind = {"c": Kind.CAPACITANCE, "q": Kind.CHARGE, "l": Kind.INDUCTANCE}[key]
    return Element(kind, name, nodes, 1.0, loc, expression=folded)


def storage_law(
    element: Element, value: Callable[[Element], Any], mutual: Callable[[Element], Any]
) -> ElementLaws:
    """i − C(v)·v' = 0 (``C=``, ``Q=``) or v − L(i)·i' = 0 (``L=``): a linear capacitor's or inductor's form.

    ``value(element)`` is 1 (the element's value): the derivative term never enters the equations.
    """
    own = (element.key, 0)
    if element.kind is Kind.INDUCTANCE:
        return ElementLaws(v=((own, own, 1),), di=((own, own, -value(element)),))
    return ElementLaws(i=((own, own, 1),), dv=((own, own, -value(element)),))


def write_storage(circuit: Any, element: Element, text: SpiceText) -> None:
    """``C name n+ n− C={...}`` (or ``Q={...}``), ``L name n+ n− L={...}``."""
    value = f"{_KEYWORD[element.kind]}={{{text.expression(element.expression or '')}}}"
    (circuit.L if element.kind is Kind.INDUCTANCE else circuit.C)(text.name, text.plus, text.minus, value)


FAMILY = Family(
    (
        DeviceKind(
            Kind.CAPACITANCE, "C", 2, "expression", linear=False, law=storage_law, spice=write_storage
        ),
        DeviceKind(Kind.CHARGE, "C", 2, "expression", linear=False, law=storage_law, spice=write_storage),
        DeviceKind(
            Kind.INDUCTANCE,
            "L",
            2,
            "expression",
            linear=False,
            law=storage_law,
            spice=write_storage,
        ),
    )
)
