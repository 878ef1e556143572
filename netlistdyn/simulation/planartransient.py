"""Transient of a planar mechanism: its exact equations x' = f(t, x) integrated, energy watched.

:func:`simulate_planar` integrates :class:`~netlistdyn.formulation.planar.PlanarSystem` with
scipy's ``solve_ivp`` (DOP853 by default: mechanisms are smooth and rarely stiff; Radau and
BDF with the complex-step Jacobian), restarted at the loads' breakpoints, or with the forward
Euler method at a fixed step (``method="euler"``) — on the nonlinear equations, as the lecture
notes' own code steps them. For a mechanism without dampers whose loads stay zero, the energy
T + V is conserved by the exact motion: its largest change over the run, relative to the
energy scale max(|E(0)|, max T), is reported as an accuracy figure.
"""

from __future__ import annotations

import itertools
import time as _time
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.integrate import solve_ivp

from netlistdyn.base.errors import UsageError
from netlistdyn.circuit.netlist import Netlist
from netlistdyn.formulation.planar import PlanarSystem
from netlistdyn.simulation.integrators import SimResult

#: Methods for a planar mechanism (solve_ivp's, and the fixed-step forward Euler); first: default.
PLANAR_METHODS = ("DOP853", "Radau", "BDF", "euler")
#: Tightest relative tolerance (solve_ivp's DOP853 is reliable to about 100 ulp).
PLANAR_MIN_RTOL = 1e-13
#: A state beyond this (m, rad, m/s, rad/s) has left any physical scale: the run says so.
RUNAWAY = 1e12


def energy_drift(system: PlanarSystem, states: NDArray[np.float64]) -> dict[str, float] | None:
    """The energy E = T + V along the run; None when it is not conserved (a damper).

    Returns ``energy_drift``: the largest |E(t) − E(0)| relative to the energy scale
    max(|E(0)|, max T) (E's zero is where the potential's reference is; max T keeps the figure
    meaningful when E(0) is near zero), and ``energy_start``, ``energy_end``, ``energy_max`` (J).
    """
    if not system.model.conservative:
        return None
    energies = np.array([system.model.energy(x) for x in states])
    total = energies.sum(axis=1)
    scale = max(abs(float(total[0])), float(np.max(energies[:, 0])), 1e-300)
    return {
        "energy_drift": float(np.max(np.abs(total - total[0]))) / scale,
        "energy_start": float(total[0]),
        "energy_end": float(total[-1]),
        "energy_max": float(np.max(total)),
    }


def _loads_zero(system: PlanarSystem, times: NDArray[np.float64]) -> bool:
    if not system.model.ninputs:
        return True
    return bool(all(not np.any(system.inputs(float(t))) for t in times))


def simulate_planar(
    netlist: Netlist,
    outputs: Sequence[str],
    times: NDArray[np.float64],
    method: str = "auto",
    rtol: float = 1e-10,
    x0: NDArray[np.float64] | None = None,
    progress: Callable[[float], None] | None = None,
    step: float | None = None,
) -> tuple[SimResult, str]:
    """Integrate the mechanism from ``x0`` (default: rest at q = 0) and read ``outputs``.

    Parameters
    ----------
    netlist : Netlist
        A netlist of planar cards.
    outputs : sequence of str
        Names as :func:`netlistdyn.formulation.planar.output_values` reads them.
    times : ndarray
        Output times (s), from 0; for ``euler`` the steps k·step.
    method : str
        ``auto`` (DOP853), ``DOP853``, ``Radau``, ``BDF`` or ``euler``.
    rtol : float
        Relative tolerance of solve_ivp (absolute: rtol × 1e-3 m, rad, m/s, rad/s).
    x0 : ndarray, optional
        Initial (q, q'), absolute.
    progress : callable, optional
    step : float, optional
        Euler's step (s).

    Returns
    -------
    (SimResult, str)
        The run (its message: the energy drift when conserved) and where it started.
    """
    if method == "auto":
        method = PLANAR_METHODS[0]
    if method not in PLANAR_METHODS:
        raise UsageError(
            f"--method {method}: a planar mechanism is integrated with {', '.join(PLANAR_METHODS)}"
        )
    start = _time.perf_counter()
    times = np.asarray(times, dtype=float)
    span = (float(times[-1]) / max(times.size - 1, 1), float(times[-1]))
    system = PlanarSystem(netlist, span)
    x = np.zeros(system.nstates) if x0 is None else np.asarray(x0, dtype=float).copy()
    how = "rest at q = 0" if x0 is None else "the given initial state"
    states = np.zeros((times.size, system.nstates))
    status, note = "ok", ""
    if method == "euler":
        assert step is not None
        states[0] = x
        for k in range(1, times.size):
            x = x + step * system.f(float(times[k - 1]), x)
            states[k] = x
            if not np.all(np.isfinite(x)):
                states[k:] = np.nan
                status, note = "diverged", f"forward Euler overflowed at t = {times[k]:.6g} s"
                break
            if progress is not None and k % 1000 == 0:
                progress(k / times.size)
        setting = f"step={step:g}, on the nonlinear equations"
        stats = {"steps": float(times.size - 1), "f": float(system.stats["f"])}
    else:
        cpu = _time.process_time()
        used = max(rtol, PLANAR_MIN_RTOL)
        tstop = float(times[-1])
        edges = np.unique(np.r_[0.0, system.breakpoints(tstop), tstop])
        steps = 0
        for a, b in itertools.pairwise(edges):
            sol = solve_ivp(
                system.f,
                (a, b),
                x,
                method=method,
                rtol=used,
                atol=used * 1e-3,
                dense_output=True,
                **({"jac": system.jacobian} if method != "DOP853" else {}),
            )
            if sol.status != 0:
                status, note = "failed", f"{method} failed at t = {sol.t[-1]:.6g} s: {sol.message}"
                break
            inside = (times >= a) & (times <= b)
            if inside.any():
                states[inside] = sol.sol(times[inside]).T
            x = sol.y[:, -1]
            steps += int(sol.t.size - 1)
            if progress is not None:
                progress(b / tstop)
        setting = f"rtol={used:g}" + (f", raised from {rtol:g}" if used != rtol else "")
        stats = {
            "steps": float(steps),
            "f": float(system.stats["f"]),
            "jac": float(system.stats["jac"]),
            "integration_cpu": _time.process_time() - cpu,
        }
    finite = np.all(np.isfinite(states), axis=1)
    if status == "ok":
        big = np.flatnonzero(np.max(np.abs(states), axis=1) > RUNAWAY)
        if big.size:
            note = (
                f"the state passed {RUNAWAY:g} (m, rad, m/s, rad/s) at t = {times[big[0]]:.6g} s: "
                "beyond any physical scale"
            )
            status = "diverged"
    values = np.full((times.size, len(outputs)), np.nan)
    for k in np.flatnonzero(finite).tolist():
        values[k] = system.outputs(states[k], outputs)
    if status == "ok":
        energy = energy_drift(system, states) if _loads_zero(system, times) else None
        if energy is not None:
            stats.update(energy)
            note = (
                f"energy drift {energy['energy_drift']:.3g} (largest |E(t) - E(0)| / max(|E(0)|, max T); "
                f"E(0) = {energy['energy_start']:.12g} J, E(end) = {energy['energy_end']:.12g} J, "
                f"largest {energy['energy_max']:.12g} J)"
            )
    result = SimResult(
        times,
        values,
        method,
        setting,
        _time.perf_counter() - start,
        status,
        note,
        stats,
    )
    return result, how
