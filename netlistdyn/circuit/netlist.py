"""Typed, immutable records for a parsed netlist.

The parser produces a :class:`Netlist`; every later stage reads it and none
changes it. Names keep the user's spelling for messages; ``key`` is the
case-folded name used for look-ups (SPICE is case-insensitive).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Any

from netlistdyn.base.errors import NetlistError, SourceLocation
from netlistdyn.circuit.waveforms import Waveform

GROUND = "0"


class Kind(enum.Enum):
    """Element classes, named by their SPICE letter where they have one."""

    RESISTOR = "R"
    CAPACITOR = "C"
    INDUCTOR = "L"
    VSOURCE = "V"
    ISOURCE = "I"
    VCVS = "E"
    VCCS = "G"
    CCCS = "F"
    CCVS = "H"
    COUPLING = "K"
    TRANSFORMER = "TRANSFORMER"  # ideal two-port: gears and (mobility analogy) motors
    DIODE = "D"
    BVOLTAGE = "BV"  # nonlinear behavioural voltage source (B V=, E value=)
    BCURRENT = "BI"  # nonlinear behavioural current source (B I=, G value=)
    CAPACITANCE = "CC"  # nonlinear capacitor C={expr of its voltage}: i = C(v) dv/dt
    CHARGE = "CQ"  # nonlinear capacitor Q={expr of its voltage}: i = dQ(v)/dt
    INDUCTANCE = "LL"  # nonlinear inductor L={expr of its current}: v = L(i) di/dt


#: Kinds that make a netlist nonlinear (compiled through :mod:`netlistdyn.nonlinear`).
NONLINEAR_KINDS = frozenset(
    {Kind.DIODE, Kind.BVOLTAGE, Kind.BCURRENT, Kind.CAPACITANCE, Kind.CHARGE, Kind.INDUCTANCE}
)
#: Nonlinear capacitors and inductors (``expression`` is their folded C, Q or L).
STORAGE_KINDS = frozenset({Kind.CAPACITANCE, Kind.CHARGE, Kind.INDUCTANCE})


@dataclass(frozen=True, slots=True)
class DiodeModel:
    """Parameters of a ``.model NAME D(...)`` card (ngspice's level-1 diode).

    Attributes
    ----------
    name : str
        Model name (lower case).
    IS : float
        Saturation current (A).
    N : float
        Emission coefficient.
    RS : float
        Ohmic series resistance (Ω).
    CJO : float
        Zero-bias junction capacitance (F).
    VJ : float
        Junction potential (V).
    M : float
        Grading coefficient.
    TT : float
        Transit time (s): diffusion charge TT·I.
    FC : float
        Forward-bias depletion capacitance coefficient.
    BV : float, optional
        Reverse breakdown voltage (V); ``None``: no breakdown.
    IBV : float
        Current at the breakdown voltage (A).
    NBV : float, optional
        Breakdown emission coefficient (``None``: N).
    IKF, IKR : float
        Forward and reverse high-injection knee currents (A); ``inf``: none.
    ISR : float
        Recombination saturation current (A).
    NR : float
        Recombination emission coefficient.
    EG : float
        Activation energy (eV).
    XTI : float
        Saturation-current temperature exponent.
    TNOM : float
        Temperature the parameters were measured at (°C): the card's, else ``.options tnom``.
    temp : float
        The circuit temperature this instance sees (°C): ``.temp`` / ``.options temp``.
    mult : float
        The instance's multiplier M= (ngspice 39 scales IBV by it; the area factor includes it).
    """

    name: str
    IS: float = 1e-14
    N: float = 1.0
    RS: float = 0.0
    CJO: float = 0.0
    VJ: float = 1.0
    M: float = 0.5
    TT: float = 0.0
    FC: float = 0.5
    BV: float | None = None
    IBV: float = 1e-3
    NBV: float | None = None
    IKF: float = math.inf
    IKR: float = math.inf
    ISR: float = 0.0
    NR: float = 2.0
    EG: float = 1.11
    XTI: float = 3.0
    TNOM: float = 27.0
    temp: float = 27.0
    mult: float = 1.0


@dataclass(frozen=True, slots=True)
class RodSpec:
    """Geometry of a pendulum rod (``ROD name pivot bob length [g=] [inverted]``).

    Attributes
    ----------
    length : float
        Rod length (m).
    g : float
        Gravitational acceleration (m/s²).
    inverted : bool
        Linearised about the upright equilibrium (negative stiffness).
    tension : float
        Weight carried (N), filled in once the masses are known.
    """

    length: float
    g: float = 9.81
    inverted: bool = False
    tension: float = 0.0


@dataclass(frozen=True, slots=True)
class Element:
    """One netlist element.

    Attributes
    ----------
    kind : Kind
        Element class.
    name : str
        Name as written in the netlist (``R1``, ``MASS m1`` → ``m1``).
    nodes : tuple of str
        Canonical node names, ``(n+, n-)``; four for a transformer
        ``(p1+, p1-, p2+, p2-)``; empty for a coupling.
    value : float
        Resistance (Ω), capacitance (F), inductance (H), gain (V/V, A/V,
        A/A, V/A), coupling coefficient, transformer ratio, or a source's DC
        value (V or A).
    loc : SourceLocation
        Where it was defined.
    control_nodes : tuple of str, optional
        Controlling node pair of an E or G source.
    control_source : str, optional
        Key of the voltage source whose current controls an F or H source.
    coupled : tuple of str, optional
        Keys of the two inductors a K element couples.
    waveform : Waveform, optional
        Transient waveform of an independent source (``None``: DC value).
    keyword : str, optional
        Mechanical keyword (``MASS``, ``SPRING``...) the element came from.
    rod : RodSpec, optional
        For ``ROD`` elements: length, g and orientation.
    ic : float, optional
        ``IC=`` of a capacitor (V) or inductor (A): its initial state for
        ``simulate`` and ``validate`` (``None``: not given).
    expression : str, optional
        For elements compiled from a behavioural source (``B``, or ``E``/``G``
        with ``value=``/``vol=``/``cur=``): the source's expression text, in
        which this element is one linear term; for ``BVOLTAGE``/``BCURRENT``
        the whole (nonlinear) expression; for ``CAPACITANCE``, ``CHARGE`` and
        ``INDUCTANCE`` the folded C(v) (F), Q(v) (C) or L(i) (H).
    diode : DiodeModel, optional
        For a ``DIODE``: its model (``value`` is then the area factor).
    """

    kind: Kind
    name: str
    nodes: tuple[str, ...]
    value: float
    loc: SourceLocation
    control_nodes: tuple[str, str] | None = None
    control_source: str | None = None
    coupled: tuple[str, str] | None = None
    waveform: Waveform | None = None
    keyword: str | None = None
    rod: RodSpec | None = None
    ic: float | None = None
    expression: str | None = None
    diode: DiodeModel | None = None

    @property
    def key(self) -> str:
        """Case-folded name for look-ups."""
        return self.name.lower()

    @property
    def label(self) -> str:
        """How messages refer to the element: ``R1`` or ``SPRING k1``."""
        return f"{self.keyword} {self.name}" if self.keyword else self.name

    @property
    def is_source(self) -> bool:
        """True for independent sources (the model's inputs)."""
        return self.kind in (Kind.VSOURCE, Kind.ISOURCE)


@dataclass(frozen=True, slots=True)
class TranSpec:
    """A ``.tran TSTEP TSTOP [TSTART [TMAX]] [UIC]`` directive (s).

    ``uic``: start from the initial conditions (element ``IC=``, ``.ic``; else zero) instead of
    the DC operating point (see :mod:`netlistdyn.initial`).
    """

    tstep: float
    tstop: float
    tstart: float = 0.0
    tmax: float | None = None
    loc: SourceLocation | None = None
    uic: bool = False


@dataclass(frozen=True, slots=True)
class InitialCondition:
    """One ``.ic v(node)=value`` entry: a node voltage at t = 0 (V).

    Attributes
    ----------
    node : str
        Canonical node name.
    value : float
        Voltage (V).
    loc : SourceLocation
        Where it was given.
    """

    node: str
    value: float
    loc: SourceLocation


@dataclass(frozen=True, slots=True)
class StepSpec:
    """A ``.step param NAME ...`` directive: the values to sweep a parameter over.

    Attributes
    ----------
    param : str
        Lower-case parameter name (defined by ``.param``).
    values : tuple of float
        The values, in order.
    loc : SourceLocation
        Where it was given.
    """

    param: str
    values: tuple[float, ...]
    loc: SourceLocation


@dataclass(frozen=True, slots=True)
class Diagnostic:
    """A warning tied to a place in the netlist."""

    loc: SourceLocation
    message: str

    def __str__(self) -> str:
        return f"{self.loc}: warning: {self.message}"


@dataclass(frozen=True, slots=True)
class Netlist:
    """A parsed, flattened, fully evaluated netlist.

    Attributes
    ----------
    title : str
        First line of the file.
    path : str
        File it was read from.
    elements : tuple of Element
        In file order.
    params : dict
        Final parameter values (lower-case names).
    tran : TranSpec, optional
        The ``.tran`` directive, if any.
    warnings : tuple of Diagnostic
        Things the user should know that did not stop compilation.
    initial_conditions : tuple of InitialCondition
        ``.ic v(n)=...`` entries (node voltages at t = 0); element ``IC=``
        values are on the elements.
    steps : tuple of StepSpec
        ``.step param`` sweeps (LTspice), in file order.
    planar : tuple
        The planar-mechanism cards (:class:`netlistdyn.devices.planar.PlanarCard`), in file
        order; a netlist with them is compiled by :mod:`netlistdyn.formulation.planar`.
    """

    title: str
    path: str
    elements: tuple[Element, ...]
    params: dict[str, float] = field(default_factory=dict)
    tran: TranSpec | None = None
    warnings: tuple[Diagnostic, ...] = ()
    initial_conditions: tuple[InitialCondition, ...] = ()
    steps: tuple[StepSpec, ...] = ()
    planar: tuple[Any, ...] = ()

    def step_cases(self, limit: int = 100_000) -> list[dict[str, float]]:
        """The parameter cases of the ``.step param`` lines: every combination, in order.

        Raises
        ------
        NetlistError
            When the combinations are more than ``limit``.
        """
        cases: list[dict[str, float]] = [{}]
        for step in self.steps:
            if len(cases) * len(step.values) > limit:
                raise NetlistError(f".step: more than {limit} cases", step.loc)
            cases = [{**case, step.param: value} for case in cases for value in step.values]
        return cases if self.steps else []

    @property
    def is_nonlinear(self) -> bool:
        """True when some element is a diode, a nonlinear behavioural source, capacitor or inductor."""
        return any(e.kind in NONLINEAR_KINDS for e in self.elements)

    def element(self, key: str) -> Element:
        """The element with this (case-insensitive) name."""
        lowered = key.lower()
        for elem in self.elements:
            if elem.key == lowered:
                return elem
        raise KeyError(key)

    @property
    def sources(self) -> tuple[Element, ...]:
        """Independent sources in file order: the model's inputs."""
        return tuple(e for e in self.elements if e.is_source)

    @property
    def nodes(self) -> tuple[str, ...]:
        """Node names in order of first appearance, ground excluded."""
        seen: dict[str, None] = {}
        for elem in self.elements:
            for node in elem.nodes:
                if node != GROUND:
                    seen.setdefault(node, None)
        return tuple(seen)
