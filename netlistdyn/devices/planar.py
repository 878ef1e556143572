"""Planar-mechanism cards: points, bodies, rods, joints, springs, dampers, gravity and loads in a plane.

These cards describe a mechanism by its geometry, and :mod:`netlistdyn.formulation.planar`
compiles them to the exact equations of motion M(q) q'' = Q(q, q', u) (no small-angle step).
They are a family of their own, beside the linearised one-dimensional cards of
:mod:`netlistdyn.devices.mechanics` (``MASS``, ``ROD``...): a netlist uses one family or the other.

=====================================  ===================================================================
card                                   meaning
=====================================  ===================================================================
``GRAVITY g [angle=-90]``              gravity of g (m/s²) pointing at ``angle`` (degrees from +x)
``FIXED name x y``                     a fixed point at (x, y) (m); ``0`` is a fixed point at (0, 0)
``BODY name point m [J=0]``            a mass m (kg) centred on ``point``, inertia J (kg·m²) about it,
                                       turning with the rod or slider that places the point
``LINK name a b l [hanging|upright]``  a revolute joint at point ``a`` and a massless rigid rod of
                                       length l (m) from it to the new point ``b``; coordinate
                                       ``angle(name)`` (rad), from the vertical (down along gravity
                                       when ``hanging``, the default; up when ``upright`` or
                                       ``upright=1``), positive when ``b`` is on the +x side of ``a``
``SLIDER name base point [angle=0]``   a prismatic joint: ``point`` slides on the line through
``       [s0=0]``                      ``base`` at ``angle`` (degrees, in ``base``'s frame); it sits
                                       at s0 + x(point) along it (m); coordinate ``x(point)``
``PSPRING name a b k [l0=]``           a spring k (N/m) along the line a–b, rest length l0 (m;
                                       default: the distance at q = 0)
``PDAMPER name a b d``                 a damper d (N·s/m) along the line a–b
``PFORCE name point [angle=0] wave``   a force of size wave(t) (N, a SPICE source value or
                                       waveform) on ``point`` at ``angle`` (degrees from +x)
``PTORQUE name link wave``             a torque wave(t) (N·m, counter-clockwise) on the link's rod
=====================================  ===================================================================

Every joint places exactly one point, so the joints form a tree rooted at the fixed points;
a joint that would place a point a second time closes a kinematic loop, which is refused
(:func:`mechanism_tree`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from netlistdyn.base.errors import NetlistError, SourceLocation
from netlistdyn.circuit.netlist import GROUND

#: Card keywords of the planar family (first word of a line, case-insensitive).
PLANAR_KEYWORDS = frozenset(
    {"gravity", "fixed", "body", "link", "slider", "pspring", "pdamper", "pforce", "ptorque"}
)
#: Default gravity direction (degrees from +x): straight down.
DOWN_DEGREES = -90.0


@dataclass(frozen=True, slots=True)
class PlanarCard:
    """One planar card, its values evaluated.

    Attributes
    ----------
    keyword : str
        Lower-case card keyword (``link``, ``slider``...).
    name : str
        The card's name as written (``gravity`` for the GRAVITY card).
    points : tuple of str
        Lower-case point names it connects (``0`` is the fixed origin).
    value : float
        Its main number: g (m/s²), mass (kg), length (m), stiffness (N/m), damping (N·s/m),
        or a load's DC value (N, N·m).
    inertia : float
        A BODY's moment of inertia about its centre (kg·m²).
    rest : float or None
        A PSPRING's rest length (m); None: its length at q = 0.
    angle : float
        Direction (rad): gravity's, a slider's track (in its base's frame), a force's (world).
    position : tuple of float
        A FIXED point's (x, y) (m); a SLIDER's (s0, 0) offset along its track.
    upright : bool
        A LINK's angle is measured from the upward vertical.
    waveform : object or None
        A load's SPICE waveform (None: constant ``value``).
    loc : SourceLocation
    """

    keyword: str
    name: str
    points: tuple[str, ...]
    value: float
    loc: SourceLocation
    inertia: float = 0.0
    rest: float | None = None
    angle: float = 0.0
    position: tuple[float, float] = (0.0, 0.0)
    upright: bool = False
    waveform: Any = None

    @property
    def label(self) -> str:
        """How messages name the card: ``LINK r1`` (``GRAVITY``)."""
        return "GRAVITY" if self.keyword == "gravity" else f"{self.keyword.upper()} {self.name}"

    @property
    def key(self) -> str:
        """Case-folded name."""
        return self.name.lower()


def _point(name: str) -> str:
    low = name.lower()
    return GROUND if low in ("0", "gnd") else low


def build_planar(
    keyword: str,
    fields: Sequence[str],
    loc: SourceLocation,
    number: Callable[[str, str], float],
    waveform: Callable[[Sequence[str], str], tuple[float, Any]],
) -> PlanarCard:
    """Make the card of one planar line.

    Parameters
    ----------
    keyword : str
        Lower-case keyword (one of :data:`PLANAR_KEYWORDS`).
    fields : sequence of str
        Tokens after the keyword (``key = value`` as three tokens).
    loc : SourceLocation
    number : callable
        The parser's evaluator ``number(token, what)`` (``.param`` names and expressions).
    waveform : callable
        The parser's source reader ``waveform(tokens, what) -> (dc, waveform)``.

    Raises
    ------
    NetlistError
        Missing or surplus fields, a non-positive length, mass or gravity, a negative
        stiffness, damping or inertia.
    """
    word = keyword.upper()
    fields = list(fields)
    if keyword == "gravity":
        fields = ["gravity", *fields]
    if not fields:
        raise NetlistError(f"{word}: missing name", loc)
    name = fields[0]
    label = f"{word} {name}"
    positional: list[str] = []
    options: dict[str, str] = {}
    flags: list[str] = []
    i = 1
    loads = keyword in ("pforce", "ptorque")
    while i < len(fields):
        if i + 1 < len(fields) and fields[i + 1] == "=":
            if i + 2 >= len(fields):
                raise NetlistError(f"{label}: {fields[i]}= needs a value", loc)
            options[fields[i].lower()] = fields[i + 2]
            i += 3
        elif fields[i].lower() in ("upright", "hanging") and keyword == "link":
            flags.append(fields[i].lower())
            i += 1
        elif loads and positional:  # the rest is the waveform (options come before it)
            positional.extend(fields[i:])
            break
        else:
            positional.append(fields[i])
            i += 1

    def value(text: str, what: str) -> float:
        v = float(number(text, label))
        if not math.isfinite(v):
            raise NetlistError(f"{label}: {what} is not finite", loc)
        return v

    def option(key: str, default: float, what: str) -> float:
        return value(options.pop(key), what) if key in options else default

    def expect(count: int, what: str) -> list[str]:
        if len(positional) < count:
            raise NetlistError(f"{label}: expected {what}", loc)
        if len(positional) > count:
            raise NetlistError(f"{label}: unexpected field {positional[count]!r}", loc)
        return positional

    def done(card: PlanarCard) -> PlanarCard:
        if options:
            raise NetlistError(f"{label}: unknown option {next(iter(options))}=", loc)
        return card

    if keyword == "gravity":
        (g_text,) = expect(1, "GRAVITY g [angle=DEG]")
        g = value(g_text, "g")
        if g < 0:
            raise NetlistError(f"{label}: g must not be negative, got {g:g}", loc)
        angle = math.radians(option("angle", DOWN_DEGREES, "angle"))
        return done(PlanarCard(keyword, name, (), g, loc, angle=angle))
    if keyword == "fixed":
        x, y = expect(2, "FIXED name x y")
        return done(
            PlanarCard(keyword, name, (_point(name),), 0.0, loc, position=(value(x, "x"), value(y, "y")))
        )
    if keyword == "body":
        point, m = expect(2, "BODY name point m [J=J]")
        mass = value(m, "mass")
        inertia = option("j", 0.0, "J")
        if mass < 0 or inertia < 0:
            raise NetlistError(f"{label}: mass and J must not be negative", loc)
        return done(PlanarCard(keyword, name, (_point(point),), mass, loc, inertia=inertia))
    if keyword == "link":
        a, b, length_text = expect(3, "LINK name a b length [hanging|upright]")
        length = value(length_text, "length")
        if not length > 0:
            raise NetlistError(f"{label}: a rod's length must be positive, got {length:g}", loc)
        if "upright" in options:  # upright={inv}: a .param chooses the convention
            flags.append("upright" if value(options.pop("upright"), "upright") != 0 else "hanging")
        if len(set(flags)) > 1:
            raise NetlistError(f"{label}: hanging or upright, not both", loc)
        if _point(b) == GROUND:
            raise NetlistError(f"{label}: its end {b} is the fixed origin", loc)
        return done(
            PlanarCard(keyword, name, (_point(a), _point(b)), length, loc, upright="upright" in flags)
        )
    if keyword == "slider":
        base, point = expect(2, "SLIDER name base point [angle=DEG] [s0=M]")
        angle = math.radians(option("angle", 0.0, "angle"))
        s0 = option("s0", 0.0, "s0")
        if _point(point) == GROUND:
            raise NetlistError(f"{label}: its point {point} is the fixed origin", loc)
        return done(
            PlanarCard(
                keyword, name, (_point(base), _point(point)), 0.0, loc, angle=angle, position=(s0, 0.0)
            )
        )
    if keyword in ("pspring", "pdamper"):
        what = "stiffness" if keyword == "pspring" else "damping"
        a, b, v = expect(3, f"{word} name a b {what}" + (" [l0=M]" if keyword == "pspring" else ""))
        k = value(v, what)
        if k < 0:
            raise NetlistError(f"{label}: {what} must not be negative, got {k:g}", loc)
        if _point(a) == _point(b):
            raise NetlistError(f"{label}: both ends are the point {a}", loc)
        rest = None
        if keyword == "pspring" and "l0" in options:
            rest = value(options.pop("l0"), "l0")
            if rest < 0:
                raise NetlistError(f"{label}: rest length must not be negative, got {rest:g}", loc)
        return done(PlanarCard(keyword, name, (_point(a), _point(b)), k, loc, rest=rest))
    if keyword in ("pforce", "ptorque"):
        if not positional:
            raise NetlistError(f"{label}: expected a {'point' if keyword == 'pforce' else 'link'}", loc)
        target, wave_tokens = positional[0], positional[1:]
        angle = math.radians(option("angle", 0.0, "angle")) if keyword == "pforce" else 0.0
        if options:
            raise NetlistError(f"{label}: unknown option {next(iter(options))}=", loc)
        dc, wave = waveform(wave_tokens, label)
        points = (_point(target),)
        return PlanarCard(keyword, name, points, float(dc), loc, angle=angle, waveform=wave)
    raise AssertionError(keyword)  # pragma: no cover
