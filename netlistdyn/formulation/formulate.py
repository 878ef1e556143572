"""Tree/cotree state equations: KCL on tree-capacitor cutsets, KVL on link-inductor loops.

Every branch has one *primary* unknown: its voltage when it is a tree
branch, its current when it is a link. Every other branch quantity follows
from the normal tree (:class:`~netlistdyn.formulation.graph.TreeSplit`):

* link voltages by KVL around their fundamental loops, v_l = Σ loops[l,t] v_t;
* tree currents by KCL across their fundamental cutsets, i_t = −Σ loops[l,t] i_l.

Each branch contributes one constitutive equation, giving a linear
descriptor system ``G w + E w' + F u = 0`` in the primaries ``w``. The
primaries fall into four classes:

* ``x``: tree-capacitor voltages and link-inductor currents — the states;
* ``s``: independent-source primaries, equal to an input;
* ``d``: excess elements — link-capacitor currents C·d/dt(loop voltage) and
  tree-inductor voltages d/dt(cutset flux) — defined by derivatives;
* ``y``: everything else, found from the resistive equations.

Eliminating ``s``, ``d`` and ``y`` (one sparse factorisation of the
resistive part) leaves ``M x' = N x + B₀ u + K₀ u'``. An input derivative
that survives is removed by the change of variable x̃ = x − M⁻¹K₀ u, and
an output that needs it gets the explicit term ``D1 u'``. Finally capacitor
voltages are scaled to charges, so the states are the seeds' Q_C and I_L.

That elimination (:func:`reduce`, with the outputs, the displacements that
springs hold and the ``x(n)`` integrators) is written once, over a matrix
:class:`~netlistdyn.formulation.algebra.Algebra`: sparse floats with rounding-aware
zero tests and equilibrated LU for the numeric model here, or sympy's
rational functions for :mod:`netlistdyn.symbolic` on the tree chosen here.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from fractions import Fraction
from typing import Any

import numpy as np
import scipy.sparse as sp

from netlistdyn.base.errors import (
    NetlistError,
    SingularCircuitError,
    SourceLocation,
    TopologyError,
    UsageError,
)
from netlistdyn.circuit.netlist import GROUND, Diagnostic, Element, Kind, Netlist
from netlistdyn.circuit.probes import Probe
from netlistdyn.devices.mechanics import DISPLACEMENT_KEYWORD, state_prefix
from netlistdyn.devices.registry import REGISTRY, Registry
from netlistdyn.devices.traits import ElementLaws
from netlistdyn.formulation.algebra import EXACT, NUMERIC, Algebra, Block, NotSupportedError, _clean
from netlistdyn.formulation.graph import CircuitGraph, TreeSplit, build_graph, check_sources, normal_tree
from netlistdyn.statespace.model import CompileInfo, ExcessElement, Pencil, StateShift, StateSpaceModel


@dataclass(frozen=True)
class Classes:
    """Branch indices of each class of primary unknown (see module docstring)."""

    x: np.ndarray
    s: np.ndarray
    d: np.ndarray
    y: np.ndarray
    source_input: np.ndarray  # for each s branch, its input column


@dataclass(frozen=True)
class _Equations:
    """The descriptor system G w + E w' + F u = 0 with maps from primaries to branch quantities.

    Matrices of an :class:`~netlistdyn.formulation.algebra.Algebra` (sparse floats or sympy).
    """

    G: Any
    E: Any
    F: Any
    vmap: Any  # branch voltages from primaries
    imap: Any  # branch currents from primaries


class OutputDerivativeError(UsageError):
    """An output needs second derivatives of the circuit variables on this tree."""


def compile_on_tree(
    netlist: Netlist, circuit: CircuitGraph, tree: TreeSplit, probes: Sequence[Probe]
) -> StateSpaceModel:
    check_sources(circuit, tree)
    reduced = reduce(NUMERIC, NUMERIC_VALUES, netlist, circuit, tree, probes)
    if circuit.nbranches <= EXACT_BRANCH_LIMIT:
        reduced = _rounded_exactly(reduced, netlist, circuit, tree, probes)
    classes, equations = reduced.classes, reduced.equations
    nx_ = len(classes.x)
    states = tuple(state_name(circuit.branches[k].element) for k in classes.x)
    inputs = tuple(e.name for e in netlist.sources)
    info = CompileInfo(
        order=nx_,
        tree=tuple(b.label for b in circuit.branches if tree.in_tree[b.index]),
        excess=_excess(circuit, tree, classes),
        shifts=_shifts(reduced.K, states, inputs),
        warnings=netlist.warnings + check_couplings(netlist),
        integrators=reduced.integrators,
        passive=is_passive(netlist) and not check_couplings(netlist),
    )
    # The same laws with every element value set to 0 leave the topology's ±1: the rest of G
    # is made of element values (R, gains, turns ratios), the part a value's rounding perturbs.
    structure = branch_laws(netlist, circuit, lambda e: 0.0, lambda *_: 0.0)
    G_topology, _ = _law_matrices(NUMERIC, structure, tree, equations.vmap, equations.imap)
    return StateSpaceModel(
        reduced.A,
        reduced.B,
        reduced.C,
        reduced.D,
        reduced.D1,
        (*states, *reduced.integrators),
        inputs,
        tuple(p.name for p in probes),
        netlist.title,
        info,
        pencil=Pencil(equations.G, equations.E, nx_, _clean(equations.G - G_topology)),
    )


#: Circuits with up to this many branches take A, B, C, D, D1 from the exact reduction, rounded
#: once (:func:`_rounded_exactly`): at most 16 ms of CPU on the netlists measured, up to a fully
#: meshed 12-node RLC network of 89 branches (``python benchmarks/entrywise_accuracy.py``).
EXACT_BRANCH_LIMIT = 100


def _rounded_exactly(
    reduced: Reduction, netlist: Netlist, circuit: CircuitGraph, tree: TreeSplit, probes: Sequence[Probe]
) -> Reduction:
    """The numeric reduction's matrices replaced by the exact ones, correctly rounded.

    Floating-point elimination is accurate normwise, but an entry much smaller
    than its neighbours (element values decades apart) can lose digits to
    cancellation: on random networks of E12 values an entry of A came out
    1.9e-4 off. The same reduction in exact rationals on the same tree
    (:class:`~netlistdyn.formulation.algebra.ExactRationals`) gives every entry to the last
    bit of the parsed values. Where it cannot run (a derivative of a resistive
    unknown, a product the numeric algebra judged zero to rounding that is not
    exactly zero) the numeric matrices stay.
    """
    try:
        exact = reduce(EXACT, EXACT_VALUES, netlist, circuit, tree, probes)
    except (NetlistError, ZeroDivisionError):
        return reduced
    rounded = [m.to_float() for m in (exact.A, exact.B, exact.C, exact.D, exact.D1, exact.K)]
    if not all(np.all(np.isfinite(m.data)) for m in rounded):
        return reduced
    A, B, C, D, D1, K = rounded
    return replace(reduced, A=A, B=B, C=C, D=D, D1=D1, K=K)


def held_displacements(
    netlist: Netlist, probes: Sequence[Probe]
) -> dict[int, tuple[int | None, list[tuple[str, int]]]]:
    """``x(...)`` outputs that chains of springs determine, and the chains.

    x(pos) − x(neg) of a spring (an inductor: L = 1/k) is its flux L·i, so
    the positions of nodes joined by springs differ by sums of fluxes. A
    node joined to the frame (node 0) by springs has its position held; in a
    chain that nothing ties to the frame, one position needs an integrator
    and the others follow from it.

    Returns
    -------
    dict
        For each probe index that needs no integrator of its own:
        ``(base, path)`` — the probe's value is the base probe's (None: no
        base) plus the fluxes of ``path``, a list of ``(inductor key, sign)``.
    """
    picks = [j for j, p in enumerate(probes) if p.kind == "x"]
    if not picks:
        return {}
    adjacency: dict[str, list[tuple[str, str, int]]] = {}
    for e in netlist.elements:
        if e.kind is Kind.INDUCTOR:
            pos, neg = e.nodes
            adjacency.setdefault(neg, []).append((pos, e.key, +1))  # x(pos) = x(neg) + φ
            adjacency.setdefault(pos, []).append((neg, e.key, -1))
    root_of: dict[str, str] = {}
    path_to_root: dict[str, list[tuple[str, int]]] = {}
    for start in [GROUND, *adjacency]:
        if start in root_of:
            continue
        root_of[start], path_to_root[start] = start, []
        queue = [start]
        while queue:
            node = queue.pop()
            for other, key, sign in adjacency.get(node, ()):
                if other not in root_of:
                    root_of[other] = start
                    path_to_root[other] = [*path_to_root[node], (key, sign)]
                    queue.append(other)

    def between(a: str, b: str) -> list[tuple[str, int]]:
        """Springs from b to a: x(a) − x(b) = (x(a) − x(root)) − (x(b) − x(root))."""
        return path_to_root.get(a, []) + [(key, -sign) for key, sign in path_to_root.get(b, [])]

    held: dict[int, tuple[int | None, list[tuple[str, int]]]] = {}
    bases: dict[str, int] = {}  # root of a free chain -> the probe x(c) integrated for it
    for j in picks:
        a, b = probes[j].nodes
        if root_of.get(a, a) == root_of.get(b, b):
            held[j] = (None, between(a, b))
        elif b == GROUND:
            root = root_of.get(a, a)
            if root in bases:
                base = bases[root]
                held[j] = (base, between(a, probes[base].nodes[0]))
            else:
                bases[root] = j
    return held


#: Up to this many transformers every orientation is tried; above, a greedy search.
EXHAUSTIVE_TRANSFORMERS = 8


def tree_candidates(netlist: Netlist, devices: Registry = REGISTRY) -> list[tuple[CircuitGraph, TreeSplit]]:
    """Normal trees to try, best first.

    Without transformers there is one. An ideal transformer (gear, lever,
    motor) needs exactly one port in the tree: that port is voltage-defined
    (like a controlled voltage source) and the other current-defined. Which
    port goes in the tree decides which capacitors and inductors end up as
    states, so every orientation is tried (greedily above
    :data:`EXHAUSTIVE_TRANSFORMERS`) and ranked by the number of states it
    gives — the order of complexity is the largest — preferring the default
    orientation (first port in the tree) on ties. ``devices``: the registry of the element kinds.
    """
    keys = [e.key for e in netlist.elements if e.kind is Kind.TRANSFORMER]
    controlled = {e.kind for e in netlist.elements} & {Kind.VCCS, Kind.CCCS, Kind.VCVS, Kind.CCVS}
    # Controlled sources as sources (the default), then current-type, then all, as resistors.
    variants: list[frozenset[Kind]] = [frozenset()]
    if controlled & {Kind.VCCS, Kind.CCCS}:
        variants.append(frozenset(controlled & {Kind.VCCS, Kind.CCCS}))
    if controlled & {Kind.VCVS, Kind.CCVS}:
        variants.append(frozenset(controlled))

    def states_of(circuit: CircuitGraph, tree: TreeSplit) -> int:
        return sum(
            1
            for b in circuit.branches
            if (b.element.kind is Kind.CAPACITOR and tree.in_tree[b.index])
            or (b.element.kind is Kind.INDUCTOR and not tree.in_tree[b.index])
        )

    found: list[tuple[int, int, int, CircuitGraph, TreeSplit]] = []
    for rank, resistive in enumerate(variants):
        for count, circuit, tree in _transformer_trees(netlist, keys, resistive, states_of, devices):
            found.append((states_of(circuit, tree), rank, count, circuit, tree))
    if not found:
        element = next(e for e in netlist.elements if e.kind is Kind.TRANSFORMER)
        raise TopologyError(
            f"{element.label}: cannot place exactly one port in the tree (each port lies in a loop of "
            "voltage sources or a cutset of current sources)",
            element.loc,
        )
    found.sort(key=lambda item: (-item[0], item[1], item[2]))
    unique: list[tuple[CircuitGraph, TreeSplit]] = []
    seen: set[bytes] = set()
    for _, _, _, circuit, tree in found:
        signature = tree.in_tree.tobytes() + bytes(int(b.role) for b in circuit.branches)
        if signature not in seen:
            seen.add(signature)
            unique.append((circuit, tree))
    return unique


def _transformer_trees(
    netlist: Netlist,
    keys: list[str],
    resistive: frozenset[Kind],
    states_of: Callable[[CircuitGraph, TreeSplit], int],
    devices: Registry = REGISTRY,
) -> list[tuple[int, CircuitGraph, TreeSplit]]:
    """Normal trees over the transformer orientations (exhaustive, or greedy above the limit)."""

    def attempt(swapped: frozenset[str]) -> tuple[int, CircuitGraph, TreeSplit] | None:
        circuit = build_graph(netlist, swapped, resistive, devices)
        tree = normal_tree(circuit)
        if _misplaced_transformers(circuit, tree):
            return None
        return states_of(circuit, tree), circuit, tree

    out: list[tuple[int, CircuitGraph, TreeSplit]] = []
    if len(keys) <= EXHAUSTIVE_TRANSFORMERS:
        for mask in range(1 << len(keys)):
            swapped = frozenset(k for i, k in enumerate(keys) if mask >> i & 1)
            result = attempt(swapped)
            if result is not None:
                out.append((len(swapped), result[1], result[2]))
        return out
    swapped = frozenset()
    best = attempt(swapped)
    improved = True
    while improved:
        improved = False
        for key in keys:
            trial = swapped ^ {key}
            result = attempt(trial)
            if result is not None and (best is None or result[0] > best[0]):
                swapped, best, improved = trial, result, True
    if best is not None:
        out.append((len(swapped), best[1], best[2]))
    return out


def _misplaced_transformers(circuit: CircuitGraph, tree: TreeSplit) -> list[Element]:
    counts: dict[str, tuple[Element, int]] = {}
    for branch in circuit.branches:
        if branch.element.kind is Kind.TRANSFORMER:
            elem, n = counts.get(branch.element.key, (branch.element, 0))
            counts[branch.element.key] = (elem, n + int(tree.in_tree[branch.index]))
    return [elem for elem, n in counts.values() if n != 1]


@dataclass(frozen=True)
class BranchLaws:
    """Every branch's constitutive equation, in branch quantities.

    Row k is branch k's law. Each list holds ``(row, column, coefficient)``
    triplets; the coefficient is a float for the numeric formulation or a
    sympy expression for :mod:`netlistdyn.symbolic`, which shares these laws.

    Attributes
    ----------
    v, i : list
        Coefficients of branch voltages and currents (column: branch index).
    dv, di : list
        Coefficients of their time derivatives (capacitances, inductances).
    control : list
        ``(row, (node a, node b), gain)``: coefficient of v(a) − v(b).
    u : list
        Coefficients of the inputs (column: input index).
    """

    v: list[tuple[int, int, Any]]
    i: list[tuple[int, int, Any]]
    dv: list[tuple[int, int, Any]]
    di: list[tuple[int, int, Any]]
    control: list[tuple[int, tuple[str, str], Any]]
    u: list[tuple[int, int, Any]]


def element_laws(
    element: Element,
    value: Callable[[Element], Any],
    mutual: Callable[[Element], Any],
    devices: Registry = REGISTRY,
) -> ElementLaws:
    """The constitutive equations of one element (SPICE sign conventions), from its device's record.

    Each device family states its law once (:attr:`~netlistdyn.devices.traits.DeviceKind.law`,
    e.g. :func:`netlistdyn.devices.passive.resistor_law`): the tree/cotree
    formulation (:func:`branch_laws`, numeric and symbolic) and the modified
    nodal equations of :mod:`netlistdyn.formulation.nonlinear` both read it here.

    Parameters
    ----------
    element : Element
        An R, C, L, V, I, E, F, G, H, transformer or K element (or a nonlinear
        capacitor, inductor or behavioural voltage source, whose law has a linear form).
    value : callable
        ``value(element)``: the element's value (Ω, F, H, V/V, A/A, …), a
        float or a symbol.
    mutual : callable
        ``mutual(coupling)``: the mutual inductance (H) of a ``K`` element.
    devices : Registry
        Where the law is looked up.

    Returns
    -------
    ElementLaws
        A K element gives the two inductors' mutual terms in their rows.
    """
    law = devices[element.kind].law
    assert law is not None, element.kind  # the parser admits no other linear kinds
    return law(element, value, mutual)


def branch_laws(
    netlist: Netlist,
    circuit: CircuitGraph,
    value: Callable[[Element], Any],
    mutual: Callable[[Element, Any, Any], Any],
) -> BranchLaws:
    """Write each branch's constitutive equation (SPICE sign conventions).

    Parameters
    ----------
    netlist : Netlist
    circuit : CircuitGraph
    value : callable
        ``value(element)``: the element's value (Ω, F, H, V/V, A/A, …), a
        float or a symbol.
    mutual : callable
        ``mutual(coupling, L_a, L_b)``: mutual inductance (H) of a ``K`` element.

    Returns
    -------
    BranchLaws
        :func:`element_laws` of every element, rows and columns numbered as
        the circuit's branches.
    """
    laws = BranchLaws([], [], [], [], [], [])
    inputs = {e.key: j for j, e in enumerate(netlist.sources)}
    index = {(b.element.key, b.port): b.index for b in circuit.branches}
    inductor = {b.element.key: b.element for b in circuit.branches if b.element.kind is Kind.INDUCTOR}

    def coupling(element: Element) -> Any:
        assert element.coupled is not None
        a, b = element.coupled
        return mutual(element, inductor[a], inductor[b])

    v, i, dv, di, control, u = laws.v, laws.i, laws.dv, laws.di, laws.control, laws.u

    def place(local: ElementLaws) -> None:
        """Append every row of ``local``, numbered as branches (a loop per list: most are empty)."""
        for r, c, x in local.v:
            v.append((index[r], index[c], x))
        for r, c, x in local.i:
            i.append((index[r], index[c], x))
        for r, c, x in local.dv:
            dv.append((index[r], index[c], x))
        for r, c, x in local.di:
            di.append((index[r], index[c], x))
        for r, pair, x in local.control:
            control.append((index[r], pair, x))
        for r, key, x in local.u:
            u.append((index[r], inputs[key], x))

    for branch in circuit.branches:
        if branch.port == 0:  # a transformer's laws give the rows of both its ports
            place(element_laws(branch.element, value, coupling, circuit.devices))
    for element in netlist.elements:
        if element.kind is Kind.COUPLING:
            place(element_laws(element, value, coupling, circuit.devices))
    return laws


def _numeric_mutual(coupling: Element, la: Element, lb: Element) -> float:
    """M = k·sqrt(|L_a L_b|) (H), as ngspice computes it whatever the inductances' signs."""
    return coupling.value * float(np.sqrt(abs(la.value * lb.value)))


#: Element values must lie within this magnitude range (their products and reciprocals stay finite).
VALUE_RANGE = (1e-150, 1e150)


def check_value_range(netlist: Netlist) -> None:
    """Refuse element values whose products or reciprocals would overflow double precision.

    Raises
    ------
    NetlistError
        Naming the element, e.g. ``R1 in a 1e-308`` (1/(R·C) overflows).
    """
    low, high = VALUE_RANGE
    for element in netlist.elements:
        magnitude = abs(element.value)
        if element.value != 0 and not low <= magnitude <= high:
            raise NetlistError(
                f"{element.label}: value {element.value:g} is outside the range the model can be computed "
                f"in ({low:g} to {high:g} in magnitude): its products with other values overflow",
                element.loc,
            )


def check_couplings(netlist: Netlist) -> tuple[Diagnostic, ...]:
    """Warn about coupled inductors whose inductance matrix is not positive definite.

    Each group of inductors joined by ``K`` elements (couplings on one pair
    add, as in ngspice) has a positive definite inductance matrix in any
    magnetic circuit when its inductances are positive; otherwise the stored
    energy ½ iᵀ L i can be negative (a total coupling of 1 or more). ngspice
    and Xyce read such a netlist all the same (Xyce's regression suite has
    one), so it is compiled with the same meaning — its model is then not
    passive and typically unstable — and the couplings are named in a warning.

    Returns
    -------
    tuple of Diagnostic
        One warning per offending group, at its first coupling.
    """
    inductors = {e.key: e for e in netlist.elements if e.kind is Kind.INDUCTOR}
    # A coupling naming no inductor is reported by the graph's reference check.
    couplings = [
        e
        for e in netlist.elements
        if e.kind is Kind.COUPLING and e.coupled is not None and all(n in inductors for n in e.coupled)
    ]
    if not couplings:
        return ()
    parent: dict[str, str] = {}

    def root(key: str) -> str:
        while parent.get(key, key) != key:
            key = parent[key]
        return key

    for k in couplings:
        assert k.coupled is not None
        a, b = (root(name) for name in k.coupled)
        if a != b:
            parent[a] = b
    groups: dict[str, list[Element]] = {}
    for k in couplings:
        assert k.coupled is not None
        groups.setdefault(root(k.coupled[0]), []).append(k)
    found = []
    for members in groups.values():
        names = sorted({name for k in members for name in k.coupled or ()})
        if any(inductors[name].value <= 0 for name in names):
            continue  # negative inductances: no energy argument
        pos = {name: j for j, name in enumerate(names)}
        matrix = np.diag([inductors[name].value for name in names])
        for k in members:
            assert k.coupled is not None
            i, j = (pos[name] for name in k.coupled)
            m = _numeric_mutual(k, inductors[names[i]], inductors[names[j]])
            matrix[i, j] += m
            matrix[j, i] += m
        # Scaled to a unit diagonal (dimensionless coupling matrix), definiteness is scale-free.
        d = 1.0 / np.sqrt(np.diag(matrix))
        coupling_matrix = matrix * d[:, None] * d[None, :]
        if np.linalg.eigvalsh(coupling_matrix).min() <= 4 * len(names) * float(np.finfo(float).eps):
            labels = ", ".join(k.label for k in members)
            found.append(
                Diagnostic(
                    members[0].loc,
                    f"{labels}: the inductance matrix of {', '.join(inductors[n].label for n in names)} is "
                    "not positive definite (total coupling of 1 or more): no magnetic circuit does this; "
                    "compiled as ngspice reads it, the model is not passive",
                )
            )
    return tuple(found)


def _potential_rows(tree: TreeSplit, pairs: Sequence[tuple[str, str]], n: int) -> sp.csr_array:
    """Rows v(a) − v(b) over the primaries, one per (a, b) pair."""
    rows, cols, vals = [], [], []
    for r, (a, b) in enumerate(pairs):
        coeffs: dict[int, float] = {}
        for node, sign in ((a, 1.0), (b, -1.0)):
            if node != GROUND:
                for k, c in tree.potential(node).items():
                    coeffs[k] = coeffs.get(k, 0.0) + sign * c
        for k, c in coeffs.items():
            if c:
                rows.append(r)
                cols.append(k)
                vals.append(c)
    return sp.csr_array((vals, (rows, cols)), shape=(len(pairs), n))


def primary_maps(tree: TreeSplit) -> tuple[sp.csr_array, sp.csr_array]:
    """Branch voltages and currents from the primaries: (vmap, imap), entries 0/±1."""
    tree_diag = sp.diags_array(tree.in_tree.astype(float))
    link_diag = sp.diags_array((~tree.in_tree).astype(float))
    return (tree_diag + tree.loops).tocsr(), (link_diag - tree.loops.T).tocsr()


def assemble(
    netlist: Netlist, circuit: CircuitGraph, tree: TreeSplit, algebra: Algebra, values: ElementValues
) -> _Equations:
    """Write one constitutive equation per branch over the primary unknowns.

    Parameters
    ----------
    netlist : Netlist
    circuit : CircuitGraph
    tree : TreeSplit
    algebra : Algebra
        The matrix type (sparse floats, or sympy for :mod:`netlistdyn.symbolic`).
    values : ElementValues
        The element values in that algebra.

    Returns
    -------
    _Equations
        ``G w + E w' + F u = 0`` with ``vmap``/``imap`` giving every branch
        voltage and current from ``w``.
    """
    n = circuit.nbranches
    vmap_topology, imap_topology = primary_maps(tree)
    vmap, imap = algebra.topology(vmap_topology), algebra.topology(imap_topology)
    laws = branch_laws(netlist, circuit, values.value, values.mutual)
    G, E = _law_matrices(algebra, laws, tree, vmap, imap)
    F = algebra.triplets(laws.u, (n, len(netlist.sources)))
    return _Equations(algebra.clean(G), algebra.clean(E), F, vmap, imap)


def _law_matrices(
    algebra: Algebra, laws: BranchLaws, tree: TreeSplit, vmap: Any, imap: Any
) -> tuple[Any, Any]:
    """G and E of ``G w + E w' + F u = 0`` from the branch laws and the primary maps."""
    n = vmap.shape[0]
    G = algebra.triplets(laws.v, (n, n)) @ vmap + algebra.triplets(laws.i, (n, n)) @ imap
    if laws.control:
        ctrl = algebra.topology(_potential_rows(tree, [pair for _, pair, _ in laws.control], n))
        place = algebra.triplets(
            [(row, j, gain) for j, (row, _, gain) in enumerate(laws.control)], (n, len(laws.control))
        )
        G = G + place @ ctrl
    E = algebra.triplets(laws.dv, (n, n)) @ vmap + algebra.triplets(laws.di, (n, n)) @ imap
    return G, E


def classify(circuit: CircuitGraph, tree: TreeSplit, netlist: Netlist) -> Classes:
    """Sort the primaries into states, sources, excess elements and the rest."""
    inputs = {e.key: j for j, e in enumerate(netlist.sources)}
    x_caps: list[int] = []
    x_inds: list[int] = []
    d: list[int] = []
    s, y, source_input = [], [], []
    for branch in circuit.branches:
        k = branch.index
        in_tree = bool(tree.in_tree[k])
        kind = branch.element.kind
        if kind is Kind.CAPACITOR:
            (x_caps if in_tree else d).append(k)
        elif kind is Kind.INDUCTOR:
            (d if in_tree else x_inds).append(k)
        elif (kind is Kind.VSOURCE and in_tree) or (kind is Kind.ISOURCE and not in_tree):
            s.append(k)
            source_input.append(inputs[branch.element.key])
        else:
            y.append(k)
    as_array = lambda v: np.asarray(v, dtype=np.intp)  # noqa: E731
    return Classes(as_array(x_caps + x_inds), as_array(s), as_array(d), as_array(y), as_array(source_input))


@dataclass(frozen=True)
class ElementValues:
    """Element values as coefficients of an algebra: floats, or sympy expressions of symbols.

    Attributes
    ----------
    value : callable
        ``value(element)``: R (Ω), C (F), L (H), a gain or turns ratio.
    mutual : callable
        ``mutual(coupling, L_a, L_b)``: mutual inductance (H) of a ``K`` element.
    rod_length : callable
        ``rod_length(rod)``: length (m) of a pendulum ``ROD``.
    """

    value: Callable[[Element], Any]
    mutual: Callable[[Element, Element, Element], Any]
    rod_length: Callable[[Element], Any]


def _rod_length(rod: Element) -> float:
    assert rod.rod is not None
    return rod.rod.length


#: The netlist's own values, as floats.
NUMERIC_VALUES = ElementValues(lambda e: e.value, _numeric_mutual, _rod_length)

#: The netlist's doubles, taken exactly (a coupling's M and a rod's length as their doubles).
EXACT_VALUES = ElementValues(
    lambda e: Fraction(e.value),
    lambda *elements: Fraction(_numeric_mutual(*elements)),
    lambda rod: Fraction(_rod_length(rod)),
)


@dataclass(frozen=True)
class Reduction:
    """The state-space matrices a reduction produces, in the matrices of its algebra.

    Attributes
    ----------
    A, B, C, D, D1
        x' = A x + B u, y = C x + D u + D1 u', in the states of ``classes.x``
        (charges for capacitors, currents for inductors) followed by one
        integrator per name in ``integrators``.
    K
        The input shift: the states are z = x − K u (charge units).
    integrators : tuple of str
        The ``x(n)`` outputs that got an integrator state.
    classes : Classes
    equations : _Equations
        The equations the matrices were reduced from.
    """

    A: Any
    B: Any
    C: Any
    D: Any
    D1: Any
    K: Any
    integrators: tuple[str, ...]
    classes: Classes
    equations: _Equations


def reduce(
    algebra: Algebra,
    values: ElementValues,
    netlist: Netlist,
    circuit: CircuitGraph,
    tree: TreeSplit,
    probes: Sequence[Probe],
) -> Reduction:
    """Eliminate everything but the states on a normal tree and build A, B, C, D, D1.

    The one statement of the algebra in the module docstring, for the
    numeric compiler (``algebra`` :data:`~netlistdyn.formulation.algebra.NUMERIC`,
    ``values`` :data:`NUMERIC_VALUES`) and the symbolic one
    (:mod:`netlistdyn.symbolic`, exact rational functions).

    Parameters
    ----------
    algebra : Algebra
        The matrix type and its rounding-aware (or exact) operations.
    values : ElementValues
        The element values in that algebra.
    netlist : Netlist
    circuit : CircuitGraph
    tree : TreeSplit
        The normal tree (chosen by :func:`formulate`).
    probes : sequence of Probe
        The outputs.

    Returns
    -------
    Reduction

    Raises
    ------
    SingularCircuitError
        When the resistive part or the capacitance/inductance matrix is singular.
    NotSupportedError, OutputDerivativeError
        When the circuit or an output needs second derivatives on this tree.
    """
    m = len(netlist.sources)
    equations = assemble(netlist, circuit, tree, algebra, values)
    classes = classify(circuit, tree, netlist)
    G, E, F = equations.G, equations.E, equations.F
    involved = _controlled_labels(netlist)
    where = _first_location(netlist, involved)
    rows = algebra.rows

    def solve(matrix: Any, rhs: Any, message: str) -> Any:
        try:
            return -algebra.solve(matrix, rhs, message)
        except SingularCircuitError as exc:
            raise SingularCircuitError(exc.message, where) from None

    yb = _eliminate(
        algebra, rows(G, classes.y), rows(E, classes.y), rows(F, classes.y), equations, classes, m
    )
    if algebra.nonzero(yb.dy):
        yb = algebra.algebraic_derivatives(yb, involved, netlist)
    resistive_msg = "the resistive part of the circuit has no unique solution for these values" + (
        f" (check {', '.join(involved)})" if involved else " (check negative resistances)"
    )
    rhs = algebra.hstack([yb.x, yb.dx, yb.u, yb.du])
    solved = solve(yb.y, rhs, resistive_msg) if yb.y.shape[0] else algebra.zeros(0, rhs.shape[1])
    nx_ = len(classes.x)
    splits = np.cumsum([nx_, nx_, m])
    P = algebra.clean(solved[:, : splits[0]])
    R = algebra.clean(solved[:, splits[0] : splits[1]])
    Q = algebra.clean(solved[:, splits[1] : splits[2]])
    S = algebra.clean(solved[:, splits[2] :])

    xb = _eliminate(
        algebra, rows(G, classes.x), rows(E, classes.x), rows(F, classes.x), equations, classes, m
    )
    if not (algebra.negligible(xb.dy, R) and algebra.negligible(xb.dy, S)):
        raise NotSupportedError(
            "the circuit needs second derivatives of its variables (higher index); not supported",
            netlist.elements[0].loc,
        )
    mass = algebra.clean(xb.dx + xb.dy @ P + xb.y @ R)
    n0 = algebra.clean(xb.x + xb.y @ P)
    nu = algebra.clean(xb.u + xb.y @ Q)
    nud = algebra.clean(xb.du + xb.dy @ Q + xb.y @ S)
    mass_msg = (
        "the capacitance/inductance matrix is singular for these values: the states are not "
        "independent" + (f" (check {', '.join(involved)})" if involved else " (check negative values)")
    )
    solved_x = solve(mass, algebra.hstack([n0, nu, nud]), mass_msg)
    A = algebra.clean(solved_x[:, :nx_])
    B = algebra.clean(solved_x[:, nx_ : nx_ + m])
    K = algebra.clean(solved_x[:, nx_ + m :])

    held = held_displacements(netlist, probes)
    C, D, D1 = _outputs(
        algebra, values, probes, held, netlist, circuit, tree, equations, classes, (P, Q, R, S), (A, B, K), m
    )

    # From x to the shifted state z = x − K u: z' = A z + (B + A K) u, y = C z + (D + C K) u + D1 u'.
    B_z = algebra.clean(B + A @ K)
    D_z = algebra.clean(D + C @ K)

    # Capacitor voltages → charges: q = C v.
    scale = [
        values.value(circuit.branches[k].element) if circuit.branches[k].element.kind is Kind.CAPACITOR else 1
        for k in classes.x
    ]
    T, T_inv = algebra.diag(scale), algebra.diag(scale, inverse=True)
    A_q = algebra.clean(T @ A @ T_inv)
    B_q = algebra.clean(T @ B_z)
    C_q = algebra.clean(C @ T_inv)
    K_q = algebra.clean(T @ K)
    algebra.check_finite(netlist, {"A": A_q, "B": B_q, "C": C_q, "D": D_z, "D1": D1})

    A_q, B_q, C_q, D_z, D1, integrators = _integrate_displacements(
        algebra, (A_q, B_q, C_q, D_z, D1), probes, held
    )
    # x(a) = x(c) + (x(a) − x(c)): a position in a free chain of springs is another's plus fluxes.
    based = [(j, base, 1) for j, (base, _) in held.items() if base is not None]
    if based:
        add = algebra.triplets(based, (len(probes), len(probes)))
        C_q, D_z, D1 = (algebra.clean(M + add @ M) for M in (C_q, D_z, D1))
    return Reduction(A_q, B_q, C_q, D_z, D1, K_q, integrators, classes, equations)


def _eliminate(algebra: Algebra, G: Any, E: Any, F: Any, full: _Equations, classes: Classes, m: int) -> Block:
    """Substitute source primaries (= inputs) and excess-element primaries (derivatives).

    Parameters
    ----------
    algebra : Algebra
    G, E, F : matrices
        Rows to transform (coefficients of w, w' and u).
    full : _Equations
        The whole system (for the excess elements' defining rows).
    classes : Classes
    m : int
        Number of inputs.
    """
    cols = algebra.cols
    unit = algebra.triplets([(r, int(j), 1) for r, j in enumerate(classes.source_input)], (len(classes.s), m))
    u = F + cols(G, classes.s) @ unit
    du = cols(E, classes.s) @ unit
    dx, dy = cols(E, classes.x), cols(E, classes.y)
    if len(classes.d):
        # Excess rows read w_d + E_d w' = 0, so w_d = −E_d w' (never another excess primary).
        # Where a substituted term cancels an existing one, the difference is zero up to rounding:
        # judged against the magnitudes that were added, never against a unit-dependent level.
        e_d = algebra.rows(full.E, classes.d)
        g_d = cols(G, classes.d)
        e_du = cols(e_d, classes.s) @ unit
        dx = algebra.cancelled(dx, g_d, cols(e_d, classes.x))
        dy = algebra.cancelled(dy, g_d, cols(e_d, classes.y))
        du = algebra.cancelled(du, g_d, e_du)
    clean = algebra.clean
    return Block(cols(G, classes.x), cols(G, classes.y), clean(dx), clean(dy), clean(u), clean(du))


def _outputs(
    algebra: Algebra,
    values: ElementValues,
    probes: Sequence[Probe],
    held: dict[int, tuple[int | None, list[tuple[str, int]]]],
    netlist: Netlist,
    circuit: CircuitGraph,
    tree: TreeSplit,
    equations: _Equations,
    classes: Classes,
    y_solution: tuple[Any, ...],
    state_solution: tuple[Any, ...],
    m: int,
) -> tuple[Any, Any, Any]:
    """C, D, D1 in the unshifted voltage/current states x (see :func:`reduce`).

    A displacement ``x(a, b)`` that springs hold (see :func:`held_displacements`)
    is the sum of the fluxes L·i + Σ M·i_other on its path; another ``x(n)``
    is its velocity ``v(n)`` here, integrated by :func:`_integrate_displacements`.
    """
    P, Q, R, S = y_solution
    A, B, K = state_solution
    n, p = circuit.nbranches, len(probes)
    if not probes:
        return algebra.zeros(0, len(classes.x)), algebra.zeros(0, m), algebra.zeros(0, m)
    # Output rows over the primaries, in one sparse product each (one per probe is slow for
    # thousands of nodes): node potentials, then branch currents with their weights.
    across = [j for j, pr in enumerate(probes) if pr.kind in ("v", "x") and j not in held]
    potentials = algebra.topology(_potential_rows(tree, [probes[j].nodes for j in across], n))
    place = algebra.triplets([(j, r, 1) for r, j in enumerate(across)], (p, len(across)))
    c_w = place @ potentials
    weights = _current_weights(values, probes, held, netlist, circuit)
    if weights:
        c_w = c_w + algebra.triplets(weights, (p, n)) @ equations.imap
    block = _eliminate(algebra, c_w, algebra.zeros(p, n), algebra.zeros(p, m), equations, classes, m)
    c_x = block.x + block.y @ P
    c_dx = block.dx + block.y @ R
    c_u = block.u + block.y @ Q
    c_du = block.du + block.y @ S
    if algebra.nonzero(block.dy):  # y' = P x' + Q u' + R x'' + S u'': R and S must not be reached
        if not (algebra.negligible(block.dy, R) and algebra.negligible(block.dy, S)):
            raise OutputDerivativeError(
                "an output needs second derivatives of the circuit variables; not supported"
            )
        c_dx = c_dx + block.dy @ P
        c_du = c_du + block.dy @ Q
    C = algebra.clean(c_x + c_dx @ A)
    D = algebra.clean(c_u + c_dx @ B)
    D1 = algebra.clean(c_du + c_dx @ K)
    return C, D, D1


def _current_weights(
    values: ElementValues,
    probes: Sequence[Probe],
    held: dict[int, tuple[int | None, list[tuple[str, int]]]],
    netlist: Netlist,
    circuit: CircuitGraph,
) -> list[tuple[int, int, Any]]:
    """``(probe, branch, weight)``: the outputs that are weighted sums of branch currents.

    ``i(X)`` (a two-port's first port), ``angle(rod)`` = −L·i/l (i = k·(x_pivot − x_bob)
    with L = 1/k), and each held displacement: Σ sign·(L·i + Σ M·i_other) over its path.
    """
    through = [j for j, probe in enumerate(probes) if j in held or probe.kind not in ("v", "x")]
    if not through:
        return []
    key_branch: dict[str, int] = {}
    for branch in circuit.branches:  # a two-port's current is its first port's
        key_branch.setdefault(branch.element.key, branch.index)
    by_key = {e.key: e for e in netlist.elements}
    mutual: dict[str, list[tuple[str, Any]]] = {}
    if held:
        for e in netlist.elements:
            if e.kind is Kind.COUPLING and e.coupled is not None:
                a, b = e.coupled
                m_ab = values.mutual(e, by_key[a], by_key[b])
                mutual.setdefault(a, []).append((b, m_ab))
                mutual.setdefault(b, []).append((a, m_ab))
    out: list[tuple[int, int, Any]] = []
    for j in through:
        probe = probes[j]
        if j in held:
            for key, sign in held[j][1]:
                out.append((j, key_branch[key], sign * values.value(by_key[key])))
                out.extend((j, key_branch[other], sign * m_ab) for other, m_ab in mutual.get(key, ()))
        else:
            weight: Any = 1
            if probe.kind == "angle":
                rod = circuit.branches[key_branch[probe.element]].element
                weight = -values.value(rod) / values.rod_length(rod)
            out.append((j, key_branch[probe.element], weight))
    return out


def _integrate_displacements(
    algebra: Algebra,
    matrices: tuple[Any, Any, Any, Any, Any],
    probes: Sequence[Probe],
    held: dict[int, tuple[int | None, list[tuple[str, int]]]],
) -> tuple[Any, Any, Any, Any, Any, tuple[str, ...]]:
    """Integrate the velocity rows of ``x(...)`` outputs that springs do not hold into states.

    Only the displacements a user asks for get a state (named like the
    output): z' = C_v x + D_v u, and the output is z + D1_v u, so a velocity
    with an input-derivative term integrates exactly.
    """
    A, B, C, D, D1 = matrices
    picks = [j for j, pr in enumerate(probes) if pr.kind == "x" and j not in held]
    if not picks:
        return A, B, C, D, D1, ()
    k, p, nx_ = len(picks), len(probes), A.shape[0]
    rows_c, rows_d, rows_d1 = (algebra.rows(M, picks) for M in (C, D, D1))
    A = algebra.vstack(
        [algebra.hstack([A, algebra.zeros(nx_, k)]), algebra.hstack([rows_c, algebra.zeros(k, k)])]
    )
    B = algebra.vstack([B, rows_d])
    select = algebra.triplets([(j, col, 1) for col, j in enumerate(picks)], (p, k))
    keep = algebra.diag([0 if j in picks else 1 for j in range(p)])
    C = algebra.hstack([keep @ C, select])
    clean = algebra.clean
    return (
        clean(A),
        clean(B),
        clean(C),
        clean(keep @ D + select @ rows_d1),
        clean(keep @ D1),
        tuple(probes[j].name for j in picks),
    )


def is_passive(netlist: Netlist) -> bool:
    """True when every element is passive (positive R, L, C; |k| < 1; transformers; sources)."""
    for element in netlist.elements:
        kind = element.kind
        if kind in (Kind.RESISTOR, Kind.CAPACITOR, Kind.INDUCTOR) and element.value <= 0:
            return False
        if kind in (Kind.VCVS, Kind.VCCS, Kind.CCCS, Kind.CCVS):
            return False
    return True


def state_name(element: Element) -> str:
    """Name of the state an element carries: ``q(C1)``, ``i(L1)``, ``p(m1)``, ``f(k1)`` or ``x(n)``."""
    if element.keyword == DISPLACEMENT_KEYWORD:  # a linearised mechanism's integrator of v(n)
        return element.name
    return f"{state_prefix(element)}({element.name})"


def _first_location(netlist: Netlist, involved: list[str]) -> SourceLocation:
    """Where to point a whole-circuit error: the first controlled element, else the first element."""
    for element in netlist.elements:
        if element.label in involved:
            return element.loc
    return netlist.elements[0].loc


def _controlled_labels(netlist: Netlist) -> list[str]:
    return [
        e.label
        for e in netlist.elements
        if e.kind in (Kind.VCVS, Kind.VCCS, Kind.CCCS, Kind.CCVS, Kind.TRANSFORMER)
    ]


def _excess(circuit: CircuitGraph, tree: TreeSplit, classes: Classes) -> tuple[ExcessElement, ...]:
    out = []
    for k in classes.d:
        branch = circuit.branches[k]
        if branch.element.kind is Kind.CAPACITOR:
            members = tuple(circuit.branches[t].label for t in tree.loop_members(int(k)))
            out.append(ExcessElement(branch.label, "capacitor loop", members))
        else:
            members = tuple(circuit.branches[t].label for t in tree.cutset_members(int(k)))
            out.append(ExcessElement(branch.label, "inductor cutset", members))
    return tuple(out)


def _shifts(K: sp.csr_array, states: tuple[str, ...], inputs: tuple[str, ...]) -> tuple[StateShift, ...]:
    out = []
    dense = K.toarray() if K.nnz else None
    if dense is None:
        return ()
    for i, name in enumerate(states):
        coeffs = tuple((inputs[j], float(dense[i, j])) for j in range(len(inputs)) if dense[i, j] != 0)
        if coeffs:
            out.append(StateShift(name, coeffs))
    return tuple(out)
