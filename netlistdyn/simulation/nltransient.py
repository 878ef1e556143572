"""Transient of a nonlinear netlist: x' = f(x, u, t) with charges and currents as states.

The states are those of the linear compiler — capacitor charges q(C),
inductor currents i(L) — plus the junction charge q(D) of each diode with
capacitance. ``f`` is evaluated by solving the *resistive* network at the
given states (:class:`netlistdyn.formulation.nonlinear.NonlinearCircuit` in ``state``
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
import math
import os
import time as _time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.integrate import solve_ivp

from netlistdyn.base.errors import NetlistError, SourceLocation, UsageError
from netlistdyn.circuit.netlist import GROUND, Element, Kind, Netlist
from netlistdyn.circuit.sources import SourceValues, breakpoints, resolved_waveforms
from netlistdyn.circuit.waveforms import Sin
from netlistdyn.devices.models import junction_charge, junction_current
from netlistdyn.formulation.nlsystem import NonlinearSystem
from netlistdyn.formulation.nonlinear import NonlinearCircuit
from netlistdyn.simulation.initial import held_nodes, uses_uic
from netlistdyn.simulation.integrators import SimResult
from netlistdyn.simulation.transient import single_thread


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


#: Methods (scipy.integrate.solve_ivp) offered for the nonlinear transient; the first is the default.
#: DOP853 (explicit, order 8) only on request: for smooth, non-stiff mechanics at tight tolerances.
NONLINEAR_METHODS = ("BDF", "Radau", "DOP853")
#: Relative tolerance of netlistdyn's side in ``validate`` (errors measured: below 2e-5 of peak).
NONLINEAR_VALIDATE_RTOL = 1e-7
#: Tightest relative tolerance used (a tighter request is raised to it, and the setting says so).
MIN_RTOL = 1e-9
#: Decades a state may grow past its scale (the larger of its natural scale, see :func:`_scale`,
#: and its starting value) before the run is stopped as diverged: a solution 1e12 times its
#: scale is a blow-up (x' = x² from 1 reaches it 1e-12 s before t = 1), not a circuit's response.
DIVERGENCE_DECADES = 12
#: Decades of growth that make a failed step (the integrator's step size collapsing) a divergence.
FAILED_GROWTH_DECADES = 6


#: Steps (accepted) a nonlinear transient may take; ``$NETLISTDYN_MAX_STEPS`` overrides it.
MAX_STEPS = 1_000_000
MAX_STEPS_VARIABLE = "NETLISTDYN_MAX_STEPS"
#: Fewest steps an error-controlled integrator spends on one period of a sine.
STEPS_PER_PERIOD = 20
#: Steps between progress reports and work checks.
PROGRESS_EVERY = 200
#: Steps after which the work is projected to the horizon (earlier, a start-up transient's
#: small steps would exaggerate it).
PROJECT_AFTER = 20_000


class WorkLimit(NetlistError):
    """The nonlinear transient would take more steps than its limit."""


class Diverged(NetlistError):
    """The nonlinear transient grew without bound (or to overflow) at time ``t`` (s)."""

    def __init__(self, message: str, loc: SourceLocation, t: float) -> None:
        super().__init__(message, loc)
        self.t = t


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
    """:func:`run` with the interface of ``simulate``'s pipeline.

    (That interface is :func:`~netlistdyn.simulation.integrators.run`'s.)

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
    setting = f"rtol={used:g}" + (f", raised from {rtol:g}" if used != rtol else "")
    begun = _time.perf_counter()
    try:
        result = run(netlist, outputs, times, used, start, progress, method)
    except (Diverged, WorkLimit) as exc:
        empty = np.zeros((0, len(outputs)))
        seconds = _time.perf_counter() - begun
        status = "diverged" if isinstance(exc, Diverged) else "failed"
        message = exc.message if isinstance(exc, Diverged) else str(exc)
        return SimResult(times[:0], empty, method, setting, seconds, status, message, {}), how
    note = f"nonlinear transient; {result.stats['steps']} steps"
    return (
        SimResult(
            result.time,
            result.outputs,
            method,
            setting,
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

    With ``.tran ... UIC`` no operating point is solved: every capacitor starts at its ``IC=``
    voltage, else at the difference of its nodes' ``.ic`` voltages, every inductor at its ``IC=``
    current, a diode junction at the ``.ic`` voltage across it (as ngspice 39 does; rest when
    none is given). A mechanism whose forces read displacements is released from where it is
    drawn. Otherwise the start is the DC operating point with the sources at their t = 0
    values, as ngspice's transient starts (rest when that point is zero).
    """
    circuit = NonlinearCircuit(netlist)
    if uses_uic(netlist):
        x = uic_state(netlist, circuit)
        if x is None:
            return None, True, "rest (UIC: zero charges and currents)"
        return x, True, "UIC: IC= and .ic values"
    if circuit.disp_index:
        return None, True, "rest at the drawn position (a mechanism with forces of x(n))"
    point = circuit.operating_point(np.asarray(u0, dtype=float))
    x = circuit.states_at(point)
    if not np.any(x) and not np.any(u0):
        return None, True, "rest (the operating point is zero)"
    return x, False, f"the DC operating point ({point.method}, {point.iterations} Newton iterations)"


def uic_state(netlist: Netlist, circuit: NonlinearCircuit) -> NDArray[np.float64] | None:
    """The state ``UIC`` starts from: ``IC=`` and ``.ic`` values on the circuit's states; None for rest.

    A capacitor's charge is its charge at its ``IC=`` voltage, else at the difference of its
    nodes' ``.ic`` voltages (a node not named counts as 0 V); an inductor's current its ``IC=``
    current, else 0; a diode junction's charge the charge at the ``.ic`` voltage across the
    diode; displacements start at 0 (the drawn position).

    Raises
    ------
    NetlistError
        An ``.ic`` on the ground node or on a node the netlist does not have.
    """
    volts = {GROUND: 0.0, **{node: value for node, (value, _) in held_nodes(netlist).items()}}

    def across(a: str, b: str) -> float:
        return volts.get(a, 0.0) - volts.get(b, 0.0)

    x = np.zeros(len(circuit.state_names))
    k = 0
    for e in circuit.capacitors:
        v = e.ic if e.ic is not None else across(e.nodes[0], e.nodes[1])
        x[k] = circuit.charge(e, v)[0] if v else 0.0
        k += 1
    for e in circuit.inductors:
        x[k] = e.ic if e.ic is not None else 0.0
        k += 1
    for d in circuit.charged_diodes:
        vd = across(d.element.nodes[0], d.element.nodes[1])
        if vd:
            i, g = junction_current(vd, d.junction)
            x[k] = junction_charge(vd, i, g, d.junction)[0]
        k += 1
    if not np.all(np.isfinite(x)):
        raise NetlistError(
            "UIC: the IC= and .ic values give a non-finite starting charge", SourceLocation(netlist.path, 0)
        )
    return x if np.any(x) else None


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
    check_work(netlist, system.waveforms, tstop)
    x = np.zeros(system.nstates) if x0 is None else np.asarray(x0, dtype=float)
    scale = _scale(system, times)
    atol = np.maximum(rtol * 1e-3 * scale, 1e-300)
    watch = _Watch(netlist, system, scale, x, tstop, progress)
    edges = np.unique(np.r_[0.0, breakpoints(system.waveforms, tstop), tstop])
    states = np.zeros((times.size, system.nstates))
    steps = 0
    with single_thread():  # BLAS threads only slow the small dense solves down
        if system.nstates:
            watch.rhs(0.0, x)  # an overflow at the start itself (a huge --ic)
        for a, b in itertools.pairwise(edges):
            inside = (times >= a) & (times <= b)
            if system.nstates == 0:
                states[inside] = 0.0
                continue
            implicit = method in ("BDF", "Radau", "LSODA")
            sol = solve_ivp(
                watch.rhs,
                (a, b),
                x,
                method=method,
                rtol=rtol,
                atol=atol,
                dense_output=True,
                **({"jac": system.jacobian} if implicit else {}),
                first_step=min((b - a) * 1e-6, tstop * 1e-9) or None,
                events=watch.event,
            )
            last = sol.y[:, -1]
            grown = np.abs(last) / np.maximum(scale, np.abs(x))
            if sol.status == 1 or (sol.status != 0 and not np.all(grown < 10.0**FAILED_GROWTH_DECADES)):
                raise watch.diverged(float(sol.t[-1]), last, np.maximum(scale, np.abs(x)))
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


def step_limit() -> int:
    """The nonlinear transient's step limit: ``$NETLISTDYN_MAX_STEPS`` when a positive integer."""
    text = os.environ.get(MAX_STEPS_VARIABLE, "").strip()
    return int(text) if text.isdigit() and int(text) > 0 else MAX_STEPS


def _fastest(netlist: Netlist, waveforms: Sequence[object]) -> tuple[Element, float] | None:
    """The source whose sine is fastest, with its frequency (Hz); None without a SIN."""
    best = None
    for element, wave in zip(netlist.sources, waveforms, strict=True):
        if isinstance(wave, Sin) and wave.freq and wave.va and (best is None or wave.freq > best[1]):
            best = (element, float(wave.freq))
    return best


def check_work(netlist: Netlist, waveforms: Sequence[object], tstop: float) -> None:
    """Refuse, before any step, a horizon holding more periods of a SIN source than the steps allow.

    An error-controlled integrator follows a sine with at least :data:`STEPS_PER_PERIOD` steps a
    period, so ``frequency × horizon × STEPS_PER_PERIOD`` steps is a lower bound of the work
    (PULSE and PWL sources are bounded by their breakpoints, refused earlier).

    Raises
    ------
    NetlistError
        At the source's line, naming its frequency, the periods and the limit.
    """
    fastest = _fastest(netlist, waveforms)
    if fastest is None:
        return
    element, freq = fastest
    periods = freq * tstop
    limit = step_limit()
    if periods * STEPS_PER_PERIOD > limit:
        raise NetlistError(
            f"{element.name}: a SIN of {freq:.6g} Hz makes {periods:.3g} periods over the {tstop:.6g} s "
            f"horizon; the nonlinear transient needs {STEPS_PER_PERIOD} steps a period at least, more than "
            f"its limit of {limit:,} steps: shorten the horizon or set {MAX_STEPS_VARIABLE}",
            element.loc,
        )


class _Watch:
    """What one nonlinear run watches at every step: growth, overflow, work and progress.

    Parameters
    ----------
    netlist, system
        The circuit being integrated.
    scale : ndarray
        Each state's natural scale (:func:`_scale`).
    x0 : ndarray
        The starting state (a state starting large is measured against its start).
    tstop : float
        The horizon (s).
    progress : callable, optional
        Called with the fraction done, every :data:`PROGRESS_EVERY` steps.
    """

    def __init__(
        self,
        netlist: Netlist,
        system: NonlinearSystem,
        scale: NDArray[np.float64],
        x0: NDArray[np.float64],
        tstop: float,
        progress: Callable[[float], None] | None,
    ) -> None:
        self.netlist, self.system = netlist, system
        self.limit = np.maximum(scale, np.abs(x0)) * 10.0**DIVERGENCE_DECADES
        self.base = np.maximum(scale, np.abs(x0))
        self.tstop, self.progress = tstop, progress
        self.steps = 0
        self.max_steps = step_limit()
        self.where = SourceLocation(netlist.path, 0)

    def rhs(self, t: float, y: NDArray[np.float64]) -> NDArray[np.float64]:
        """``f(t, y)``; an overflow (or a non-finite value) is a divergence at ``t``."""
        try:
            with np.errstate(all="ignore"):
                dy = self.system.f(t, y)
        except (OverflowError, FloatingPointError):
            dy = None
        if dy is None or not np.all(np.isfinite(dy)):
            raise self.diverged(t, y, self.base, overflow=True)
        return dy

    def event(self, t: float, y: NDArray[np.float64]) -> float:
        """Positive while every state is finite and below its limit; counts the steps (solve_ivp
        evaluates it once per accepted step) and stops a run whose work passes the limit."""
        self.steps += 1
        if self.steps % PROGRESS_EVERY == 0:
            self._check_work(t)
        ratio = np.abs(y) / self.limit
        return 1.0 - float(ratio.max()) if np.all(np.isfinite(ratio)) else -1.0

    def _check_work(self, t: float) -> None:
        done = t / self.tstop if self.tstop > 0 else 1.0
        if self.progress is not None:
            self.progress(done)
        projected = self.steps / done if done > 0 else math.inf
        if self.steps >= self.max_steps or (self.steps >= PROJECT_AFTER and projected > self.max_steps):
            fastest = _fastest(self.netlist, self.system.waveforms)
            why = (
                f"; the fastest source is {fastest[0].name}, a SIN of {fastest[1]:.6g} Hz"
                if fastest is not None
                else ""
            )
            raise WorkLimit(
                f"the nonlinear transient took {self.steps:,} steps to reach t = {t:.6g} s of "
                f"{self.tstop:.6g} s: at that pace it needs about {projected:.2g}, more than its limit of "
                f"{self.max_steps:,}{why}; shorten the horizon or set {MAX_STEPS_VARIABLE}",
                fastest[0].loc if fastest is not None else self.where,
            )

    def diverged(
        self, t: float, y: NDArray[np.float64], base: NDArray[np.float64], overflow: bool = False
    ) -> Diverged:
        """The error for a run that blew up at ``t`` with state ``y``, naming the largest state."""
        grown = np.abs(y) / base
        k = int(np.argmax(np.where(np.isfinite(grown), grown, np.inf)))
        names = self.system.circuit.state_names
        if overflow and np.isfinite(y[k]):
            how = f"the equations overflow at {names[k]} = {y[k]:.3g}"
        elif not np.isfinite(y[k]):
            how = f"{names[k]} grew to overflow"
        else:
            how = f"{names[k]} = {y[k]:.3g} grew past {grown[k]:.2g} times its scale"
        return Diverged(f"at t = {t:.6g} s {how}: the solution blows up", self.where, t)


_Watch.event.terminal = True  # type: ignore[attr-defined]  # solve_ivp: the event ends the run


def _scale(system: NonlinearSystem, times: NDArray[np.float64]) -> NDArray[np.float64]:
    """Natural scale of each state: capacitance × voltage scale (C), current scale (A), ...

    The absolute tolerance is ``rtol × 1e-3 ×`` this; the divergence limit ``10**12 ×`` it.
    """
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
        scale[nl + k] = d.junction.cjo * d.junction.vj + d.junction.tt * iscale
    return scale
