"""How results look to people: engineering notation, and the notebook views.

:func:`eng` writes a number with an SI prefix (``10 µH``, ``250 µs``). The
``model_*``, ``eigen_*`` and ``simulation_*`` functions are what
``repr()``, ``_repr_html_`` and ``_repr_latex_`` of
:class:`~netlistdyn.model.StateSpaceModel`,
:class:`~netlistdyn.analysis.EigenAnalysis` and
:class:`~netlistdyn.api.Simulation` return (Jupyter shows the HTML). JSON
output never goes through this module: it keeps full-precision numbers.
"""

from __future__ import annotations

import html
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

#: SI prefixes by decimal exponent (a multiple of 3).
PREFIXES: dict[int, str] = {
    -24: "y",
    -21: "z",
    -18: "a",
    -15: "f",
    -12: "p",
    -9: "n",
    -6: "µ",
    -3: "m",
    0: "",
    3: "k",
    6: "M",
    9: "G",
    12: "T",
}
#: Largest model whose matrices the notebook views print entry by entry.
VIEW_MATRIX_LIMIT = 16
#: Most modes listed in a text or HTML view of an eigen analysis.
VIEW_MODE_LIMIT = 40


def eng(value: float, unit: str = "", digits: int = 4) -> str:
    """A number in engineering notation with an SI prefix.

    Parameters
    ----------
    value : float
        The number, in the base unit (s, H, F, Hz ...).
    unit : str
        The unit symbol appended after the prefix (may be empty).
    digits : int
        Significant digits.

    Returns
    -------
    str
        ``eng(1e-5, "H")`` is ``"10 µH"``, ``eng(0.00025, "s")`` is
        ``"250 µs"``, ``eng(2200)`` is ``"2.2k"``; outside 1e-24..1e15 the
        exponent is written out.
    """
    value = float(value)
    space = " " if unit else ""
    if not math.isfinite(value):
        return f"{value}{space}{unit}"
    if value == 0:
        return f"0{space}{unit}"
    exponent = 3 * math.floor(math.log10(abs(value)) / 3)
    if exponent not in PREFIXES:
        return f"{value:.{digits}g}{space}{unit}"
    mantissa = float(f"{value / 10.0**exponent:.{digits}g}")
    if abs(mantissa) >= 1000 and exponent + 3 in PREFIXES:  # 999.96 rounded up to 1000
        exponent += 3
        mantissa = float(f"{value / 10.0**exponent:.{digits}g}")
    if unit:
        return f"{mantissa:.{digits}g} {PREFIXES[exponent]}{unit}"
    return f"{mantissa:.{digits}g}{PREFIXES[exponent]}"  # a bare number: 10k, 2.2µ


def eng_formatter(unit: str) -> Any:
    """A matplotlib tick formatter writing ``unit`` with SI prefixes (µs, kHz ...)."""
    from matplotlib.ticker import EngFormatter

    return EngFormatter(unit=unit, sep=" ")


def element_value(name: str, value: float, unit: str = "") -> str:
    """``L1 = 10 µH``: an element's value with its unit (see :func:`element_unit`).

    A unit that already has a prefix (kg, kg·m²) is written after a plain
    number (``0.0008 kg·m²``, not ``800 µkg·m²``).
    """
    if unit.startswith("kg"):
        return f"{name} = {float(value):.4g} {unit}"
    return f"{name} = {eng(value, unit)}"


def _signals(names: Sequence[str]) -> str:
    return ", ".join(names) if names else "none"


def _plural(count: int, word: str) -> str:
    return f"{count} {word}" + ("" if count == 1 else "s")


# --- the model -------------------------------------------------------------------------


def model_text(model: Any) -> str:
    """``repr(model)``: sizes, labels and (for small models) the labelled matrices."""
    from .report import format_matrix

    head = (
        f"<StateSpaceModel {model.title!r}: {_plural(model.nstates, 'state')}, "
        f"{_plural(model.ninputs, 'input')}, {_plural(model.noutputs, 'output')}>"
    )
    lines = [
        head,
        f"states:  {_signals(model.states)}",
        f"inputs:  {_signals(model.inputs)}",
        f"outputs: {_signals(model.outputs)}",
    ]
    if max(model.nstates, model.ninputs, model.noutputs) > VIEW_MATRIX_LIMIT:
        for name in ("A", "B", "C", "D"):
            matrix = getattr(model, f"{name}_sparse")
            lines.append(f"{name}: {matrix.shape[0]}x{matrix.shape[1]}, {matrix.nnz} non-zeros")
    else:
        for name, rows, cols in _blocks(model):
            lines += format_matrix(name, getattr(model, name), rows, cols)
    return "\n".join(lines)


def _blocks(model: Any) -> list[tuple[str, Sequence[str], Sequence[str]]]:
    blocks: list[tuple[str, Sequence[str], Sequence[str]]] = [
        ("A", model.states, model.states),
        ("B", model.states, model.inputs),
        ("C", model.outputs, model.states),
        ("D", model.outputs, model.inputs),
    ]
    if model.has_input_derivative:
        blocks.append(("D1", model.outputs, model.inputs))
    return blocks


def _cell(value: float) -> str:
    return f"{value:.6g}" if value else "0"


def model_html(model: Any) -> str:
    """``_repr_html_``: the block matrix [[A, B], [C, D]] as a labelled table."""
    esc = html.escape
    title = (
        f"<p><b>StateSpaceModel</b> {esc(model.title)}: {_plural(model.nstates, 'state')}, "
        f"{_plural(model.ninputs, 'input')}, {_plural(model.noutputs, 'output')}</p>"
    )
    if max(model.nstates, model.ninputs, model.noutputs) > VIEW_MATRIX_LIMIT:
        sizes = "".join(
            f"<li>{name}: {m.shape[0]}×{m.shape[1]}, {m.nnz} non-zeros</li>"
            for name in ("A", "B", "C", "D")
            for m in [getattr(model, f"{name}_sparse")]
        )
        return title + f"<ul>{sizes}</ul>"
    cols = [*model.states, *model.inputs]
    head = "<tr><th></th>" + "".join(f"<th>{esc(c)}</th>" for c in cols) + "</tr>"
    rows = []
    top = np.hstack([model.A, model.B])
    bottom = np.hstack([model.C, model.D])
    for label, row, kind in [
        *((s, r, "x'") for s, r in zip(model.states, top, strict=True)),
        *((o, r, "y") for o, r in zip(model.outputs, bottom, strict=True)),
    ]:
        cells = "".join(
            f'<td style="text-align:right{";border-left:1px solid" if k == model.nstates else ""}">'
            f"{_cell(v)}</td>"
            for k, v in enumerate(row)
        )
        rows.append(f"<tr><th>{kind} {esc(label)}</th>{cells}</tr>")
    note = "<p>y also gets D1·du/dt (see <code>.D1</code>)</p>" if model.has_input_derivative else ""
    return title + f"<table>{head}{''.join(rows)}</table>" + note


def _latex_label(name: str) -> str:
    return r"\text{" + name.replace("_", r"\_").replace("#", r"\#") + "}"


def model_latex(model: Any) -> str | None:
    """``_repr_latex_``: ẋ = Ax + Bu, y = Cx + Du as one block matrix (small models only)."""
    if max(model.nstates, model.ninputs, model.noutputs) > VIEW_MATRIX_LIMIT or not model.nstates:
        return None
    n, m = model.nstates, model.ninputs
    top = np.hstack([model.A, model.B])
    bottom = np.hstack([model.C, model.D])

    def rows(block: np.ndarray) -> str:
        return r" \\ ".join(" & ".join(_cell(v) for v in row) for row in block)

    spec = "c" * n + ("|" + "c" * m if m else "")
    matrix = rf"\left[\begin{{array}}{{{spec}}} {rows(top)} \\ \hline {rows(bottom)} \end{{array}}\right]"
    x = r" \\ ".join(_latex_label(s) for s in model.states)
    u = r" \\ ".join(_latex_label(s) for s in model.inputs)
    y = r" \\ ".join(_latex_label(s) for s in model.outputs)
    lhs = r"\begin{bmatrix} \dot{x} \\ y \end{bmatrix}"
    legend = rf",\quad x = \begin{{bmatrix}} {x} \end{{bmatrix}}"
    legend += rf",\ u = \begin{{bmatrix}} {u} \end{{bmatrix}}" if m else ""
    legend += rf",\ y = \begin{{bmatrix}} {y} \end{{bmatrix}}" if model.noutputs else ""
    rhs = r"\begin{bmatrix} x \\ u \end{bmatrix}" if m else "x"
    return f"$${lhs} = {matrix} {rhs}{legend}$$"


# --- eigenvalues -----------------------------------------------------------------------


def _mode_row(mode: Any) -> tuple[str, str, str, str, str]:
    value = complex(mode.value.real + 0.0, mode.value.imag + 0.0)  # no "-0"
    lam = f"{value.real:.8g}" + (
        f" {'-' if value.imag < 0 else '+'} {abs(value.imag):.8g}j" if value.imag else ""
    )
    zeta = f"{mode.damping:.4g}" if math.isfinite(mode.damping) else "-"
    tau = eng(mode.time_constant, "s") if math.isfinite(mode.time_constant) else "∞"
    return (
        lam,
        eng(mode.natural_frequency, "rad/s"),
        eng(mode.natural_frequency / (2 * math.pi), "Hz"),
        zeta,
        tau,
    )


EIGEN_HEADINGS = ("λ [1/s]", "ωn", "fn = ωn/2π", "ζ", "τ")


def eigen_text(analysis: Any) -> str:
    """``repr(analysis)``: verdict, method and a table of the modes."""
    rows = [_mode_row(m) for m in analysis.modes[:VIEW_MODE_LIMIT]]
    widths = [
        max(len(h), *(len(r[k]) for r in rows)) if rows else len(h) for k, h in enumerate(EIGEN_HEADINGS)
    ]
    lines = [
        f"<EigenAnalysis: {_plural(len(analysis.modes), 'eigenvalue')}"
        + ("" if analysis.complete else " (not all)")
        + f", {analysis.verdict}>",
        f"method: {analysis.method}",
        "  ".join(h.rjust(w) for h, w in zip(EIGEN_HEADINGS, widths, strict=True)),
    ]
    lines += ["  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
    if len(analysis.modes) > VIEW_MODE_LIMIT:
        lines.append(f"... {len(analysis.modes) - VIEW_MODE_LIMIT} more (see .modes)")
    if analysis.stiffness_ratio is not None:
        lines.append(f"stiffness ratio: {analysis.stiffness_ratio:.4g}")
    lines += [f"warning: {w}" for w in analysis.warnings]
    return "\n".join(lines)


def eigen_html(analysis: Any) -> str:
    """``_repr_html_`` of an eigen analysis: the same table."""
    esc = html.escape
    head = "<tr>" + "".join(f"<th>{esc(h)}</th>" for h in EIGEN_HEADINGS) + "</tr>"
    body = "".join(
        "<tr>" + "".join(f'<td style="text-align:right">{esc(c)}</td>' for c in _mode_row(m)) + "</tr>"
        for m in analysis.modes[:VIEW_MODE_LIMIT]
    )
    more = len(analysis.modes) - VIEW_MODE_LIMIT
    tail = f"<p>... {more} more (see <code>.modes</code>)</p>" if more > 0 else ""
    stiff = (
        f"; stiffness ratio {analysis.stiffness_ratio:.4g}" if analysis.stiffness_ratio is not None else ""
    )
    warn = "".join(f"<p>warning: {esc(w)}</p>" for w in analysis.warnings)
    return (
        f"<p><b>EigenAnalysis</b>: {_plural(len(analysis.modes), 'eigenvalue')}, "
        f"{esc(analysis.verdict)}{stiff}<br><small>{esc(analysis.method)}</small></p>"
        f"<table>{head}{body}</table>{tail}{warn}"
    )


def eigen_latex(analysis: Any) -> str | None:
    """``_repr_latex_``: the eigenvalues as a column (up to :data:`VIEW_MODE_LIMIT`)."""
    if not analysis.modes or len(analysis.modes) > VIEW_MODE_LIMIT:
        return None

    def number(z: complex) -> str:
        re, im = z.real + 0.0, z.imag + 0.0
        text = f"{re:.8g}"
        if im:
            text += f" {'-' if im < 0 else '+'} {abs(im):.8g}\\,j"
        return text.replace("e", r"\mathrm{e}")

    body = r" \\ ".join(number(m.value) for m in analysis.modes)
    return rf"$$\lambda(A) = \begin{{bmatrix}} {body} \end{{bmatrix}}\ \text{{({analysis.verdict})}}$$"


# --- simulations -----------------------------------------------------------------------


def simulation_rows(sim: Any) -> list[tuple[str, str, str, str]]:
    """Per output: name, final value, minimum and maximum (engineering notation)."""
    rows = []
    for j, (name, unit) in enumerate(zip(sim.outputs, sim.units, strict=True)):
        column = sim.values[:, j]
        rows.append((name, eng(column[-1], unit, 6), eng(column.min(), unit, 6), eng(column.max(), unit, 6)))
    return rows


def simulation_text(sim: Any) -> str:
    """``repr(simulation)``: what was simulated and each output's final value and range."""
    rows = simulation_rows(sim)
    width = max(6, *(len(r[0]) for r in rows)) if rows else 6
    lines = [
        f"<Simulation {sim.title!r}: 0..{eng(sim.horizon.tstop, 's')}, {sim.time.size} points, "
        f"{sim.method} ({sim.setting}), {sim.status}>",
        f"  {'output':<{width}} {'final':>12} {'min':>12} {'max':>12}",
    ]
    lines += [f"  {n:<{width}} {f:>12} {lo:>12} {hi:>12}" for n, f, lo, hi in rows]
    lines.append("(samples: .time and .values, or sim['name'])")
    return "\n".join(lines)


def simulation_html(sim: Any) -> str:
    """``_repr_html_`` of a simulation: the summary table."""
    esc = html.escape
    head = "<tr><th>output</th><th>final</th><th>min</th><th>max</th></tr>"
    body = "".join(
        "<tr>" + "".join(f'<td style="text-align:right">{esc(c)}</td>' for c in row) + "</tr>"
        for row in simulation_rows(sim)
    )
    return (
        f"<p><b>Simulation</b> {esc(sim.title)}: 0..{esc(eng(sim.horizon.tstop, 's'))}, "
        f"{sim.time.size} points, {esc(sim.method)} ({esc(sim.setting)}), {esc(sim.status)}</p>"
        f"<table>{head}{body}</table>"
    )


#: Keywords whose nodes turn (rad/s, N·m) rather than translate (m/s, N).
ROTATIONAL = frozenset({"inertia", "torque"})

#: Across, through and displacement units of a node of each domain.
DOMAIN_UNITS = {
    "electrical": ("V", "A", ""),
    "translational": ("m/s", "N", "m"),
    "rotational": ("rad/s", "N·m", "rad"),
}


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
            words = {keyword.get(a) for a in args}
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
    from .netlist import Kind

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
    simple = {Kind.RESISTOR: "Ω", Kind.CAPACITOR: "F", Kind.INDUCTOR: "H"}
    if element.kind in simple and not word:
        return simple[element.kind]
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
