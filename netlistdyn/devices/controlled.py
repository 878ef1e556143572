"""Linear controlled sources: ``E`` (VCVS), ``G`` (VCCS), ``F`` (CCCS) and ``H`` (CCVS)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from netlistdyn.base.errors import NetlistError
from netlistdyn.circuit.netlist import GROUND, Element, Kind
from netlistdyn.devices.behavioural import build_behavioural, expression_after, poly_expression
from netlistdyn.devices.cards import CardContext, CardLine, canonical_node, split_keywords
from netlistdyn.devices.traits import DeviceKind, ElementLaws, Family, Mna, Role, SpiceText, Triplets

#: Source forms of E, G, F and H that are not supported.
_NONLINEAR_KEYWORDS = ("table", "laplace", "freq", "tablea", "chebyshev")


def build_controlled(line: CardLine, ctx: CardContext) -> list[Element]:
    """``E``/``G name n+ n- c+ c- gain``, ``F``/``H name n+ n- Vcontrol gain``, or their ``POLY(n)``
    and ``value=`` forms (:mod:`netlistdyn.devices.behavioural`)."""
    name = line.text.split(None, 1)[0]
    letter = name[0].lower()
    loc = line.loc
    values = ctx.values
    fields = ctx.fields(line)
    if len(fields) > 3 and fields[3].lower() == "poly":
        mode = "v" if letter in "eh" else "i"
        return build_behavioural(line, mode, poly_expression(fields, letter, values, loc), ctx)
    if letter in "eg":
        if len(fields) > 3 and fields[3].lower() in _NONLINEAR_KEYWORDS:
            raise NetlistError(f"{name}: {fields[3].upper()} sources are not supported", loc)
        found = expression_after(line, ("value", "vol", "cur"), ctx)
        if found is not None:
            key, expr = found
            if (letter == "e" and key == "cur") or (letter == "g" and key == "vol"):
                raise NetlistError(f"{name}: {key}= does not belong to a {letter.upper()} source", loc)
            return build_behavioural(line, "v" if letter == "e" else "i", expr, ctx)
        kind = Kind.VCVS if letter == "e" else Kind.VCCS
        if len(fields) < 5:
            raise NetlistError(f"{name}: expected 4 nodes, got {len(fields) - 1}", loc)
        n = tuple(canonical_node(x) for x in fields[1:5])
        positional, keywords = split_keywords(fields, 5, name, loc)
        if len(positional) != 1 or keywords:
            extra = positional[1] if len(positional) > 1 else next(iter(keywords), "gain")
            raise NetlistError(f"{name}: expected one gain, got {extra!r}", loc)
        gain = values.number(positional[0], loc, name)
        return [Element(kind, name, n[:2], gain, loc, control_nodes=(n[2], n[3]))]
    kind = Kind.CCCS if letter == "f" else Kind.CCVS
    if len(fields) > 3 and fields[3].lower() in _NONLINEAR_KEYWORDS:
        raise NetlistError(f"{name}: {fields[3].upper()} sources are not supported", loc)
    if len(fields) < 4:
        raise NetlistError(f"{name}: missing controlling voltage source", loc)
    if len(fields) != 5:
        raise NetlistError(f"{name}: expected {name} n+ n- Vcontrol gain", loc)
    gain = values.number(fields[4], loc, name)
    return [
        Element(
            kind,
            name,
            (canonical_node(fields[1]), canonical_node(fields[2])),
            gain,
            loc,
            control_source=fields[3].lower(),
        )
    ]


def voltage_controlled_law(
    element: Element, value: Callable[[Element], Any], mutual: Callable[[Element], Any]
) -> ElementLaws:
    """v (E) or i (G) − gain·(v_a − v_b) = 0."""
    own = (element.key, 0)
    assert element.control_nodes is not None
    control = ((own, element.control_nodes, -value(element)),)
    if element.kind is Kind.VCVS:
        return ElementLaws(v=((own, own, 1),), control=control)
    return ElementLaws(i=((own, own, 1),), control=control)


def current_controlled_law(
    element: Element, value: Callable[[Element], Any], mutual: Callable[[Element], Any]
) -> ElementLaws:
    """i (F) or v (H) − gain·i_control = 0."""
    own = (element.key, 0)
    assert element.control_source is not None
    gain = (own, (element.control_source, 0), -value(element))
    if element.kind is Kind.CCCS:
        return ElementLaws(i=((own, own, 1), gain))
    return ElementLaws(v=((own, own, 1),), i=(gain,))


def _sense(elem: Element, mna: Mna) -> int:
    """The current unknown of an F or H source's controlling voltage source."""
    sense = mna.branch_of.get(elem.control_source or "")
    if sense is None:
        raise NetlistError(f"{elem.name}: no voltage source {elem.control_source!r}", elem.loc)
    return sense


def vccs_stamp(elem: Element, mna: Mna) -> None:
    """Transconductance from the control pair to n+ and n−."""
    a, b = mna.ends(elem)
    c, d = (mna.index[node] for node in elem.control_nodes or (GROUND, GROUND))
    mna.A.branch(a, b, c, d, -elem.value)


def cccs_stamp(elem: Element, mna: Mna) -> None:
    """gain·i_control out of n+ and into n−."""
    a, b = mna.ends(elem)
    sense = _sense(elem, mna)
    mna.A.add(a, sense, -elem.value)
    mna.A.add(b, sense, elem.value)


def vcvs_stamp(elem: Element, mna: Mna) -> None:
    """Current unknown k with v(n+) − v(n−) = gain·(v(c) − v(d))."""
    k = mna.current(elem)
    c, d = (mna.index[node] for node in elem.control_nodes or (GROUND, GROUND))
    mna.A.add(k, c, -elem.value)
    mna.A.add(k, d, elem.value)


def ccvs_stamp(elem: Element, mna: Mna) -> None:
    """Current unknown k with v(n+) − v(n−) = gain·i_control."""
    k = mna.current(elem)
    sense = _sense(elem, mna)
    mna.A.add(k, sense, -elem.value)


def vccs_current(elem: Element, mna: Mna, row: int, c: Triplets, d: Triplets) -> None:
    """gain·(v(c+) − v(c−))."""
    cp, cn = (mna.index[node] for node in elem.control_nodes or (GROUND, GROUND))
    c.add(row, cp, elem.value)
    c.add(row, cn, -elem.value)


def cccs_current(elem: Element, mna: Mna, row: int, c: Triplets, d: Triplets) -> None:
    """gain·i_control."""
    c.add(row, mna.branch_of[elem.control_source or ""], elem.value)


def write_vcvs(circuit: Any, element: Element, text: SpiceText) -> None:
    """``E name n+ n− c+ c− gain``."""
    assert element.control_nodes is not None
    cp, cn = (text.node(x) for x in element.control_nodes)
    circuit.VCVS(text.name, text.plus, text.minus, cp, cn, voltage_gain=element.value)


def write_vccs(circuit: Any, element: Element, text: SpiceText) -> None:
    """``G name n+ n− c+ c− gain``."""
    assert element.control_nodes is not None
    cp, cn = (text.node(x) for x in element.control_nodes)
    circuit.VCCS(text.name, text.plus, text.minus, cp, cn, transconductance=element.value)


def write_cccs(circuit: Any, element: Element, text: SpiceText) -> None:
    """``F name n+ n− Vsense gain``."""
    assert element.control_source is not None
    sense = text.name_of(element.control_source)
    circuit.CCCS(text.name, text.plus, text.minus, sense, current_gain=element.value)


def write_ccvs(circuit: Any, element: Element, text: SpiceText) -> None:
    """``H name n+ n− Vsense gain``."""
    assert element.control_source is not None
    sense = text.name_of(element.control_source)
    circuit.CCVS(text.name, text.plus, text.minus, sense, transresistance=element.value)


FAMILY = Family(
    (
        DeviceKind(
            Kind.VCVS,
            "E",
            2,
            "gain",
            role=Role.VTYPE,
            branch_current=True,
            law=voltage_controlled_law,
            stamp=vcvs_stamp,
            spice=write_vcvs,
        ),
        DeviceKind(
            Kind.VCCS,
            "G",
            2,
            "transconductance",
            role=Role.ITYPE,
            law=voltage_controlled_law,
            stamp=vccs_stamp,
            spice=write_vccs,
            current=vccs_current,
        ),
        DeviceKind(
            Kind.CCCS,
            "F",
            2,
            "gain",
            role=Role.ITYPE,
            law=current_controlled_law,
            stamp=cccs_stamp,
            spice=write_cccs,
            current=cccs_current,
        ),
        DeviceKind(
            Kind.CCVS,
            "H",
            2,
            "transresistance",
            role=Role.VTYPE,
            branch_current=True,
            law=current_controlled_law,
            stamp=ccvs_stamp,
            spice=write_ccvs,
        ),
    ),
    {"e": build_controlled, "g": build_controlled, "f": build_controlled, "h": build_controlled},
)
