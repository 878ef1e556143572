"""Output specifications: ``v(n)``, ``v(a,b)``, ``i(elem)``.

Names are case-insensitive, like the netlist. A probe that names a node or
element the netlist lacks is a usage error, reported before any work.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

from netlistdyn.base.errors import UsageError
from netlistdyn.circuit.netlist import GROUND, Kind, Netlist

_PROBE = re.compile(r"^\s*([A-Za-z]+)\s*\(\s*([^,()\s]+)\s*(?:,\s*([^,()\s]+)\s*)?\)\s*$")


@dataclass(frozen=True, slots=True)
class Probe:
    """One requested output.

    Attributes
    ----------
    kind : str
        ``"v"`` (node voltage or difference: V, or a velocity), ``"i"``
        (branch current: A, or a force), ``"x"`` (displacement of a node
        from its rest position, the integral of its velocity) or
        ``"angle"`` (of a pendulum rod, rad).
    name : str
        Label as shown to the user, e.g. ``v(out)`` or ``i(R1)``.
    nodes : tuple of str
        ``(a, b)`` for a voltage probe (b is ground for ``v(n)``).
    element : str
        Element key for a current probe.
    """

    kind: str
    name: str
    nodes: tuple[str, str] = (GROUND, GROUND)
    element: str = ""


def _canonical(node: str) -> str:
    low = node.lower()
    return GROUND if low in ("0", "gnd") else low


def parse_probes(texts: Sequence[str], netlist: Netlist) -> list[Probe]:
    """:func:`parse_probe` of each text, the netlist's node set formed once (not once per text)."""
    known = frozenset(netlist.nodes) | {GROUND}
    return [parse_probe(text, netlist, known) for text in texts]


def parse_probe(text: str, netlist: Netlist, known: frozenset[str] | None = None) -> Probe:
    """Parse one ``--output`` value against a netlist.

    Parameters
    ----------
    text : str
        ``v(n)``, ``v(a,b)`` or ``i(elem)``.
    netlist : Netlist
        For checking that the nodes and elements exist.
    known : frozenset of str, optional
        The netlist's nodes and ground, when the caller has them (see :func:`parse_probes`).

    Returns
    -------
    Probe

    Raises
    ------
    UsageError
        For malformed specifications and unknown names.
    """
    match = _PROBE.match(text)
    if not match:
        raise UsageError(f"--output {text!r}: expected v(node), v(node1,node2) or i(element)")
    func, first, second = match.group(1).lower(), match.group(2), match.group(3)
    if func in ("v", "x"):
        if known is None:
            known = frozenset(netlist.nodes) | {GROUND}
        a, b = _canonical(first), _canonical(second) if second else GROUND
        for node in (a, b):
            if node not in known:
                raise UsageError(f"--output {text}: no node {node!r} in the netlist")
        name = f"{func}({first},{second})" if second else f"{func}({first})"
        return Probe(func, name, (a, b))
    if func == "angle" and second is None:
        try:
            element = netlist.element(first.lower())
        except KeyError:
            raise UsageError(f"--output {text}: no element {first!r} in the netlist") from None
        if element.rod is None:
            raise UsageError(f"--output {text}: {element.label} is not a ROD")
        return Probe("angle", f"angle({element.name})", element=element.key)
    if func == "i" and second is None:
        key = first.lower()
        try:
            element = netlist.element(key)
        except KeyError:
            raise UsageError(f"--output {text}: no element {first!r} in the netlist") from None
        if element.kind in (Kind.COUPLING, Kind.TRANSFORMER):
            raise UsageError(f"--output {text}: {element.label} has no single branch current")
        return Probe("i", f"i({element.name})", element=key)
    raise UsageError(
        f"--output {text!r}: expected v(node), v(node1,node2), i(element), x(node) or angle(rod)"
    )


def default_probes(netlist: Netlist) -> list[Probe]:
    """Every non-ground node voltage, in order of first appearance."""
    return [Probe("v", f"v({node})", (node, GROUND)) for node in netlist.nodes]
