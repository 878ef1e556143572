"""The ideal transformer: gears and (in the mobility analogy) DC motors."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from netlistdyn.circuit.netlist import Element, Kind
from netlistdyn.devices.traits import DeviceKind, ElementLaws, Family, SpiceText


def transformer_law(
    element: Element, value: Callable[[Element], Any], mutual: Callable[[Element], Any]
) -> ElementLaws:
    """Port 1: v1 − N v2 = 0.  Port 2: i2 + N i1 = 0 (lossless: v1 i1 + v2 i2 = 0)."""
    own = (element.key, 0)
    second = (element.key, 1)
    n = value(element)
    return ElementLaws(v=((own, own, 1), (own, second, -n)), i=((second, second, 1), (second, own, n)))


def write_transformer(circuit: Any, element: Element, text: SpiceText) -> None:
    """v1 = N v2 (E on port 1) and i2 = −N i1 (F on port 2, sensing i1)."""
    name = text.name
    p1, n1, p2, n2 = (text.node(x) for x in element.nodes)
    inner = f"{name}_port1"
    circuit.V(f"{name}_sense", p1, inner, 0)
    circuit.VCVS(name, inner, n1, p2, n2, voltage_gain=element.value)
    circuit.CCCS(name, p2, n2, f"V{name}_sense", current_gain=-element.value)


#: Its two ports' tree roles are chosen by the formulation (one voltage-defined, one current-defined).
FAMILY = Family(
    (DeviceKind(Kind.TRANSFORMER, "E", 4, "ratio", law=transformer_law, spice=write_transformer),)
)
