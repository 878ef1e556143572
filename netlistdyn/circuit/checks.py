"""The checks every netlist passes before any command works on it.

One pass over the parsed elements, run by the parser at the end of every parse, so that ``analyze``,
``op``, ``simulate`` (linear and nonlinear), ``validate`` and ``sweep`` agree on what a netlist may
reference: a controlling node is a node of the circuit, a controlling element is a voltage source,
a coupling joins two distinct inductors, and every node has a path to ground. (``.ic`` lines are
checked where a transient uses them: Xyce's ``.ic v(x3.b)`` of a subcircuit port does not stop
``analyze``.) Each failure is one :class:`~netlistdyn.base.errors.TopologyError` naming the
element and its line (the messages are those of the linear compiler's graph, which checks the same).
"""

from __future__ import annotations

from collections.abc import Collection, Container

from netlistdyn.base.errors import TopologyError
from netlistdyn.circuit.netlist import GROUND, Element, Kind, Netlist

#: Kinds a coupling ``K`` may join (a nonlinear inductor is refused later, with its own reason).
COUPLED_KINDS = (Kind.INDUCTOR, Kind.INDUCTANCE)


def check_netlist(netlist: Netlist) -> None:
    """Refuse a netlist whose references or connections no analysis can use.

    Raises
    ------
    TopologyError
        A controlling node that no element connects, a controlling element that is not a
        voltage source, a coupling of anything but two distinct inductors, or a node with no
        path to ground.
    """
    check_references(netlist, {GROUND, *netlist.nodes})
    _check_grounded(netlist)


def check_references(
    netlist: Netlist, nodes: Container[str], coupled_kinds: Collection[Kind] = COUPLED_KINDS
) -> None:
    """Refuse a controlling node outside ``nodes``, a controlling element that is not a voltage
    source, and a coupling of anything but two distinct elements of ``coupled_kinds``.

    Parameters
    ----------
    netlist : Netlist
    nodes : container of str
        The nodes the circuit has (the parsed node set, or the compiler's graph).
    coupled_kinds : collection of Kind
        What a ``K`` may join (the linear compiler: linear inductors only).

    Raises
    ------
    TopologyError
        Naming the element and its line.
    """
    by_key = {e.key: e for e in netlist.elements}
    for element in netlist.elements:
        for node in element.control_nodes or ():
            if node not in nodes:
                raise TopologyError(
                    f"{element.label}: controlling node {node!r} is not connected to any element", element.loc
                )
        if element.control_source is not None:
            sense = by_key.get(element.control_source)
            if sense is None or sense.kind is not Kind.VSOURCE:
                raise TopologyError(
                    f"{element.label}: controlling element {element.control_source!r} "
                    "is not a voltage source in this netlist",
                    element.loc,
                )
        if element.coupled is not None:
            for name in element.coupled:
                other = by_key.get(name)
                if other is None or other.kind not in coupled_kinds:
                    raise TopologyError(
                        f"{element.label}: {name!r} is not an inductor in this netlist", element.loc
                    )
            if element.coupled[0] == element.coupled[1]:
                raise TopologyError(f"{element.label}: couples {element.coupled[0]} with itself", element.loc)


def _check_grounded(netlist: Netlist) -> None:
    """Every node reaches ground through elements (a coupling is no connection)."""
    parent: dict[str, str] = {}

    def root(node: str) -> str:
        parent.setdefault(node, node)
        while parent[node] != node:
            parent[node] = parent[parent[node]]
            node = parent[node]
        return node

    for element in netlist.elements:
        if element.kind is Kind.COUPLING:
            continue
        ends = element.nodes
        for a, b in zip(ends[::2], ends[1::2], strict=False):
            parent[root(a)] = root(b)
    ground = root(GROUND)
    floating = [n for n in netlist.nodes if root(n) != ground]
    if not floating:
        return
    culprit = next(e for e in netlist.elements if any(n in floating for n in e.nodes))
    shown = ", ".join(floating[:5]) + (", ..." if len(floating) > 5 else "")
    raise TopologyError(f"{culprit.label}: node(s) {shown} have no path to ground (node 0)", culprit.loc)


#: Branches that fix a voltage (at DC an inductor is a short and fixes one too).
VOLTAGE_KINDS = frozenset({Kind.VSOURCE, Kind.VCVS, Kind.CCVS, Kind.BVOLTAGE})


def voltage_loop(netlist: Netlist, kinds: frozenset[Kind] = VOLTAGE_KINDS) -> tuple[Element, ...]:
    """The first loop of voltage-fixing branches (of ``kinds``), the closing one first; () when none.

    Such a loop leaves the current around it undetermined (and its voltages inconsistent unless
    they happen to sum to zero): no operating point exists, whatever Newton's method tries. A
    branch with both ends on one node is a loop by itself.
    """
    links: dict[str, list[tuple[str, Element]]] = {}
    parent: dict[str, str] = {}

    def root(node: str) -> str:
        parent.setdefault(node, node)
        while parent[node] != node:
            parent[node] = parent[parent[node]]
            node = parent[node]
        return node

    for element in netlist.elements:
        if element.kind not in kinds:
            continue
        a, b = element.nodes[0], element.nodes[1]
        if root(a) == root(b):
            return (element, *_path(links, a, b))
        parent[root(a)] = root(b)
        links.setdefault(a, []).append((b, element))
        links.setdefault(b, []).append((a, element))
    return ()


def _path(links: dict[str, list[tuple[str, Element]]], start: str, goal: str) -> list[Element]:
    """The elements on the forest path from ``start`` to ``goal`` (breadth first)."""
    came: dict[str, tuple[str, Element] | None] = {start: None}
    queue = [start]
    for node in queue:
        if node == goal:
            break
        for other, element in links.get(node, ()):
            if other not in came:
                came[other] = (node, element)
                queue.append(other)
    path: list[Element] = []
    node = goal
    while came.get(node) is not None:
        previous, element = came[node]  # type: ignore[misc]
        path.append(element)
        node = previous
    return path
