"""Nonlinear behavioural sources (``B V=``/``I=``, ``E``/``G`` with ``value=``): v or i = f(v, i, time).

A behavioural source whose expression is linear is compiled as controlled sources
(:mod:`netlistdyn.devices.controlled`); these kinds hold the others, their expression
evaluated with its derivatives by :class:`netlistdyn.devices.models.Behaviour`.
"""

from __future__ import annotations

import itertools
import re
from collections.abc import Callable
from typing import Any

from netlistdyn.base.errors import NetlistError, SourceLocation
from netlistdyn.circuit.expressions import ExpressionError, NonlinearError, linear_form
from netlistdyn.circuit.netlist import GROUND, Diagnostic, Element, Kind
from netlistdyn.circuit.waveforms import Waveform
from netlistdyn.devices.cards import CardContext, CardLine, CardValues, canonical_node, unwrap
from netlistdyn.devices.models import Behaviour, fold
from netlistdyn.devices.traits import DeviceKind, ElementLaws, Family, SpiceText


def build_b(line: CardLine, ctx: CardContext) -> list[Element]:
    """``B name n+ n- V={expression}`` or ``I={expression}``."""
    name = line.text.split(None, 1)[0]
    found = expression_after(line, ("v", "i"), ctx)
    if found is None:
        raise NetlistError(f"{name}: expected V={{expression}} or I={{expression}}", line.loc)
    mode, expr = found
    return build_behavioural(line, mode, expr, ctx)


def poly_expression(fields: list[str], letter: str, values: CardValues, loc: SourceLocation) -> str:
    """The SPICE2 polynomial ``POLY(n) controls p0 p1 ...`` of an E/G/F/H line as an expression.

    The controls are n node pairs (E, G) or n voltage sources (F, H); the coefficients follow
    SPICE's order: p0, the n first-order terms, then every product of two controls
    (x1², x1·x2, ..., x2², ...), of three, and so on. A single coefficient is the constant p0, as
    ngspice 39 reads it (measured: ``POLY(1) a 0 2`` gives 2 V; SPICE2 read it as the gain p1).
    A first-order polynomial is compiled as controlled sources (its constant p0 as a model input);
    a higher one is a nonlinear expression.
    """
    name = fields[0]
    if len(fields) < 5:
        raise NetlistError(f"{name}: POLY needs a dimension, controls and coefficients", loc)
    dims = values.number(fields[4], loc, f"{name} POLY")
    if dims != int(dims) or not 1 <= dims <= 20:
        raise NetlistError(f"{name}: POLY({fields[4]}): the dimension must be a whole number 1..20", loc)
    n = int(dims)
    per = 2 if letter in "eg" else 1
    controls = fields[5 : 5 + per * n]
    coefficients = fields[5 + per * n :]
    if len(controls) < per * n or not coefficients:
        raise NetlistError(
            f"{name}: POLY({n}) needs {per * n} control {'nodes' if per == 2 else 'sources'} "
            "and at least one coefficient",
            loc,
        )
    if letter in "eg":
        xs = [f"v({canonical_node(controls[2 * k])},{canonical_node(controls[2 * k + 1])})" for k in range(n)]
    else:
        xs = [f"i({controls[k]})" for k in range(n)]
    coeffs = [values.number(c, loc, f"{name} POLY coefficient") for c in coefficients]
    terms: list[str] = []
    order, index = 0, 0
    while index < len(coeffs):
        for combo in itertools.combinations_with_replacement(range(n), order):
            if index == len(coeffs):
                break
            if coeffs[index] != 0:
                terms.append("*".join([f"({coeffs[index]!r})", *(xs[k] for k in combo)]))
            index += 1
        order += 1
    return " + ".join(terms) or "0"


def expression_after(line: CardLine, keys: tuple[str, ...], ctx: CardContext) -> tuple[str, str] | None:
    """The raw ``key=expression`` of a behavioural source (rest of the line)."""
    match = re.search(r"(?i)\b(" + "|".join(keys) + r")\s*=\s*", line.text)
    if match is None:
        return None
    rest = line.text[match.end() :].strip()
    if not rest:
        raise NetlistError(f"{line.text.split()[0]}: {match.group(1)}= has no expression", line.loc)
    expr = rest
    if rest[0] in "{'":
        try:
            first = ctx.split(rest)[0]
        except ValueError as exc:
            raise NetlistError(f"{line.text.split()[0]}: {exc} (ngspice refuses it too)", line.loc) from None
        expr = first
        tail = rest[len(first) :].strip()
        if tail:
            raise NetlistError(f"{line.text.split()[0]}: unexpected {tail!r} after the expression", line.loc)
    return match.group(1).lower(), unwrap(expr)


def build_behavioural(line: CardLine, mode: str, expr: str, ctx: CardContext) -> list[Element]:
    """A linear behavioural source as a sum of controlled sources.

    ``mode`` is ``"v"`` (a voltage: series chain of VCVS/CCVS through
    internal nodes ``name.n1``, ...) or ``"i"`` (a current: parallel
    VCCS/CCCS). A constant term becomes an independent source (an input of
    the model, named ``name.dc``).
    """
    fields = line.text.split()
    name = fields[0]
    loc = line.loc
    if len(fields) < 3:
        raise NetlistError(f"{name}: expected 2 nodes", loc)
    plus, minus = canonical_node(fields[1]), canonical_node(fields[2])
    try:
        form = linear_form(expr, ctx.values.params, ctx.values.functions)
    except NonlinearError:
        return [nonlinear_behavioural(name, plus, minus, mode, expr, ctx, loc)]
    except ExpressionError as exc:
        raise NetlistError(f"{name}: {exc}", loc) from None
    terms: list[tuple[Kind, float, tuple[str, str] | None, str | None]] = []
    for (what, ref), coeff in form.terms:
        if what == "v":
            terms.append(
                (Kind.VCVS if mode == "v" else Kind.VCCS, coeff, (canonical_node(ref), GROUND), None)
            )
        else:
            terms.append((Kind.CCVS if mode == "v" else Kind.CCCS, coeff, None, ref))
    constant = form.const
    if not terms and constant == 0:
        raise NetlistError(f"{name}: the expression is identically zero", loc)
    labels = [name] + [f"{name}.t{k}" for k in range(2, len(terms) + 1)]
    pieces: list[tuple[Kind, str, float, tuple[str, str] | None, str | None, Waveform | None]] = [
        (kind, label, coeff, cnodes, csource, None)
        for (kind, coeff, cnodes, csource), label in zip(terms, labels, strict=False)
    ]
    if constant != 0:
        source_kind = Kind.VSOURCE if mode == "v" else Kind.ISOURCE
        label = name if not pieces else f"{name}.dc"
        pieces.append((source_kind, label, constant, None, None, None))
        ctx.warnings.append(
            Diagnostic(
                loc,
                f"{name}: the constant term {constant:g} of its expression is a model input ({label})",
            )
        )
    if mode == "v":  # voltage pieces in series through internal nodes
        key = name.lower()
        chain = [plus] + [f"{key}.n{k}" for k in range(1, len(pieces))] + [minus]
        ends = list(itertools.pairwise(chain))
    else:  # current pieces in parallel
        ends = [(plus, minus)] * len(pieces)
    return [
        Element(
            kind,
            label,
            nodes,
            coeff,
            loc,
            control_nodes=cnodes,
            control_source=csource,
            waveform=wave,
            expression=expr,
        )
        for (kind, label, coeff, cnodes, csource, wave), nodes in zip(pieces, ends, strict=True)
    ]


def nonlinear_behavioural(
    name: str, plus: str, minus: str, mode: str, expr: str, ctx: CardContext, loc: SourceLocation
) -> Element:
    """A behavioural source whose expression is not linear: one element with the folded expression."""
    try:
        folded = fold(expr, ctx.values.params, ctx.values.functions)
        Behaviour.from_text(folded)
    except ExpressionError as exc:
        raise NetlistError(f"{name}: {exc}", loc) from None
    kind = Kind.BVOLTAGE if mode == "v" else Kind.BCURRENT
    return Element(kind, name, (plus, minus), 0.0, loc, expression=folded)


def bvoltage_law(
    element: Element, value: Callable[[Element], Any], mutual: Callable[[Element], Any]
) -> ElementLaws:
    """v − f = 0, with f in the nonlinear part of the equations."""
    return ElementLaws(v=(((element.key, 0), (element.key, 0), 1.0),))


def write_behavioural(circuit: Any, element: Element, text: SpiceText) -> None:
    """``B name n+ n− V={...}`` or ``I={...}``."""
    expression = text.expression(element.expression or "")
    key = "voltage_expression" if element.kind is Kind.BVOLTAGE else "current_expression"
    circuit.BehavioralSource(text.name, text.plus, text.minus, **{key: expression})


FAMILY = Family(
    (
        DeviceKind(
            Kind.BVOLTAGE,
            "B",
            2,
            "expression",
            linear=False,
            law=bvoltage_law,
            spice=write_behavioural,
        ),
        DeviceKind(Kind.BCURRENT, "B", 2, "expression", linear=False, spice=write_behavioural),
    ),
    {"b": build_b},
)
