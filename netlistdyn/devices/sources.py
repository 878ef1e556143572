"""Independent voltage and current sources (``V``, ``I``): the model's inputs."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

from netlistdyn.base.errors import NetlistError
from netlistdyn.circuit.netlist import Element, Kind
from netlistdyn.devices.cards import CardContext, CardLine, canonical_node
from netlistdyn.devices.traits import DeviceKind, ElementLaws, Family, Mna, Role, SpiceText, Triplets


def build_source(line: CardLine, ctx: CardContext) -> list[Element]:
    """``V``/``I name n+ n- [DC] value [AC ...] [PULSE(...)|SIN(...)|...] [portnum n z0 z]``.

    An S-parameter port's ``z0`` is a series resistor ``name.z0`` (a parallel one for ``I``).
    """
    name = line.text.split(None, 1)[0]
    letter = name[0].lower()
    loc = line.loc
    fields = ctx.fields(line, keep_parens=True)
    if len(fields) < 3 or "(" in fields[1:3] or ")" in fields[1:3]:
        raise NetlistError(f"{name}: expected 2 nodes", loc)
    kind = Kind.VSOURCE if letter == "v" else Kind.ISOURCE
    nodes = (canonical_node(fields[1]), canonical_node(fields[2]))
    rest, parasitics = _ltspice_parasitics(fields[3:]) if kind is Kind.VSOURCE else (fields[3:], {})
    dc, waveform, z0 = ctx.source(rest, loc, name)
    source = Element(kind, name, nodes, dc, loc, waveform=waveform)
    if parasitics:
        if z0 is not None:
            raise NetlistError(f"{name}: Rser=/Cpar= together with portnum", loc)
        return _with_parasitics(source, parasitics, ctx)
    if z0 is None:
        return [source]
    if kind is Kind.ISOURCE:
        return [source, Element(Kind.RESISTOR, f"{name}.z0", nodes, z0, loc)]
    inner = f"{name.lower()}.port"
    return [
        replace(source, nodes=(inner, nodes[1])),
        Element(Kind.RESISTOR, f"{name}.z0", (nodes[0], inner), z0, loc),
    ]


#: LTspice's parasitics of a voltage source: Rser= in series, Cpar= across its terminals.
LTSPICE_SOURCE_PARASITICS = ("rser", "cpar")


def _ltspice_parasitics(fields: list[str]) -> tuple[list[str], dict[str, str]]:
    """The source's fields without ``Rser=``/``Cpar=`` (LTspice's), and those values."""
    rest: list[str] = []
    found: dict[str, str] = {}
    k = 0
    while k < len(fields):
        word = fields[k].lower()
        if word in LTSPICE_SOURCE_PARASITICS and fields[k + 1 : k + 2] == ["="]:
            if k + 2 >= len(fields):
                return fields, {}  # ctx.source refuses it: "Rser= has no value"
            found[word] = fields[k + 2]
            k += 3
            continue
        rest.append(fields[k])
        k += 1
    return rest, found


def _with_parasitics(source: Element, parasitics: dict[str, str], ctx: CardContext) -> list[Element]:
    """An LTspice voltage source with ``Rser=`` (a resistor from n+ to the source) and ``Cpar=``
    (a capacitor across n+ and n−), as LTspice means them."""
    loc, name = source.loc, source.name
    values = {k: ctx.values.number(v, loc, f"{name} {k}") for k, v in parasitics.items()}
    plus, minus = source.nodes
    out = [source]
    if values.get("rser"):
        inner = f"{source.key}.rser"
        out = [
            replace(source, nodes=(inner, minus)),
            Element(Kind.RESISTOR, f"{name}.Rser", (plus, inner), values["rser"], loc),
        ]
    if values.get("cpar"):
        out.append(Element(Kind.CAPACITOR, f"{name}.Cpar", (plus, minus), values["cpar"], loc))
    for extra in out[1:]:
        if extra.value <= 0:
            raise NetlistError(f"{extra.label}: value must be positive, got {extra.value:g}", loc)
    return out


def vsource_law(
    element: Element, value: Callable[[Element], Any], mutual: Callable[[Element], Any]
) -> ElementLaws:
    """v − u = 0."""
    own = (element.key, 0)
    return ElementLaws(v=((own, own, 1),), u=((own, element.key, -1),))


def isource_law(
    element: Element, value: Callable[[Element], Any], mutual: Callable[[Element], Any]
) -> ElementLaws:
    """i − u = 0."""
    own = (element.key, 0)
    return ElementLaws(i=((own, own, 1),), u=((own, element.key, -1),))


def vsource_stamp(elem: Element, mna: Mna) -> None:
    """Current unknown k with v(n+) − v(n−) = u."""
    k = mna.current(elem)
    mna.B.add(k, mna.source_col[elem.key], -1.0)


def isource_stamp(elem: Element, mna: Mna) -> None:
    """u taken out of n+ and put into n−."""
    a, b = mna.ends(elem)
    mna.B.add(a, mna.source_col[elem.key], -1.0)
    mna.B.add(b, mna.source_col[elem.key], 1.0)


def isource_current(elem: Element, mna: Mna, row: int, c: Triplets, d: Triplets) -> None:
    """The input u itself."""
    d.add(row, mna.source_col[elem.key], 1.0)


def write_source(circuit: Any, element: Element, text: SpiceText) -> None:
    """``V``/``I name n+ n− [DC value] [waveform] [AC 1]``, the waveform written out in full."""
    waveform = element.waveform.resolved(*text.span) if element.waveform is not None else None
    wave = waveform.spice() if waveform is not None else f"DC {element.value!r}"
    if element.waveform is not None and element.value:
        wave = f"DC {element.value!r} {wave}"
    if text.ac:
        wave = f"{wave} AC 1"
    (circuit.V if element.kind is Kind.VSOURCE else circuit.I)(text.name, text.plus, text.minus, wave)


FAMILY = Family(
    (
        DeviceKind(
            Kind.VSOURCE,
            "V",
            2,
            "voltage",
            role=Role.VSOURCE,
            branch_current=True,
            law=vsource_law,
            stamp=vsource_stamp,
            spice=write_source,
        ),
        DeviceKind(
            Kind.ISOURCE,
            "I",
            2,
            "current",
            role=Role.ISOURCE,
            law=isource_law,
            stamp=isource_stamp,
            spice=write_source,
            current=isource_current,
        ),
    ),
    {"v": build_source, "i": build_source},
)
