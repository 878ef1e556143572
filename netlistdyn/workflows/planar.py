"""The planar-mechanism family through ``op``, ``analyze`` and ``simulate``.

- :func:`planar_point`: an equilibrium, M(q)·0 = Q(q, 0, u0), by Newton's method from q = 0 (the
  hanging or upright position the links declare), or with some coordinates held (``--at``).
- :func:`planar_linear_model`: the exact Jacobians A = ∂f/∂x, B = ∂f/∂u there (complex step), as
  a :class:`~netlistdyn.statespace.model.StateSpaceModel` in the mechanism's own coordinates.
- :func:`prepare_planar`: the model and initial state for ``simulate`` (``--ic`` on the states, or
  on a link end's horizontal position ``x(b1)``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from netlistdyn.analysis.coordinates import Prepared
from netlistdyn.base.errors import NetlistError, SourceLocation, UsageError
from netlistdyn.base.values import parse_number
from netlistdyn.circuit.netlist import Diagnostic, Netlist
from netlistdyn.formulation.planar import PlanarModel, PlanarSystem, output_values
from netlistdyn.statespace.model import CompileInfo, StateSpaceModel

#: Newton on Q(q, 0, u) = 0 stops when the step is below this (rad, m).
NEWTON_TOL = 1e-14
#: Generalised force below this fraction of the largest weight term counts as zero (equilibrium).
EQUILIBRIUM_RTOL = 1e-10


@dataclass(frozen=True)
class PlanarPoint:
    """An operating point of a mechanism.

    Attributes
    ----------
    q : ndarray
        Coordinates (m, rad).
    u : ndarray
        Loads (N, N·m).
    names : tuple of str
        The coordinates' names.
    inputs : tuple of str
        The loads' names.
    residual : float
        max |Q(q, 0, u)| (N, N·m) there.
    iterations : int
        Newton iterations.
    method : str
        How it was found.
    drift : dict
        With held coordinates: the accelerations that remain (not an equilibrium), by name.
    """

    q: NDArray[np.float64]
    u: NDArray[np.float64]
    names: tuple[str, ...]
    inputs: tuple[str, ...]
    residual: float
    iterations: int
    method: str
    drift: Mapping[str, float]

    @property
    def x(self) -> NDArray[np.float64]:
        """The state (q, 0)."""
        return np.concatenate([self.q, np.zeros_like(self.q)])


def planar_point(netlist: Netlist, at: Mapping[str, float] | None = None) -> PlanarPoint:
    """The equilibrium nearest q = 0 (or with held coordinates), loads at their t = 0 values.

    Parameters
    ----------
    netlist : Netlist
    at : Mapping, optional
        Load name → value (N, N·m), or coordinate name → value held there (``angle(r1)=3.14159``).

    Raises
    ------
    NetlistError
        A name that is neither a load nor a coordinate; Newton's method not converging.
    """
    system = PlanarSystem(netlist)
    model = system.model
    mech = system.mechanism
    n = model.n
    u = np.asarray(system.inputs(0.0), dtype=float).copy()
    q = np.zeros(n)
    coords = {c.lower(): k for k, c in enumerate(mech.coordinates)}
    loads = {c.lower(): k for k, c in enumerate(mech.input_names)}
    held: dict[int, float] = {}
    for name, value in (at or {}).items():
        key = name.lower().replace(" ", "")
        if key in loads:
            u[loads[key]] = value
        elif key in coords:
            held[coords[key]] = value
            q[coords[key]] = value
        else:
            raise NetlistError(
                f"--at {name}: not a load or a coordinate of the mechanism (coordinates: "
                f"{', '.join(mech.coordinates)}; loads: {', '.join(mech.input_names) or 'none'})",
                SourceLocation(netlist.path, 0),
            )
    free = np.array([k for k in range(n) if k not in held], dtype=np.intp)
    zero = np.zeros(n)

    def forcing(qq: NDArray[Any]) -> NDArray[Any]:
        return model.mass_forcing(qq, zero, u)[1]

    def jac(qq: NDArray[np.float64]) -> NDArray[np.float64]:
        out = np.empty((n, n))
        for j in range(n):
            qc = qq.astype(complex)
            qc[j] += 1e-100j
            out[:, j] = forcing(qc).imag / 1e-100
        return out

    Q = forcing(q)
    iterations = 0
    for iterations in range(1, 101):  # noqa: B007
        if not free.size:
            break
        step = np.linalg.lstsq(jac(q)[:, free], -Q, rcond=None)[0]
        for _ in range(40):  # damped: a step must not raise |Q|
            trial = q.copy()
            trial[free] += step
            Qt = forcing(trial)
            if np.linalg.norm(Qt) <= np.linalg.norm(Q) or np.max(np.abs(step)) < NEWTON_TOL:
                break
            step = step / 2
        q, Q = trial, Qt
        if np.max(np.abs(step)) < NEWTON_TOL * max(1.0, float(np.max(np.abs(q)))):
            break
    scale = _weight_scale(model, u)
    drift: dict[str, float] = {}
    if held:
        if np.max(np.abs(Q), initial=0.0) > EQUILIBRIUM_RTOL * scale:  # released here, everything accelerates
            acc = model.rhs(np.concatenate([q, zero]), u)[n:]
            drift = {mech.velocities[k]: float(acc[k]) for k in range(n)}
    elif np.max(np.abs(Q), initial=0.0) > EQUILIBRIUM_RTOL * scale:
        raise NetlistError(
            f"no equilibrium found near q = 0 (largest generalised force left {np.max(np.abs(Q)):.3g}); "
            "hold a coordinate with --at to choose another point",
            SourceLocation(netlist.path, 0),
        )
    method = "Newton from q = 0" if not held else "coordinates held (--at), the others by Newton"
    return PlanarPoint(
        q,
        u,
        mech.coordinates,
        mech.input_names,
        float(np.max(np.abs(Q), initial=0.0)),
        iterations,
        method,
        drift,
    )


def _weight_scale(model: PlanarModel, u: NDArray[np.float64]) -> float:
    """The size of the forces in play (N): weights, loads, spring forces at rest (for judging zero)."""
    mech = model.mechanism
    g = math.hypot(*mech.gravity)
    lengths = [abs(j.length) for j in mech.joints] + [1.0]
    weights = sum(m for _, m, _ in mech.bodies) * g * max(lengths)
    springs = sum(k * max(rest, 1.0) for _, _, k, rest in mech.springs)
    return max(weights + springs + float(np.sum(np.abs(u))) * max(lengths), 1e-300)


def planar_linear_model(
    netlist: Netlist,
    outputs: Sequence[str] | None = None,
    at: Mapping[str, float] | None = None,
    point: PlanarPoint | None = None,
    note: bool = True,
) -> StateSpaceModel:
    """A = ∂f/∂x, B = ∂f/∂u at the operating point; C, D of the outputs (default: the coordinates).

    The states are the mechanism's (q, q'); ``note`` adds the warning that says so. Outputs are read as
    :func:`netlistdyn.formulation.planar.output_values` reads them, differentiated by the
    complex step as well (their value at the point is left out: deviations).
    """
    if point is None:
        point = planar_point(netlist, at)
    system = PlanarSystem(netlist)
    model = system.model
    mech = system.mechanism
    A, B = model.jacobians(point.x, point.u)
    names = list(outputs) if outputs else list(mech.coordinates)
    output_values(model, point.x, names)  # refuses an unknown name
    C = np.empty((len(names), model.nstates))
    for j in range(model.nstates):
        xc = point.x.astype(complex)
        xc[j] += 1e-100j
        C[:, j] = _complex_outputs(model, xc, names).imag / 1e-100
    D = np.zeros((len(names), model.ninputs))
    remark = Diagnostic(
        SourceLocation(netlist.path, 0),
        f"planar mechanism: A, B, C, D are the exact Jacobians of its equations of motion at the "
        f"operating point ({point.method}, largest generalised force {point.residual:.2g}), in deviations "
        "from it (simulate integrates the nonlinear equations)",
    )
    warnings = [*netlist.warnings, *([remark] if note else [])]
    if point.drift:
        terms = ", ".join(f"d{k}/dt = {v:.6g}" for k, v in point.drift.items())
        warnings.append(Diagnostic(remark.loc, f"--at: not an equilibrium: {terms} (left out of the model)"))
    return StateSpaceModel(
        sp.csr_array(A),
        sp.csr_array(B),
        sp.csr_array(C),
        sp.csr_array(D),
        sp.csr_array(D.shape),
        mech.state_names,
        mech.input_names,
        tuple(names),
        netlist.title,
        CompileInfo(order=model.nstates, warnings=tuple(warnings)),
    )


def _complex_outputs(
    model: PlanarModel, x: NDArray[np.complex128], names: Sequence[str]
) -> NDArray[np.complex128]:
    """:func:`output_values` carried through complex states (for the complex-step C)."""
    mech = model.mechanism
    states = {s.lower(): k for k, s in enumerate(mech.state_names)}
    points = {p: k for k, p in enumerate(mech.points)}
    n = model.n
    p = model.kinematics(x[:n], x[n:])[0]
    out = np.empty(len(names), dtype=complex)
    for k, raw in enumerate(names):
        name = raw.lower().replace(" ", "")
        if name in states:
            out[k] = x[states[name]]
        else:
            kind, _, rest = name.partition("(")
            out[k] = p[points[rest.rstrip(")")], 0 if kind in ("px", "x") else 1]
    return out


def point_text(point: PlanarPoint, netlist: Netlist) -> str:
    """The operating point for ``op``."""
    lines = [
        f"operating point of the planar mechanism ({point.method}, {point.iterations} iterations, "
        f"largest generalised force {point.residual:.3g}):"
    ]
    lines += [f"  {name} = {value:.12g}" for name, value in zip(point.names, point.q, strict=True)]
    lines += [f"  {name} = {value:.12g} (load)" for name, value in zip(point.inputs, point.u, strict=True)]
    if point.drift:
        lines.append("not an equilibrium for these loads (the held coordinates accelerate):")
        lines += [f"  d{name}/dt = {value:.12g}" for name, value in point.drift.items()]
    return "\n".join(lines) + "\n"


def point_dict(point: PlanarPoint) -> dict[str, object]:
    """The operating point for ``op --format json``."""
    return {
        "method": point.method,
        "iterations": point.iterations,
        "residual": point.residual,
        "coordinates": {n: float(v) for n, v in zip(point.names, point.q, strict=True)},
        "inputs": {n: float(v) for n, v in zip(point.inputs, point.u, strict=True)},
        **({"drift": {f"d{k}/dt": v for k, v in point.drift.items()}} if point.drift else {}),
    }


def prepare_planar(
    netlist: Netlist,
    outputs: Sequence[str] | None = None,
    coordinates: str | None = None,
    ics: Sequence[str] = (),
    extra: Sequence[str] = (),
) -> Prepared:
    """The linearised model (for the horizon) and the initial state of a planar ``simulate``.

    ``--ic NAME=VALUE``: a state (``angle(r1)=-0.01``, ``v(cart)=0``...), absolute; or ``x(b)`` of
    a link's end ``b`` (gravity vertical): its horizontal displacement, which sets the link's angle
    (asin of the offset over the length, after the states given by name).

    Raises
    ------
    UsageError
        ``--coordinates`` other than the states; an unknown name.
    NetlistError
        An ``x(b)`` farther from the link's pivot than its length (at the LINK card).
    """
    system = PlanarSystem(netlist)
    mech = system.mechanism
    if coordinates is not None:
        wanted = [c.strip().lower() for c in coordinates.split(",") if c.strip()]
        if sorted(wanted) != sorted(s.lower() for s in mech.state_names):
            raise UsageError(
                f"--coordinates: a planar mechanism's states are already its coordinates "
                f"({', '.join(mech.state_names)})"
            )
    shown = tuple(outputs) if outputs else mech.coordinates
    names = list(dict.fromkeys([*shown, *extra]))
    model = planar_linear_model(netlist, names, point=_rest_point(system), note=False)
    x0 = _initial_state(system, ics) if ics else None
    return Prepared(model, shown, None, x0)


def _rest_point(system: PlanarSystem) -> PlanarPoint:
    """q = 0 with the loads at t = 0 (the linearisation there only sizes the horizon)."""
    n = system.model.n
    u = np.asarray(system.inputs(0.0), dtype=float)
    forcing = system.model.mass_forcing(np.zeros(n), np.zeros(n), u)[1]
    mech = system.mechanism
    return PlanarPoint(
        np.zeros(n),
        u,
        mech.coordinates,
        mech.input_names,
        float(np.max(np.abs(forcing), initial=0.0)),
        0,
        "q = 0",
        {},
    )


def _initial_state(system: PlanarSystem, ics: Sequence[str]) -> NDArray[np.float64]:
    mech = system.mechanism
    model = system.model
    states = {s.lower(): k for k, s in enumerate(mech.state_names)}
    ends = {j.card.points[1]: j for j in mech.joints if j.kind == "link" and j.card is not None}
    x = np.zeros(model.nstates)
    offsets: list[tuple[str, float]] = []
    for item in ics:
        name, sep, text = item.partition("=")
        key = name.strip().lower().replace(" ", "")
        if not sep:
            raise UsageError(f"--ic {item}: expected NAME=VALUE")
        value = parse_number(text.strip())
        if value is None:
            raise UsageError(f"--ic {item}: {text.strip()!r} is not a number")
        if key in states:
            x[states[key]] = value
        elif key.startswith("x(") and key[2:].rstrip(")") in ends:
            offsets.append((key[2:].rstrip(")"), value))
        else:
            raise UsageError(
                f"--ic {name.strip()}: not a state of the mechanism ({', '.join(mech.state_names)}) "
                "or x(end) of a link's end"
            )
    order = {j.point: k for k, j in enumerate(mech.joints)}
    p0 = model.positions(np.zeros(model.nstates))
    for end, value in sorted(offsets, key=lambda o: order[mech.points.index(o[0])]):
        joint = ends[end]
        card = joint.card
        assert card is not None
        if abs(math.cos(mech.gravity_angle)) > 1e-12:
            raise UsageError(f"--ic x({end}): needs vertical gravity (set the angle of {card.label} instead)")
        pivot = model.positions(x)[joint.parent, 0]
        target = p0[joint.point, 0] + value
        ratio = -math.sin(mech.gravity_angle) * (target - pivot) / joint.length
        if not abs(ratio) <= 1:
            raise NetlistError(
                f"{card.label}: --ic x({end})={value:g} puts its end {abs(target - pivot):.6g} m from its "
                f"pivot horizontally, farther than the rod's length {joint.length:g} m",
                card.loc,
            )
        x[joint.coordinate] = math.asin(ratio)
    return x


__all__ = [
    "PlanarPoint",
    "planar_linear_model",
    "planar_point",
    "point_dict",
    "point_text",
    "prepare_planar",
]
