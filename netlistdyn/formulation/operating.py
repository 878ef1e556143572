"""The operating point of a nonlinear netlist and its linearisation there.

:func:`operating_point` solves the DC network (or holds chosen states and makes x' as small as it can);
:func:`linearise` replaces every nonlinear element by its tangent at that point, so that the linear
reduction compiles the small-signal model; :func:`linearised` does both."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from netlistdyn.base.errors import NetlistError, SourceLocation
from netlistdyn.base.formatting import eng
from netlistdyn.circuit.netlist import GROUND, STORAGE_KINDS, Diagnostic, Element, Kind, Netlist
from netlistdyn.devices.mechanics import DISPLACEMENT_KEYWORD
from netlistdyn.devices.models import DISPLACEMENT, junction_charge, junction_current
from netlistdyn.devices.units import signal_units
from netlistdyn.formulation.nlsystem import NonlinearSystem
from netlistdyn.formulation.nonlinear import (
    NonlinearCircuit,
    NoOperatingPoint,
    OperatingPoint,
    _Behavioural,
    _junction_nodes,
    _series_resistance,
)


def operating_point(netlist: Netlist, at: Mapping[str, float] | None = None) -> OperatingPoint:
    """The DC operating point of ``netlist`` (sources at their DC values, ``at`` overriding).

    Parameters
    ----------
    netlist : Netlist
    at : Mapping, optional
        Source name → value (V or A) replacing its DC value, or state name → value: a state
        held there (``x(bob)`` in rad or m, ``q(C1)`` in C, ``i(L1)`` in A, ``p(m1)``...). With
        held states, the other states are chosen to make x' = f(x, u) as small as they can
        (Gauss–Newton from the DC operating point, least squares); what remains is the point's
        :attr:`OperatingPoint.drift` (empty at an equilibrium).

    Raises
    ------
    NetlistError
        A name that is neither an independent source nor a state.
    """
    circuit = NonlinearCircuit(netlist)
    u = np.array([circuit.dc_value(e) for e in circuit.sources])
    states = {name.lower(): k for k, name in enumerate(circuit.state_names)}
    held: dict[int, float] = {}
    for name, value in (at or {}).items():
        key = name.lower().replace(" ", "")
        if key in circuit.source_index:
            u[circuit.source_index[key]] = value
        elif key in states:
            held[states[key]] = value
        else:
            raise NetlistError(
                f"--at {name}: not an independent source or a state of the netlist "
                f"(states: {', '.join(circuit.state_names) or 'none'})",
                SourceLocation(netlist.path, 0),
            )
    if not held:
        return circuit.operating_point(u)
    return _held_point(netlist, circuit, u, held)


#: A state derivative below this fraction of the terms that make it up (Σ|∂f/∂x|·|x|) is zero:
#: the point is an equilibrium to rounding.
EQUILIBRIUM_RTOL = 1e-9


def _held_point(
    netlist: Netlist, circuit: NonlinearCircuit, u: NDArray[np.float64], held: Mapping[int, float]
) -> OperatingPoint:
    """The point with some states held: the others by least squares on f, its drift f(x0, u0)."""
    system = NonlinearSystem(netlist)
    system.inputs = lambda t: u
    try:
        x = circuit.states_at(circuit.operating_point(u))
    except NoOperatingPoint:
        x = np.zeros(len(circuit.state_names))
    index = np.array(list(held), dtype=np.intp)
    x[index] = list(held.values())
    free = np.array([k for k in range(x.size) if k not in held], dtype=np.intp)
    f = system.f(0.0, x)
    for _ in range(50 if free.size else 0):
        jac = system.jacobian(0.0, x)
        jac = jac.toarray() if isinstance(jac, sp.csc_array) else np.asarray(jac)
        step = np.linalg.lstsq(jac[:, free], -f, rcond=None)[0]
        for _ in range(40):  # damped: a step must lower |f| (and keep the network solvable)
            trial = x.copy()
            trial[free] += step
            try:
                f_trial = system.f(0.0, trial)
            except NetlistError:
                f_trial = np.full_like(f, np.inf)
            if np.all(np.isfinite(f_trial)) and np.linalg.norm(f_trial) <= np.linalg.norm(f):
                break
            step = step / 2
        else:
            break
        x, f = trial, f_trial
        if np.all(np.abs(step) <= 1e-14 * np.maximum(np.abs(x[free]), 1e-300)):
            break
    f = system.f(0.0, x)
    jac = system.jacobian(0.0, x)
    jac = jac.toarray() if isinstance(jac, sp.csc_array) else np.asarray(jac)
    scale = np.abs(jac) @ np.abs(x)
    names = circuit.state_names
    drift = {names[k]: float(f[k]) for k in range(f.size) if abs(f[k]) > EQUILIBRIUM_RTOL * scale[k]}
    point = circuit.operating_point(u, 0.0, "state", x)
    return replace(point, method="states held (--at)", drift=drift)


def linearise(netlist: Netlist, point: OperatingPoint) -> Netlist:
    """The linear netlist of small deviations about ``point``.

    A diode becomes a conductance ``name.gd`` = dI/dV (gmin included) in
    parallel with its incremental capacitance ``name`` = dQ/dV (omitted when
    zero), behind ``name.rs`` when RS > 0; a behavioural source becomes one
    controlled source per variable it reads (its partial derivative as gain),
    named like the linear behavioural sources of the parser (``B1``,
    ``B1.t2``...). Every other element is kept; ``time`` is frozen at 0.
    """
    circuit = NonlinearCircuit(netlist)
    z = point.z
    out: list[Element] = []
    bh_of = {b.element.key: b for b in circuit.behavioural}
    diode_of = {d.element.key: d for d in circuit.diodes}
    for e in netlist.elements:
        if e.kind is Kind.DIODE:
            d = diode_of[e.key]
            model = e.diode
            assert model is not None
            anode = e.nodes[0]
            if model.RS > 0:
                out.append(_series_resistance(e))
                anode = _junction_nodes(e)[0]
            vd = circuit._junction_from_z(d, z)
            i, g = junction_current(vd, d.junction)
            _, cap = junction_charge(vd, i, g, d.junction)
            out.append(Element(Kind.RESISTOR, f"{e.name}.gd", (anode, e.nodes[1]), 1.0 / g, e.loc))
            if cap > 0:
                out.append(Element(Kind.CAPACITOR, e.name, (anode, e.nodes[1]), cap, e.loc))
        elif e.kind in (Kind.BVOLTAGE, Kind.BCURRENT):
            out.extend(_linear_behavioural(bh_of[e.key], z, netlist))
        elif e.kind in STORAGE_KINDS:  # its incremental capacitance dq/dv or inductance L(i)
            store = circuit.storage[e.key]
            if store.capacitor:
                value = circuit.charge(e, circuit._v(z, e.nodes[0]) - circuit._v(z, e.nodes[1]))[1]
                kind = Kind.CAPACITOR
            else:
                value = store.value(float(z[circuit.branch_index[e.key]]))[0]
                kind = Kind.INDUCTOR
            if not value > 0:
                raise NetlistError(f"{e.name}: its {kind.name.lower()} at the point is {value:.6g}", e.loc)
            out.append(Element(kind, e.name, e.nodes, value, e.loc))
        else:
            out.append(e)
    for node in circuit.disp_index:
        # the displacement x(n) = ∫ v(n) dt as a state: v(n) charges 1 F at node "x(n)", whose voltage is x(n)
        loc = next(
            b.element.loc
            for b in circuit.behavioural
            if any(r == DISPLACEMENT + node for _, r in b.behaviour.variables)
        )
        aux = f"x({node})"
        out.append(
            Element(
                Kind.VCCS,
                f"{aux}.in",
                (GROUND, aux),
                1.0,
                loc,
                control_nodes=(node, GROUND),
                keyword=DISPLACEMENT_KEYWORD,
            )
        )
        out.append(Element(Kind.CAPACITOR, aux, (aux, GROUND), 1.0, loc, keyword=DISPLACEMENT_KEYWORD))
    return replace(netlist, elements=tuple(out))


def _linear_behavioural(b: _Behavioural, z: NDArray[np.float64], netlist: Netlist) -> list[Element]:
    e = b.element
    args = np.array([0.0 if r is None else float(z[r]) for r in b.refs])
    _, grad = b.behaviour.evaluate(args)
    terms: list[tuple[Kind, float, tuple[str, str] | None, str | None]] = []
    voltage = e.kind is Kind.BVOLTAGE
    for (kind, ref), gk in zip(b.behaviour.variables, grad, strict=True):
        if kind == "time" or gk == 0:
            continue
        if kind == "v":
            terms.append((Kind.VCVS if voltage else Kind.VCCS, float(gk), (ref, GROUND), None))
        elif ref.startswith(DISPLACEMENT):  # read from the integrator node x(n)
            node = f"x({ref[len(DISPLACEMENT) :]})"
            terms.append((Kind.VCVS if voltage else Kind.VCCS, float(gk), (node, GROUND), None))
        else:
            terms.append((Kind.CCVS if voltage else Kind.CCCS, float(gk), None, ref))
    plus, minus = e.nodes
    if not terms:
        if voltage:  # a constant voltage: a short for deviations
            return [Element(Kind.VCVS, e.name, (plus, minus), 1.0, e.loc, control_nodes=(minus, minus))]
        return []
    labels = [e.name] + [f"{e.name}.t{k}" for k in range(2, len(terms) + 1)]
    if voltage:
        chain = [plus] + [f"{e.key}.n{k}" for k in range(1, len(terms))] + [minus]
        return [
            Element(
                kind,
                label,
                (chain[k], chain[k + 1]),
                gain,
                e.loc,
                control_nodes=cn,
                control_source=cs,
                expression=e.expression,
            )
            for k, ((kind, gain, cn, cs), label) in enumerate(zip(terms, labels, strict=True))
        ]
    return [
        Element(
            kind,
            label,
            (plus, minus),
            gain,
            e.loc,
            control_nodes=cn,
            control_source=cs,
            expression=e.expression,
        )
        for (kind, gain, cn, cs), label in zip(terms, labels, strict=True)
    ]


def default_outputs(netlist: Netlist) -> list[str]:
    """Every node voltage of the netlist as written (no internal nodes), ``v(n)``."""
    return [f"v({n})" for n in netlist.nodes]


def point_text(point: OperatingPoint, netlist: Netlist) -> str:
    """The operating point as a short report, in SI units with prefixes (12 significant digits)."""
    rows = [(f"v({node})", point.voltages[node]) for node in netlist.nodes]
    rows += [(f"x({node})", value) for node, value in point.displacements.items()]
    rows += [(f"i({e.name})", point.currents[e.key]) for e in netlist.elements if e.key in point.currents]
    units = signal_units(netlist, [name for name, _ in rows])
    lines = [
        f"operating point ({point.method}, {point.iterations} Newton iterations, "
        f"largest residual {point.residual:.3g}):"
    ]
    lines += [
        f"  {name} = {eng(value, unit, OP_DIGITS)}" for (name, value), unit in zip(rows, units, strict=True)
    ]
    if point.drift:
        lines.append("not an equilibrium for these inputs (the held states move):")
        lines += [f"  d{name}/dt = {value:.12g}" for name, value in point.drift.items()]
    return "\n".join(lines) + "\n"


#: Significant digits of an operating point in the text report (JSON keeps every digit).
OP_DIGITS = 12


def point_dict(point: OperatingPoint, netlist: Netlist) -> dict[str, object]:
    """The operating point for ``--format json``."""
    return {
        "method": point.method,
        "iterations": point.iterations,
        "residual": point.residual,
        "voltages": {f"v({n})": point.voltages[n] for n in netlist.nodes},
        "displacements": {f"x({n})": v for n, v in point.displacements.items()},
        "currents": {
            f"i({e.name})": point.currents[e.key] for e in netlist.elements if e.key in point.currents
        },
        "inputs": dict(point.inputs),
        **({"drift": {f"d{name}/dt": value for name, value in point.drift.items()}} if point.drift else {}),
    }


def linear_warnings(netlist: Netlist, point: OperatingPoint) -> tuple[Diagnostic, ...]:
    """A note that the model is the linearisation at the operating point (and its drift, if any)."""
    loc = SourceLocation(netlist.path, 0)
    notes = [
        Diagnostic(
            loc,
            f"nonlinear netlist: A, B, C, D are its linearisation at the operating point ({point.method}, "
            f"residual {point.residual:.2g}), in deviations from it (simulate integrates the circuit itself)",
        )
    ]
    if point.drift:
        terms = ", ".join(f"d{name}/dt = {value:.6g}" for name, value in point.drift.items())
        notes.append(
            Diagnostic(
                loc,
                f"--at: not an equilibrium for these inputs: {terms}; A, B, C, D are the Jacobians there "
                "(this drift f(x0, u0) is left out of the model)",
            )
        )
    return tuple(notes)


def linearised(
    netlist: Netlist, outputs: Sequence[str] | None = None, at: Mapping[str, float] | None = None
) -> tuple[Netlist, list[str]]:
    """The linear netlist at the operating point (with a note among its warnings) and its outputs.

    The default outputs are the node voltages of the netlist as written (the
    linearisation's internal nodes are not outputs unless asked for).
    """
    point = operating_point(netlist, at)
    lin = linearise(netlist, point)
    lin = replace(lin, warnings=lin.warnings + linear_warnings(netlist, point))
    return lin, list(outputs) if outputs else default_outputs(netlist)
