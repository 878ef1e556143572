"""The junction diode (``D``, ngspice's level-1 model).

Its equations (current, junction charge, limiting) are in :mod:`netlistdyn.devices.models`;
the nonlinear modified nodal equations (:mod:`netlistdyn.formulation.nonlinear`) evaluate them,
with RS as a resistor's law and the junction charge as a capacitor's.
"""

from __future__ import annotations

from typing import Any

from netlistdyn.base.errors import NetlistError
from netlistdyn.circuit.netlist import DiodeModel, Element, Kind
from netlistdyn.devices.cards import CardContext, CardLine, canonical_node, split_keywords
from netlistdyn.devices.models import DIODE_NEUTRAL, DIODE_PARAMS
from netlistdyn.devices.traits import DeviceKind, Family, SpiceText


def build_diode(line: CardLine, ctx: CardContext) -> list[Element]:
    """``Dname anode cathode model [area] [area=] [m=]`` with a ``.model NAME D(...)``."""
    fields = ctx.fields(line)
    name, loc = fields[0], line.loc
    if len(fields) < 4:
        raise NetlistError(f"{name}: expected {name} anode cathode model [area]", loc)
    nodes = (canonical_node(fields[1]), canonical_node(fields[2]))
    positional, keywords = split_keywords(fields, 4, name, loc)
    mname = fields[3].lower()
    if mname not in ctx.models:
        raise NetlistError(f"{name}: no .model {fields[3]}", loc)
    mtype, mparams, mloc = ctx.models[mname]
    if mtype != "d":
        raise NetlistError(f"{name}: model {fields[3]} is a {mtype.upper()} model, not D", loc)
    values = ctx.values
    area = 1.0
    if positional:
        if len(positional) > 1 or positional[0].lower() == "off":
            raise NetlistError(f"{name}: unexpected field {positional[-1]!r} (expected an area)", loc)
        area = values.number(positional[0], loc, f"{name} area")
    if "area" in keywords:
        area = values.number(keywords.pop("area"), loc, f"{name} area")
    if "m" in keywords:
        area *= values.number(keywords.pop("m"), loc, f"{name} m")
    if keywords:
        raise NetlistError(f"{name}: unsupported parameter {next(iter(keywords))}= on a diode", loc)
    if not area > 0:
        raise NetlistError(f"{name}: the area must be positive, got {area:g}", loc)
    if (ctx.temp is not None and ctx.temp != 27.0) or ctx.tnom != 27.0:
        raise NetlistError(f"{name}: diodes are modelled at 27 °C only (TEMP = TNOM = 27)", loc)
    given: dict[str, float] = {}
    for key, text in mparams.items():
        what = f".model {mname} {key.upper()}"
        if key in DIODE_PARAMS:
            given[DIODE_PARAMS[key]] = values.number(text, mloc, what)
        elif key in DIODE_NEUTRAL:
            if values.number(text, mloc, what) != DIODE_NEUTRAL[key]:
                raise NetlistError(f"{what}: only the default {DIODE_NEUTRAL[key]:g} is supported", mloc)
        else:
            raise NetlistError(
                f"{what}: parameter not supported (netlistdyn reads IS N RS CJO VJ M TT FC)", mloc
            )
    model = DiodeModel(mname, **given)
    if not (model.IS > 0 and model.N > 0 and model.RS >= 0 and model.CJO >= 0 and model.TT >= 0):
        raise NetlistError(f".model {mname}: IS and N must be positive, RS, CJO and TT not negative", mloc)
    if model.CJO > 0 and not (model.VJ > 0 and 0 < model.M < 1 and 0 <= model.FC < 1):
        raise NetlistError(f".model {mname}: needs VJ > 0, 0 < M < 1 and 0 <= FC < 1", mloc)
    return [Element(Kind.DIODE, name, nodes, area, loc, diode=model)]


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


FAMILY = Family(
    (DeviceKind(Kind.DIODE, "D", 2, "area", linear=False, spice=write_diode),), {"d": build_diode}
)
