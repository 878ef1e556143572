"""Work-precision benchmark: error against run time for every method and for ngspice.

Every run is scored on one common grid of output times (``points`` + 1
uniform samples of the horizon) against a reference solution:

* the reference is computed twice by independent means and the two must
  agree: ``exact`` (dense matrix exponential) against ``rational`` at
  rtol 1e-12 for models up to 400 states; for larger ones ``rational`` at
  rtol 1e-12 against ``rational`` at 1e-11 (different step sequences) and,
  where the horizon reaches steady state, against the exact DC solution
  −A⁻¹Bu at the final time;
* ngspice gets a 0 V PWL source with a corner at every grid time, so its
  own time points include the grid (no interpolation on either side);
  ngspice reports no point at t = 0, so every run is scored from the first
  grid step on;
* each run happens in a child process (a stalled solver is stopped at the
  time limit) and is timed inside it; runs are repeated and interleaved
  (method by method, round by round) so machine noise hits all of them;
  the table gives the median.

Error: max over outputs and grid times of |y − y_ref| / max|y_ref| (per
output peak).
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from . import integrators
from .model import StateSpaceModel
from .netlist import Netlist
from .probes import Probe
from .processes import run_in_child
from .simulate import Horizon, InputSignals, input_signals
from .spice import SpiceSettings, ngspice_missing, run_transient

#: Tolerance ladders per method family.
LADDERS: dict[str, tuple[float, ...]] = {
    "exact": (0.0,),
    "rational": (1e-4, 1e-7, 1e-10),
    "krylov": (0.0,),
    "Radau": (1e-3, 1e-6, 1e-9),
    "BDF": (1e-3, 1e-6, 1e-9),
    "LSODA": (1e-3, 1e-6, 1e-9),
    "RK45": (1e-3, 1e-6, 1e-9),
    "DOP853": (1e-3, 1e-6, 1e-9),
}


#: Most grid intervals ``--points`` accepts (every method and ngspice is sampled on the grid).
MAX_POINTS = 1_000_000


@dataclass(frozen=True, slots=True)
class BenchRow:
    """One configuration's result (median over repeats)."""

    method: str
    setting: str
    error: float
    seconds: float
    status: str
    message: str = ""


@dataclass(frozen=True)
class Reference:
    """The reference solution and how it was checked."""

    outputs: np.ndarray
    method: str
    check: str
    agreement: float


@dataclass(frozen=True)
class BenchReport:
    """All rows of a benchmark."""

    netlist: str
    title: str
    nstates: int
    horizon: Horizon
    points: int
    reference: Reference
    rows: tuple[BenchRow, ...]


def _error(outputs: np.ndarray, reference: np.ndarray) -> float:
    peak = np.max(np.abs(reference[1:]), axis=0)
    peak = np.where(peak > 0, peak, 1.0)
    return float(np.max(np.abs(outputs[1:] - reference[1:]) / peak))


def compute_reference(
    model: StateSpaceModel, signals: InputSignals, times: np.ndarray, rtol: float = 1e-12
) -> Reference:
    """A reference solution on ``times`` checked by an independent computation.

    ``rtol`` is the large-model reference's tolerance; its check runs 10× looser.
    """
    if model.nstates <= integrators.EXACT_LIMIT:
        main = integrators.run(model, signals, times, "exact")
        check = integrators.run(model, signals, times, "rational", rtol=1e-12)
        return Reference(
            main.outputs, "exact (dense expm)", "rational rtol=1e-12", _error(check.outputs, main.outputs)
        )
    main = integrators.run(model, signals, times, "rational", rtol=rtol)
    check = integrators.run(model, signals, times, "rational", rtol=10 * rtol)
    agreement = _error(check.outputs, main.outputs)
    text = f"rational rtol={10 * rtol:g}"
    steady = _steady_state_gap(model, signals, times, main.outputs)
    if steady is not None and steady < 1e-6:
        text += f"; final value vs exact DC solution: {steady:.2g}"
        agreement = max(agreement, steady)
    elif steady is not None:
        text += f" (the horizon ends {steady:.2g} short of steady state: no DC check)"
    return Reference(main.outputs, f"rational rtol={rtol:g}", text, agreement)


def _steady_state_gap(
    model: StateSpaceModel, signals: InputSignals, times: np.ndarray, outputs: np.ndarray
) -> float | None:
    """|y(T) − y_DC| / peak when the inputs are constant at the end, else None."""
    u_end = signals(times[-2:])
    if not np.allclose(u_end[0], u_end[1]) or model.nstates == 0:
        return None
    try:
        x_dc = -spla.spsolve(sp.csc_matrix(model.A_sparse), model.B @ u_end[-1])
    except Exception:
        return None
    y_dc = model.C @ x_dc + model.D @ u_end[-1]
    peak = np.max(np.abs(outputs), axis=0)
    peak = np.where(peak > 0, peak, 1.0)
    return float(np.max(np.abs(outputs[-1] - y_dc) / peak))


def _our_child(
    conn: Any, model: StateSpaceModel, signals: InputSignals, times: np.ndarray, method: str, rtol: float
) -> None:
    result = integrators.run(model, signals, times, method, rtol=rtol if rtol else 1e-10)
    conn.send((result.outputs, result.seconds, result.status, result.message, result.setting))
    conn.close()


def ngspice_configs(horizon: Horizon, tight: SpiceSettings) -> list[tuple[str, SpiceSettings]]:
    """ngspice at its defaults (trap and gear), at reltol 1e-6, and at validate's tight settings."""
    base = SpiceSettings(horizon.tstep, horizon.tstop, waveform_step=horizon.tstep)
    configs = []
    for method in ("trap", "gear"):
        configs.append((f"ngspice-{method}", replace(base, method=method, reltol=1e-3)))
        configs.append((f"ngspice-{method}", replace(base, method=method, reltol=1e-6)))
    configs.append((f"ngspice-{tight.method}", replace(tight, tstep=min(tight.tstep, horizon.tstep))))
    return configs


def run_bench(
    netlist: Netlist,
    model: StateSpaceModel,
    probes: list[Probe],
    horizon: Horizon,
    tight: SpiceSettings | None = None,
    points: int = 1000,
    repeats: int = 3,
    timeout: float = 600.0,
    methods: tuple[str, ...] | None = None,
    with_ngspice: bool = True,
    reference_rtol: float = 1e-12,
    progress: Callable[[float], None] | None = None,
) -> BenchReport:
    """Run every configuration and score it against a checked reference.

    Parameters
    ----------
    netlist, model, probes : the circuit, compiled with ``probes`` as outputs
    horizon : Horizon
    tight : SpiceSettings, optional
        validate's reference settings, run as one more ngspice row.
    points : int
        Grid intervals (the grid has points + 1 samples).
    repeats : int
        Timed repetitions (median reported).
    timeout : float
        Seconds allowed to each run.
    methods : tuple of str, optional
        Our methods to run (default: all that apply to the model size).
    with_ngspice : bool
        Include ngspice rows (skipped with a status when ngspice is missing).
    progress : callable, optional
        Called with the fraction of runs done.
    """
    times = np.linspace(0.0, horizon.tstop, points + 1)
    signals = input_signals(netlist, horizon.tstep, horizon.tstop)
    reference = compute_reference(model, signals, times, reference_rtol)
    chosen = methods or tuple(
        m
        for m in LADDERS
        if not (m == "exact" and model.nstates > integrators.EXACT_LIMIT)
        and not (m == "krylov" and model.nstates > 2000)
    )
    configs: list[tuple[str, str, Any]] = []
    for method in chosen:
        for rtol in LADDERS.get(method, (1e-6,)):
            configs.append(("ours", method, rtol))
    if with_ngspice:
        missing = ngspice_missing()
        if missing is None:
            spice_horizon = replace(horizon, tstep=horizon.tstop / points)
            for name, settings in ngspice_configs(
                spice_horizon, tight or SpiceSettings(spice_horizon.tstep, horizon.tstop)
            ):
                configs.append(("spice", name, replace(settings, grid=points)))
    samples: dict[int, list[tuple[float, float, str, str, str]]] = {i: [] for i in range(len(configs))}
    for repeat in range(max(repeats, 1)):
        for i, (kind, name, arg) in enumerate(configs):
            if samples[i] and samples[i][-1][2] != "ok":
                continue  # a failed configuration is not retried
            samples[i].append(
                _one_run(kind, name, arg, model, netlist, probes, signals, times, reference.outputs, timeout)
            )
            if progress is not None:
                progress((repeat * len(configs) + i + 1) / (max(repeats, 1) * len(configs)))
    rows = []
    for i, (kind, name, arg) in enumerate(configs):
        runs = samples[i]
        ok = [r for r in runs if r[2] == "ok"]
        if ok:
            error, note = ok[0][0], ""
            if (
                kind == "ours"
                and reference.method.startswith(name)
                and (name != "rational" or arg == reference_rtol)
            ):
                error, note = reference.agreement, "the reference: error is its agreement with the check"
            rows.append(BenchRow(name, ok[0][3], error, statistics.median(r[1] for r in ok), "ok", note))
        else:
            error, seconds, status, setting, message = runs[-1]
            rows.append(BenchRow(name, setting, error, seconds, status, message))
    if with_ngspice and ngspice_missing() is not None:
        rows.append(BenchRow("ngspice", "-", math.nan, math.nan, "skipped", str(ngspice_missing())))
    return BenchReport(netlist.path, netlist.title, model.nstates, horizon, points, reference, tuple(rows))


def _one_run(
    kind: str,
    name: str,
    arg: Any,
    model: StateSpaceModel,
    netlist: Netlist,
    probes: list[Probe],
    signals: InputSignals,
    times: np.ndarray,
    reference: np.ndarray,
    timeout: float,
) -> tuple[float, float, str, str, str]:
    """(error, seconds, status, setting, message) of one run."""
    if kind == "ours":
        result = run_in_child(_our_child, (model, signals, times, name, arg), timeout)
        if result is None:
            return math.nan, timeout, "timeout", f"rtol={arg:g}", f"no result within {timeout:g} s"
        outputs, seconds, status, message, setting = result
        if status == "unverified":  # numbers, but outside their own tolerance: scored and shown
            return _error(outputs, reference), seconds, status, setting, message
        if status != "ok":
            return math.nan, seconds, status, setting, message
        return _error(outputs, reference), seconds, "ok", setting, ""
    settings: SpiceSettings = arg
    setting = settings.describe().split("; .options ")[-1]
    run = run_transient(netlist, probes, settings, timeout)
    if not run.ok:
        status = "timeout" if "did not finish" in run.message else "failed"
        return math.nan, run.seconds, status, setting, run.message
    picked = np.searchsorted(run.time, times[1:] - 1e-9 * times[-1])
    picked = np.minimum(picked, run.time.size - 1)
    if np.max(np.abs(run.time[picked] - times[1:])) > 1e-9 * times[-1]:
        return math.nan, run.seconds, "failed", setting, "ngspice skipped grid points"
    spice_out = np.column_stack([run.outputs[p.name][picked] for p in probes])
    full = np.vstack([reference[:1], spice_out])  # t = 0 is not scored
    return _error(full, reference), run.seconds, "ok", setting, ""
