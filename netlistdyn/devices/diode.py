"""The junction diode (``D``, ngspice's level-1 model).

Its equations (current, junction charge, limiting) are in :mod:`netlistdyn.devices.models`;
the nonlinear modified nodal equations (:mod:`netlistdyn.formulation.nonlinear`) evaluate them,
with RS as a resistor's law and the junction charge as a capacitor's.
"""

from __future__ import annotations

from typing import Any

from netlistdyn.circuit.netlist import Element, Kind
from netlistdyn.devices.traits import DeviceKind, Family, SpiceText


def write_diode(circuit: Any, element: Element, text: SpiceText) -> None:
    """``D name a k dmod_name area=`` with its own ``.model dmod_name D(...)``."""
    model = element.diode
    assert model is not None
    mname = f"dmod_{text.name}".replace(".", "_")
    circuit.model(
        mname,
        "D",
        IS=model.IS,
        N=model.N,
        RS=model.RS,
        CJO=model.CJO,
        VJ=model.VJ,
        M=model.M,
        TT=model.TT,
        FC=model.FC,
    )
    circuit.D(text.name, text.plus, text.minus, model=mname, area=element.value)


FAMILY = Family((DeviceKind(Kind.DIODE, "D", 2, "area", linear=False, spice=write_diode),))
