"""Mechanical elements as their electrical analogs (force–current, mobility analogy).

A node's velocity plays the node voltage and a force the current:

========================  =======================  ==========================
keyword                   analog                   state / quantity
========================  =======================  ==========================
``MASS n m``              C = m from n to ground   p = m·v, momentum (kg·m/s)
``SPRING a b k``          L = 1/k                  f = k·(x_a − x_b) (N)
``DAMPER a b d``          R = 1/d                  force d·(v_a − v_b)
``FORCE a b F``           current source b → a     pushes a, reaction on b
``VELOCITY a b v``        voltage source a − b     imposes v(a) − v(b)
``GEAR a b N``            ideal transformer        ω(a) = N ω(b), τ_b = N τ_a
``MOTOR e+ e- m Km``      ideal transformer        v = Km ω(m), τ = Km i
``ROD pivot bob l``       L = l / T (T: weight)    horizontal force (N)
``[g=9.81] [inverted]``
========================  =======================  ==========================

Rotation is the same with ``INERTIA`` (J), torsional springs, ``TORQUE``
and angular velocity. In this analogy a DC motor is a transformer, not a
gyrator: its back-emf is proportional to the across variable ω and its
torque to the through variable i.

A linearised pendulum rod is, in horizontal coordinates, a spring of
stiffness T/l between pivot and bob, where T = g × (the mass on the bob
plus everything hanging from it through further rods); ``inverted`` rods
(upright equilibrium) have stiffness −T/l.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

from netlistdyn.base.errors import NetlistError, SourceLocation
from netlistdyn.circuit.netlist import GROUND, Diagnostic, Element, Kind, RodSpec
from netlistdyn.devices.behavioural import nonlinear_behavioural
from netlistdyn.devices.cards import CardContext, CardLine, canonical_node, is_expr, unwrap
from netlistdyn.devices.models import mechanical_expression
from netlistdyn.devices.traits import Family

KEYWORDS = frozenset(
    {"mass", "inertia", "spring", "damper", "force", "torque", "velocity", "gear", "motor", "rod"}
)


def build_card(line: CardLine, ctx: CardContext) -> list[Element]:
    """One mechanical line, ``KEYWORD name nodes... value``: its analog element (:func:`build_mechanical`).

    A ``FORCE`` or ``TORQUE`` whose ``{expression}`` reads the motion is a force of the motion: a
    behavioural current source from b into a
    (:func:`~netlistdyn.devices.behavioural.nonlinear_behavioural`).
    """
    word = line.text.split(None, 1)[0]
    loc = line.loc
    values = ctx.values
    fields = ctx.fields(line)
    moving = word.lower() in ("force", "torque") and len(fields) == 5 and is_expr(fields[4])
    if moving and mechanical_expression(fields[4]):
        # a force of the motion, FORCE name a b {expr}: pushes a (current from b into a)
        a, b = canonical_node(fields[2]), canonical_node(fields[3])
        element = nonlinear_behavioural(f"{word.upper()} {fields[1]}", b, a, "i", unwrap(fields[4]), ctx, loc)
        return [replace(element, name=fields[1], keyword=word.upper())]
    return [
        build_mechanical(
            word.lower(),
            fields[1:],
            loc,
            lambda token, what: values.number(token, loc, what),
            canonical_node,
            lambda tokens, what: ctx.source(list(tokens), loc, what)[:2],
            ctx.warnings,
        )
    ]


def build_mechanical(
    keyword: str,
    fields: list[str],
    loc: SourceLocation,
    number: object,
    node: object,
    waveform: object,
    warnings: list[Diagnostic],
) -> Element:
    """Make the analog element of one mechanical line.

    Parameters
    ----------
    keyword : str
        Lower-case keyword.
    fields : list of str
        Tokens after the keyword (name, nodes, values...).
    loc : SourceLocation
    number, node, waveform : callables
        The parser's value evaluator ``number(token, what)``, node
        canonicaliser ``node(name)`` and source waveform parser
        ``waveform(tokens, name) -> (dc, waveform)``.
    warnings : list of Diagnostic
        Negative values are recorded here.
    """
    word = keyword.upper()
    if not fields:
        raise NetlistError(f"{word}: missing name", loc)
    name = fields[0]
    label = f"{word} {name}"

    def nodes(count: int) -> list[str]:
        if len(fields) < 1 + count:
            raise NetlistError(f"{label}: expected {count} node(s), got {len(fields) - 1}", loc)
        return [node(n) for n in fields[1 : 1 + count]]  # type: ignore[operator]

    def value(index: int, what: str, allow_more: bool = False) -> float:
        if len(fields) <= index:
            raise NetlistError(f"{label}: missing {what}", loc)
        if not allow_more and len(fields) > index + 1:
            raise NetlistError(f"{label}: unexpected field {fields[index + 1]!r}", loc)
        v = float(number(fields[index], label))  # type: ignore[operator]
        if v == 0:
            raise NetlistError(f"{label}: {what} is zero", loc)
        if v < 0:
            warnings.append(Diagnostic(loc, f"{label} has a negative {what} ({v:g})"))
        return v

    if keyword in ("mass", "inertia"):
        (n,) = nodes(1)
        return Element(Kind.CAPACITOR, name, (n, GROUND), value(2, word.lower()), loc, keyword=word)
    if keyword == "spring":
        a, b = nodes(2)
        return Element(Kind.INDUCTOR, name, (a, b), 1.0 / value(3, "stiffness"), loc, keyword=word)
    if keyword == "damper":
        a, b = nodes(2)
        return Element(Kind.RESISTOR, name, (a, b), 1.0 / value(3, "damping"), loc, keyword=word)
    if keyword in ("force", "torque", "velocity"):
        a, b = nodes(2)
        dc, wave = waveform(fields[3:], label)  # type: ignore[operator]
        if keyword == "velocity":
            return Element(Kind.VSOURCE, name, (a, b), dc, loc, waveform=wave, keyword=word)
        # A SPICE current source drives current out of n+ into n-: n+ = b, n- = a pushes a.
        return Element(Kind.ISOURCE, name, (b, a), dc, loc, waveform=wave, keyword=word)
    if keyword == "gear":
        a, b = nodes(2)
        return Element(Kind.TRANSFORMER, name, (a, GROUND, b, GROUND), value(3, "ratio"), loc, keyword=word)
    if keyword == "motor":
        ep, en, m = nodes(3)
        return Element(
            Kind.TRANSFORMER, name, (ep, en, m, GROUND), value(4, "motor constant Km"), loc, keyword=word
        )
    if keyword == "rod":
        pivot, bob = nodes(2)
        length = value(3, "length", allow_more=True)
        g, inverted = 9.81, False
        rest = fields[4:]
        i = 0
        while i < len(rest):
            word_i = rest[i].lower()
            if word_i in ("g", "inverted") and i + 1 < len(rest) and rest[i + 1] == "=":
                if i + 2 >= len(rest):
                    raise NetlistError(f"{label}: {word_i}= needs a value", loc)
                parsed = float(number(rest[i + 2], label))  # type: ignore[operator]
                if word_i == "g":
                    g = parsed
                else:
                    inverted = parsed != 0
                i += 3
            elif word_i == "inverted":
                inverted = True
                i += 1
            else:
                raise NetlistError(
                    f"{label}: unexpected field {rest[i]!r} (expected g=VALUE or inverted[=0|1])", loc
                )
        if length < 0:
            raise NetlistError(f"{label}: length must be positive", loc)
        if g <= 0:
            raise NetlistError(f"{label}: g must be positive", loc)
        # The inductance is set by resolve_rods once the carried weight is known.
        return Element(
            Kind.INDUCTOR, name, (pivot, bob), 1.0, loc, keyword=word, rod=RodSpec(length, g, inverted)
        )
    raise AssertionError(keyword)  # pragma: no cover


#: The mechanical cards, by keyword; their elements are the electrical analogs' kinds.
FAMILY = Family((), dict.fromkeys(sorted(KEYWORDS), build_card))


def carried_masses(elements: Sequence[Element]) -> dict[str, tuple[Element, ...]]:
    """The MASS/INERTIA elements each rod carries, by rod key.

    A rod carries the mass on its bob node plus, through further rods
    pivoted at that bob, everything hanging below.

    Raises
    ------
    NetlistError
        For rods that form a cycle.
    """
    rods = [e for e in elements if e.rod is not None]
    masses_at: dict[str, list[Element]] = {}
    for e in elements:
        if e.keyword in ("MASS", "INERTIA"):
            masses_at.setdefault(e.nodes[0], []).append(e)
    children: dict[str, list[Element]] = {}
    for rod in rods:
        children.setdefault(rod.nodes[0], []).append(rod)
    carried: dict[str, tuple[Element, ...]] = {}
    # Depth-first, with an explicit stack: a hanging chain of thousands of rods is valid input.
    for root in rods:
        if root.key in carried:
            continue
        stack = [(root, iter(children.get(root.nodes[1], [])))]
        trail = [root.key]
        while stack:
            rod, below = stack[-1]
            child = next(below, None)
            if child is None:
                stack.pop()
                trail.pop()
                bob = rod.nodes[1]
                hanging = (m for c in children.get(bob, []) for m in carried[c.key])
                carried[rod.key] = (*masses_at.get(bob, []), *hanging)
            elif child.key in trail:
                cycle = " -> ".join((*trail[trail.index(child.key) :], child.key))
                raise NetlistError(f"ROD {child.name}: rods form a cycle ({cycle})", child.loc)
            elif child.key not in carried:
                stack.append((child, iter(children.get(child.nodes[1], []))))
                trail.append(child.key)
    return carried


def resolve_rods(elements: Sequence[Element]) -> list[Element]:
    """Set each rod's tension T = g·(carried mass) and analog inductance ±l/T.

    Raises
    ------
    NetlistError
        For a rod that carries no mass and for rods that form a cycle.
    """
    if not any(e.rod is not None for e in elements):
        return list(elements)
    carried = carried_masses(elements)
    out = []
    for e in elements:
        if e.rod is None:
            out.append(e)
            continue
        mass = sum(m.value for m in carried[e.key])
        if mass == 0:
            raise NetlistError(
                f"ROD {e.name}: carries no weight (no MASS on node {e.nodes[1]!r} or below it)", e.loc
            )
        tension = e.rod.g * mass
        stiffness = (-1.0 if e.rod.inverted else 1.0) * tension / e.rod.length
        out.append(replace(e, value=1.0 / stiffness, rod=replace(e.rod, tension=tension)))
    return out


#: Keyword of the 1 F integrator named ``x(n)`` whose voltage is node n's displacement (or angle)
#: in a linearised nonlinear mechanism; its state is named ``x(n)``.
DISPLACEMENT_KEYWORD = "DISPLACEMENT"


def state_prefix(element: Element) -> str:
    """``p`` (momentum) for masses, ``f`` (force) for springs and rods, else SPICE's q/i."""
    if element.keyword in ("MASS", "INERTIA"):
        return "p"
    if element.keyword in ("SPRING", "ROD"):
        return "f"
    return "q" if element.kind is Kind.CAPACITOR else "i"
