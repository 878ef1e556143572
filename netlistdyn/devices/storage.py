"""Nonlinear capacitors and inductors: ngspice's ``C={C(v)}``, ``Q={Q(v)}`` and ``L={L(i)}``.

Their law has the form of a linear capacitor's or inductor's (i = C(v)·v', v = L(i)·i'); its
derivative term never enters the nonlinear equations (the operating point drops it, the state
equations replace the law by the state).
"""

from __future__ import annotations

from typing import Any

from netlistdyn.circuit.netlist import Element, Kind
from netlistdyn.devices.passive import capacitor_law, inductor_law
from netlistdyn.devices.traits import DeviceKind, Family, SpiceText

#: The keyword of each kind on its ngspice card.
_KEYWORD = {Kind.CAPACITANCE: "C", Kind.CHARGE: "Q", Kind.INDUCTANCE: "L"}


def write_storage(circuit: Any, element: Element, text: SpiceText) -> None:
    """``C name n+ n− C={...}`` (or ``Q={...}``), ``L name n+ n− L={...}``."""
    value = f"{_KEYWORD[element.kind]}={{{text.expression(element.expression or '')}}}"
    (circuit.L if element.kind is Kind.INDUCTANCE else circuit.C)(text.name, text.plus, text.minus, value)


FAMILY = Family(
    (
        DeviceKind(
            Kind.CAPACITANCE, "C", 2, "expression", linear=False, law=capacitor_law, spice=write_storage
        ),
        DeviceKind(Kind.CHARGE, "C", 2, "expression", linear=False, law=capacitor_law, spice=write_storage),
        DeviceKind(
            Kind.INDUCTANCE,
            "L",
            2,
            "expression",
            linear=False,
            law=inductor_law,
            spice=write_storage,
        ),
    )
)
