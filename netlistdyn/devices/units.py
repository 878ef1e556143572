"""The units of a netlist's signals and element values, from each element's kind and mechanical keyword
(never from its name's first letter)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from netlistdyn.circuit.netlist import Kind
from netlistdyn.devices.registry import REGISTRY


def _domains(netlist: Any) -> tuple[dict[str, str], dict[str, str]]:
    """Each node's and each element's domain: electrical, translational or rotational.

    A node is mechanical when a mechanical element touches it, rotational when
    an INERTIA or TORQUE does. A mechanical element takes its nodes' domain (a
    SPRING between rotational nodes is torsional), a motor's shaft node that
    of the shaft; every other element is electrical. Keys are lower case.
    """
    node_kind: dict[str, str] = {}
    for element in netlist.elements if netlist is not None else ():
        word = (element.keyword or "").lower()
        if not word:
            for node in element.nodes:
                node_kind.setdefault(node.lower(), "electrical")
            continue
        kind = "rotational" if word in ROTATIONAL else "translational"
        nodes = element.nodes[2:3] if word == "motor" else element.nodes
        if word == "motor":
            for node in element.nodes[:2]:
                node_kind[node.lower()] = "electrical"
        for node in nodes:
            if node_kind.get(node.lower()) != "rotational":
                node_kind[node.lower()] = kind
    element_kind: dict[str, str] = {}
    for element in netlist.elements if netlist is not None else ():
        word = (element.keyword or "").lower()
        if not word:
            element_kind[element.name.lower()] = "electrical"
            continue
        nodes = element.nodes[2:3] if word == "motor" else element.nodes
        kinds = {node_kind.get(n.lower(), "") for n in nodes if n != "0"}
        element_kind[element.name.lower()] = (
            "rotational" if word in ROTATIONAL or "rotational" in kinds else "translational"
        )
    return node_kind, element_kind


def signal_units(netlist: Any, names: Sequence[str]) -> tuple[str, ...]:
    """The unit of each signal of ``netlist``: V and A in circuits, m/s and N on mechanical nodes.

    Parameters
    ----------
    netlist : Netlist or None
        The parsed netlist (None: units where they do not depend on it).
    names : sequence of str
        Output names such as ``v(a)``, ``v(a,b)``, ``i(R1)``, ``x(cart)``,
        ``angle(r1)``, or state names ``q(C1)``, ``p(m1)``, ``f(k1)``.

    Returns
    -------
    tuple of str
        One unit per name; empty where it cannot be told.
    """
    if netlist is not None and netlist.planar:  # a planar mechanism's coordinates and points
        planar = {"x": "m", "y": "m", "px": "m", "py": "m", "v": "m/s", "angle": "rad", "omega": "rad/s"}
        return tuple(planar.get(name.partition("(")[0].strip().lower(), "") for name in names)
    node_kind, element_kind = _domains(netlist)
    elements = netlist.elements if netlist is not None else ()
    keyword = {e.name.lower(): (e.keyword or "").lower() for e in elements}
    out = []
    for name in names:
        head, _, rest = name.partition("(")
        head = head.rsplit(".", 1)[-1].lower()
        args = [a.strip().lower() for a in rest.rstrip(")").split(",") if a.strip()]
        if head == "angle":
            out.append("rad")
            continue
        if head == "p":  # a mass's momentum or an inertia's angular momentum
            words = {keyword.get(a, "") for a in args}
            out.append(
                {"mass": "kg·m/s", "inertia": "kg·m²/s"}.get(words.pop(), "") if len(words) == 1 else ""
            )
            continue
        if head in ("i", "f", "q"):
            kinds = {element_kind.get(a, "") for a in args}
        else:
            kinds = {node_kind.get(a, "") for a in args if a != "0"}
        kind = kinds.pop() if len(kinds) == 1 else ""
        if head == "q":
            out.append("C" if kind == "electrical" else "")
            continue
        column = {"v": 0, "i": 1, "f": 1, "x": 2}.get(head)
        out.append(DOMAIN_UNITS[kind][column] if kind in DOMAIN_UNITS and column is not None else "")
    return tuple(out)


def _ratio(top: str, bottom: str) -> str:
    """``top`` per ``bottom`` as one unit, without cancelling (V/V, N·s/m, N·m·s/rad, m/(N·s))."""
    if not top or not bottom:
        return ""

    def split(unit: str) -> tuple[list[str], list[str]]:
        num, _, den = unit.partition("/")
        return num.split("·"), den.split("·") if den else []

    (t_num, t_den), (b_num, b_den) = split(top), split(bottom)
    num, den = t_num + b_den, b_num + t_den
    below = "·".join(den)
    return "·".join(num) + "/" + (f"({below})" if len(den) > 1 else below)


def element_unit(netlist: Any, element: Any) -> str:
    """The unit of ``element.value`` as a person reads it, from its kind and mechanical keyword.

    Ω, F, H for resistors, capacitors and inductors; kg, kg·m², N/m (N·m/rad
    torsional), N·s/m (N·m·s/rad) for masses, inertias, springs and dampers in
    their own units (stiffness, not the analog inductance); a controlled
    source's gain as its output's unit per its control's (V/V, A/V, A/A, V/A
    in a circuit, N/m or N·m/rad for a linearised force or torque reading a
    displacement or angle); empty for ratios and coupling coefficients.

    Parameters
    ----------
    netlist : Netlist
        The netlist ``element`` belongs to (it tells mechanical nodes and
        linearised displacements apart from circuit nodes).
    element : Element

    Returns
    -------
    str
        The unit, or ``""`` for a dimensionless value or one that cannot be told.
    """
    node_kind, element_kind = _domains(netlist)
    domain = element_kind.get(element.name.lower(), "electrical")
    word = (element.keyword or "").upper()
    if word in ("MASS", "INERTIA", "SPRING", "DAMPER", "MOTOR", "ROD"):
        turning = domain == "rotational"
        return {
            "MASS": "kg",
            "INERTIA": "kg·m²",
            "SPRING": "N·m/rad" if turning else "N/m",
            "DAMPER": "N·m·s/rad" if turning else "N·s/m",
            "MOTOR": "N·m/A",  # Km: also V·s/rad
            "ROD": "",  # its symbols are the length l_<rod> (m) and g (m/s²)
        }[word]
    unit = REGISTRY[element.kind].unit  # Ω, F, H: a value whose unit the circuit does not change
    if unit and not word:
        return unit
    if element.kind in (Kind.VSOURCE, Kind.ISOURCE):
        column = 0 if element.kind is Kind.VSOURCE else 1
        return DOMAIN_UNITS[domain][column] if domain in DOMAIN_UNITS else ""
    controlled = (Kind.VCVS, Kind.VCCS, Kind.CCCS, Kind.CCVS)
    if element.kind not in controlled or word:  # ratios, couplings, the integrators of displacements
        return ""

    def pair_kind(nodes: Sequence[str]) -> str:
        kinds = {node_kind.get(n.lower(), "") for n in nodes if n != "0"}
        return kinds.pop() if len(kinds) == 1 else ""

    output_kind = pair_kind(element.nodes)
    across = element.kind in (Kind.VCVS, Kind.CCVS)
    top = DOMAIN_UNITS[output_kind][0 if across else 1] if output_kind in DOMAIN_UNITS else ""
    if element.control_source is not None:
        control_kind = element_kind.get(element.control_source.lower(), "")
        bottom = DOMAIN_UNITS[control_kind][1] if control_kind in DOMAIN_UNITS else ""
        return _ratio(top, bottom)
    assert element.control_nodes is not None
    # a linearised mechanism reads a displacement x(n) as the voltage of its integrator's node
    integrated = {
        e.nodes[1].lower(): e.control_nodes[0]
        for e in netlist.elements
        if (e.keyword or "").upper() == "DISPLACEMENT" and e.control_nodes is not None
    }
    read = [n for n in element.control_nodes if n != "0"]
    if read and all(n.lower() in integrated for n in read):
        control_kind = pair_kind([integrated[n.lower()] for n in read])
        bottom = DOMAIN_UNITS[control_kind][2] if control_kind in DOMAIN_UNITS else ""
    else:
        control_kind = pair_kind(element.control_nodes)
        bottom = DOMAIN_UNITS[control_kind][0] if control_kind in DOMAIN_UNITS else ""
    return _ratio(top, bottom)


#: Keywords whose nodes turn (rad/s, N·m) rather than translate (m/s, N).
ROTATIONAL = frozenset({"inertia", "torque"})


#: Across, through and displacement units of a node of each domain.
DOMAIN_UNITS = {
    "electrical": ("V", "A", ""),
    "translational": ("m/s", "N", "m"),
    "rotational": ("rad/s", "N·m", "rad"),
}
