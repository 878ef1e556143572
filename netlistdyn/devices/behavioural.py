"""Nonlinear behavioural sources (``B V=``/``I=``, ``E``/``G`` with ``value=``): v or i = f(v, i, time).

A behavioural source whose expression is linear is compiled as controlled sources
(:mod:`netlistdyn.devices.controlled`); these kinds hold the others, their expression
evaluated with its derivatives by :class:`netlistdyn.devices.models.Behaviour`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from netlistdyn.circuit.netlist import Element, Kind
from netlistdyn.devices.traits import DeviceKind, ElementLaws, Family, SpiceText


def bvoltage_law(
    element: Element, value: Callable[[Element], Any], mutual: Callable[[Element], Any]
) -> ElementLaws:
    """v − f = 0, with f in the nonlinear part of the equations."""
    return ElementLaws(v=(((element.key, 0), (element.key, 0), 1.0),))


def write_behavioural(circuit: Any, element: Element, text: SpiceText) -> None:
    """``B name n+ n− V={...}`` or ``I={...}``."""
    expression = text.expression(element.expression or "")
    key = "voltage_expression" if element.kind is Kind.BVOLTAGE else "current_expression"
    circuit.BehavioralSource(text.name, text.plus, text.minus, **{key: expression})


FAMILY = Family(
    (
        DeviceKind(
            Kind.BVOLTAGE,
            "B",
            2,
            "expression",
            linear=False,
            law=bvoltage_law,
            spice=write_behavioural,
        ),
        DeviceKind(Kind.BCURRENT, "B", 2, "expression", linear=False, spice=write_behavioural),
    )
)
