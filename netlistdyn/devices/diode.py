"""The junction diode (``D``, ngspice's level-1 model).

Its equations (current, junction charge, limiting) are in :mod:`netlistdyn.devices.models`;
the nonlinear modified nodal equations (:mod:`netlistdyn.formulation.nonlinear`) evaluate them,
with RS as a resistor's law and the junction charge as a capacitor's.
"""

from __future__ import annotations

import math
from typing import Any

from netlistdyn.base.errors import NetlistError
from netlistdyn.circuit.netlist import Diagnostic, DiodeModel, Element, Kind
from netlistdyn.devices.cards import CardContext, CardLine, canonical_node, split_keywords
from netlistdyn.devices.models import (
    CELSIUS_TO_KELVIN,
    DIODE_IGNORED,
    DIODE_NEUTRAL,
    DIODE_PARAMS,
    DIODE_REFUSED,
    KNEE_EPSMIN,
)
from netlistdyn.devices.traits import DeviceKind, Family, SpiceText


def _warn_once(ctx: CardContext, note: Diagnostic) -> None:
    """Add a warning unless the same one is there (a .model's note, once for all its instances)."""
    if note not in ctx.warnings:
        ctx.warnings.append(note)


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
    mult = 1.0
    if "m" in keywords:
        mult = values.number(keywords.pop("m"), loc, f"{name} m")
        area *= mult
    temp = ctx.temp if ctx.temp is not None else 27.0
    if "temp" in keywords:
        temp = values.number(keywords.pop("temp"), loc, f"{name} temp")
    if "dtemp" in keywords:
        temp += values.number(keywords.pop("dtemp"), loc, f"{name} dtemp")
    if keywords:
        raise NetlistError(f"{name}: unsupported parameter {next(iter(keywords))}= on a diode", loc)
    if not area > 0:
        raise NetlistError(f"{name}: the area must be positive, got {area:g}", loc)
    given: dict[str, float] = {"TNOM": ctx.tnom}
    for key, text in mparams.items():
        what = f".model {mname} {key.upper()}"
        if key in DIODE_PARAMS:
            given[DIODE_PARAMS[key]] = values.number(text, mloc, what)
            if DIODE_PARAMS[key] in ("IKF", "IKR") and given[DIODE_PARAMS[key]] < KNEE_EPSMIN:
                del given[DIODE_PARAMS[key]]  # ngspice 39 disables a knee this small
                _warn_once(ctx, Diagnostic(mloc, f"{what}: too small, no knee (as ngspice 39)"))
        elif key in DIODE_IGNORED:  # no effect on op, .ac or transient (the number is still checked)
            values.number(text, mloc, what)
        elif key in DIODE_NEUTRAL:
            if values.number(text, mloc, what) != DIODE_NEUTRAL[key]:
                raise NetlistError(f"{what}: only the default {DIODE_NEUTRAL[key]:g} is supported", mloc)
        elif key in DIODE_REFUSED:
            raise NetlistError(
                f"{what}: ngspice's diode parameter is not supported (netlistdyn reads IS N RS CJO VJ M TT "
                "FC BV IBV NBV IKF IKR ISR NR EG XTI TNOM, ignores KF AF)",
                mloc,
            )
        else:  # ngspice 39: "unrecognized parameter - ignored"
            _warn_once(ctx, Diagnostic(mloc, f"{what}: not a diode parameter: ignored, as ngspice 39 does"))
    model = DiodeModel(mname, **given, temp=temp, mult=mult)
    if not (model.IS > 0 and model.N > 0 and model.RS >= 0 and model.CJO >= 0 and model.TT >= 0):
        raise NetlistError(f".model {mname}: IS and N must be positive, RS, CJO and TT not negative", mloc)
    if model.CJO > 0 and not (model.VJ > 0 and 0 < model.M < 1 and 0 <= model.FC < 1):
        raise NetlistError(f".model {mname}: needs VJ > 0, 0 < M < 1 and 0 <= FC < 1", mloc)
    if model.BV is not None and not (model.BV > 0 and model.IBV > 0 and (model.NBV or model.N) > 0):
        raise NetlistError(f".model {mname}: BV, IBV and NBV must be positive", mloc)
    if not (model.IKF > 0 and model.IKR > 0 and model.ISR >= 0 and model.NR > 0):
        raise NetlistError(f".model {mname}: IKF, IKR and NR must be positive, ISR not negative", mloc)
    if model.ISR > 0 and not model.VJ > 0:
        raise NetlistError(f".model {mname}: ISR needs VJ > 0", mloc)
    if model.temp + CELSIUS_TO_KELVIN <= 0 or model.TNOM + CELSIUS_TO_KELVIN <= 0:
        raise NetlistError(f"{name}: temperature below absolute zero", loc)
    return [Element(Kind.DIODE, name, nodes, area, loc, diode=model)]


def write_diode(circuit: Any, element: Element, text: SpiceText) -> None:
    """``D name a k dmod_name area= temp=`` with its own ``.model dmod_name D(...)``."""
    model = element.diode
    assert model is not None
    mname = f"dmod_{text.name}".replace(".", "_")
    extra: dict[str, float] = {"EG": model.EG, "XTI": model.XTI, "TNOM": model.TNOM}
    if model.BV is not None:  # ngspice 39 scales IBV by M= alone: the area factor carries M here
        extra.update(BV=model.BV, IBV=model.IBV * model.mult, NBV=model.NBV or model.N)
    extra.update({k: getattr(model, k) for k in ("IKF", "IKR") if math.isfinite(getattr(model, k))})
    if model.ISR > 0:
        extra.update(ISR=model.ISR, NR=model.NR)
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
        **extra,
    )
    circuit.D(text.name, text.plus, text.minus, model=mname, area=element.value, temperature=model.temp)


FAMILY = Family(
    (DeviceKind(Kind.DIODE, "D", 2, "area", linear=False, spice=write_diode),), {"d": build_diode}
)
