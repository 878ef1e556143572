"""Circuit graph and normal tree.

The circuit is a :class:`networkx.MultiGraph` whose edges are *branches*:
one per two-terminal element and per port of a two-port (the output port of
a controlled source; both ports of an ideal transformer). Algorithms are
free functions over the small :class:`CircuitGraph` record, as in networkx.

A **normal tree** is a spanning tree chosen by branch priority
(:class:`Role`): voltage sources, controlled voltage-type ports, capacitors,
resistors, inductors, controlled current-type ports, current sources. Every
link's fundamental loop then holds only tree branches of equal or higher
priority, and every tree branch's fundamental cutset only links of equal or
lower priority — which is what lets :mod:`netlistdyn.formulate` take tree
capacitor charges and link inductor currents as states.

Sign conventions: a branch runs from ``pos`` (n+) to ``neg`` (n-); its
voltage is v(pos) − v(neg) and its current flows from pos to neg through
the element (SPICE's convention for every element, sources included).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import networkx as nx
import numpy as np
import scipy.sparse as sp

from netlistdyn.base.errors import TopologyError
from netlistdyn.circuit.checks import check_references
from netlistdyn.circuit.netlist import GROUND, Element, Kind, Netlist
from netlistdyn.devices.registry import REGISTRY, Registry
from netlistdyn.devices.traits import Role


@dataclass(frozen=True, slots=True)
class Branch:
    """One edge of the circuit graph.

    Attributes
    ----------
    index : int
        Position in :attr:`CircuitGraph.branches`; also the column of the
        branch's primary unknown in the formulation.
    element : Element
        The element the branch belongs to.
    port : int
        0 for two-terminal elements; 0 or 1 for the ports of a two-port.
    pos, neg : str
        Node names (n+, n-).
    role : Role
        Tree priority.
    """

    index: int
    element: Element
    port: int
    pos: str
    neg: str
    role: Role

    @property
    def label(self) -> str:
        """Element label, with the port for two-ports."""
        if self.element.kind is Kind.TRANSFORMER:
            return f"{self.element.label}[{self.port + 1}]"
        return self.element.label


@dataclass(frozen=True)
class CircuitGraph:
    """Branches and nodes of a circuit; ``graph`` is the networkx view.

    The multigraph's edge keys are branch indices, so parallel elements are
    distinct edges. ``devices`` is the registry its elements' laws are looked up in.
    """

    branches: tuple[Branch, ...]
    nodes: tuple[str, ...]
    graph: nx.MultiGraph
    devices: Registry = REGISTRY

    @property
    def nbranches(self) -> int:
        """Number of branches."""
        return len(self.branches)


@dataclass(frozen=True)
class TreeSplit:
    """A normal tree and the fundamental loop matrix it defines.

    Attributes
    ----------
    in_tree : numpy.ndarray of bool
        ``in_tree[k]`` is True when branch k is a tree branch (read-only).
    loops : scipy.sparse.csr_array
        ``(nbranches, nbranches)`` matrix with ``loops[l, t] = ±1`` when tree
        branch t is in the fundamental loop of link l, such that
        v_l = Σ_t loops[l, t] v_t. Rows of tree branches are empty. By
        Tellegen's theorem the tree currents are i_t = −Σ_l loops[l, t] i_l.
    parent : dict
        ``node -> (parent node, branch index, sign)`` of the tree rooted at
        ground, where φ(node) = φ(parent) + sign · v_branch.
    """

    in_tree: np.ndarray
    loops: sp.csr_array
    parent: dict[str, tuple[str, int, int]]

    def potential(self, node: str) -> dict[int, float]:
        """Node voltage against ground as a combination of tree-branch voltages.

        Parameters
        ----------
        node : str
            Canonical node name.

        Returns
        -------
        dict
            ``{tree branch index: coefficient}``.
        """
        coeffs: dict[int, float] = {}
        while node != GROUND:
            up, branch, sign = self.parent[node]
            coeffs[branch] = coeffs.get(branch, 0.0) + sign
            node = up
        return coeffs

    def loop_members(self, link: int) -> list[int]:
        """Tree branches in the fundamental loop of ``link``."""
        row = self.loops[[link], :]
        return [int(k) for k in row.indices]

    def cutset_members(self, tree_branch: int) -> list[int]:
        """Links in the fundamental cutset of ``tree_branch``."""
        col = self.loops[:, [tree_branch]].tocoo()
        return [int(k) for k in col.row]


def build_graph(
    netlist: Netlist,
    swapped: frozenset[str] = frozenset(),
    resistive: frozenset[Kind] = frozenset(),
    devices: Registry = REGISTRY,
) -> CircuitGraph:
    """Make the branch graph of a netlist.

    Parameters
    ----------
    netlist : Netlist
        Parsed netlist.
    swapped : frozenset of str
        Keys of transformers whose second port is to be preferred in the
        tree (see :func:`normal_tree`).
    resistive : frozenset of Kind
        Controlled-source kinds whose output port takes a resistor's tree
        priority instead of a source's: a VCCS driven by its own terminals
        is a conductance, and as a link it would make an inductor in series
        with it an excess element although its current is a state.
    devices : Registry
        Where each element's tree role (:attr:`~netlistdyn.devices.traits.DeviceKind.role`) is looked up.

    Returns
    -------
    CircuitGraph

    Raises
    ------
    TopologyError
        For references to unknown elements and nodes that do not connect to
        ground.
    """
    branches: list[Branch] = []
    for element in netlist.elements:
        if element.kind is Kind.COUPLING:
            continue
        if element.kind is Kind.TRANSFORMER:
            first, second = (Role.ITYPE, Role.VTYPE) if element.key in swapped else (Role.VTYPE, Role.ITYPE)
            p1, n1, p2, n2 = element.nodes
            branches.append(Branch(len(branches), element, 0, p1, n1, first))
            branches.append(Branch(len(branches), element, 1, p2, n2, second))
            continue
        pos, neg = element.nodes
        role = Role.RESISTOR if element.kind in resistive else devices[element.kind].role
        assert role is not None, element.kind  # every two-terminal linear kind has one
        branches.append(Branch(len(branches), element, 0, pos, neg, role))
    graph = nx.MultiGraph()
    graph.add_node(GROUND)
    for branch in branches:
        graph.add_edge(branch.pos, branch.neg, key=branch.index, role=int(branch.role))
    _check_references(netlist, graph)
    _check_grounded(netlist, graph)
    return CircuitGraph(tuple(branches), tuple(graph.nodes), graph, devices)


def _check_references(netlist: Netlist, graph: nx.MultiGraph) -> None:
    """The parser's reference checks again on the compiler's graph: a netlist built in Python, or
    linearised, reaches the compiler without a parse (a coupling joins linear inductors only here)."""
    check_references(netlist, graph, (Kind.INDUCTOR,))


def _check_grounded(netlist: Netlist, graph: nx.MultiGraph) -> None:
    reach = nx.node_connected_component(graph, GROUND)
    floating = [n for n in graph.nodes if n not in reach]
    if not floating:
        return
    culprit = next(e for e in netlist.elements if any(n in floating for n in e.nodes))
    shown = ", ".join(floating[:5]) + (", ..." if len(floating) > 5 else "")
    raise TopologyError(f"{culprit.label}: node(s) {shown} have no path to ground (node 0)", culprit.loc)


def normal_tree(circuit: CircuitGraph) -> TreeSplit:
    """Choose a normal tree and build the fundamental loop matrix.

    Kruskal's algorithm on the branch priorities, then a breadth-first walk from ground for node potentials.

    Parameters
    ----------
    circuit : CircuitGraph

    Returns
    -------
    TreeSplit
    """
    # Ties in netlist order, except inductors in reverse: the tree takes the *last*
    # inductor of a cutset, so the first-listed one stays a link and a state — as the
    # first-listed capacitor of a loop enters the tree and is the state.
    ordered = sorted(
        circuit.branches,
        key=lambda b: (b.role, -b.index if b.role is Role.INDUCTOR else b.index),
    )
    uf = nx.utils.UnionFind(circuit.nodes)
    in_tree = np.zeros(circuit.nbranches, dtype=bool)
    for branch in ordered:
        if uf[branch.pos] != uf[branch.neg]:
            uf.union(branch.pos, branch.neg)
            in_tree[branch.index] = True
    adjacency: dict[str, list[tuple[str, int, int]]] = {n: [] for n in circuit.nodes}
    for branch in circuit.branches:
        if in_tree[branch.index]:
            # Stepping from neg to pos raises the potential by v_branch.
            adjacency[branch.neg].append((branch.pos, branch.index, +1))
            adjacency[branch.pos].append((branch.neg, branch.index, -1))
    parent: dict[str, tuple[str, int, int]] = {}
    depth = {GROUND: 0}
    queue = deque([GROUND])
    while queue:
        node = queue.popleft()
        for other, index, sign in adjacency[node]:
            if other not in depth:
                depth[other] = depth[node] + 1
                parent[other] = (node, index, sign)
                queue.append(other)
    rows: list[int] = []
    cols: list[int] = []
    vals: list[float] = []
    for branch in circuit.branches:
        if in_tree[branch.index]:
            continue
        for index, coeff in _path_difference(branch.pos, branch.neg, parent, depth).items():
            if coeff:
                rows.append(branch.index)
                cols.append(index)
                vals.append(coeff)
    n = circuit.nbranches
    loops = sp.csr_array((vals, (rows, cols)), shape=(n, n))
    in_tree.setflags(write=False)
    return TreeSplit(in_tree, loops, parent)


def _path_difference(
    a: str, b: str, parent: dict[str, tuple[str, int, int]], depth: dict[str, int]
) -> dict[int, float]:
    """φ(a) − φ(b) in tree-branch voltages, climbing only to the common ancestor."""
    coeffs: dict[int, float] = {}
    while a != b:
        if depth[a] >= depth[b]:
            up, index, sign = parent[a]
            coeffs[index] = coeffs.get(index, 0.0) + sign
            a = up
        else:
            up, index, sign = parent[b]
            coeffs[index] = coeffs.get(index, 0.0) - sign
            b = up
    return coeffs


def check_sources(circuit: CircuitGraph, tree: TreeSplit) -> None:
    """Reject loops of voltage sources and cutsets of current sources.

    In a normal tree a voltage-type link closes a loop of voltage-type tree
    branches only, and a current-type tree branch sits in a cutset of
    current-type links only: both make the circuit inconsistent (or its
    solution non-unique), whatever the element values.

    Raises
    ------
    TopologyError
        Naming the elements of the loop or cutset.
    """
    for branch in circuit.branches:
        if branch.element.kind is Kind.TRANSFORMER:
            continue
        if not tree.in_tree[branch.index] and branch.role <= Role.VTYPE:
            members = [circuit.branches[k].label for k in tree.loop_members(branch.index)]
            if not members:
                raise TopologyError(
                    f"{branch.label}: voltage source is short-circuited (both terminals on node "
                    f"{branch.pos!r})",
                    branch.element.loc,
                )
            raise TopologyError(
                f"{branch.label}: loop of voltage sources only ({', '.join([branch.label, *members])})",
                branch.element.loc,
            )
        if tree.in_tree[branch.index] and branch.role >= Role.ITYPE:
            members = [circuit.branches[k].label for k in tree.cutset_members(branch.index)]
            what = ", ".join([branch.label, *members])
            raise TopologyError(
                f"{branch.label}: cutset of current sources only ({what}); "
                "a node or group of nodes is fed only by current sources",
                branch.element.loc,
            )
