"""Mutual inductance between two inductors (``K L1 L2 k``)."""

from __future__ import annotations

import itertools
from collections.abc import Callable
from typing import Any

import numpy as np

from netlistdyn.base.errors import NetlistError
from netlistdyn.circuit.netlist import Element, Kind
from netlistdyn.devices.cards import CardContext, CardLine
from netlistdyn.devices.traits import DeviceKind, ElementLaws, Family, Mna, SpiceText


def build_coupling(line: CardLine, ctx: CardContext) -> list[Element]:
    """``K name L1 L2 k`` (LTspice: ``K name L1 L2 L3 ... k`` couples every pair with k)."""
    name = line.text.split(None, 1)[0]
    loc = line.loc
    fields = ctx.fields(line)
    if len(fields) < 4:
        raise NetlistError(f"{name}: expected K name L1 L2 k", loc)
    k = ctx.values.number(fields[-1], loc, name)
    if not 0 < abs(k) < 1:
        raise NetlistError(
            f"{name}: coupling coefficient must satisfy 0 < |k| < 1, got {k:g}"
            + (" (perfect coupling is an ideal transformer; use k < 1)" if abs(k) == 1 else ""),
            loc,
        )
    inductors = [f.lower() for f in fields[1:-1]]
    # LTspice: "K1 L1 L2 L3 k" couples every pair with k (ngspice 39 takes two inductors).
    pairs = list(itertools.combinations(inductors, 2))
    labels = [name] + [f"{name}.{a}.{b}" for a, b in pairs[1:]]
    return [
        Element(Kind.COUPLING, label, (), k, loc, coupled=pair)
        for label, pair in zip(labels, pairs, strict=True)
    ]


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
    ),
    {"k": build_coupling},
)
