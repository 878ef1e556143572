"""What a device kind is, as one record: the traits every stage looks up in the registry.

ngspice keeps each device in its own folder (its parameter table, load, setup and ask
functions) and lists the folders in one device table; Xyce gives each device a traits record
(name, node count, primary parameter, linear or not). Here each device family's module
(:mod:`netlistdyn.devices.passive`, :mod:`~netlistdyn.devices.sources`, ...) states one
:class:`DeviceKind` per :class:`~netlistdyn.circuit.netlist.Kind`, and
:mod:`netlistdyn.devices.registry` collects them. The small data types those functions
produce live here, below the stages that consume them: :class:`ElementLaws` (a branch law,
read by the tree/cotree formulation and the nonlinear modified nodal equations),
:class:`Mna` (the stamps of the sparse descriptor system) and :class:`SpiceText` (what the
ngspice writer hands a device).
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, NamedTuple

from netlistdyn.circuit.netlist import Element, Kind
from netlistdyn.devices.cards import CardBuilder


class Role(enum.IntEnum):
    """Tree priority of a branch (lower goes into the tree first)."""

    VSOURCE = 0
    VTYPE = 1  # controlled voltage port (E, H) or transformer port taken as voltage-defined
    CAPACITOR = 2
    RESISTOR = 3
    INDUCTOR = 4
    ITYPE = 5  # controlled current port (G, F) or transformer port taken as current-defined
    ISOURCE = 6


#: A branch of one element: ``(element key, port)``; port 0, or 0 and 1 for a transformer's ports.
BranchRef = tuple[str, int]


class ElementLaws(NamedTuple):
    """One element's constitutive equations, in the quantities of named branches.

    The same six fields as :class:`~netlistdyn.formulation.formulate.BranchLaws` (tuples), with
    :data:`BranchRef` rows and columns in place of branch indices: row ``(key, port)`` is that
    branch's law; a ``v``/``i``/``dv``/``di`` column names the branch whose
    voltage or current the coefficient multiplies (its own or another's:
    a transformer's other port, an F/H source's controlling element, a
    coupled inductor); a ``u`` column is the key of the independent source.
    """

    v: tuple[tuple[BranchRef, BranchRef, Any], ...] = ()
    i: tuple[tuple[BranchRef, BranchRef, Any], ...] = ()
    dv: tuple[tuple[BranchRef, BranchRef, Any], ...] = ()
    di: tuple[tuple[BranchRef, BranchRef, Any], ...] = ()
    control: tuple[tuple[BranchRef, tuple[str, str], Any], ...] = ()
    u: tuple[tuple[BranchRef, str, Any], ...] = ()


#: ``law(element, value, mutual)``: the element's :class:`ElementLaws`; ``value(element)`` is an
#: element's value (a float or a symbol), ``mutual(coupling)`` a K element's mutual inductance (H).
Law = Callable[[Element, Callable[[Element], Any], Callable[[Element], Any]], ElementLaws]


class Triplets:
    """Growing COO lists for one sparse matrix (rows or columns < 0 are ground: dropped)."""

    def __init__(self) -> None:
        self.rows: list[int] = []
        self.cols: list[int] = []
        self.vals: list[float] = []

    def add(self, row: int, col: int, value: float) -> None:
        if row >= 0 and col >= 0:
            self.rows.append(row)
            self.cols.append(col)
            self.vals.append(value)

    def branch(self, a: int, b: int, col_a: int, col_b: int, value: float) -> None:
        """The 2x2 stamp ``value·[[1, −1], [−1, 1]]`` on rows (a, b), columns (col_a, col_b)."""
        self.add(a, col_a, value)
        self.add(a, col_b, -value)
        self.add(b, col_a, -value)
        self.add(b, col_b, value)


@dataclass(frozen=True)
class Mna:
    """Where a device stamps itself into ``E x' = A x + B u`` (modified nodal analysis).

    Attributes
    ----------
    index : mapping
        Unknown of each node voltage (ground: −1, which :meth:`Triplets.add` drops).
    branch_of : mapping
        Unknown of each current that is one (element key): inductors, V, E and H sources.
    inductance : mapping
        Each inductor's inductance (H) by key, for the couplings.
    source_col : mapping
        Column of ``B`` of each independent source (element key).
    E, A, B : Triplets
        The three matrices being assembled.
    """

    index: Mapping[str, int]
    branch_of: Mapping[str, int]
    inductance: Mapping[str, float]
    source_col: Mapping[str, int]
    E: Triplets
    A: Triplets
    B: Triplets

    def ends(self, element: Element) -> tuple[int, int]:
        """The unknowns of a two-terminal element's n+ and n− (−1 for ground and for a coupling)."""
        nodes = element.nodes
        return (self.index[nodes[0]], self.index[nodes[1]]) if len(nodes) == 2 else (-1, -1)

    def current(self, element: Element) -> int:
        """Stamp the KCL columns and branch-row incidences of ``element``'s current unknown; its index."""
        a, b = self.ends(element)
        k = self.branch_of[element.key]
        self.A.add(a, k, -1.0)
        self.A.add(b, k, 1.0)
        self.A.add(k, a, 1.0)
        self.A.add(k, b, -1.0)
        return k


#: ``stamp(element, mna)``: add the element's entries to the descriptor system.
Stamp = Callable[[Element, Mna], None]

#: ``current(element, mna, row, C, D)``: add the element's current (A) as output ``row`` of
#: ``y = C x + D u`` (for an element whose current is not an unknown).
Current = Callable[[Element, Mna, int, Triplets, Triplets], None]


@dataclass(frozen=True)
class SpiceText:
    """What the ngspice writer gives a device to write itself into a PySpice ``Circuit``.

    Attributes
    ----------
    name : str
        The element's ngspice name without its letter (PySpice adds it).
    plus, minus : Any
        Its first two nodes as PySpice takes them (``0`` for ground); an ammeter may sit in series.
    name_of : callable
        ``name_of(key)``: another element's full ngspice name (a controlling source, an inductor).
    expression : callable
        ``expression(text)``: a folded expression in ngspice's names.
    node : callable
        ``node(name)``: a node as PySpice takes it.
    span : tuple of float
        TSTEP and TSTOP that fill a waveform's SPICE defaults (s).
    ac : bool
        The source is given ``AC 1``.
    """

    name: str
    plus: Any
    minus: Any
    name_of: Callable[[str], str]
    expression: Callable[[str], str]
    node: Callable[[str], Any]
    span: tuple[float, float]
    ac: bool = False


#: ``write(circuit, element, text)``: add the element to a PySpice ``Circuit``.
Writer = Callable[[Any, Element, SpiceText], None]


@dataclass(frozen=True)
class DeviceKind:
    """The traits of one element kind: what each stage needs to know of it.

    Attributes
    ----------
    kind : Kind
        The element class it describes (the data tag in :class:`~netlistdyn.circuit.netlist.Element`;
        any other enum member for a kind registered outside the package, as a test's).
    letter : str
        Its letter in an ngspice netlist (``R``; ``E`` for a transformer, written as an E and an F).
    nodes : int
        Node count (0: a coupling; 4: a transformer's two ports).
    value : str
        What ``Element.value`` is (``resistance``, ``gain``...).
    unit : str
        The unit of that value when it does not depend on the circuit (Ω, F, H), else ``""``.
    role : Role or None
        Tree priority of its branch (None: no branch of its own, or a transformer's two ports).
    linear : bool
        Its law is linear (it compiles without an operating point).
    branch_current : bool
        Its current is an unknown of the modified nodal equations (and ngspice has it as a branch).
    law : callable or None
        Its constitutive equations (:data:`Law`); None when they are wholly nonlinear.
    stamp : callable or None
        Its stamp into the sparse descriptor system (:data:`Stamp`); None: not supported there.
    current : callable or None
        Its current as an output of the descriptor system, when it is not an unknown
        (:data:`Current`); None: not available there (a capacitor's).
    spice : callable or None
        How it is written for ngspice (:data:`Writer`).
    """

    kind: Kind | enum.Enum
    letter: str
    nodes: int
    value: str
    unit: str = ""
    role: Role | None = None
    linear: bool = True
    branch_current: bool = False
    law: Law | None = None
    stamp: Stamp | None = None
    spice: Writer | None = None
    current: Current | None = None


@dataclass(frozen=True)
class Family:
    """What one device module registers: its kinds' records and its cards' syntax.

    Attributes
    ----------
    devices : tuple of DeviceKind
        One record per element kind of the family.
    cards : mapping
        The builder of each netlist line the family reads, by its first letter (lower case):
        ``build(line, ctx)`` returns the line's elements (:mod:`netlistdyn.devices.cards`).
    """

    devices: tuple[DeviceKind, ...]
    cards: Mapping[str, CardBuilder] = field(default_factory=dict)
