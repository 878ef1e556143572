"""Resistors, capacitors and inductors (``R``, ``C``, ``L``): laws, stamps, ngspice text."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from netlistdyn.circuit.netlist import Element, Kind
from netlistdyn.devices.traits import DeviceKind, ElementLaws, Family, Mna, Role, SpiceText


def resistor_law(
    element: Element, value: Callable[[Element], Any], mutual: Callable[[Element], Any]
) -> ElementLaws:
    """v − R i = 0."""
    own = (element.key, 0)
    return ElementLaws(v=((own, own, 1),), i=((own, own, -value(element)),))


def capacitor_law(
    element: Element, value: Callable[[Element], Any], mutual: Callable[[Element], Any]
) -> ElementLaws:
    """i − C v' = 0."""
    own = (element.key, 0)
    return ElementLaws(i=((own, own, 1),), dv=((own, own, -value(element)),))


def inductor_law(
    element: Element, value: Callable[[Element], Any], mutual: Callable[[Element], Any]
) -> ElementLaws:
    """v − L i' − Σ M i'_other = 0 (the M terms come with K)."""
    own = (element.key, 0)
    return ElementLaws(v=((own, own, 1),), di=((own, own, -value(element)),))


def resistor_stamp(elem: Element, mna: Mna) -> None:
    """Conductance 1/R between n+ and n−."""
    a, b = mna.ends(elem)
    mna.A.branch(a, b, a, b, -1.0 / elem.value)


def capacitor_stamp(elem: Element, mna: Mna) -> None:
    """Capacitance C between n+ and n− (in E)."""
    a, b = mna.ends(elem)
    mna.E.branch(a, b, a, b, elem.value)


def inductor_stamp(elem: Element, mna: Mna) -> None:
    """Current unknown k with v(n+) − v(n−) = L i_k'."""
    k = mna.current(elem)
    mna.E.add(k, k, elem.value)


def write_resistor(circuit: Any, element: Element, text: SpiceText) -> None:
    """``R name n+ n− value``."""
    circuit.R(text.name, text.plus, text.minus, element.value)


def write_capacitor(circuit: Any, element: Element, text: SpiceText) -> None:
    """``C name n+ n− value [IC=]``."""
    ic = {} if element.ic is None else {"initial_condition": element.ic}
    circuit.C(text.name, text.plus, text.minus, element.value, **ic)


def write_inductor(circuit: Any, element: Element, text: SpiceText) -> None:
    """``L name n+ n− value [IC=]``."""
    ic = {} if element.ic is None else {"initial_condition": element.ic}
    circuit.L(text.name, text.plus, text.minus, element.value, **ic)


FAMILY = Family(
    (
        DeviceKind(
            Kind.RESISTOR,
            "R",
            2,
            "resistance",
            "Ω",
            Role.RESISTOR,
            law=resistor_law,
            stamp=resistor_stamp,
            spice=write_resistor,
        ),
        DeviceKind(
            Kind.CAPACITOR,
            "C",
            2,
            "capacitance",
            "F",
            Role.CAPACITOR,
            law=capacitor_law,
            stamp=capacitor_stamp,
            spice=write_capacitor,
        ),
        DeviceKind(
            Kind.INDUCTOR,
            "L",
            2,
            "inductance",
            "H",
            Role.INDUCTOR,
            branch_current=True,
            law=inductor_law,
            stamp=inductor_stamp,
            spice=write_inductor,
        ),
    )
)
