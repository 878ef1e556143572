"""Linear controlled sources: ``E`` (VCVS), ``G`` (VCCS), ``F`` (CCCS) and ``H`` (CCVS)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from netlistdyn.base.errors import NetlistError
from netlistdyn.circuit.netlist import GROUND, Element, Kind
from netlistdyn.devices.traits import DeviceKind, ElementLaws, Family, Mna, Role, SpiceText


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
    )
)
