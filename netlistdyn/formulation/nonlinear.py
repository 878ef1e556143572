"""Nonlinear netlists: residual and Jacobian, operating point, linearisation.

The circuit is written as modified nodal equations ``F(z) = G z − b + N(z) = 0``
in the node voltages and some branch currents. The linear part ``G z − b``
comes from the same per-element laws as the linear compiler
(:func:`netlistdyn.formulation.formulate.element_laws`): a branch whose law is explicit
in its own current, without derivatives, and whose current nothing reads is
solved for it and put into KCL (a resistor's conductance, a G or F source, a
current source); every other branch (voltage sources, inductors, capacitors,
E and H sources, a transformer's first port, any element whose current an
expression or an F/H source reads) keeps its current as an unknown and its
law as that unknown's row. A diode's RS is a resistor's law, its junction
charge a capacitor's. ``N(z)`` holds what is not linear — diode currents and
behavioural sources, with their exact derivatives
(:mod:`netlistdyn.devices`).

Two modes share the laws:

- ``dc``: the laws without their derivative terms — capacitors open,
  inductors short (the operating point);
- ``state``: each storage branch's law is replaced by its state — a capacitor's charge fixes its voltage
  (q/C, or the voltage whose charge is q for a ``C=``/``Q=`` capacitor,
  :class:`Storage`), an inductor's current is a current source, a diode's
  junction charge fixes its junction voltage — and the network is resistive. Solving it
  gives ``x' = f(x, u, t)`` (:mod:`netlistdyn.nltransient`), with the same
  charges and currents as states as the linear compiler.

The operating point is found as SPICE finds it: Newton's method with
junction-voltage limiting, then gmin stepping, then source stepping.
:func:`linearise` turns the netlist into a *linear* netlist at a point —
a diode becomes its small-signal conductance and incremental capacitance, a
behavioural source the sum of controlled sources given by its partial
derivatives — which :mod:`netlistdyn.formulate` compiles into A, B, C, D with
the usual named states (now deviations from the point).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray
from scipy.integrate import IntegrationWarning, quad

from netlistdyn.base.errors import NetlistError, SourceLocation
from netlistdyn.circuit.checks import VOLTAGE_KINDS, voltage_loop
from netlistdyn.circuit.expressions import ExpressionError
from netlistdyn.circuit.netlist import GROUND, STORAGE_KINDS, Element, Kind, Netlist
from netlistdyn.devices.mechanics import state_prefix
from netlistdyn.devices.models import (
    DISPLACEMENT,
    Behaviour,
    Junction,
    diode_charge_array,
    junction,
    junction_arrays,
    junction_charge,
    junction_current,
    junction_current_array,
)
from netlistdyn.devices.registry import REGISTRY
from netlistdyn.devices.traits import BranchRef, ElementLaws
from netlistdyn.formulation.formulate import _numeric_mutual, element_laws

#: Relative Newton step at which the solution is converged (then one more step polishes it).
NEWTON_RTOL = 1e-13
#: Absolute floors of the step test: voltages (V) and currents (A).
NEWTON_VNTOL = 1e-15
NEWTON_ABSTOL = 1e-21
#: Newton iterations allowed per solve.
MAX_ITERATIONS = 200
#: Up to this many unknowns the Newton step is a dense solve (faster than a sparse LU).
DENSE_LIMIT = 60
#: Capacitors (state: charge) and inductors (state: current), linear or not.
CAPACITOR_KINDS = (Kind.CAPACITOR, Kind.CAPACITANCE, Kind.CHARGE)
INDUCTOR_KINDS = (Kind.INDUCTOR, Kind.INDUCTANCE)
#: Relative accuracy of the charge ∫ C(v) dv of a ``C={expr}`` capacitor (adaptive Gauss–Kronrod).
QUAD_RTOL = 1e-13


class NoOperatingPoint(NetlistError):
    """Newton's method, gmin stepping and source stepping all failed."""


@dataclass(frozen=True)
class OperatingPoint:
    """A solution of the DC (or given-state) equations.

    Attributes
    ----------
    voltages : dict
        Node voltage (V) by node name, ground excluded, internal nodes included.
    currents : dict
        Branch current (A) by element key: from n+ through the element to n−.
    inputs : dict
        The independent sources' values (V or A) by name.
    iterations : int
        Newton iterations in all (every continuation step included).
    residual : float
        Largest |F| of the final equations (A on node rows, V on branch rows).
    method : str
        ``newton``, ``gmin stepping`` or ``source stepping``.
    z : ndarray
        The unknown vector (internal use).
    """

    voltages: dict[str, float]
    currents: dict[str, float]
    inputs: dict[str, float]
    iterations: int
    residual: float
    method: str
    z: NDArray[np.float64] = field(repr=False, compare=False)
    displacements: dict[str, float] = field(default_factory=dict)
    """Displacement or angle x(n) (m or rad) of each node an expression reads it at."""
    drift: dict[str, float] = field(default_factory=dict)
    """With states held by ``--at``: the derivative x' = f(x0, u0) of each state that is not zero
    (empty at an equilibrium)."""


@dataclass(frozen=True)
class _Diode:
    element: Element
    anode: int | None  # junction anode (the internal node when RS > 0)
    cathode: int | None
    isat: float
    n: float
    charge_branch: int | None
    cjo: float
    junction: Junction


@dataclass(frozen=True)
class _Behavioural:
    element: Element
    behaviour: Behaviour
    plus: int | None
    minus: int | None
    branch: int | None  # voltage sources: their current unknown
    refs: tuple[int | None, ...]  # unknown index of each variable (None: time)


class Storage:
    """A nonlinear capacitor (``C={expr}``, ``Q={expr}``) or inductor (``L={expr}``).

    ngspice 39 reads ``C={C(v)}`` as i = C(v)·dv/dt (an incremental
    capacitance), ``Q={Q(v)}`` as i = dQ(v)/dt and ``L={L(i)}`` as
    v = L(i)·di/dt (measured with ``ngspice -b``). The expression may read
    only the element's own voltage (capacitors) or, for an inductor, the
    current ``i(Vx)`` of a voltage source in series with it (ngspice has no
    vector for the inductor's own current once the value is an expression).

    A capacitor's state is its charge q(v) = ∫₀^v C(u) du (``C=``: by
    adaptive quadrature; ``Q=``: Q(v) − Q(0)); an inductor's state is its
    current, as for a linear inductor.

    Parameters
    ----------
    element : Element
    keyed : Mapping
        Every element of the netlist by key (an inductor's series source).
    netlist : Netlist

    Raises
    ------
    NetlistError
        The expression reads anything else.
    """

    def __init__(self, element: Element, keyed: Mapping[str, Element], netlist: Netlist) -> None:
        self.element = element
        e = element
        assert e.expression is not None
        try:
            self.behaviour = Behaviour.from_text(e.expression)
        except ExpressionError as exc:
            raise NetlistError(f"{e.name}: {exc}", e.loc) from None
        names = self.behaviour.variables
        self.capacitor = e.kind is not Kind.INDUCTANCE
        what = {Kind.CAPACITANCE: "C=", Kind.CHARGE: "Q=", Kind.INDUCTANCE: "L="}[e.kind]
        #: value of each variable per unit of the element's own voltage (V) or current (A)
        self.weights = np.zeros(len(names))
        if self.capacitor:
            own = {("v", e.nodes[0]): 1.0, ("v", e.nodes[1]): -1.0}
            if not names or any(key not in own for key in names):
                raise NetlistError(
                    f"{e.name}: {what}{{...}} may read only its own voltage v({e.nodes[0]},{e.nodes[1]}) "
                    "(a capacitance of time or of other variables has no charge state)",
                    e.loc,
                )
            if len(names) == 2:
                if not self._difference_only(np.array([own[key] for key in names])):
                    raise NetlistError(
                        f"{e.name}: {what}{{...}} must depend on v({e.nodes[0]})-v({e.nodes[1]}) only", e.loc
                    )
                self.weights[:] = [max(own[key], 0.0) for key in names]
            elif GROUND in e.nodes:
                self.weights[0] = own[names[0]]
            else:
                raise NetlistError(
                    f"{e.name}: {what}{{...}} reads one end of a floating capacitor; "
                    f"write v({e.nodes[0]},{e.nodes[1]})",
                    e.loc,
                )
        else:
            sense = keyed.get(names[0][1]) if len(names) == 1 and names[0][0] == "i" else None
            sign = _series_sign(sense, e, netlist) if sense is not None else None
            if sign is None:
                raise NetlistError(
                    f"{e.name}: L={{...}} may read only i(Vx) of a voltage source Vx in series with it "
                    "(as ngspice's manual writes it)",
                    e.loc,
                )
            self.weights[0] = sign
        self._cache: dict[float, tuple[float, float]] = {}
        self._last_v = 0.0

    def _difference_only(self, signs: NDArray[np.float64]) -> bool:
        """True when the expression gives the same values when both ends move together."""
        ends = signs > 0  # which variable is v(n+)
        for s in (0.37, -0.81, 1.7):
            try:
                a = self.behaviour.evaluate(np.where(ends, s, 0.0))[0]
                b = self.behaviour.evaluate(np.where(ends, s + 1.3, 1.3))[0]
            except ExpressionError:
                return False
            if abs(a - b) > 1e-9 * max(abs(a), abs(b), 1e-300):
                return False
        return True

    def value(self, s: float) -> tuple[float, float]:
        """The expression (F, C or H) and its derivative at own voltage or current ``s``."""
        try:
            value, grad = self.behaviour.evaluate(self.weights * s)
        except ExpressionError as exc:
            raise NetlistError(f"{self.element.name}: {exc}", self.element.loc) from None
        return value, float(grad @ self.weights)

    def _capacitance(self, v: float) -> float:
        try:
            return self.behaviour.value(self.weights * v)
        except ExpressionError as exc:
            raise NetlistError(f"{self.element.name}: {exc}", self.element.loc) from None

    def charge(self, v: float) -> tuple[float, float]:
        """Charge q(v) (C, zero at 0 V) and incremental capacitance dq/dv (F) at voltage ``v``."""
        if self.element.kind is Kind.CHARGE:
            q, cap = self.value(v)
            return q - self.value(0.0)[0], cap
        if v in self._cache:
            return self._cache[v]
        cap = self.value(v)[0]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", IntegrationWarning)
            q = quad(self._capacitance, 0.0, v, epsabs=0.0, epsrel=QUAD_RTOL, limit=200)[0]
        if len(self._cache) > 64:
            self._cache.clear()
        self._cache[v] = (q, cap)
        return q, cap

    def voltage(self, q: float) -> float:
        """The voltage (V) whose charge is ``q`` (C): Newton on q(v), from the last answer."""
        v = self._last_v
        for _ in range(100):
            charge, cap = self.charge(v)
            if not cap > 0:
                break
            step = (charge - q) / cap
            v -= step
            if abs(step) <= 1e-14 * abs(v) + 1e-300:
                self._last_v = v
                return v
        raise NetlistError(
            f"{self.element.name}: no voltage carries the charge {q:.6g} C (is the capacitance positive?)",
            self.element.loc,
        )


def _series_sign(sense: Element, inductor: Element, netlist: Netlist) -> float | None:
    """+1 or −1 when voltage source ``sense`` carries the inductor's current (n+ to n−) or its opposite."""
    if sense.kind is not Kind.VSOURCE:
        return None
    for node in set(sense.nodes) & set(inductor.nodes):
        if node == GROUND:
            continue
        at = [e for e in netlist.elements if node in e.nodes and e.kind is not Kind.COUPLING]
        if len(at) == 2:
            same = (node == sense.nodes[1]) == (node == inductor.nodes[0])
            return 1.0 if same else -1.0
    return None


def _pnjlim(vnew: float, vold: float, vte: float, vcrit: float) -> float:
    """SPICE's junction limiting: a forward step above ``vcrit`` taken in the logarithm (V)."""
    if vnew > vcrit and abs(vnew - vold) > 2 * vte:
        if vold > 0:
            arg = 1 + (vnew - vold) / vte
            return vold + vte * math.log(arg) if arg > 0 else vcrit
        return vte * math.log(vnew / vte)
    return vnew


#: Kinds whose law is linear (:func:`netlistdyn.formulation.formulate.element_laws` states it).
LINEAR_KINDS = frozenset(d.kind for d in REGISTRY if d.linear)


def _junction_nodes(diode: Element) -> tuple[str, str]:
    """The junction's anode (the internal node behind RS when RS > 0) and cathode."""
    model = diode.diode
    assert model is not None
    return (f"{diode.key}#anode" if model.RS > 0 else diode.nodes[0]), diode.nodes[1]


def _series_resistance(diode: Element) -> Element:
    """A diode's RS (Ω, divided by the area) as a resistor from its anode to the junction."""
    model = diode.diode
    assert model is not None
    return Element(
        Kind.RESISTOR,
        f"{diode.name}.rs",
        (diode.nodes[0], _junction_nodes(diode)[0]),
        model.RS / diode.value,
        diode.loc,
    )


def _element_law(e: Element, keyed: Mapping[str, Element]) -> ElementLaws | None:
    """Element ``e``'s law with its values (``keyed``: every element by key, for couplings).

    A linear element's is :func:`formulate.element_laws`'; a nonlinear capacitor's or
    inductor's has the form of a linear one's (i = C(v)·v', v = L(i)·i'; its derivative
    term never enters the equations: ``dc`` drops it, ``state`` replaces the law); a
    behavioural voltage source's is v − f = 0 with f in N(z). None: diodes and behavioural
    current sources, wholly in N(z).
    """

    def mutual(coupling: Element) -> float:
        assert coupling.coupled is not None
        a, b = coupling.coupled
        return _numeric_mutual(coupling, keyed[a], keyed[b])

    def value(element: Element) -> float:
        return element.value

    if REGISTRY[e.kind].law is None:
        return None
    return element_laws(e, value, mutual)


@dataclass(frozen=True)
class _Law:
    """One branch law of the modified nodal equations, in the unknowns.

    ``current`` is the unknown of the branch's current, or None when the law
    is solved for it (own coefficient ``own``) and the current put into KCL at
    ``plus`` and ``minus``. ``terms`` are the law's derivative-free
    coefficients of unknowns (the own current excluded when it is solved
    for), ``inputs`` those of the inputs. ``storage`` is ``v`` when a state
    gives the branch's voltage (a capacitor, a diode's junction charge),
    ``i`` when it gives its current (an inductor), with the element's
    capacitance or inductance (F, H) as ``value``.
    """

    name: str
    plus: int | None
    minus: int | None
    current: int | None
    own: float
    terms: tuple[tuple[int, float], ...]
    inputs: tuple[tuple[int, float], ...]
    storage: str | None
    value: float


class NonlinearCircuit:
    """The modified nodal equations of a netlist, linear or not.

    Parameters
    ----------
    netlist : Netlist

    Raises
    ------
    NetlistError
        An expression names a node or element that does not exist.
    """

    def __init__(self, netlist: Netlist) -> None:
        self.netlist = netlist
        elements = netlist.elements
        keyed = {e.key: e for e in elements}
        wanted: set[str] = set()
        behaviours: dict[str, Behaviour] = {}
        displaced: dict[str, Element] = {}  # nodes whose displacement x(n) an expression reads
        for e in elements:
            if e.kind in (Kind.BVOLTAGE, Kind.BCURRENT):
                assert e.expression is not None
                try:
                    b = Behaviour.from_text(e.expression)
                except ExpressionError as exc:
                    raise NetlistError(f"{e.name}: {exc}", e.loc) from None
                behaviours[e.key] = b
                for kind, ref in b.variables:
                    if kind == "i" and ref.startswith(DISPLACEMENT):
                        displaced.setdefault(ref[len(DISPLACEMENT) :], e)
                    elif kind == "i":
                        if ref not in keyed:
                            raise NetlistError(f"{e.name}: i({ref}) names no element", e.loc)
                        if keyed[ref].kind in (Kind.ISOURCE, Kind.BCURRENT, Kind.DIODE, Kind.COUPLING):
                            raise NetlistError(
                                f"{e.name}: i({ref}): only V, L, C, R, E, F, G, H, B V= currents can be read",
                                e.loc,
                            )
                        wanted.add(ref)
        self.nodes: list[str] = list(netlist.nodes)
        node_set = set(self.nodes)
        for e in elements:
            if e.kind is Kind.DIODE and e.diode is not None and e.diode.RS > 0:
                self.nodes.append(f"{e.key}#anode")
        self.node_index = {n: k for k, n in enumerate(self.nodes)}
        for key, b in behaviours.items():
            for kind, ref in b.variables:
                if kind == "v" and ref not in node_set:
                    elem = keyed[key]
                    raise NetlistError(f"{elem.name}: v({ref}) names no node of the circuit", elem.loc)
        for node, elem in displaced.items():
            if node not in node_set:
                raise NetlistError(f"{elem.name}: x({node}) names no node of the circuit", elem.loc)
        #: Nonlinear capacitors and inductors by key.
        self.storage = {e.key: Storage(e, keyed, netlist) for e in elements if e.kind in STORAGE_KINDS}
        for e in elements:
            if e.kind is Kind.COUPLING and any(k in self.storage for k in e.coupled or ()):
                raise NetlistError(f"{e.name}: a coupling of a nonlinear inductor is not supported", e.loc)
        n = len(self.nodes)
        self.sources = netlist.sources
        self.source_index = {e.key: j for j, e in enumerate(self.sources)}
        #: Unknown of each branch current (element key; ``key#q``: a diode's junction-charge branch).
        self.branch_index: dict[str, int] = {}
        self._laws = self._branch_laws(wanted)
        self.diodes: list[_Diode] = []
        for e in elements:
            if e.kind is Kind.DIODE:
                model = e.diode
                assert model is not None
                jn = junction(model, e.value)
                self.diodes.append(
                    _Diode(
                        e,
                        self._at(_junction_nodes(e)[0]),
                        self._at(e.nodes[1]),
                        jn.isat,
                        jn.n,
                        self.branch_index.get(e.key + "#q"),
                        jn.cjo,
                        jn,
                    )
                )
        first = n + len(self.branch_index)
        #: Unknown of each displacement x(n) read by an expression (a state in ``state`` mode).
        self.disp_index = {node: first + k for k, node in enumerate(displaced)}
        self.size = first + len(self.disp_index)
        self.behavioural: list[_Behavioural] = []
        for e in elements:
            if e.key in behaviours:
                b = behaviours[e.key]
                refs = tuple(self._variable(kind, ref) for kind, ref in b.variables)
                self.behavioural.append(
                    _Behavioural(
                        e, b, self._at(e.nodes[0]), self._at(e.nodes[1]), self.branch_index.get(e.key), refs
                    )
                )
        self.capacitors = [e for e in elements if e.kind in CAPACITOR_KINDS]
        self.inductors = [e for e in elements if e.kind in INDUCTOR_KINDS]
        self.charged_diodes = [d for d in self.diodes if d.charge_branch is not None]
        self._diode_arrays()
        self._input_rows()
        self._linear: dict[str, sp.csc_array] = {}
        self._abs_linear: dict[str, sp.csc_array] = {}
        self._floor: NDArray[np.float64] | None = None
        self._vj_last: NDArray[np.float64] | None = None
        self._dense: dict[str, NDArray[np.float64]] = {}
        self._abs_dense: dict[str, NDArray[np.float64]] = {}

    def _branch_laws(self, read: set[str]) -> list[_Law]:
        """The linear part of the equations: every branch's law from :func:`formulate.element_laws`.

        The linear elements' laws, then the diodes' (RS as a resistor, the
        junction charge as a capacitor whose state is its voltage). A branch
        whose law is explicit in its own current, without derivatives, and
        whose current no other law nor expression (``read``: keys) reads is
        solved for its current, which KCL takes (a conductance, VCCS or
        current-source stamp); every other branch keeps its current as an
        unknown, numbered here, and its law as that unknown's row.
        """
        keyed = {e.key: e for e in self.netlist.elements}
        local = [(e, law) for e in self.netlist.elements if (law := _element_law(e, keyed)) is not None]
        junction: list[Element] = []  # each diode's series resistor and junction charge, in order
        for e in self.netlist.elements:
            if e.kind is Kind.DIODE and e.diode is not None:
                if e.diode.RS > 0:
                    junction.append(_series_resistance(e))
                if e.diode.CJO > 0 or e.diode.TT > 0:
                    junction.append(Element(Kind.CAPACITOR, f"{e.name}#q", _junction_nodes(e), 1.0, e.loc))
        local += [(e, law) for e in junction if (law := _element_law(e, keyed)) is not None]
        # each branch's law by branch: its v, i, dv, di, control and u terms as (column, coefficient)
        table: dict[BranchRef, tuple[list[tuple[Any, Any]], ...]] = {}
        where: dict[BranchRef, tuple[str, str, str]] = {}  # its unknown's name and nodes
        for e, _ in local:
            if e.kind is not Kind.COUPLING:
                key = e.key
                for port in range(len(e.nodes) // 2):
                    table[(key, port)] = ([], [], [], [], [], [])
                    pos, neg = e.nodes[2 * port : 2 * port + 2]
                    where[(key, port)] = (key if port == 0 else f"{key}#{port + 1}", pos, neg)
        for _, laws in local:
            for field_, entries in enumerate((laws.v, laws.i, laws.dv, laws.di, laws.control, laws.u)):
                for r, c, x in entries:
                    table[r][field_].append((c, x))
        readers = {(key, 0) for key in read}
        for ref, (_, i, _, di, _, _) in table.items():
            readers.update(c for c, _ in (*i, *di) if c != ref)
        solved: dict[BranchRef, float] = {}
        n = len(self.nodes)
        for ref, (_, i, dv, di, _, _) in table.items():
            own = sum(x for c, x in i if c == ref)
            if own != 0 and not dv and not di and ref not in readers:
                solved[ref] = own
            else:
                self.branch_index[where[ref][0]] = n + len(self.branch_index)
        at = self._at
        out = []
        for ref, (v, i, dv, di, control, u) in table.items():
            name, pos, neg = where[ref]
            terms: list[tuple[int | None, float]] = []
            for c, x in v:
                terms += [(at(where[c][1]), x), (at(where[c][2]), -x)]
            for c, x in i:
                if not (c == ref and ref in solved):
                    terms.append((self.branch_index[where[c][0]], x))
            for (a, b), x in control:
                terms += [(at(a), x), (at(b), -x)]
            own_dv = [x for c, x in dv if c == ref]
            own_di = [x for c, x in di if c == ref]
            storage = "v" if own_dv else "i" if own_di else None
            out.append(
                _Law(
                    name,
                    at(pos),
                    at(neg),
                    None if ref in solved else self.branch_index[name],
                    solved.get(ref, 0.0),
                    tuple((k, float(x)) for k, x in terms if k is not None),
                    tuple((self.source_index[key], float(x)) for key, x in u),
                    storage,
                    -float(sum(own_dv or own_di)),
                )
            )
        return out

    def _variable(self, kind: str, ref: str) -> int | None:
        """Unknown read by an expression variable (None: time)."""
        if kind == "time":
            return None
        if kind == "v":
            return self.node_index[ref]
        if ref.startswith(DISPLACEMENT):
            return self.disp_index[ref[len(DISPLACEMENT) :]]
        return self.branch_index[ref]

    def _diode_arrays(self) -> None:
        """Index and parameter arrays of the diodes (ground is the extra slot ``size``)."""
        size = self.size

        def slot(index: int | None) -> int:
            return size if index is None else index

        self._da = np.array([slot(d.anode) for d in self.diodes], dtype=np.intp)
        self._dk = np.array([slot(d.cathode) for d in self.diodes], dtype=np.intp)
        self._dp = junction_arrays([d.junction for d in self.diodes])
        rows = np.concatenate([self._da, self._da, self._dk, self._dk])
        cols = np.concatenate([self._da, self._dk, self._da, self._dk])
        self._dkeep = (rows < size) & (cols < size)
        self._drows, self._dcols = rows[self._dkeep], cols[self._dkeep]
        charged = self.charged_diodes
        self._qp = junction_arrays([d.junction for d in charged])
        self._qa = np.array([slot(d.anode) for d in charged], dtype=np.intp)
        self._qk = np.array([slot(d.cathode) for d in charged], dtype=np.intp)
        self._qtt = self._qp["tt"]
        self._qbranch = np.array([d.charge_branch for d in charged], dtype=np.intp)

    def charge_of(self, vd: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Charge (C) and capacitance (F) of every charged junction at junction voltages ``vd``."""
        p = self._qp
        i, g = junction_current_array(vd, p)
        return diode_charge_array(vd, i, g, p["cjo"], p["vj"], p["m"], p["tt"], p["fc"])

    def junction_voltages(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """The junction voltages (V) whose charges are ``q`` (C): Newton on the monotonic q(v)."""
        # start from the last answer (a transient asks for nearby charges step after step)
        v = (
            self._vj_last.copy()
            if self._vj_last is not None and self._vj_last.size == q.size
            else np.zeros(q.size)
        )
        vte = self._qp["n"] * self._qp["vt"]
        for _ in range(200):
            charge, cap = self.charge_of(v)
            new = v - (charge - q) / cap
            # exponential diffusion charge: forward steps in the logarithm; deep reverse: bounded steps
            new = np.where((new > v + 4 * vte) & (self._qtt > 0), v + 4 * vte, new)
            deep = (self._qp["cjo"] > 0) & (new < v) & (new < -1e3 * self._qp["vj"])
            new = np.where(deep, np.where(v < 0, np.maximum(new, 2 * v - 1.0), -1.0), new)
            done = np.abs(new - v) <= 1e-15 * np.maximum(1.0, np.abs(v))
            v = new
            if np.all(done):
                break
        if np.all(np.isfinite(v)):
            self._vj_last = v
        return v

    # ------------------------------------------------------------------ stamps

    def _at(self, node: str) -> int | None:
        return None if node == GROUND else self.node_index[node]

    def linear_matrix(self, mode: str) -> sp.csc_array:
        """The constant part G of ``F(z) = G z − b + N(z)`` in ``mode`` (``dc`` or ``state``).

        Rows are KCL at each node (currents leaving it), then each branch
        law (:meth:`_branch_laws`) as its current's row. ``dc`` drops the
        laws' derivative terms (a capacitor's current is 0, an inductor's
        voltage is 0); ``state`` replaces a storage branch's law by its state
        (voltage or current given by ``b``).
        """
        if mode in self._linear:
            return self._linear[mode]
        rows: list[int] = []
        cols: list[int] = []
        vals: list[float] = []

        def add(r: int | None, c: int | None, v: float) -> None:
            if r is not None and c is not None and v != 0:
                rows.append(r)
                cols.append(c)
                vals.append(v)

        for law in self._laws:
            k = law.current
            if k is None:  # its current −(terms)/own leaves plus, enters minus
                for c, x in law.terms:
                    add(law.plus, c, -x / law.own)
                    add(law.minus, c, x / law.own)
                continue
            add(law.plus, k, 1.0)
            add(law.minus, k, -1.0)
            if mode == "state" and law.storage == "v":
                add(k, law.plus, 1.0)
                add(k, law.minus, -1.0)
            elif mode == "state" and law.storage == "i":
                add(k, k, 1.0)
            else:
                for c, x in law.terms:
                    add(k, c, x)
        for node, k in self.disp_index.items():  # dc: at rest, v(n) = 0; state: x(n) given
            add(k, self.node_index[node] if mode == "dc" else k, 1.0)
        matrix = sp.csc_array((vals, (rows, cols)), shape=(self.size, self.size))
        matrix.sum_duplicates()
        self._linear[mode] = matrix
        self._abs_linear[mode] = abs(matrix)
        if self.size <= DENSE_LIMIT:
            self._dense[mode] = matrix.toarray()
            self._abs_dense[mode] = np.abs(self._dense[mode])
        return matrix

    def _input_rows(self) -> None:
        """b = (rows, columns, values) · u: the laws' input terms, on their rows or in KCL."""
        rows: list[int] = []
        cols: list[int] = []
        vals: list[float] = []
        for law in self._laws:
            for j, x in law.inputs:
                if law.current is not None:
                    rows.append(law.current)
                    cols.append(j)
                    vals.append(-x)
                else:
                    for node, sign in ((law.plus, 1.0), (law.minus, -1.0)):
                        if node is not None:
                            rows.append(node)
                            cols.append(j)
                            vals.append(sign * x / law.own)
        self._u_rows = np.asarray(rows, dtype=np.intp)
        self._u_cols = np.asarray(cols, dtype=np.intp)
        self._u_vals = np.asarray(vals, dtype=float)
        stored = {law.name: law for law in self._laws if law.storage is not None}
        linear = [(k, stored[e.key]) for k, e in enumerate(self.capacitors) if e.key not in self.storage]
        #: linear capacitors: state index, row, capacitance (F); nonlinear ones: state index, row, Storage
        self._cap_states = np.array([k for k, _ in linear], dtype=np.intp)
        self._cap_rows = np.array([law.current for _, law in linear], dtype=np.intp)
        self._cap_values = np.array([law.value for _, law in linear])
        self._nl_cap_rows = [
            (k, self.branch_index[e.key], self.storage[e.key])
            for k, e in enumerate(self.capacitors)
            if e.key in self.storage
        ]
        self._ind_rows = np.array([self.branch_index[e.key] for e in self.inductors], dtype=np.intp)

    def inductance_matrix(self) -> NDArray[np.float64]:
        """L of the inductors (H; couplings' M off the diagonal), from their laws' i' terms.

        A nonlinear inductor's entry is its element value 1 (its L(i) divides later).
        """
        index = {e.key: k for k, e in enumerate(self.inductors)}
        keyed = {e.key: e for e in self.netlist.elements}
        L = np.zeros((len(index), len(index)))
        for e in self.netlist.elements:
            if e.kind in (*INDUCTOR_KINDS, Kind.COUPLING):
                law = _element_law(e, keyed)
                assert law is not None
                for (a, _), (b, _), x in law.di:
                    L[index[a], index[b]] -= x
        return L

    def rhs(
        self, mode: str, u: NDArray[np.float64], x: NDArray[np.float64] | None = None
    ) -> NDArray[np.float64]:
        """The constant vector b of ``F = G z − b + N(z)``: sources (and states in ``state`` mode)."""
        b = np.bincount(self._u_rows, weights=self._u_vals * u[self._u_cols], minlength=self.size).astype(
            float
        )
        if mode == "state":
            assert x is not None
            nc = len(self.capacitors)
            nl = len(self.inductors)
            b[self._cap_rows] = x[self._cap_states] / self._cap_values
            for k, row, cap in self._nl_cap_rows:
                b[row] = cap.voltage(float(x[k]))
            b[self._ind_rows] = x[nc : nc + nl]
            nd = len(self.charged_diodes)
            if nd:
                b[self._qbranch] = self.junction_voltages(np.asarray(x[nc + nl : nc + nl + nd], dtype=float))
            for k, index in enumerate(self.disp_index.values()):
                b[index] = x[nc + nl + len(self.charged_diodes) + k]
        return b

    def nonlinear(
        self, z: NDArray[np.float64], t: float, mode: str
    ) -> tuple[NDArray[np.float64], NDArray[np.intp], NDArray[np.intp], NDArray[np.float64]]:
        """N(z) and its Jacobian triplets (diodes and behavioural sources)."""
        rows: list[int] = []
        cols: list[int] = []
        vals: list[float] = []
        tri_r, tri_c, tri_v = [], [], []
        if self.diodes:
            ext = np.append(z, 0.0)
            vd = ext[self._da] - ext[self._dk]
            i, g = junction_current_array(vd, self._dp)
            acc = np.zeros(self.size + 1)
            np.add.at(acc, self._da, i)
            np.add.at(acc, self._dk, -i)
            out = acc[: self.size]
            tri_r, tri_c = [self._drows], [self._dcols]
            tri_v = [np.concatenate([g, -g, -g, g])[self._dkeep]]
        else:
            out = np.zeros(self.size)
        for b in self.behavioural:
            args = np.array([t if r is None else float(z[r]) for r in b.refs])
            try:
                value, grad = b.behaviour.evaluate(args)
            except ExpressionError as exc:
                raise NetlistError(f"{b.element.name}: {exc}", b.element.loc) from None
            if b.branch is not None:  # row: v_a − v_b − f = 0
                targets: tuple[tuple[int | None, float], ...] = ((b.branch, -1.0),)
            else:  # current f from n+ to n−
                targets = ((b.plus, 1.0), (b.minus, -1.0))
            for r, sign in targets:
                if r is None:
                    continue
                out[r] += sign * value
                for c, gk in zip(b.refs, grad, strict=True):
                    if c is not None and gk != 0:
                        rows.append(r)
                        cols.append(c)
                        vals.append(sign * float(gk))
        return (
            out,
            np.concatenate([*tri_r, np.asarray(rows, dtype=np.intp)]),
            np.concatenate([*tri_c, np.asarray(cols, dtype=np.intp)]),
            np.concatenate([*tri_v, np.asarray(vals, dtype=float)]),
        )

    def _junction_from_z(self, d: _Diode, z: NDArray[np.float64]) -> float:
        return (0.0 if d.anode is None else float(z[d.anode])) - (
            0.0 if d.cathode is None else float(z[d.cathode])
        )

    def evaluate(
        self,
        z: NDArray[np.float64],
        mode: str,
        b: NDArray[np.float64],
        t: float = 0.0,
        gshunt: float = 0.0,
    ) -> tuple[NDArray[np.float64], Any]:
        """F(z) and its Jacobian (dense up to ``DENSE_LIMIT`` unknowns, else sparse CSC)."""
        F, J, _ = self._evaluate(z, mode, b, t, gshunt)
        return F, J

    def _evaluate(
        self,
        z: NDArray[np.float64],
        mode: str,
        b: NDArray[np.float64],
        t: float,
        gshunt: float,
    ) -> tuple[NDArray[np.float64], Any, NDArray[np.float64]]:
        """F(z), its Jacobian and the rounding scale of each row (|G||z| + |b| + |N|)."""
        G = self.linear_matrix(mode)
        nl, rows, cols, vals = self.nonlinear(z, t, mode)
        n = len(self.nodes)
        if self.size <= DENSE_LIMIT:  # small: dense arrays (scipy.sparse's overhead dominates)
            dense = self._dense[mode]
            F = dense @ z - b + nl
            J: Any = dense.copy()
            np.add.at(J, (rows, cols), vals)
            scale = self._abs_dense[mode] @ np.abs(z) + np.abs(b) + np.abs(nl)
            if gshunt:
                F[:n] += gshunt * z[:n]
                J[np.arange(n), np.arange(n)] += gshunt
            return F, J, scale
        F = G @ z - b + nl
        J = G + sp.csc_array((vals, (rows, cols)), shape=(self.size, self.size)) if vals.size else G
        scale = self._abs_linear[mode] @ np.abs(z) + np.abs(b) + np.abs(nl)
        if gshunt:
            F[:n] += gshunt * z[:n]
            J = J + sp.diags_array(np.r_[np.full(n, gshunt), np.zeros(self.size - n)]).tocsc()
        return F, J, scale

    # ------------------------------------------------------------------ Newton

    def _limit(self, z: NDArray[np.float64], dz: NDArray[np.float64]) -> float:
        """Step fraction that keeps every forward junction step within SPICE's pnjlim."""
        alpha = 1.0
        for d in self.diodes:
            vold = self._junction_from_z(d, z)
            dv = (0.0 if d.anode is None else dz[d.anode]) - (0.0 if d.cathode is None else dz[d.cathode])
            vnew = vold + dv
            jn = d.junction
            vte = jn.vte
            vcrit = vte * math.log(vte / (math.sqrt(2.0) * d.isat))
            vtebrk = jn.nbv * jn.vt
            if math.isfinite(jn.bv) and vnew < min(0.0, -jn.bv + 10 * vtebrk):
                # in breakdown, ngspice limits the step of the mirrored junction −(vd + BV)
                limited = -(_pnjlim(-(vnew + jn.bv), -(vold + jn.bv), vtebrk, vcrit) + jn.bv)
            else:
                limited = _pnjlim(vnew, vold, vte, vcrit)
            if dv != 0 and limited != vnew:
                alpha = min(alpha, max((limited - vold) / dv, 1e-6))
        return alpha

    def newton(
        self,
        z0: NDArray[np.float64],
        mode: str,
        b: NDArray[np.float64],
        t: float = 0.0,
        gshunt: float = 0.0,
        max_iterations: int = MAX_ITERATIONS,
    ) -> tuple[NDArray[np.float64], int, bool]:
        """Damped Newton from ``z0``; (z, iterations, converged).

        Converged when a full step is below ``NEWTON_RTOL`` of the unknowns
        (with absolute floors), or when the residual of every row is at the
        rounding level of the terms that make it up.
        """
        z = z0.copy()
        n = len(self.nodes)
        if self._floor is None:
            self._floor = np.r_[np.full(n, NEWTON_VNTOL), np.full(self.size - n, NEWTON_ABSTOL)]
        floor = self._floor
        eps64 = 64 * 2.220446049250313e-16
        try:
            F, J, scale = self._evaluate(z, mode, b, t, gshunt)
        except NetlistError:
            return z, 0, False
        if not np.all(np.isfinite(F)):
            return z, 0, False
        if np.all(np.abs(F) <= eps64 * scale + 1e-300):
            return z, 0, True
        for it in range(1, max_iterations + 1):
            try:
                with np.errstate(all="ignore"):
                    if self.size <= DENSE_LIMIT:
                        dz = np.linalg.solve(J, -F)
                    else:
                        dz = spla.splu(J.tocsc()).solve(-F)
            except (RuntimeError, np.linalg.LinAlgError):
                return z, it, False
            if not np.all(np.isfinite(dz)):
                return z, it, False
            alpha = self._limit(z, dz)
            for _ in range(40):  # back off from overflow (exp of a large voltage) or a domain error
                trial = z + alpha * dz
                try:
                    F, J, scale = self._evaluate(trial, mode, b, t, gshunt)
                    if np.all(np.isfinite(F)):
                        break
                except NetlistError:
                    pass
                alpha *= 0.5
            else:
                return z, it, False
            # per unknown, with a floor of NEWTON_RTOL of the largest voltage or current (norm-wise):
            # a small current that is a difference of large ones is known only to that floor
            big = np.maximum(np.abs(z), np.abs(trial))
            kinds = np.r_[
                np.full(n, big[:n].max(initial=0.0)), np.full(self.size - n, big[n:].max(initial=0.0))
            ]
            size = float(np.max(np.abs(dz) / (NEWTON_RTOL * (big + kinds) + floor)))
            z = trial
            if alpha == 1.0 and (size <= 1.0 or np.all(np.abs(F) <= eps64 * scale + 1e-300)):
                return z, it, True
        return z, max_iterations, False

    def operating_point(
        self,
        u: NDArray[np.float64] | None = None,
        t: float = 0.0,
        mode: str = "dc",
        x: NDArray[np.float64] | None = None,
    ) -> OperatingPoint:
        """Solve F(z) = 0: Newton, then gmin stepping, then source stepping.

        Parameters
        ----------
        u : ndarray, optional
            Source values (default: each source's DC value, ngspice's op).
        t : float
            Time seen by behavioural expressions (s).
        mode : str
            ``dc`` or ``state`` (then ``x`` gives the states).
        x : ndarray, optional
            States in ``state`` mode.

        Raises
        ------
        NoOperatingPoint
            When every method fails.
        """
        if u is None:
            u = np.array([self.dc_value(e) for e in self.sources])
        b = self.rhs(mode, u, x)
        z0 = np.zeros(self.size)
        total = 0
        z, its, ok = self.newton(z0, mode, b, t)
        total += its
        method = "newton"
        if not ok:
            method = "gmin stepping"
            z = z0
            for gshunt in [10.0**-k for k in range(2, 13)] + [0.0]:
                z, its, ok = self.newton(z, mode, b, t, gshunt)
                total += its
                if not ok:
                    break
        if not ok:
            method = "source stepping"
            z, lam, step = z0.copy(), 0.0, 0.1
            ok = True
            while lam < 1.0:
                trial_lam = min(1.0, lam + step)
                bl = self.rhs(mode, trial_lam * u, x)
                trial, its, good = self.newton(z, mode, bl, t)
                total += its
                if good:
                    z, lam = trial, trial_lam
                    step = min(step * 2, 0.5)
                else:
                    step /= 4
                    if step < 1e-6:
                        ok = False
                        break
        if not ok:
            self._why_no_point(z0, mode, b, t, mode == "dc")
            raise NoOperatingPoint(
                "no operating point (for a mechanism: no static equilibrium): Newton's method, gmin stepping "
                "and source stepping all failed "
                f"({total} iterations)",
                SourceLocation(self.netlist.path, 0),
            )
        F, _ = self.evaluate(z, mode, b, t)
        return self._point(z, u, total, float(np.max(np.abs(F))) if F.size else 0.0, method)

    def _why_no_point(
        self, z0: NDArray[np.float64], mode: str, b: NDArray[np.float64], t: float, dc: bool
    ) -> None:
        """Name the element when the operating point cannot exist or cannot be started.

        Raises
        ------
        NoOperatingPoint
            At the element's line: a loop of voltage sources (B V= and, at DC, inductors among
            them) leaves the loop's current undetermined; an expression that cannot be evaluated
            at Newton's starting point (every node at 0 V: a division by v(n), sqrt or log of a
            negative number) gives Newton nothing to start from.
        """
        kinds = VOLTAGE_KINDS | ({Kind.INDUCTOR, Kind.INDUCTANCE} if dc else set())
        loop = voltage_loop(self.netlist, frozenset(kinds))
        if loop:
            names = ", ".join(e.label for e in loop)
            what = (
                "voltage sources and inductors"
                if any(e.kind in INDUCTOR_KINDS for e in loop)
                else "voltage sources"
            )
            raise NoOperatingPoint(
                f"{loop[0].label}: loop of {what} only ({names}): "
                "the current around it is undetermined, so there is no operating point",
                loop[0].loc,
            )
        try:
            self._evaluate(z0, mode, b, t, 0.0)
        except NetlistError as exc:
            raise NoOperatingPoint(
                f"{exc.message} at Newton's starting point (every node at 0 V): no operating point",
                exc.loc,
            ) from None

    def _point(
        self, z: NDArray[np.float64], u: NDArray[np.float64], its: int, res: float, method: str
    ) -> OperatingPoint:
        voltages = {n: float(z[k]) for k, n in enumerate(self.nodes)}
        currents = {key: float(z[k]) for key, k in self.branch_index.items() if "#" not in key}
        keys = {e.key for e in self.netlist.elements}
        for law in self._laws:  # a current solved from its law: −(terms)/own
            if law.current is None and law.name in keys:
                terms = sum(x * float(z[c]) for c, x in law.terms) + sum(
                    x * float(u[j]) for j, x in law.inputs
                )
                currents[law.name] = -terms / law.own
        for d in self.diodes:
            vd = self._junction_from_z(d, z)
            i, _ = junction_current(vd, d.junction)
            currents[d.element.key] = i + (0.0 if d.charge_branch is None else float(z[d.charge_branch]))
        for bh in self.behavioural:
            if bh.branch is None:
                args = np.array([0.0 if r is None else float(z[r]) for r in bh.refs])
                currents[bh.element.key] = bh.behaviour.evaluate(args)[0]
        inputs = {e.name: float(u[j]) for j, e in enumerate(self.sources)}
        moved = {node: float(z[k]) for node, k in self.disp_index.items()}
        return OperatingPoint(voltages, currents, inputs, its, res, method, z, moved)

    def _v(self, z: NDArray[np.float64], node: str) -> float:
        return 0.0 if node == GROUND else float(z[self.node_index[node]])

    @staticmethod
    def dc_value(e: Element) -> float:
        """A source's value at the operating point (its DC value, as ngspice's ``.op``)."""
        return float(e.value)

    def states_at(self, point: OperatingPoint) -> NDArray[np.float64]:
        """The state vector (capacitor charges, inductor currents, diode charges) at a point."""
        z = point.z
        x = [self.charge(e, self._v(z, e.nodes[0]) - self._v(z, e.nodes[1]))[0] for e in self.capacitors]
        x += [float(z[self.branch_index[e.key]]) for e in self.inductors]
        for d in self.charged_diodes:
            vd = self._junction_from_z(d, z)
            i, g = junction_current(vd, d.junction)
            x.append(junction_charge(vd, i, g, d.junction)[0])
        x += [float(z[k]) for k in self.disp_index.values()]
        return np.array(x, dtype=float)

    def charge(self, e: Element, v: float) -> tuple[float, float]:
        """Charge (C) and incremental capacitance (F) of capacitor ``e`` at voltage ``v``."""
        cap = self.storage.get(e.key)
        return (e.value * v, e.value) if cap is None else cap.charge(v)

    @property
    def state_names(self) -> list[str]:
        """``q(C1)``, ``i(L1)``, ``q(D1)`` in the order of the state vector."""
        return (
            [
                f"q({e.name})" if e.key in self.storage else f"{state_prefix(e)}({e.name})"
                for e in self.capacitors
            ]
            + [f"{state_prefix(e)}({e.name})" for e in self.inductors]
            + [f"q({d.element.name})" for d in self.charged_diodes]
            + [f"x({node})" for node in self.disp_index]
        )
