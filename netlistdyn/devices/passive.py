"""Resistors, capacitors and inductors (``R``, ``C``, ``L``): card syntax, laws, stamps, ngspice text."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

from netlistdyn.base.errors import NetlistError, SourceLocation
from netlistdyn.circuit.netlist import Diagnostic, Element, Kind
from netlistdyn.devices.cards import CardContext, CardLine, canonical_node, check_value, split_keywords
from netlistdyn.devices.storage import nonlinear_storage
from netlistdyn.devices.traits import DeviceKind, ElementLaws, Family, Mna, Role, SpiceText, Triplets

_PASSIVE = {
    "r": (Kind.RESISTOR, ("r", "resistance", "value"), "resistance"),
    "c": (Kind.CAPACITOR, ("c", "capacitance", "value"), "capacitance"),
    "l": (Kind.INDUCTOR, ("l", "inductance", "value"), "inductance"),
}
# Keywords with no effect on the model: noise parameters, and LTspice's part ratings and
# catalogue fields (voltage/current/power ratings, tolerance, manufacturer, part number).
_RATINGS = {"mfg": "", "pn": "", "type": "", "pppkg": ""}
_PASSIVE_IGNORED = {
    "r": {"noisy": "", "kf": "", "af": "", "bv_max": "", "tol": "", "pwr": "", **_RATINGS},
    "c": {"bv_max": "", "v": "", "irms": "", "rpeak": "", "tol": "", **_RATINGS},
    "l": {"ipk": "", "rpeak": "", "irms": "", "tol": "", **_RATINGS},
}
_LTSPICE_PARASITICS = {"r": (), "c": ("rser", "lser", "rpar", "cpar"), "l": ("rser", "rpar", "cpar")}


def _temperature_factor(
    name: str, tc1: float, tc2: float, keywords: dict[str, str], ctx: CardContext, loc: SourceLocation
) -> float:
    if not tc1 and not tc2:
        return 1.0
    nominal = ctx.tnom
    temp = ctx.temp if ctx.temp is not None else 27.0
    if "temp" in keywords:
        temp = ctx.values.number(keywords["temp"], loc, f"{name} temp")
    if "dtemp" in keywords:
        temp = temp + ctx.values.number(keywords["dtemp"], loc, f"{name} dtemp")
    dt = temp - nominal
    return 1.0 + tc1 * dt + tc2 * dt * dt


def build_passive(line: CardLine, ctx: CardContext) -> list[Element]:
    """``R``/``C``/``L name n+ n- [value] [model] [key=value...]``; a nonlinear ``C=``, ``Q=``, ``L=``
    is :func:`~netlistdyn.devices.storage.nonlinear_storage`'s."""
    fields = ctx.fields(line)
    name = fields[0]
    letter = name[0].lower()
    loc = line.loc
    kind, value_keys, quantity = _PASSIVE[letter]
    if len(fields) < 3:
        raise NetlistError(f"{name}: expected 2 nodes, got {len(fields) - 1}", loc)
    nodes = (canonical_node(fields[1]), canonical_node(fields[2]))
    positional, keywords = split_keywords(fields, 3, name, loc)
    if letter in "cl":
        storage = nonlinear_storage(name, letter, nodes, positional, keywords, ctx, loc)
        if storage is not None:
            return [storage]
    values = ctx.values
    value: float | None = None
    model: tuple[str, dict[str, str], SourceLocation] | None = None
    for token in positional:
        if value is None and values.is_value(token):
            value = values.number(token, loc, name)
        elif model is None and token.lower() in ctx.models:
            model = ctx.models[token.lower()]
            mtype = model[0]
            if mtype[0] != letter and not (letter == "r" and mtype == "res"):
                raise NetlistError(
                    f"{name}: model {token} is a {mtype.upper()} model, not {letter.upper()}", loc
                )
        else:
            raise NetlistError(f"{name}: unexpected field {token!r} (ngspice refuses it too)", loc)
    for key in value_keys:
        if key in keywords:
            if value is not None:
                raise NetlistError(f"{name}: the {quantity} is given twice", loc)
            value = values.number(keywords.pop(key), loc, name)
    mult = values.number(keywords.pop("m"), loc, f"{name} m") if "m" in keywords else 1.0
    if mult <= 0:
        raise NetlistError(f"{name}: m= must be positive, got {mult:g}", loc)
    ic = values.number(keywords.pop("ic"), loc, f"{name} IC") if letter in "cl" and "ic" in keywords else None
    tc1 = values.number(keywords.pop("tc1"), loc, f"{name} tc1") if "tc1" in keywords else 0.0
    tc2 = values.number(keywords.pop("tc2"), loc, f"{name} tc2") if "tc2" in keywords else 0.0
    ac_value = (
        values.number(keywords.pop("ac"), loc, f"{name} ac") if letter == "r" and "ac" in keywords else None
    )
    length = values.number(keywords.pop("l"), loc, f"{name} l") if letter == "r" and "l" in keywords else None
    width = values.number(keywords.pop("w"), loc, f"{name} w") if letter == "r" and "w" in keywords else None
    parasitics = {k: keywords.pop(k) for k in _LTSPICE_PARASITICS[letter] if k in keywords}
    for key in _PASSIVE_IGNORED[letter]:  # no effect on the model
        keywords.pop(key, None)
    temp_keys: dict[str, str] = {k: keywords.pop(k) for k in ("temp", "dtemp") if k in keywords}
    if keywords:
        key = next(iter(keywords))
        raise NetlistError(f"{name}: unknown parameter {key}= on {quantity} element", loc)
    if model is not None:
        mparams = model[1]
        tc1 = tc1 or (values.number(mparams["tc1"], model[2], "tc1") if "tc1" in mparams else 0.0)
        tc2 = tc2 or (values.number(mparams["tc2"], model[2], "tc2") if "tc2" in mparams else 0.0)
        if value is None and letter == "r" and "rsh" in mparams and length is not None:
            rsh = values.number(mparams["rsh"], model[2], "rsh")
            short = values.number(mparams["short"], model[2], "short") if "short" in mparams else 0.0
            narrow = values.number(mparams["narrow"], model[2], "narrow") if "narrow" in mparams else 0.0
            w = width if width is not None else values.number(mparams.get("defw", "10u"), model[2], "defw")
            value = rsh * (length - short) / (w - narrow)
        if value is None and letter == "r":
            for key in ("r", "res"):
                if key in mparams:
                    value = values.number(mparams[key], model[2], f"model {key}")
                    break
        allowed = {"tc1", "tc2", "tnom", "bv_max"}
        if letter == "r":
            allowed |= {"r", "res", "rsh", "short", "narrow", "defw", "kf", "af", "noisy"}
        unknown = sorted(set(mparams) - allowed)
        if unknown:
            raise NetlistError(f"{name}: model parameter {unknown[0]} is not supported", loc)
        if "tnom" in mparams and (tc1 or tc2):
            raise NetlistError(f"{name}: a model TNOM with temperature coefficients is not supported", loc)
    elif length is not None or width is not None:
        raise NetlistError(f"{name}: l=/w= need a resistor model with RSH", loc)
    if value is None:
        raise NetlistError(f"{name}: missing {quantity}", loc)
    value *= _temperature_factor(name, tc1, tc2, temp_keys, ctx, loc)
    value = value * mult if letter == "c" else value / mult
    if ac_value is not None and ac_value != value:
        ctx.warnings.append(
            Diagnostic(
                loc,
                f"{name}: ac={ac_value:g} is used by ngspice only in .ac analysis; the model uses {value:g}",
            )
        )
    element = Element(kind, name, nodes, value, loc, ic=ic)
    check_value(element, ctx.warnings)
    if not parasitics:
        return [element]
    return _ltspice_parasitics(element, parasitics, ctx)


def _ltspice_parasitics(element: Element, parasitics: dict[str, str], ctx: CardContext) -> list[Element]:
    """LTspice ``Rser=``/``Lser=`` in series and ``Rpar=``/``Cpar=`` across the whole element."""
    loc = element.loc
    name = element.name
    vals = {k: ctx.values.number(v, loc, f"{name} {k}") for k, v in parasitics.items()}
    plus, minus = element.nodes
    out: list[Element] = []
    series = [(Kind.RESISTOR, "Rser", vals["rser"])] if vals.get("rser") else []
    if vals.get("lser"):
        series.append((Kind.INDUCTOR, "Lser", vals["lser"]))
    node = minus
    inner_nodes = [f"{element.key}.{label.lower()}" for _, label, _ in series]
    main_minus = inner_nodes[0] if inner_nodes else minus
    out.append(replace(element, nodes=(plus, main_minus)))
    for k, (kind, label, value) in enumerate(series):
        node = inner_nodes[k + 1] if k + 1 < len(inner_nodes) else minus
        out.append(Element(kind, f"{name}.{label}", (inner_nodes[k], node), value, loc))
    if vals.get("rpar"):
        out.append(Element(Kind.RESISTOR, f"{name}.Rpar", (plus, minus), vals["rpar"], loc))
    if vals.get("cpar"):
        out.append(Element(Kind.CAPACITOR, f"{name}.Cpar", (plus, minus), vals["cpar"], loc))
    for extra in out[1:]:
        check_value(extra, ctx.warnings)
    return out


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


def resistor_current(elem: Element, mna: Mna, row: int, c: Triplets, d: Triplets) -> None:
    """(v(n+) − v(n−)) / R."""
    a, b = mna.ends(elem)
    c.add(row, a, 1.0 / elem.value)
    c.add(row, b, -1.0 / elem.value)


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
            current=resistor_current,
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
    ),
    {"r": build_passive, "c": build_passive, "l": build_passive},
)
