"""Transient of a nonlinear netlist: x' = f(x, u, t) with charges and currents as states.

The states are those of the linear compiler — capacitor charges q(C),
inductor currents i(L) — plus the junction charge q(D) of each diode with
capacitance. ``f`` is evaluated by solving the *resistive* network at the
given states (:class:`netlistdyn.nonlinear.NonlinearCircuit` in ``state``
mode: a capacitor is a voltage source q/C, an inductor a current source, a
diode junction a voltage source at the voltage whose charge is q(D)); then

- q(C)' = the capacitor's current, i(L)' = L⁻¹ v(L) (couplings included;
  v(L)/L(i) for an ``L={expr}`` inductor), q(D)' = the junction's capacitive
  current.

The Jacobian ∂f/∂x follows from the same factorisation by implicit
differentiation (exact, no finite differences); it is the linearised A at
that point. Integration is scipy's Radau (implicit, L-stable, error
controlled), restarted at every source breakpoint. Capacitor loops and
inductor cutsets (excess elements) are refused: their states are not
independent.
"""

from __future__ import annotations

import itertools
import time as _time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray
from scipy.integrate import solve_ivp

from .devices import diode_current_array
from .errors import NetlistError, SourceLocation, UsageError
from .integrators import SimResult
from .netlist import GROUND, Kind, Netlist
from .nonlinear import NonlinearCircuit
from .simulate import source_waveform
from .transient import SourceValues, breakpoints, single_thread
from .waveforms import Waveform


@dataclass(frozen=True)
class NonlinearRun:
    """A nonlinear transient.

    Attributes
    ----------
    time : ndarray
        Output times (s).
    outputs : ndarray
        ``(len(time), len(names))``.
    names : tuple of str
        Output names.
    states : ndarray
        ``(len(time), nstates)`` state trajectory.
    state_names : tuple of str
    stats : dict
        Right-hand-side and Jacobian evaluations, Newton iterations, steps.
    seconds : float
        Wall time (s).
    """

    time: NDArray[np.float64]
    outputs: NDArray[np.float64]
    names: tuple[str, ...]
    states: NDArray[np.float64]
    state_names: tuple[str, ...]
    stats: dict[str, int]
    seconds: float


def resolved_waveforms(netlist: Netlist, span: tuple[float, float] | None = None) -> list[Waveform]:
    """Every source's waveform with SPICE's defaults for ``span`` = (TSTEP, TSTOP) (see NonlinearSystem)."""
    if span is None:
        span = (netlist.tran.tstep, netlist.tran.tstop) if netlist.tran is not None else (1.0, 1.0)
    return [source_waveform(e).resolved(*span) for e in netlist.sources]


class NonlinearSystem:
    """x' = f(x, u(t), t) of a netlist, with its Jacobian.

    Parameters
    ----------
    netlist : Netlist
    span : tuple of float, optional
        (TSTEP, TSTOP) of the transient (s): the SPICE defaults of the source waveforms'
        omitted times (a PULSE's TR, TF = TSTEP, PW, PER = TSTOP). Default: the netlist's
        ``.tran``, else 1 s for both (then only ``f`` at a given input means anything).
    """

    def __init__(self, netlist: Netlist, span: tuple[float, float] | None = None) -> None:
        self.netlist = netlist
        c = self.circuit = NonlinearCircuit(netlist)
        self.waveforms = resolved_waveforms(netlist, span)
        self.inputs = SourceValues(self.waveforms)
        nc, nl, nd = len(c.capacitors), len(c.inductors), len(c.charged_diodes)
        self.nstates = nc + nl + nd + len(c.disp_index)
        self.offsets = (nc, nc + nl)
        # a nonlinear inductor's row of L⁻¹ is 1 here; f() divides it by L(i)
        L = c.inductance_matrix()
        self.Linv = np.linalg.inv(L) if nl else L
        size = c.size
        # P: ∂F/∂x up to sign (F rows of the state-fixed branches), S: f = S z for the linear part
        srows: list[int] = []
        scols: list[int] = []
        svals: list[float] = []
        # a linear capacitor's voltage is q/C (a nonlinear one's moves by dq/C(v), set by jacobian())
        rows, cols, vals = list(c._cap_rows), list(c._cap_states), list(1.0 / c._cap_values)
        for k, e in enumerate(c.capacitors):
            srows.append(k)
            scols.append(c.branch_index[e.key])
            svals.append(1.0)
        for k, e in enumerate(c.inductors):
            rows.append(c.branch_index[e.key])
            cols.append(nc + k)
            vals.append(1.0)
            for j in range(nl):
                g = self.Linv[j, k]
                if g == 0:
                    continue
                for node, sign in ((e.nodes[0], 1.0), (e.nodes[1], -1.0)):
                    if node != GROUND:
                        srows.append(nc + j)
                        scols.append(c.node_index[node])
                        svals.append(sign * g)
        for k, d in enumerate(c.charged_diodes):
            srows.append(nc + nl + k)
            scols.append(d.charge_branch)
            svals.append(1.0)
        for k, (node, index) in enumerate(c.disp_index.items()):  # x(n)' = v(n)
            rows.append(index)
            cols.append(nc + nl + nd + k)
            vals.append(1.0)
            srows.append(nc + nl + nd + k)
            scols.append(c.node_index[node])
            svals.append(1.0)
        self._P_fixed = (rows, cols, vals)
        #: (state index, branch, element) of nonlinear capacitors, and of nonlinear inductors
        self._nl_caps = [
            (k, c.branch_index[e.key], e) for k, e in enumerate(c.capacitors) if e.key in c.storage
        ]
        self._nl_inds = [(nc + k, c.storage[e.key]) for k, e in enumerate(c.inductors) if e.key in c.storage]
        self.S = sp.csr_array((svals, (srows, scols)), shape=(self.nstates, size))
        self.z = np.zeros(size)
        self.stats = {"f": 0, "jac": 0, "newton": 0}
        self._lu = self._fixed_network()

    def _fixed_network(self) -> Any:
        """A factorisation of the state-mode matrix when, states given, the network is linear.

        That is the case when every diode has a charge state (its junction voltage, hence its
        current, is then fixed by the state) and there is no behavioural source: then
        F(z) = G z − b + N with N independent of z, and one LU serves the whole run.
        """
        c = self.circuit
        if c.behavioural or len(c.charged_diodes) != len(c.diodes):
            return None
        G = c.linear_matrix("state")
        try:
            with warnings.catch_warnings():  # an exactly singular matrix: no factorisation to reuse
                warnings.simplefilter("error", scipy.linalg.LinAlgWarning)
                if c.size <= 60:
                    return ("dense", scipy.linalg.lu_factor(G.toarray(), check_finite=True))
                return ("sparse", spla.splu(G.tocsc()))
        except (
            RuntimeError,
            ValueError,
            np.linalg.LinAlgError,
            scipy.linalg.LinAlgError,
            scipy.linalg.LinAlgWarning,
        ):
            return None

    def _solve_fixed(self, rhs: NDArray[np.float64]) -> NDArray[np.float64]:
        kind, lu = self._lu
        if kind == "dense":
            return scipy.linalg.lu_solve(lu, rhs)
        return lu.solve(rhs)

    def solve(self, x: NDArray[np.float64], t: float) -> NDArray[np.float64]:
        """The network's unknowns at states ``x`` and time ``t`` (warm-started Newton)."""
        c = self.circuit
        b = c.rhs("state", self.inputs(t), x)
        if self._lu is not None:  # linear given the states: one solve with the run's factorisation
            injected = np.zeros(c.size + 1)
            if c.diodes:
                i, _ = diode_current_array(b[c._qbranch], c._qis, c._qn)
                np.add.at(injected, c._qa, i)
                np.add.at(injected, c._qk, -i)
            z = self._solve_fixed(b - injected[: c.size])
            if np.all(np.isfinite(z)):
                self.z = z
                return z
        if c.disp_index:  # displacements are given: start there (expressions of them are then exact)
            index = list(c.disp_index.values())
            self.z[index] = b[index]
        z, its, ok = c.newton(self.z, "state", b, t)
        self.stats["newton"] += its
        if not ok:
            z, its, ok = c.newton(np.zeros(c.size), "state", b, t)
            self.stats["newton"] += its
        if not ok:
            raise self._no_solution(t)
        self.z = z
        return z

    def _no_solution(self, t: float) -> NetlistError:
        return NetlistError(
            f"nonlinear transient: the resistive network has no solution at t = {t:.6g} s "
            "(a loop of capacitors, junction capacitances and voltage sources, or a cutset of inductors "
            "and current sources?)",
            SourceLocation(self.netlist.path, 0),
        )

    def f(self, t: float, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """x' (C/s, A/s)."""
        self.stats["f"] += 1
        out = self.S @ self.solve(x, t)
        for k, store in self._nl_inds:  # i' = v / L(i)
            out[k] /= store.value(float(x[k]))[0]
        return out

    def jacobian(self, t: float, x: NDArray[np.float64]) -> NDArray[np.float64] | sp.csc_array:
        """∂f/∂x at (t, x): S (∂z/∂x), with J ∂z/∂x = P by implicit differentiation."""
        self.stats["jac"] += 1
        c = self.circuit
        z = self.solve(x, t)
        _, J = c.evaluate(z, "state", c.rhs("state", self.inputs(t), x), t)
        rows, cols, vals = (list(v) for v in self._P_fixed)
        first = self.offsets[1]
        if c.charged_diodes:  # a junction's voltage moves by dq/C(v)
            ext = np.append(z, 0.0)
            _, cap = c.charge_of(ext[c._qa] - ext[c._qk])
            rows += list(c._qbranch)
            cols += list(range(first, first + len(c.charged_diodes)))
            vals += list(1.0 / cap)
        for k, branch, e in self._nl_caps:  # its voltage moves by dq/C(v)
            rows.append(branch)
            cols.append(k)
            vals.append(1.0 / c.charge(e, c._v(z, e.nodes[0]) - c._v(z, e.nodes[1]))[1])
        P = sp.csc_array((vals, (rows, cols)), shape=(c.size, self.nstates))
        try:
            if isinstance(J, np.ndarray):
                jac = np.asarray(self.S @ np.linalg.solve(J, P.toarray()))
            else:
                dz = spla.splu(J.tocsc()).solve(P.toarray())  # one factorisation, every column at once
                jac = np.asarray(self.S @ dz)
        except (np.linalg.LinAlgError, RuntimeError):  # singular: the states are not independent
            raise self._no_solution(t) from None
        if self._nl_inds:  # rows of i' = v / L(i): d/dx (v/L) = (dv/dx)/L − v L'(i)/L² on its own column
            v = self.S @ z
            for k, store in self._nl_inds:
                value, slope = store.value(float(x[k]))
                jac[k] /= value
                jac[k, k] -= v[k] * slope / value**2
        return jac if self.nstates <= DENSE_JACOBIAN else sp.csc_array(jac)

    def outputs(
        self, z: NDArray[np.float64], names: Sequence[str], u: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """Output values from the network's unknowns."""
        c = self.circuit
        point = None
        out = np.empty(len(names))
        for k, name in enumerate(names):
            kind, _, rest = name.partition("(")
            args = [a.strip().lower() for a in rest.rstrip(")").split(",")]
            if kind.lower() == "x" and _ground(args[0]) in c.disp_index:
                out[k] = float(z[c.disp_index[_ground(args[0])]])
            elif kind.lower() == "v":
                out[k] = c._v(z, _ground(args[0])) - (c._v(z, _ground(args[1])) if len(args) > 1 else 0.0)
            else:
                if point is None:
                    point = c._point(z, u, 0, 0.0, "state")
                key = args[0]
                if key not in point.currents:
                    raise NetlistError(
                        f"output {name}: no such element current", SourceLocation(self.netlist.path, 0)
                    )
                out[k] = point.currents[key]
        return out


def _ground(node: str) -> str:
    return GROUND if node in ("0", "gnd") else node


#: Methods (scipy.integrate.solve_ivp) offered for the nonlinear transient; the first is the default.
#: DOP853 (explicit, order 8) only on request: for smooth, non-stiff mechanics at tight tolerances.
NONLINEAR_METHODS = ("BDF", "Radau", "DOP853")
#: Largest state count whose Jacobian is handed to the integrator dense (above: sparse, sparse LU).
DENSE_JACOBIAN = 50
#: Relative tolerance of netlistdyn's side in ``validate`` (errors measured: below 2e-5 of peak).
NONLINEAR_VALIDATE_RTOL = 1e-7
#: Tightest relative tolerance used (a tighter request is raised to it, and the setting says so).
MIN_RTOL = 1e-9


def simulate_nonlinear(
    netlist: Netlist,
    outputs: Sequence[str],
    times: NDArray[np.float64],
    method: str = "auto",
    rtol: float = 1e-8,
    x0: NDArray[np.float64] | None = None,
    progress: Callable[[float], None] | None = None,
    x0_names: Sequence[str] = (),
    u0: NDArray[np.float64] | None = None,
) -> tuple[SimResult, str]:
    """:func:`run` with the interface of :func:`netlistdyn.integrators.run` (``simulate``'s pipeline).

    Without ``x0`` the run starts where SPICE starts a transient (:func:`nonlinear_start`; ``u0``
    are the sources at t = 0). Returns the result and where it started.

    Raises
    ------
    UsageError
        A method other than ``auto``, ``BDF``, ``Radau`` or ``DOP853``, or an initial state on a
        state the nonlinear circuit does not have.
    """
    if method == "auto":
        method = NONLINEAR_METHODS[0]
    if method not in NONLINEAR_METHODS:
        raise UsageError(f"--method {method}: a nonlinear netlist is integrated with BDF, Radau or DOP853")
    if x0 is not None:
        start, how = initial_state(netlist, x0, x0_names), "the given initial state"
    else:
        span = (float(times[-1]) / max(times.size - 1, 1), float(times[-1]))
        u_start = u0 if u0 is not None else SourceValues(resolved_waveforms(netlist, span))(0.0)
        start, _, how = nonlinear_start(netlist, u_start)
    used = max(rtol, MIN_RTOL)
    result = run(netlist, outputs, times, used, start, progress, method)
    note = f"nonlinear transient; {result.stats['steps']} steps"
    return (
        SimResult(
            result.time,
            result.outputs,
            method,
            f"rtol={used:g}" + (f", raised from {rtol:g}" if used != rtol else ""),
            result.seconds,
            "ok",
            note,
            {k: float(v) for k, v in result.stats.items()},
        ),
        how,
    )


def nonlinear_start(
    netlist: Netlist, u0: NDArray[np.float64]
) -> tuple[NDArray[np.float64] | None, bool, str]:
    """Where SPICE starts the transient of a nonlinear netlist: (state or None for rest, uic, description).

    With ``.tran ... UIC``, and for a mechanism whose forces read displacements (released from
    where it is drawn), the start is rest: zero charges, currents and displacements (IC= values
    are not used). Otherwise it is the DC operating point with the sources at their t = 0 values,
    as ngspice's transient starts (rest when that point is zero).
    """
    from .initial import uses_uic

    circuit = NonlinearCircuit(netlist)
    if uses_uic(netlist):
        return None, True, "rest (UIC: zero charges and currents)"
    if circuit.disp_index:
        return None, True, "rest at the drawn position (a mechanism with forces of x(n))"
    point = circuit.operating_point(np.asarray(u0, dtype=float))
    x = circuit.states_at(point)
    if not np.any(x) and not np.any(u0):
        return None, True, "rest (the operating point is zero)"
    return x, False, f"the DC operating point ({point.method}, {point.iterations} Newton iterations)"


def initial_state(
    netlist: Netlist, x0: NDArray[np.float64] | None, names: Sequence[str]
) -> NDArray[np.float64] | None:
    """The nonlinear circuit's initial state from ``--ic`` values given on the linearised model's states.

    ``--ic`` values are absolute (as for a linear netlist, whose zero state is all charges and
    currents zero). A displacement is ``x(n)``, as in the linearised model; charges, currents and
    momenta keep their names. A diode's junction charge cannot be set.

    Raises
    ------
    UsageError
        A non-zero value on a state the nonlinear circuit does not have.
    """
    if x0 is None or not np.any(np.asarray(x0) != 0):
        return None
    circuit = NonlinearCircuit(netlist)
    targets = {name: k for k, name in enumerate(circuit.state_names)}
    diodes = {f"q({d.element.name})" for d in circuit.charged_diodes}
    out = np.zeros(len(targets))
    for name, value in zip(names, np.asarray(x0, dtype=float), strict=True):
        if value == 0:
            continue
        if name in diodes or name not in targets:
            raise UsageError(f"--ic {name}: not a state the nonlinear transient can start from")
        out[targets[name]] = value
    return out


def run(
    netlist: Netlist,
    outputs: Sequence[str],
    times: NDArray[np.float64],
    rtol: float = 1e-8,
    x0: NDArray[np.float64] | None = None,
    progress: Callable[[float], None] | None = None,
    method: str = "BDF",
    span: tuple[float, float] | None = None,
) -> NonlinearRun:
    """Integrate the nonlinear netlist from ``x0`` (default: zero charges and currents).

    Parameters
    ----------
    netlist : Netlist
    outputs : sequence of str
        ``v(n)``, ``v(a,b)``, ``i(X)``.
    times : ndarray
        Sorted output times (s), from 0.
    rtol : float
        The integrator's relative tolerance; the absolute tolerance of each state is
        ``rtol`` times its scale (C·V for a charge, the source scale over the
        smallest resistance... see the code), so small states are still
        followed to ``rtol``.
    x0 : ndarray, optional
        Initial state.
    progress : callable, optional
        Called with the fraction done.
    method : str
        ``BDF`` or ``Radau`` (scipy), both implicit with error control.
    span : tuple of float, optional
        (TSTEP, TSTOP) for the waveforms' SPICE defaults (s); default: the spacing of a uniform
        ``times`` and its end.
    """
    start = _time.perf_counter()
    times = np.asarray(times, dtype=float)
    if span is None:
        span = (float(times[-1]) / max(times.size - 1, 1), float(times[-1]))
    system = NonlinearSystem(netlist, span)
    tstop = float(times[-1])
    x = np.zeros(system.nstates) if x0 is None else np.asarray(x0, dtype=float)
    atol = _atol(system, times, rtol)
    edges = np.unique(np.r_[0.0, breakpoints(system.waveforms, tstop), tstop])
    states = np.zeros((times.size, system.nstates))
    steps = 0
    with single_thread():  # BLAS threads only slow the small dense solves down
        for a, b in itertools.pairwise(edges):
            inside = (times >= a) & (times <= b)
            if system.nstates == 0:
                states[inside] = 0.0
                continue
            implicit = method in ("BDF", "Radau", "LSODA")
            sol = solve_ivp(
                system.f,
                (a, b),
                x,
                method=method,
                rtol=rtol,
                atol=atol,
                dense_output=True,
                **({"jac": system.jacobian} if implicit else {}),
                first_step=min((b - a) * 1e-6, tstop * 1e-9) or None,
            )
            if sol.status != 0:
                raise NetlistError(
                    f"nonlinear transient failed at t = {sol.t[-1]:.6g} s: {sol.message}",
                    SourceLocation(netlist.path, 0),
                )
            steps += int(sol.t.size - 1)
            if inside.any():
                states[inside] = sol.sol(times[inside]).T
            x = sol.y[:, -1]
            if progress is not None:
                progress(b / tstop)
    values = np.empty((times.size, len(outputs)))
    for k, t in enumerate(times):
        u = system.inputs(float(t))
        z = system.solve(states[k], float(t))
        values[k] = system.outputs(z, outputs, u)
    stats = dict(system.stats)
    stats["steps"] = steps
    return NonlinearRun(
        times,
        values,
        tuple(outputs),
        states,
        tuple(system.circuit.state_names),
        stats,
        _time.perf_counter() - start,
    )


def _atol(system: NonlinearSystem, times: NDArray[np.float64], rtol: float) -> NDArray[np.float64]:
    """Absolute tolerance per state: rtol × (capacitance × voltage scale, or current scale)."""
    c = system.circuit
    sample = np.linspace(0.0, float(times[-1]), 257)
    u = np.array([system.inputs(float(t)) for t in sample]) if c.sources else np.zeros((1, 0))
    volts = [abs(u[:, j]).max() for j, e in enumerate(c.sources) if e.kind is Kind.VSOURCE]
    amps = [abs(u[:, j]).max() for j, e in enumerate(c.sources) if e.kind is Kind.ISOURCE]
    # without voltage sources (mechanics, current-driven circuits) the across variable's scale is 1
    # (1 V, 1 m/s, 1 rad/s); displacements and angles are on the scale of 1 m or 1 rad
    vscale = max([*volts, 0.001]) if volts else 1.0
    resistors = [abs(e.value) for e in system.netlist.elements if e.kind is Kind.RESISTOR]
    iscale = max([*amps, vscale / max(min(resistors), 0.001) if resistors else 0.001])
    nc, nl = system.offsets
    scale = np.ones(system.nstates)
    scale[:nc] = [abs(c.charge(e, 0.0)[1]) * vscale for e in c.capacitors]
    scale[nc:nl] = iscale
    for k, d in enumerate(c.charged_diodes):
        model = d.element.diode
        assert model is not None
        scale[nl + k] = d.cjo * model.VJ + model.TT * iscale
    return np.maximum(rtol * 1e-3 * scale, 1e-300)
