"""A device kind added through the registry alone: its card, its tree role and its law, in one record.

The toy is a linear conductance ``Y name n+ n- G`` (i − G·v = 0, in siemens), a kind netlistdyn
does not have. It lives in a registry made for this test (:meth:`Registry.with_family`); the
package's own :data:`REGISTRY` is not changed, and still refuses a ``Y`` line.
"""

from __future__ import annotations

import enum
import pickle
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from netlistdyn.base.errors import NetlistError
from netlistdyn.circuit.netlist import Element, Kind
from netlistdyn.devices.cards import CardContext, CardLine, canonical_node
from netlistdyn.devices.registry import REGISTRY, Registry
from netlistdyn.devices.traits import DeviceKind, ElementLaws, Family, Role
from netlistdyn.formulation.compile import formulate
from netlistdyn.frontend.parser import parse_text

#: Relative agreement of a compiled matrix entry with its closed form: the reduction does a few
#: floating-point operations on values of order 1e3..1e6, so a few ulps.
RTOL = 1e-12


class ToyKind(enum.Enum):
    """The toy's own tag (the package's tags are :class:`~netlistdyn.circuit.netlist.Kind`)."""

    CONDUCTANCE = "Y"


def build_conductance(line: CardLine, ctx: CardContext) -> list[Element]:
    """``Y name n+ n- G``."""
    fields = ctx.fields(line)
    if len(fields) != 4:
        raise NetlistError(f"{fields[0]}: expected Y name n+ n- conductance", line.loc)
    nodes = (canonical_node(fields[1]), canonical_node(fields[2]))
    g = ctx.values.number(fields[3], line.loc, fields[0])
    return [Element(ToyKind.CONDUCTANCE, fields[0], nodes, g, line.loc)]  # type: ignore[arg-type]


def conductance_law(
    element: Element, value: Callable[[Element], Any], mutual: Callable[[Element], Any]
) -> ElementLaws:
    """i − G v = 0."""
    own = (element.key, 0)
    return ElementLaws(i=((own, own, 1),), v=((own, own, -value(element)),))


CONDUCTANCE = Family(
    (DeviceKind(ToyKind.CONDUCTANCE, "Y", 2, "conductance", "S", Role.RESISTOR, law=conductance_law),),
    {"y": build_conductance},
)

#: An RC low-pass whose resistor is the toy conductance: G = 1 mS (1 kΩ), C = 1 µF, tau = 1 ms.
NETLIST = """toy conductance low-pass
V1 in 0 1
Y1 in out {g}
C1 out 0 1u
.param g=1m
.end
"""


def with_toy() -> Registry:
    return REGISTRY.with_family(CONDUCTANCE)


def test_a_toy_kind_compiles_through_the_registry_alone() -> None:
    """dq/dt = G·(u − q/C): A = −G/C, B = G, and v(out) = q/C: C = 1/C, D = 0 (closed form)."""
    devices = with_toy()
    netlist = parse_text(NETLIST, devices=devices)
    assert [e.kind for e in netlist.elements] == [Kind.VSOURCE, ToyKind.CONDUCTANCE, Kind.CAPACITOR]
    model = formulate(netlist, ["v(out)"], devices=devices).model
    g, c = 1e-3, 1e-6
    assert model.states == ("q(C1)",)
    np.testing.assert_allclose(model.A, [[-g / c]], rtol=RTOL)
    np.testing.assert_allclose(model.B, [[g]], rtol=RTOL)
    np.testing.assert_allclose(model.C, [[1 / c]], rtol=RTOL)
    np.testing.assert_array_equal(model.D, [[0.0]])


def test_the_toy_law_is_the_one_used() -> None:
    """Another conductance in the card changes the pole as the closed form says (the law is read)."""
    devices = with_toy()
    model = formulate(
        parse_text(NETLIST, overrides={"g": 2e-3}, devices=devices), ["v(out)"], devices=devices
    )
    np.testing.assert_allclose(model.model.A, [[-2e-3 / 1e-6]], rtol=RTOL)


def test_the_package_registry_is_unchanged() -> None:
    """The toy was added to a new registry: the package's still refuses a Y line, and has no Y kind."""
    with_toy()
    assert ToyKind.CONDUCTANCE not in REGISTRY
    assert REGISTRY.card("y") is None
    with pytest.raises(NetlistError, match=r"Y1: .* not supported"):
        parse_text(NETLIST)


def test_a_kind_or_letter_registered_twice_is_refused() -> None:
    with pytest.raises(ValueError, match="registered twice"):
        with_toy().with_family(CONDUCTANCE)
    clash = Family((), {"r": build_conductance})
    with pytest.raises(ValueError, match="card letter 'r' registered twice"):
        REGISTRY.with_family(clash)


def test_every_kind_has_a_record() -> None:
    """Every element kind of the package is registered, and each letter a record names reads a card."""
    assert set(Kind) == set(REGISTRY.kinds)
    for record in REGISTRY:
        assert REGISTRY.card(record.letter) is not None, record.kind


def test_a_registry_pickles() -> None:
    """A compiled formulation carries its registry to ``sweep --jobs`` workers: it pickles, toy kinds too."""
    devices = with_toy()
    copy = pickle.loads(pickle.dumps(devices))
    assert dict(copy.kinds) == dict(devices.kinds) and dict(copy.cards) == dict(devices.cards)
    formulation = formulate(parse_text(NETLIST, devices=devices), ["v(out)"], devices=devices)
    again = pickle.loads(pickle.dumps(formulation))
    np.testing.assert_array_equal(again.model.A, formulation.model.A)
