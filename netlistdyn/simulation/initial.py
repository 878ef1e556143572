"""Where a transient starts, as SPICE defines it (``.tran ... UIC``, ``.ic`` and element ``IC=``).

ngspice 39's rules (manual, ``.ic`` and ``.tran``), applied to the state-space model:

- Without ``UIC`` the transient starts at the **DC operating point** with every source at its
  t = 0 value: ``A x = −B u(0)``. Node voltages named on ``.ic`` lines are forced during that
  solution and released for the transient (here: a current source at each such node, whose
  current the solution also finds); element ``IC=`` values are ignored (with a warning).
- With ``UIC`` no operating point is computed: every capacitor starts at its ``IC=`` voltage, else
  at the difference of its nodes' ``.ic`` voltages (a node not named counts as 0 V), and every
  inductor at its ``IC=`` current, else 0. Only states can be set this way: a capacitor or
  inductor that is not a state of the model (its voltage or current follows from others and
  from the sources) with a nonzero starting value is refused, naming it.

A netlist without ``.tran`` (no SPICE transient) starts as with ``UIC``: from rest, or from its
``IC=`` and ``.ic`` values. ``--ic`` on the command line replaces all of this (the states or
variables it names, the rest 0).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse as sparse
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

from netlistdyn.base.errors import NetlistError, SourceLocation
from netlistdyn.circuit.netlist import GROUND, Diagnostic, Element, Kind, Netlist
from netlistdyn.circuit.waveforms import Am, Dc, Exp, Pulse, Pwl, Sffm, Sin, Waveform
from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.formulation.descriptor import assemble
from netlistdyn.simulation.foh import InputSignals
from netlistdyn.statespace.model import StateSpaceModel

#: How far from singular ``A`` (or the forced-node system) may be, relative to its norm, for a
#: unique operating point: below this reciprocal condition number it has none or many.
RCOND_LIMIT = 1e-13


@dataclass(frozen=True, slots=True)
class Start:
    """The initial state of a transient and how it was chosen.

    Attributes
    ----------
    x0 : numpy.ndarray
        Initial state, in the model's state order.
    uic : bool
        True when the netlist's ``.tran`` says ``UIC`` (no operating point).
    how : str
        One phrase for reports: ``"DC operating point"``, ``"UIC: IC= and .ic values"``, ...
    warnings : tuple of Diagnostic
        Initial conditions that do not apply (``IC=`` without ``UIC``).
    """

    x0: NDArray[np.float64]
    uic: bool
    how: str
    warnings: tuple[Diagnostic, ...] = ()


def uses_uic(netlist: Netlist) -> bool:
    """True when the transient starts from initial conditions rather than an operating point.

    That is when the ``.tran`` line carries ``UIC``, and when there is no ``.tran`` at all: such a
    netlist asks for no SPICE transient, and ``simulate`` starts it from rest (zero state, or the
    ``IC=`` and ``.ic`` values), as a state-space model's response is usually meant.
    """
    return netlist.tran is None or bool(getattr(netlist.tran, "uic", False))


def transient_start(netlist: Netlist, model: StateSpaceModel, u0: NDArray[np.float64]) -> Start:
    """The initial state SPICE uses for the transient of ``netlist``.

    Parameters
    ----------
    netlist : Netlist
        Parsed netlist (its ``.tran``, ``.ic`` lines and element ``IC=`` values).
    model : StateSpaceModel
        Its compiled model (inputs in the order of ``netlist.sources``).
    u0 : numpy.ndarray
        Every input's value at t = 0 (V or A).

    Raises
    ------
    NetlistError
        When there is no unique operating point, or a starting value cannot be imposed.
    """
    given = [e for e in netlist.elements if e.ic is not None and e.kind in (Kind.CAPACITOR, Kind.INDUCTOR)]
    if uses_uic(netlist):
        return _uic_start(netlist, model, u0, given)
    warnings = ignored_ic_warnings(netlist)
    if netlist.initial_conditions:
        x0 = _forced_operating_point(netlist, model, u0)
        return Start(x0, False, "DC operating point with the .ic node voltages held", warnings)
    return Start(operating_point(netlist, model, u0), False, "DC operating point", warnings)


def ignored_ic_warnings(netlist: Netlist) -> tuple[Diagnostic, ...]:
    """Without ``UIC``: one warning per element ``IC=``, which does not apply (as in ngspice)."""
    return tuple(
        Diagnostic(e.loc, f"{e.name}: IC= applies only with .tran ... UIC (ngspice ignores it too)")
        for e in netlist.elements
        if e.ic is not None and e.kind in (Kind.CAPACITOR, Kind.INDUCTOR)
    )


def held_nodes(netlist: Netlist) -> dict[str, tuple[float, SourceLocation]]:
    """The ``.ic`` node voltages (V) and where each was given; the last one for a node wins.

    Raises
    ------
    NetlistError
        For the ground node or a node the netlist does not have.
    """
    conditions: dict[str, tuple[float, SourceLocation]] = {}
    for ic in netlist.initial_conditions:
        conditions[ic.node] = (ic.value, ic.loc)  # the last one wins, as on one .ic line
    known = {n for e in netlist.elements for n in e.nodes}
    for node, (_, loc) in conditions.items():
        if node == GROUND:
            raise NetlistError(".ic: the ground node's voltage is 0 by definition", loc)
        if node not in known:
            raise NetlistError(f".ic: no node {node!r} in the netlist", loc)
    return conditions


def holder_elements(
    nodes: list[str], conditions: dict[str, tuple[float, SourceLocation]]
) -> tuple[Element, ...]:
    """A 0 A current source from ground into each held node (its current is solved for)."""
    return tuple(
        Element(Kind.ISOURCE, f"ic.hold{k}", (GROUND, node), 0.0, conditions[node][1])
        for k, node in enumerate(nodes)
    )


def uic_values(netlist: Netlist) -> list[tuple[Element, float]]:
    """Under ``UIC``, each capacitor's and inductor's nonzero starting value, in netlist order.

    A capacitor starts at its ``IC=`` voltage, else at the difference of its nodes' ``.ic``
    voltages (a node not named counts as 0 V); an inductor at its ``IC=`` current, else 0.
    """
    ic_nodes: dict[str, float] = {GROUND: 0.0}
    for ic in netlist.initial_conditions:
        ic_nodes[ic.node] = ic.value
    out = []
    for element in netlist.elements:
        if element.kind is Kind.CAPACITOR:
            if element.ic is not None:
                value = element.ic
            else:
                value = ic_nodes.get(element.nodes[0], 0.0) - ic_nodes.get(element.nodes[1], 0.0)
        elif element.kind is Kind.INDUCTOR:
            value = element.ic if element.ic is not None else 0.0
        else:
            continue
        if value != 0:
            out.append((element, value))
    return out


def _where(netlist: Netlist) -> SourceLocation:
    tran = netlist.tran
    if tran is not None and tran.loc is not None:
        return tran.loc
    return netlist.elements[0].loc if netlist.elements else SourceLocation(netlist.path, 0)


def _solve_unique(matrix: NDArray[np.float64], rhs: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """The solution of a square system, or None when it is singular to working precision.

    The decision is made on the matrix equilibrated by rows, then columns (each largest entry 1):
    states of different units (a 1 nF capacitor's charge beside a 10 µH inductor's current) put
    entries decades apart in A, and the unscaled condition number then calls a regular system
    singular. Scaling states and equations changes neither the solution nor its existence.
    """
    if matrix.shape[0] == 0:
        return np.zeros(0)
    if not np.all(np.isfinite(matrix)):
        return None
    magnitude = np.abs(matrix)
    rows = magnitude.max(axis=1)
    if not np.all(rows > 0):
        return None  # an empty row: singular whatever the values
    r = 1.0 / rows
    cols = (magnitude * r[:, None]).max(axis=0)
    if not np.all(cols > 0):
        return None
    c = 1.0 / cols
    scaled = matrix * r[:, None] * c[None, :]
    try:
        rcond = 1.0 / (np.linalg.cond(scaled, 1))
    except np.linalg.LinAlgError:
        return None
    if not rcond > RCOND_LIMIT:
        return None
    return c * np.linalg.solve(scaled, r * rhs)


def operating_point(netlist: Netlist, model: StateSpaceModel, u0: NDArray[np.float64]) -> NDArray[np.float64]:
    """The state at the DC operating point: ``A x = −B u(0)`` (zero when every input is 0 at t = 0).

    Raises
    ------
    NetlistError
        When ``A`` is singular and some input is nonzero at t = 0: a zero eigenvalue (a node that
        only capacitors reach, a loop of inductors, a free mass) leaves the operating point
        undetermined, as ngspice's "singular matrix".
    """
    n = model.nstates
    rhs = -(model.B_sparse @ np.asarray(u0, dtype=float)) if n else np.zeros(0)
    if n == 0 or not np.any(rhs):
        return np.zeros(n)
    # Displacement states of x(...) outputs only integrate a velocity: they start at 0 (the
    # displacement from the start), and the operating point is solved for the others.
    keep = np.array([s not in model.info.integrators for s in model.states])
    inner = _solve_unique(model.A_sparse.toarray()[np.ix_(keep, keep)], rhs[keep])
    if inner is None:
        raise NetlistError(
            "no unique DC operating point to start the transient from (the model has a zero "
            "eigenvalue: a node that only capacitors reach, a loop of inductors or a free mass); "
            "add UIC to the .tran line to start from the given initial conditions, or give --ic",
            _where(netlist),
        )
    x0 = np.zeros(n)
    x0[keep] = inner
    return x0


def _forced_operating_point(
    netlist: Netlist, model: StateSpaceModel, u0: NDArray[np.float64]
) -> NDArray[np.float64]:
    """The operating point with the ``.ic`` node voltages held by ideal sources.

    A current source from ground into each named node is added (it changes no state of the
    model); the operating point and those currents solve ``A x + B u0 + Bw w = 0`` together with
    ``v(node) = value`` for each node.
    """
    conditions = held_nodes(netlist)
    nodes = list(conditions)
    first = netlist.initial_conditions[0].loc
    holders = holder_elements(nodes, conditions)
    held = replace(netlist, elements=netlist.elements + holders)
    try:
        extended = compile_netlist(held, [f"v({node})" for node in nodes])
    except NetlistError as exc:
        raise NetlistError(
            f".ic: the node voltages cannot be held during the operating point ({exc})", first
        ) from None
    if tuple(extended.states) != tuple(model.states):
        raise NetlistError(
            ".ic: holding these node voltages changes the model's states; use UIC instead", first
        )
    n, m, k = model.nstates, len(u0), len(nodes)
    A = extended.A_sparse.toarray()
    B = extended.B_sparse.toarray()
    C = extended.C_sparse.toarray()
    D = extended.D_sparse.toarray()
    top = np.hstack([A, B[:, m:]])
    bottom = np.hstack([C, D[:, m:]])
    matrix = np.vstack([top, bottom]) if n else bottom
    values = np.array([conditions[node][0] for node in nodes])
    rhs = np.concatenate([-(B[:, :m] @ u0), values - D[:, :m] @ u0])
    solution = _solve_unique(matrix, rhs)
    if solution is None:
        raise NetlistError(
            ".ic: the held node voltages leave no unique operating point (a node held twice through "
            "other held nodes and sources, or a zero eigenvalue); use UIC instead",
            first,
        )
    return solution[:n] if k else solution


def _uic_start(
    netlist: Netlist, model: StateSpaceModel, u0: NDArray[np.float64], given: list[Element]
) -> Start:
    """Capacitor and inductor starting values of ``UIC`` on the states they carry."""
    index = {s: k for k, s in enumerate(model.states)}
    shifted = {shift.state for shift in model.info.shifts}
    x0 = np.zeros(model.nstates)
    for element, value in uic_values(netlist):
        if element.kind is Kind.CAPACITOR:
            state, start = f"q({element.name})", element.value * value
        else:
            state, start = f"i({element.name})", value
        if start == 0:
            continue
        what = "voltage" if element.kind is Kind.CAPACITOR else "current"
        if state not in index:
            raise NetlistError(
                f"{element.name}: UIC starting {what} {value:g} on an element that is not a state of "
                "the model (it follows from other capacitors, inductors and sources); netlistdyn cannot "
                "impose it",
                element.loc,
            )
        if state in shifted:
            raise NetlistError(
                f"{element.name}: UIC starting {what} {value:g} on a state that sources drive directly "
                f"({state} is shifted by an input); netlistdyn cannot impose it",
                element.loc,
            )
        x0[index[state]] = start
    label = "UIC" if netlist.tran is not None else "no .tran"
    how = f"{label}: IC= and .ic values" if given or netlist.initial_conditions else f"{label}: zero state"
    return Start(x0, True, how)


def _offset(wave: Waveform, c: float) -> Waveform:
    """The waveform minus the constant ``c`` (same shape, breakpoints and smoothness)."""
    if isinstance(wave, Dc):
        return replace(wave, value=wave.value - c)
    if isinstance(wave, Pulse | Exp):
        return replace(wave, v1=wave.v1 - c, v2=wave.v2 - c)
    if isinstance(wave, Sin | Sffm):
        return replace(wave, vo=wave.vo - c)
    if isinstance(wave, Am):
        return replace(wave, offset=wave.offset - c)
    if isinstance(wave, Pwl):
        return replace(wave, values=tuple(v - c for v in wave.values))
    raise TypeError(f"no offset for {type(wave).__name__}")


def around_equilibrium(
    model: StateSpaceModel, signals: InputSignals, x0: NDArray[np.float64]
) -> tuple[InputSignals, NDArray[np.float64]] | None:
    """Inputs relative to their t = 0 values and the constant output, when ``x0`` is an equilibrium.

    From an operating point x0 (``A x0 + B u(0) = 0``) the response is the constant
    ``C x0 + D u(0)`` plus the zero-state response to ``u(t) − u(0)``: simulated that way, a
    circuit that stays at its operating point gives exactly its operating point, and the
    integrators' error estimates, relative to each output's peak, see only what moves.
    None when ``x0`` is zero or not an equilibrium (``.ic`` held during the operating point).
    """
    if not np.any(x0):
        return None
    u0 = signals(np.array([0.0]))[0]
    drift = model.A_sparse @ x0 + model.B_sparse @ u0
    scale = abs(model.A_sparse) @ np.abs(x0) + abs(model.B_sparse) @ np.abs(u0)
    if np.any(np.abs(drift) > 1e-12 * np.maximum(scale, np.finfo(float).tiny)):
        return None
    waves = tuple(_offset(w, float(c)) for w, c in zip(signals.waveforms, u0, strict=True))
    y0 = model.C_sparse @ x0 + model.D_sparse @ u0
    return replace(signals, waveforms=waves), np.asarray(y0, dtype=float)


# --- the sparse descriptor form (netlistdyn.descriptor) ------------------------------------


def descriptor_start(
    netlist: Netlist, system: Any, outputs: Sequence[str] | None, u0: NDArray[np.float64]
) -> tuple[NDArray[np.float64] | None, str, tuple[Diagnostic, ...]]:
    """The same rules on the descriptor unknowns ``x`` of ``E x' = A x + B u``.

    Parameters
    ----------
    netlist : Netlist
    system : DescriptorSystem
        ``assemble(netlist, outputs)``.
    outputs : sequence of str, optional
        The outputs ``system`` was assembled with (they decide which sources it reduces).
    u0 : numpy.ndarray
        Every input's value at t = 0 (V or A).

    Returns
    -------
    x0 : numpy.ndarray or None
        Unknowns to start from (the transient then makes the algebraic ones consistent and
        keeps the charges and fluxes ``E x0``), or None: the plain DC operating point, or
        zero under ``UIC`` without values.
    how : str
        One phrase for reports.
    warnings : tuple of Diagnostic
        ``IC=`` values that do not apply (no ``UIC``).

    Under ``UIC`` each capacitor's charge C·v and each inductor's current are set
    (:func:`uic_values`); the node voltages are any whose capacitor charges sum, node by
    node, to those charges (all that the transient reads of them). Without ``UIC``, ``.ic``
    nodes are held by current sources during the operating point (:func:`holder_elements`).
    """
    if uses_uic(netlist):
        values = uic_values(netlist)
        if not values:
            return None, "zero (UIC)", ()
        return _descriptor_uic(netlist, system, outputs, values), "IC= and .ic values (UIC)", ()
    warnings = ignored_ic_warnings(netlist)
    if not netlist.initial_conditions:
        return None, "DC operating point", warnings
    x0 = _descriptor_held(netlist, system, outputs, u0)
    return x0, "DC operating point with the .ic node voltages held", warnings


def _extended(netlist: Netlist, system: Any, extra: tuple[Element, ...], outputs: Sequence[str]) -> Any:
    """The system assembled with extra current sources (same unknowns: they reduce nothing)."""
    extended = assemble(replace(netlist, elements=netlist.elements + extra), outputs)
    if tuple(extended.variables) != tuple(system.variables):  # pragma: no cover - current sources
        raise RuntimeError("the initial-condition sources changed the descriptor unknowns")
    return extended


def _descriptor_uic(
    netlist: Netlist, system: Any, outputs: Sequence[str] | None, values: list[tuple[Element, float]]
) -> NDArray[np.float64]:
    x0 = np.zeros(system.size)
    index = {name.lower(): k for k, name in enumerate(system.variables)}
    for element, value in values:
        if element.kind is Kind.INDUCTOR:
            x0[index[f"i({element.name})".lower()]] = value
    caps = [(e, v) for e, v in values if e.kind is Kind.CAPACITOR]
    if not caps:
        return x0
    # A charge q between a capacitor's nodes enters E x like a current source's column enters B.
    sources = tuple(Element(Kind.ISOURCE, f"ic.q{k}", e.nodes, 0.0, e.loc) for k, (e, _) in enumerate(caps))
    extended = _extended(netlist, system, sources, list(outputs) if outputs else _voltages(netlist))
    m = len(system.inputs)
    charges = np.array([e.value * v for e, v in caps])
    target = -(extended.B[:, m:] @ charges)[: system.nnodes]
    E = system.E.tocsr()[: system.nnodes].tocsc()[:, : system.nnodes]
    rows = np.flatnonzero(np.diff(E.tocsr().indptr))
    block = E[rows][:, rows]
    try:
        x0[rows] = spla.splu(sp.csc_matrix(block)).solve(target[rows])
    except RuntimeError:  # a group of capacitors reaching no ground: any voltages with those charges
        x0[rows] = spla.lsqr(block, target[rows], atol=1e-15, btol=1e-15)[0]
    residual = np.abs(E @ x0[: system.nnodes] - target)
    if not np.all(residual <= 1e-9 * max(float(np.abs(target).max()), np.finfo(float).tiny)):
        raise NetlistError(
            "UIC: the capacitors' starting charges cannot be placed on the nodes", caps[0][0].loc
        )
    return x0


def _voltages(netlist: Netlist) -> list[str]:
    return [f"v({node})" for node in netlist.nodes]


def _descriptor_held(
    netlist: Netlist, system: Any, outputs: Sequence[str] | None, u0: NDArray[np.float64]
) -> NDArray[np.float64]:

    conditions = held_nodes(netlist)
    nodes = list(conditions)
    first = netlist.initial_conditions[0].loc
    shown = list(outputs) if outputs else _voltages(netlist)
    extended = _extended(
        netlist, system, holder_elements(nodes, conditions), shown + [f"v({node})" for node in nodes]
    )
    n, m, k = system.size, len(system.inputs), len(nodes)
    A, B = extended.A, extended.B.tocsc()
    C, D = extended.C.tocsr()[-k:], extended.D.tocsr()[-k:]
    matrix = sparse.bmat([[A, B[:, m:]], [C, D[:, m:]]], format="csc")
    values = np.array([conditions[node][0] for node in nodes])
    rhs = np.concatenate([-(B[:, :m] @ u0), values - D[:, :m] @ u0])
    try:
        solution = spla.splu(matrix).solve(rhs)
    except RuntimeError:
        solution = None
    if (
        solution is None
        or not np.all(np.isfinite(solution))
        or (np.linalg.norm(matrix @ solution - rhs) > 1e-8 * max(float(np.linalg.norm(rhs)), 1e-300))
    ):
        raise NetlistError(
            ".ic: the held node voltages leave no unique operating point (a node held twice through "
            "other held nodes and sources, a node a supply fixes, or a node only capacitors reach); "
            "use UIC instead",
            first,
        )
    return solution[:n]
