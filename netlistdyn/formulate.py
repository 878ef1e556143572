"""Tree/cotree state equations: KCL on tree-capacitor cutsets, KVL on link-inductor loops.

Every branch has one *primary* unknown: its voltage when it is a tree
branch, its current when it is a link. Every other branch quantity follows
from the normal tree (:class:`~netlistdyn.graph.TreeSplit`):

* link voltages by KVL around their fundamental loops, v_l = Σ loops[l,t] v_t;
* tree currents by KCL across their fundamental cutsets, i_t = −Σ loops[l,t] i_l.

Each branch contributes one constitutive equation, giving a linear
descriptor system ``G w + E w' + F u = 0`` in the primaries ``w``. The
primaries fall into four classes:

``x``  tree-capacitor voltages and link-inductor currents — the states;
``s``  independent-source primaries, equal to an input;
``d``  excess elements — link-capacitor currents C·d/dt(loop voltage) and
       tree-inductor voltages d/dt(cutset flux) — defined by derivatives;
``y``  everything else, found from the resistive equations.

Eliminating ``s``, ``d`` and ``y`` (one sparse factorisation of the
resistive part) leaves ``M x' = N x + B₀ u + K₀ u'``. An input derivative
that survives is removed by the change of variable x̃ = x − M⁻¹K₀ u, and
an output that needs it gets the explicit term ``D1 u'``. Finally capacitor
voltages are scaled to charges, so the states are the seeds' Q_C and I_L.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .errors import NetlistError, SingularCircuitError, SourceLocation, TopologyError, UsageError
from .graph import CircuitGraph, TreeSplit, build_graph, check_sources, normal_tree
from .mechanics import DISPLACEMENT_KEYWORD, state_prefix
from .model import CompileInfo, ExcessElement, Pencil, StateShift, StateSpaceModel
from .netlist import GROUND, Diagnostic, Element, Kind, Netlist
from .probes import Probe, default_probes, parse_probe

#: A factorisation whose pivots span more than this ratio is treated as singular.
SINGULAR_RCOND = 1e-14


@dataclass(frozen=True)
class Classes:
    """Branch indices of each class of primary unknown (see module docstring)."""

    x: np.ndarray
    s: np.ndarray
    d: np.ndarray
    y: np.ndarray
    source_input: np.ndarray  # for each s branch, its input column


class NotSupportedError(NetlistError):
    """The circuit needs a formulation this compiler does not have (higher index)."""


@dataclass(frozen=True)
class _Block:
    """Rows of equations after eliminating s and d: coefficients of x, y, x', y', u, u'."""

    x: sp.csr_array
    y: sp.csr_array
    dx: sp.csr_array
    dy: sp.csr_array
    u: sp.csr_array
    du: sp.csr_array


@dataclass(frozen=True)
class _Equations:
    """The descriptor system G w + E w' + F u = 0 with maps from primaries to branch quantities."""

    G: sp.csr_array
    E: sp.csr_array
    F: sp.csr_array
    vmap: sp.csr_array  # branch voltages from primaries
    imap: sp.csr_array  # branch currents from primaries
    G_data: sp.csr_array  # the element-value part of G (G minus the topology's ±1)


@dataclass(frozen=True)
class Formulation:
    """A compiled netlist with the normal tree that produced it.

    The tree depends only on the topology, so a sweep (:func:`recompile`)
    and the symbolic path (:mod:`netlistdyn.symbolic`) reuse it.
    """

    netlist: Netlist
    circuit: CircuitGraph
    tree: TreeSplit
    probes: tuple[Probe, ...]
    model: StateSpaceModel


def compile_netlist(netlist: Netlist, outputs: Sequence[str] | None = None) -> StateSpaceModel:
    """Compile a parsed netlist to a state-space model.

    Parameters
    ----------
    netlist : Netlist
        Parsed netlist.
    outputs : sequence of str, optional
        Output specifications (``v(n)``, ``v(a,b)``, ``i(elem)``); default:
        every non-ground node voltage.

    Returns
    -------
    StateSpaceModel

    Raises
    ------
    NetlistError
        For inconsistent topologies or singular circuits.
    UsageError
        For output specifications that name unknown nodes or elements.
    """
    return formulate(netlist, outputs).model


def formulate(netlist: Netlist, outputs: Sequence[str] | None = None) -> Formulation:
    """Choose the normal tree and compile; see :func:`compile_netlist`.

    Candidate trees are tried in order of decreasing state count: a tree
    that compiles gives the circuit's true order (the reduction is exact), a
    tree with too many states meets a singular capacitance/inductance
    matrix, one with too few meets derivatives it cannot eliminate.
    A nonlinear netlist (diodes, nonlinear behavioural sources) is compiled
    as its linearisation at the DC operating point (:mod:`netlistdyn.nonlinear`).
    """
    if netlist.is_nonlinear:
        from .nonlinear import linearised

        netlist, outputs = linearised(netlist, outputs)
    probes = (
        tuple(parse_probe(text, netlist) for text in outputs) if outputs else tuple(default_probes(netlist))
    )
    check_value_range(netlist)
    failure: NetlistError | None = None
    topology: TopologyError | None = None
    for circuit, tree in tree_candidates(netlist):
        try:
            model = _compile_on_tree(netlist, circuit, tree, probes)
        except TopologyError as exc:  # a source loop or cutset: the same on every tree
            topology = topology or exc
            continue
        except (SingularCircuitError, NotSupportedError, OutputDerivativeError) as exc:
            failure = failure or exc
            continue
        return Formulation(netlist, circuit, tree, probes, model)
    error = topology or failure
    assert error is not None
    raise error


class OutputDerivativeError(UsageError):
    """An output needs second derivatives of the circuit variables on this tree."""


def _compile_on_tree(
    netlist: Netlist, circuit: CircuitGraph, tree: TreeSplit, probes: Sequence[Probe]
) -> StateSpaceModel:
    check_sources(circuit, tree)
    equations = assemble(netlist, circuit, tree)
    classes = classify(circuit, tree, netlist)
    held = held_displacements(netlist, probes)
    if not held:
        model = reduce_to_state_space(netlist, circuit, tree, equations, classes, probes)
        return add_displacements(model, probes)
    # Positions that springs hold are sums of spring fluxes (L·i + Σ M·i): computed from the
    # currents of the inductors on the path, which are appended as hidden outputs.
    keys = sorted({key for _, path in held.values() for key, _ in path} | _partners(netlist, held))
    hidden = tuple(Probe("i", f"i({key})", element=key) for key in keys)
    full = reduce_to_state_space(netlist, circuit, tree, equations, classes, (*probes, *hidden))
    rows = _flux_rows(netlist, full, len(probes), keys, held)
    p = len(probes)
    model = StateSpaceModel(
        full.A_sparse,
        full.B_sparse,
        _replace_rows(full.C_sparse, rows[0], p),
        _replace_rows(full.D_sparse, rows[1], p),
        _replace_rows(full.D1_sparse, rows[2], p),
        full.states,
        full.inputs,
        full.outputs[:p],
        full.title,
        full.info,
        pencil=full.pencil,
    )
    unheld = [Probe("v", pr.name, pr.nodes) if j in held else pr for j, pr in enumerate(probes)]
    model = add_displacements(model, unheld)
    based = {j: base for j, (base, _) in held.items() if base is not None}
    if not based:
        return model
    # x(a) = x(c) + (x(a) − x(c)): a position in a free chain of springs is another's plus fluxes.
    C, D, D1 = (sp.lil_array(m) for m in (model.C_sparse, model.D_sparse, model.D1_sparse))
    for j, base in based.items():
        for matrix in (C, D, D1):
            matrix[[j], :] = matrix[[j], :].toarray() + matrix[[base], :].toarray()
    return replace(
        model, C_sparse=_clean(C.tocsr()), D_sparse=_clean(D.tocsr()), D1_sparse=_clean(D1.tocsr())
    )


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


def _partners(netlist: Netlist, held: dict[int, tuple[int | None, list[tuple[str, int]]]]) -> set[str]:
    """Inductors coupled to those on a held path (their currents enter the flux)."""
    on_path = {key for _, path in held.values() for key, _ in path}
    out: set[str] = set()
    for e in netlist.elements:
        if e.kind is Kind.COUPLING and e.coupled is not None and set(e.coupled) & on_path:
            out |= set(e.coupled)
    return out


def _flux_rows(
    netlist: Netlist,
    full: StateSpaceModel,
    p: int,
    keys: list[str],
    held: dict[int, tuple[int | None, list[tuple[str, int]]]],
) -> tuple[dict[int, sp.csr_array], dict[int, sp.csr_array], dict[int, sp.csr_array]]:
    """Rows of C, D, D1 for each held displacement: Σ sign·(L·i + Σ M·i_other) over its path."""
    column = {key: p + k for k, key in enumerate(keys)}
    by_key = {e.key: e for e in netlist.elements}
    mutual: dict[str, list[tuple[str, float]]] = {}
    for e in netlist.elements:
        if e.kind is Kind.COUPLING and e.coupled is not None:
            a, b = e.coupled
            m = _numeric_mutual(e, by_key[a], by_key[b])
            mutual.setdefault(a, []).append((b, m))
            mutual.setdefault(b, []).append((a, m))
    out: tuple[dict[int, sp.csr_array], ...] = ({}, {}, {})
    for j, (_, path) in held.items():
        weights: dict[str, float] = {}
        for key, sign in path:
            weights[key] = weights.get(key, 0.0) + sign * by_key[key].value
            for other, m in mutual.get(key, ()):
                weights[other] = weights.get(other, 0.0) + sign * m
        select = sp.csr_array(
            (list(weights.values()), ([0] * len(weights), [column[k] for k in weights])),
            shape=(1, full.noutputs),
        )
        for target, matrix in zip(out, (full.C_sparse, full.D_sparse, full.D1_sparse), strict=True):
            target[j] = sp.csr_array(select @ matrix)
    return out  # type: ignore[return-value]


def _replace_rows(matrix: sp.csr_array, rows: dict[int, sp.csr_array], p: int) -> sp.csr_array:
    """The first p rows of matrix, with the given rows replaced."""
    lil = sp.lil_array(matrix[:p, :])
    for j, row in rows.items():
        lil[[j], :] = row.toarray()
    return _clean(lil.tocsr())


def recompile(formulation: Formulation, netlist: Netlist) -> StateSpaceModel:
    """Compile the same circuit with other element values, on the same normal tree.

    Parameters
    ----------
    formulation : Formulation
        A compiled case of the circuit.
    netlist : Netlist
        The circuit again (same elements and nodes), with new values — as
        a sweep produces by re-reading the netlist with other ``.param``
        values.

    Returns
    -------
    StateSpaceModel
        When the topology differs, or the new values make the old tree's
        equations singular, the circuit is compiled from scratch instead.
    """
    old = formulation.netlist.elements
    same = len(old) == len(netlist.elements) and all(
        (a.key, a.kind, a.nodes, a.control_nodes, a.control_source, a.coupled)
        == (b.key, b.kind, b.nodes, b.control_nodes, b.control_source, b.coupled)
        for a, b in zip(old, netlist.elements, strict=True)
    )
    if not same:
        return compile_netlist(netlist, [p.name for p in formulation.probes])
    by_key = {e.key: e for e in netlist.elements}
    circuit = replace(
        formulation.circuit,
        branches=tuple(replace(b, element=by_key[b.element.key]) for b in formulation.circuit.branches),
    )
    try:
        return _compile_on_tree(netlist, circuit, formulation.tree, formulation.probes)
    except (SingularCircuitError, NotSupportedError):
        return compile_netlist(netlist, [p.name for p in formulation.probes])


#: Up to this many transformers every orientation is tried; above, a greedy search.
EXHAUSTIVE_TRANSFORMERS = 8


def tree_candidates(netlist: Netlist) -> list[tuple[CircuitGraph, TreeSplit]]:
    """Normal trees to try, best first.

    Without transformers there is one. An ideal transformer (gear, lever,
    motor) needs exactly one port in the tree: that port is voltage-defined
    (like a controlled voltage source) and the other current-defined. Which
    port goes in the tree decides which capacitors and inductors end up as
    states, so every orientation is tried (greedily above
    :data:`EXHAUSTIVE_TRANSFORMERS`) and ranked by the number of states it
    gives — the order of complexity is the largest — preferring the default
    orientation (first port in the tree) on ties.
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
        for count, circuit, tree in _transformer_trees(netlist, keys, resistive, states_of):
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
) -> list[tuple[int, CircuitGraph, TreeSplit]]:
    """Normal trees over the transformer orientations (exhaustive, or greedy above the limit)."""

    def attempt(swapped: frozenset[str]) -> tuple[int, CircuitGraph, TreeSplit] | None:
        circuit = build_graph(netlist, swapped, resistive)
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
    """
    laws = BranchLaws([], [], [], [], [], [])
    inputs = {e.key: j for j, e in enumerate(netlist.sources)}
    branch_of = {b.element.key: b.index for b in circuit.branches if b.element.kind is not Kind.TRANSFORMER}
    for branch in circuit.branches:
        k, element = branch.index, branch.element
        kind = element.kind
        if kind is Kind.RESISTOR:  # v − R i = 0
            laws.v.append((k, k, 1))
            laws.i.append((k, k, -value(element)))
        elif kind is Kind.CAPACITOR:  # i − C v' = 0
            laws.i.append((k, k, 1))
            laws.dv.append((k, k, -value(element)))
        elif kind is Kind.INDUCTOR:  # v − L i' − Σ M i'_other = 0
            laws.v.append((k, k, 1))
            laws.di.append((k, k, -value(element)))
        elif kind in (Kind.VSOURCE, Kind.ISOURCE):  # v − u = 0 or i − u = 0
            (laws.v if kind is Kind.VSOURCE else laws.i).append((k, k, 1))
            laws.u.append((k, inputs[element.key], -1))
        elif kind in (Kind.VCVS, Kind.VCCS):  # v (or i) − gain·(v_a − v_b) = 0
            assert element.control_nodes is not None
            (laws.v if kind is Kind.VCVS else laws.i).append((k, k, 1))
            laws.control.append((k, element.control_nodes, -value(element)))
        elif kind in (Kind.CCCS, Kind.CCVS):  # i (or v) − gain·i_control = 0
            assert element.control_source is not None
            (laws.i if kind is Kind.CCCS else laws.v).append((k, k, 1))
            laws.i.append((k, branch_of[element.control_source], -value(element)))
        elif kind is Kind.TRANSFORMER:
            # Port 1: v1 − N v2 = 0.  Port 2: i2 + N i1 = 0 (lossless: v1 i1 + v2 i2 = 0).
            if branch.port == 0:
                laws.v.extend([(k, k, 1), (k, k + 1, -value(element))])
            else:
                laws.i.extend([(k, k, 1), (k, k - 1, value(element))])
        else:  # pragma: no cover - the parser admits no other kinds
            raise AssertionError(kind)
    index = {b.element.key: b.index for b in circuit.branches if b.element.kind is Kind.INDUCTOR}
    for element in netlist.elements:
        if element.kind is Kind.COUPLING:
            assert element.coupled is not None
            a, b = (index[name] for name in element.coupled)
            m = mutual(element, circuit.branches[a].element, circuit.branches[b].element)
            laws.di.extend([(a, b, -m), (b, a, -m)])
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
            a, b = (pos[name] for name in k.coupled)
            m = _numeric_mutual(k, inductors[names[a]], inductors[names[b]])
            matrix[a, b] += m
            matrix[b, a] += m
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


def _triplets(entries: list[tuple[int, int, Any]], shape: tuple[int, int]) -> sp.csr_array:
    if not entries:
        return sp.csr_array(shape)
    rows, cols, vals = zip(*entries, strict=True)
    return sp.csr_array((np.asarray(vals, dtype=float), (rows, cols)), shape=shape)


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


def assemble(netlist: Netlist, circuit: CircuitGraph, tree: TreeSplit) -> _Equations:
    """Write one constitutive equation per branch over the primary unknowns.

    Parameters
    ----------
    netlist : Netlist
    circuit : CircuitGraph
    tree : TreeSplit

    Returns
    -------
    _Equations
        ``G w + E w' + F u = 0`` with ``vmap``/``imap`` giving every branch
        voltage and current from ``w``.
    """
    n = circuit.nbranches
    vmap, imap = primary_maps(tree)
    laws = branch_laws(netlist, circuit, lambda e: e.value, _numeric_mutual)
    G, E = _law_matrices(laws, tree, vmap, imap)
    # The same laws with every element value set to 0 leave the topology's ±1: the rest of G
    # is made of element values (R, gains, turns ratios), the part a value's rounding perturbs.
    structure = branch_laws(netlist, circuit, lambda e: 0.0, lambda *_: 0.0)
    G_topology, _ = _law_matrices(structure, tree, vmap, imap)
    F = _triplets(laws.u, (n, len(netlist.sources)))
    return _Equations(_clean(G), _clean(E), F, vmap, imap, _clean(G - G_topology))


def _law_matrices(
    laws: BranchLaws, tree: TreeSplit, vmap: sp.csr_array, imap: sp.csr_array
) -> tuple[sp.csr_array, sp.csr_array]:
    """G and E of ``G w + E w' + F u = 0`` from the branch laws and the primary maps."""
    n = vmap.shape[0]
    G = _triplets(laws.v, (n, n)) @ vmap + _triplets(laws.i, (n, n)) @ imap
    if laws.control:
        ctrl = _potential_rows(tree, [pair for _, pair, _ in laws.control], n)
        place = _triplets(
            [(row, j, gain) for j, (row, _, gain) in enumerate(laws.control)], (n, len(laws.control))
        )
        G = G + place @ ctrl
    E = _triplets(laws.dv, (n, n)) @ vmap + _triplets(laws.di, (n, n)) @ imap
    return sp.csr_array(G), sp.csr_array(E)


def classify(circuit: CircuitGraph, tree: TreeSplit, netlist: Netlist) -> Classes:
    """Sort the primaries into states, sources, excess elements and the rest."""
    inputs = {e.key: j for j, e in enumerate(netlist.sources)}
    x_caps, x_inds, s, d, y, source_input = [], [], [], [], [], []
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


def _clean(matrix: sp.sparray) -> sp.csr_array:
    """CSR copy without explicit zeros.

    Only exact zeros go: element values span many decades (1 fF beside
    1 kH), so no threshold relative to a matrix's largest entry can tell a
    small coefficient from rounding noise, and dropping a real one would
    silently change the model.
    """
    out = sp.csr_array(matrix, dtype=float)
    out.eliminate_zeros()
    return out


def _cols(matrix: sp.csr_array, index: np.ndarray) -> sp.csr_array:
    return sp.csr_array(matrix[:, index]) if len(index) else sp.csr_array((matrix.shape[0], 0))


def _rows(matrix: sp.csr_array, index: np.ndarray) -> sp.csr_array:
    return sp.csr_array(matrix[index, :]) if len(index) else sp.csr_array((0, matrix.shape[1]))


def _eliminate_sources_and_excess(
    G: sp.csr_array, E: sp.csr_array, F: sp.csr_array, full: _Equations, classes: Classes, m: int
) -> _Block:
    """Substitute source primaries (= inputs) and excess-element primaries (derivatives).

    Parameters
    ----------
    G, E, F : scipy.sparse.csr_array
        Rows to transform (coefficients of w, w' and u).
    full : _Equations
        The whole system (for the excess elements' defining rows).
    classes : Classes
    m : int
        Number of inputs.
    """
    unit = sp.csr_array(
        (np.ones(len(classes.s)), (np.arange(len(classes.s)), classes.source_input)),
        shape=(len(classes.s), m),
    )
    u = F + _cols(G, classes.s) @ unit
    du = _cols(E, classes.s) @ unit
    dx, dy = _cols(E, classes.x), _cols(E, classes.y)
    if len(classes.d):
        # Excess rows read w_d + E_d w' = 0, so w_d = −E_d w' (never another excess primary).
        # Where a substituted term cancels an existing one, the difference is zero up to rounding:
        # judged against the magnitudes that were added, never against a unit-dependent level.
        e_d = _rows(full.E, classes.d)
        g_d = _cols(G, classes.d)
        e_du = _cols(e_d, classes.s) @ unit
        dx = _cancelled(dx, g_d, _cols(e_d, classes.x))
        dy = _cancelled(dy, g_d, _cols(e_d, classes.y))
        du = _cancelled(du, g_d, e_du)
    return _Block(_cols(G, classes.x), _cols(G, classes.y), _clean(dx), _clean(dy), _clean(u), _clean(du))


#: A sum is exactly zero when it is below this multiple of eps times the sum of its terms' magnitudes.
CANCELLATION = 16 * float(np.finfo(float).eps)


def _cancelled(base: sp.csr_array, left: sp.csr_array, right: sp.csr_array) -> sp.csr_array:
    """base − left @ right, with entries that cancel to rounding level set to exactly zero."""
    value = sp.coo_array(sp.csr_array(base - left @ right))
    if value.nnz == 0:
        return sp.csr_array(value.shape)
    bound = sp.csr_array(abs(sp.csr_array(base)) + abs(sp.csr_array(left)) @ abs(sp.csr_array(right)))
    magnitude = np.asarray(bound[value.row, value.col]).ravel()
    keep = np.abs(value.data) > CANCELLATION * magnitude
    return sp.csr_array((value.data[keep], (value.row[keep], value.col[keep])), shape=value.shape)


def _negligible(left: sp.csr_array, right: sp.csr_array) -> bool:
    """True when every entry of left @ right is rounding noise relative to |left| @ |right|.

    ``right`` comes from a sparse solve, so its entries carry relative errors
    up to about the condition number times eps; a product that cancels to
    below :data:`PRODUCT_ZERO` of its terms' magnitudes is zero. The test is
    relative entry by entry, so it does not depend on units.
    """
    product = sp.coo_array(sp.csr_array(left @ right))
    if product.nnz == 0:
        return True
    bound = sp.csr_array(abs(sp.csr_array(left)) @ abs(sp.csr_array(right)))
    magnitude = np.asarray(bound[product.row, product.col]).ravel()
    return bool(np.all(np.abs(product.data) <= PRODUCT_ZERO * magnitude))


#: Relative level below which a product of solved matrices is taken as zero (see _negligible).
PRODUCT_ZERO = 1e-8


#: Largest resistive system for which derivatives of algebraic unknowns are resolved (dense SVD).
ALGEBRAIC_DERIVATIVE_LIMIT = 3000


def _substitute_algebraic_derivatives(yb: _Block, involved: list[str], netlist: Netlist) -> _Block:
    """Replace derivatives of resistive unknowns that the derivative-free rows fix.

    An excess capacitor in a loop with a controlled voltage-type branch (a
    VCVS, or a transformer port: rigidly geared inertias) puts the
    derivative of that branch's voltage into the resistive equations. When
    the rows without derivatives determine those unknowns from states and
    inputs alone (y_Z = S_x x + S_u u, checked through the null space), their
    derivatives are S_x x' + S_u u' and the system stays first order.
    """
    dy = yb.dy.tocsc()
    z = np.flatnonzero(np.diff(dy.indptr))
    dynamic = (np.diff(yb.dx.indptr) + np.diff(yb.dy.indptr) + np.diff(yb.du.indptr)) > 0
    rows = np.flatnonzero(~dynamic)
    n_y = yb.y.shape[1]
    unsupported = NotSupportedError(
        "a controlled source or transformer depends on the derivative of a resistive quantity "
        f"({', '.join(involved) or 'check the controlled sources'}); not supported",
        netlist.elements[0].loc,
    )
    if n_y > ALGEBRAIC_DERIVATIVE_LIMIT or len(rows) == 0:
        raise unsupported
    # Judged on the equilibrated rows (every row and column peaking at 1), so that the rank and
    # residual decisions do not depend on the units of the unknowns.
    r_scale, c_scale = _equilibrate(sp.csr_array(yb.y.toarray()[rows]))
    g = r_scale[:, None] * yb.y.toarray()[rows] * c_scale[None, :]
    rhs = -r_scale[:, None] * np.hstack([yb.x.toarray()[rows], yb.u.toarray()[rows]])
    scaled_solution, *_ = np.linalg.lstsq(g, rhs, rcond=None)
    if np.linalg.norm(g @ scaled_solution - rhs) > 1e-9 * max(np.linalg.norm(rhs), 1e-300):
        raise unsupported
    kernel = sla.null_space(g, rcond=1e-12) if g.shape[0] else np.eye(n_y)
    if kernel.size and np.max(np.abs(kernel[z])) > 1e-9:
        raise unsupported  # the derivative-free rows leave y_Z undetermined
    solution = c_scale[:, None] * scaled_solution
    nx_ = yb.x.shape[1]
    s_x = sp.csr_array(solution[z, :nx_])
    s_u = sp.csr_array(solution[z, nx_:])
    dy_z = sp.csr_array(dy[:, z])
    return _Block(
        yb.x,
        yb.y,
        _clean(yb.dx + dy_z @ s_x),
        sp.csr_array(yb.dy.shape),
        yb.u,
        _clean(yb.du + dy_z @ s_u),
    )


def _equilibrate(matrix: sp.csr_array) -> tuple[np.ndarray, np.ndarray]:
    """Row and column scalings r, c making every row and column of diag(r)·M·diag(c) peak at 1.

    Element values span many decades (1 fF next to 1 kH): singularity is
    judged on the equilibrated matrix, as LAPACK's expert drivers do.
    """
    abs_m = abs(sp.csr_array(matrix))
    row_max = abs_m.max(axis=1).toarray().ravel()
    r = np.where(row_max > 0, 1.0 / np.where(row_max > 0, row_max, 1.0), 1.0)
    col_max = (sp.diags_array(r) @ abs_m).max(axis=0).toarray().ravel()
    c = np.where(col_max > 0, 1.0 / np.where(col_max > 0, col_max, 1.0), 1.0)
    return r, c


def _solve(matrix: sp.csr_array, rhs: sp.csr_array, what: str) -> sp.csr_array:
    """matrix⁻¹ rhs for a square sparse matrix, refusing (near-)singular ones.

    The matrix is equilibrated first (rows, then columns, scaled to unit
    maximum); diagonal matrices are then inverted directly, small ones
    densely with LAPACK's reciprocal condition estimate, large ones with
    SuperLU.
    """
    n = matrix.shape[0]
    if n == 0 or rhs.shape[1] == 0:
        return sp.csr_array((n, rhs.shape[1]))
    r, c = _equilibrate(matrix)
    scaled = sp.csr_array(sp.diags_array(r) @ matrix @ sp.diags_array(c))
    rhs_scaled = sp.csr_array(sp.diags_array(r) @ rhs)
    return _clean(sp.diags_array(c) @ _solve_equilibrated(scaled, rhs_scaled, what))


def _solve_equilibrated(matrix: sp.csr_array, rhs: sp.csr_array, what: str) -> sp.csr_array:
    n = matrix.shape[0]
    coo = matrix.tocoo()
    if np.all(coo.row == coo.col) and coo.nnz == n:
        diag = matrix.diagonal()
        if np.min(np.abs(diag)) <= SINGULAR_RCOND * np.max(np.abs(diag)):
            raise SingularCircuitError(what)
        return _clean(sp.diags_array(1.0 / diag) @ rhs)
    if n <= 1500:
        dense = matrix.toarray()
        with warnings.catch_warnings():
            warnings.simplefilter("error", sla.LinAlgWarning)
            try:
                lu = sla.lu_factor(dense)
            except (sla.LinAlgError, sla.LinAlgWarning, ValueError):
                raise SingularCircuitError(what) from None
        rcond = _rcond(dense, lu)
        if rcond < SINGULAR_RCOND:
            raise SingularCircuitError(what)
        return _clean(sp.csr_array(sla.lu_solve(lu, rhs.toarray())))
    try:
        lu_sparse = spla.splu(sp.csc_matrix(matrix))
    except RuntimeError:
        raise SingularCircuitError(what) from None
    pivots = np.abs(lu_sparse.U.diagonal())
    if pivots.min() <= SINGULAR_RCOND * pivots.max():
        raise SingularCircuitError(what)
    rhs_csc = sp.csc_array(rhs)
    nonzero_cols = np.flatnonzero(np.diff(rhs_csc.indptr))
    result = sp.lil_array((n, rhs.shape[1]))
    for start in range(0, len(nonzero_cols), 256):
        cols = nonzero_cols[start : start + 256]
        result[:, cols] = lu_sparse.solve(rhs_csc[:, cols].toarray())
    return _clean(result)


def _rcond(dense: np.ndarray, lu: tuple[np.ndarray, np.ndarray]) -> float:
    anorm = np.linalg.norm(dense, 1)
    if anorm == 0:
        return 0.0
    (gecon,) = sla.get_lapack_funcs(("gecon",), (lu[0],))
    rcond, _ = gecon(lu[0], anorm, norm="1")
    return float(rcond)


def reduce_to_state_space(
    netlist: Netlist,
    circuit: CircuitGraph,
    tree: TreeSplit,
    equations: _Equations,
    classes: Classes,
    probes: Sequence[Probe],
) -> StateSpaceModel:
    """Eliminate everything but the states and build A, B, C, D, D1.

    See the module docstring for the algebra.
    """
    m = len(netlist.sources)
    G, E, F = equations.G, equations.E, equations.F
    involved = _controlled_labels(netlist)

    yb = _eliminate_sources_and_excess(
        _rows(G, classes.y), _rows(E, classes.y), _rows(F, classes.y), equations, classes, m
    )
    if yb.dy.nnz:
        yb = _substitute_algebraic_derivatives(yb, involved, netlist)
    resistive_msg = "the resistive part of the circuit has no unique solution for these values" + (
        f" (check {', '.join(involved)})" if involved else " (check negative resistances)"
    )
    rhs = sp.hstack([yb.x, yb.dx, yb.u, yb.du], format="csr")
    where = _first_location(netlist, involved)
    try:
        solved = -_solve(yb.y, rhs, resistive_msg) if yb.y.shape[0] else sp.csr_array((0, rhs.shape[1]))
    except SingularCircuitError as exc:
        raise SingularCircuitError(exc.message, where) from None
    nx_ = len(classes.x)
    splits = np.cumsum([nx_, nx_, m])
    P = _clean(solved[:, : splits[0]])
    R = _clean(solved[:, splits[0] : splits[1]])
    Q = _clean(solved[:, splits[1] : splits[2]])
    S = _clean(solved[:, splits[2] :])

    xb = _eliminate_sources_and_excess(
        _rows(G, classes.x), _rows(E, classes.x), _rows(F, classes.x), equations, classes, m
    )
    if not (_negligible(xb.dy, R) and _negligible(xb.dy, S)):
        raise NotSupportedError(
            "the circuit needs second derivatives of its variables (higher index); not supported",
            netlist.elements[0].loc,
        )
    mass = _clean(xb.dx + xb.dy @ P + xb.y @ R)
    n0 = _clean(xb.x + xb.y @ P)
    nu = _clean(xb.u + xb.y @ Q)
    nud = _clean(xb.du + xb.dy @ Q + xb.y @ S)
    mass_msg = (
        "the capacitance/inductance matrix is singular for these values: the states are not "
        "independent" + (f" (check {', '.join(involved)})" if involved else " (check negative values)")
    )
    try:
        solved_x = -_solve(mass, sp.hstack([n0, nu, nud], format="csr"), mass_msg)
    except SingularCircuitError as exc:
        raise SingularCircuitError(exc.message, where) from None
    A = _clean(solved_x[:, :nx_])
    B = _clean(solved_x[:, nx_ : nx_ + m])
    K = _clean(solved_x[:, nx_ + m :])

    C, D, D1 = _outputs(probes, netlist, circuit, tree, equations, classes, (P, Q, R, S), (A, B, K), m)

    # From x to the shifted state z = x − K u: z' = A z + (B + A K) u, y = C z + (D + C K) u + D1 u'.
    B_z = _clean(B + A @ K)
    D_z = _clean(D + C @ K)

    # Capacitor voltages → charges: q = C v.
    scale_vec = np.array(
        [
            circuit.branches[k].element.value if circuit.branches[k].element.kind is Kind.CAPACITOR else 1.0
            for k in classes.x
        ]
    )
    T = sp.diags_array(scale_vec)
    T_inv = sp.diags_array(1.0 / scale_vec) if nx_ else sp.csr_array((0, 0))
    A_q = _clean(T @ A @ T_inv)
    B_q = _clean(T @ B_z)
    C_q = _clean(C @ T_inv)
    K_q = _clean(T @ K)

    _check_finite(netlist, {"A": A_q, "B": B_q, "C": C_q, "D": D_z, "D1": D1})
    states = tuple(state_name(circuit.branches[k].element) for k in classes.x)
    inputs = tuple(e.name for e in netlist.sources)
    info = CompileInfo(
        order=nx_,
        tree=tuple(b.label for b in circuit.branches if tree.in_tree[b.index]),
        excess=_excess(circuit, tree, classes),
        shifts=_shifts(K_q, states, inputs),
        warnings=netlist.warnings + check_couplings(netlist),
        passive=is_passive(netlist) and not check_couplings(netlist),
    )
    return StateSpaceModel(
        sp.csr_array(A_q),
        sp.csr_array(B_q),
        sp.csr_array(C_q),
        sp.csr_array(D_z),
        sp.csr_array(D1),
        states,
        inputs,
        tuple(p.name for p in probes),
        netlist.title,
        info,
        pencil=Pencil(G, E, nx_, equations.G_data),
    )


def _check_finite(netlist: Netlist, matrices: dict[str, sp.csr_array]) -> None:
    """Refuse a model with overflowed (infinite or NaN) entries, naming the most extreme value.

    Element values near the ends of double precision (1e-308 Ω) make
    products such as 1/(R·C) overflow; a model holding ``inf`` would be
    a wrong number, not a model.
    """
    bad = [name for name, m in matrices.items() if m.nnz and not np.all(np.isfinite(m.data))]
    if not bad:
        return
    valued = [e for e in netlist.elements if e.value != 0 and np.isfinite(e.value)]
    worst = max(valued, key=lambda e: abs(np.log10(abs(e.value))), default=netlist.elements[0])
    raise NetlistError(
        f"{worst.label}: value {worst.value:g} overflows double precision in the model "
        f"({', '.join(bad)} would hold infinite entries); use values within about 1e-150…1e150",
        worst.loc,
    )


def _outputs(
    probes: Sequence[Probe],
    netlist: Netlist,
    circuit: CircuitGraph,
    tree: TreeSplit,
    equations: _Equations,
    classes: Classes,
    y_solution: tuple[sp.csr_array, ...],
    state_solution: tuple[sp.csr_array, ...],
    m: int,
) -> tuple[sp.csr_array, sp.csr_array, sp.csr_array]:
    """C, D, D1 in the unshifted voltage/current states x (see reduce_to_state_space)."""
    P, Q, R, S = y_solution
    A, B, K = state_solution
    n = circuit.nbranches
    if not probes:
        empty = sp.csr_array((0, len(classes.x)))
        return empty, sp.csr_array((0, m)), sp.csr_array((0, m))
    # Voltage-type outputs in one sparse matrix (one per probe is slow for thousands of nodes).
    across = [j for j, p in enumerate(probes) if p.kind in ("v", "x")]  # x(n) integrated later
    potentials = _potential_rows(tree, [probes[j].nodes for j in across], n)
    place = sp.csr_array(
        (np.ones(len(across)), (across, range(len(across)))), shape=(len(probes), len(across))
    )
    c_w = sp.csr_array(place @ potentials)
    through = [j for j, p in enumerate(probes) if p.kind not in ("v", "x")]
    if through:
        key_branch: dict[str, int] = {}
        for b in circuit.branches:  # a two-port's current is its first port's
            key_branch.setdefault(b.element.key, b.index)
        scale = np.ones(len(through))
        for r, j in enumerate(through):
            if probes[j].kind == "angle":
                # i = k (x_pivot − x_bob) with L = 1/k, so angle = (x_bob − x_pivot)/l = −L i / l.
                rod = circuit.branches[key_branch[probes[j].element]].element
                assert rod.rod is not None
                scale[r] = -rod.value / rod.rod.length
        picks = [key_branch[probes[j].element] for j in through]
        currents = sp.diags_array(scale) @ sp.csr_array(equations.imap[picks, :])
        place = sp.csr_array(
            (np.ones(len(through)), (through, range(len(through)))), shape=(len(probes), len(through))
        )
        c_w = sp.csr_array(c_w + place @ currents)
    zeros_e = sp.csr_array(c_w.shape)
    block = _eliminate_sources_and_excess(c_w, zeros_e, sp.csr_array((len(probes), m)), equations, classes, m)
    c_x = block.x + block.y @ P
    c_dx = block.dx + block.y @ R
    c_u = block.u + block.y @ Q
    c_du = block.du + block.y @ S
    if block.dy.nnz:
        if not (_negligible(block.dy, R) and _negligible(block.dy, S)):
            raise OutputDerivativeError(
                "an output needs second derivatives of the circuit variables; not supported"
            )
        c_dx = c_dx + block.dy @ P
        c_du = c_du + block.dy @ Q
    C = _clean(c_x + c_dx @ A)
    D = _clean(c_u + c_dx @ B)
    D1 = _clean(c_du + c_dx @ K)
    return C, D, D1


def add_displacements(model: StateSpaceModel, probes: Sequence[Probe]) -> StateSpaceModel:
    """Integrate the velocity rows of ``x(...)`` outputs into displacement states.

    Only the displacements a user asks for get a state (named like the
    output): z' = C_v x + D_v u, and the output is z + D1_v u, so a velocity
    with an input-derivative term integrates exactly.
    """
    picks = [j for j, p in enumerate(probes) if p.kind == "x"]
    if not picks:
        return model
    k = len(picks)
    C, D, D1 = model.C_sparse, model.D_sparse, model.D1_sparse
    rows_c, rows_d, rows_d1 = sp.csr_array(C[picks, :]), sp.csr_array(D[picks, :]), sp.csr_array(D1[picks, :])
    A = sp.block_array([[model.A_sparse, None], [rows_c, sp.csr_array((k, k))]], format="csr")
    B = sp.vstack([model.B_sparse, rows_d], format="csr")
    select = sp.csr_array((np.ones(k), (picks, np.arange(k))), shape=(model.noutputs, k))
    keep = sp.diags_array(np.array([0.0 if j in picks else 1.0 for j in range(model.noutputs)]))
    C_new = sp.hstack([keep @ C, select], format="csr")
    D_new = _clean(keep @ D + select @ rows_d1)
    D1_new = _clean(keep @ D1)
    names = tuple(probes[j].name for j in picks)
    info = replace(model.info, integrators=names)
    return StateSpaceModel(
        _clean(A),
        _clean(B),
        _clean(C_new),
        D_new,
        D1_new,
        (*model.states, *names),
        model.inputs,
        model.outputs,
        model.title,
        info,
        pencil=model.pencil,
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
