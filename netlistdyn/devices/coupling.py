"""Mutual inductance between two inductors (``K L1 L2 k``)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from netlistdyn.base.errors import NetlistError
from netlistdyn.circuit.netlist import Element, Kind
from netlistdyn.devices.traits import DeviceKind, ElementLaws, Family, Mna, SpiceText


def coupling_law(
    element: Element, value: Callable[[Element], Any], mutual: Callable[[Element], Any]
) -> ElementLaws:
    """−M i'_b in L_a's law, −M i'_a in L_b's."""
    assert element.coupled is not None
    a, b = ((name, 0) for name in element.coupled)
    m = mutual(element)
    return ElementLaws(di=((a, b, -m), (b, a, -m)))


def coupling_stamp(elem: Element, mna: Mna) -> None:
    """M = k·sqrt(L_a L_b) (H) in E, between the two inductor currents."""
    first, second = elem.coupled or ("", "")
    inductance = mna.inductance
    if first not in inductance or second not in inductance:
        raise NetlistError(f"{elem.name}: couples an element that is not an inductor", elem.loc)
    mutual = elem.value * float(np.sqrt(inductance[first] * inductance[second]))
    mna.E.add(mna.branch_of[first], mna.branch_of[second], mutual)
    mna.E.add(mna.branch_of[second], mna.branch_of[first], mutual)


def write_coupling(circuit: Any, element: Element, text: SpiceText) -> None:
    """``K name L1 L2 k``."""
    assert element.coupled is not None
    # PySpice prefixes the inductor names with "L" itself.
    first, second = (text.name_of(k)[1:] for k in element.coupled)
    circuit.K(text.name, first, second, element.value)


FAMILY = Family(
    (
        DeviceKind(
            Kind.COUPLING,
            "K",
            0,
            "coupling coefficient",
            law=coupling_law,
            stamp=coupling_stamp,
            spice=write_coupling,
        ),
    )
)
