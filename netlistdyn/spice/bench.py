"""Work-precision benchmark within a time budget: error against run time for our methods and ngspice.

Every run is scored on one common grid of output times (``points`` + 1
uniform samples of the horizon) against a reference solution:

* the reference is checked by an independent computation, and chosen to
  fit its share of the budget (:data:`REFERENCE_SHARE`): up to 400 states
  ``exact`` (dense matrix exponential) checked against ``rational`` at
  rtol 1e-12; above, ``krylov`` (scipy's ``expm_multiply``, truncated
  Taylor series to double precision) checked against ``rational`` (at the
  reference rtol when it fits, else at 1e-10), and, where the horizon
  reaches steady state, against the exact DC solution −A⁻¹Bu. A run that
  does not fit is stopped and the reference falls back, saying so; the
  agreement of the two is the reference's stated accuracy;
* ngspice runs in batch mode (``ngspice -b``) on a deck with a 0 V PWL
  source with a corner at every grid time, so its own time points include
  the grid (no interpolation on either side); ngspice reports no point at
  t = 0, so every run is scored from the first grid step on; its CPU and
  wall time are those of the ngspice process (resource usage);
* the budget is CPU seconds: the bench's own and its rows' processes'
  (a loaded machine stretches wall time, not these); every run happens in
  a child process stopped when its own CPU time reaches its share of the
  budget: the CPU time left divided among the rows still to run (weighted,
  see :data:`MAIN_WEIGHT`), so the whole bench ends within the budget; a
  row that is stopped says that its CPU time ran out (or, for a run that
  waits without computing, that the wall-time backstop of
  :data:`WALL_FACTOR` times its share did), and tighter settings of the
  same family are then skipped (they could not finish either);
* rows run in order of interest (our default method, ngspice at its
  defaults, ngspice at tight settings, then the rest), each repeated up to
  ``repeats`` times while its share allows (median reported), and each is
  handed to a callback as soon as it is done, so a stopped bench keeps
  what it measured.

Error: max over outputs and grid times of |y − y_ref| / max|y_ref| (per
output peak).
"""

from __future__ import annotations

import math
import resource
import signal
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from netlistdyn.base.errors import UsageError
from netlistdyn.base.processes import cpu_seconds, run_in_child_status
from netlistdyn.circuit.netlist import Netlist
from netlistdyn.circuit.probes import Probe
from netlistdyn.simulation import integrators
from netlistdyn.simulation.foh import Horizon, InputSignals, input_signals
from netlistdyn.spice.ngspice import SpiceSettings, batch_missing, run_batch
from netlistdyn.statespace.model import StateSpaceModel

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
#: Default budget of a whole bench (CPU seconds of the bench and its rows' processes).
DEFAULT_BUDGET = 120.0
#: A run is also stopped after this many times its CPU share (plus WALL_SLACK) of wall time: a
#: backstop for a run that waits instead of computing.
WALL_FACTOR, WALL_SLACK = 20.0, 10.0
#: Fraction of the budget the reference may take.
REFERENCE_SHARE = 0.4
#: Weight of the main rows (our default method, ngspice at its defaults and at tight settings)
#: in the division of the time left; the other rows weigh 1.
MAIN_WEIGHT = 4.0
#: CPU time kept back for writing the report (s, and fraction of the budget).
RESERVE = (2.0, 0.03)
#: A run given less time than this is skipped, not started (s).
MIN_RUN = 0.05


@dataclass(frozen=True, slots=True)
class BenchRow:
    """One configuration's result (median over repeats).

    ``seconds`` is wall time (ours: the integration inside its child; ngspice:
    the whole ngspice process), ``cpu`` the child's CPU time from its resource
    usage; ``status`` is "ok", "unverified", "stopped" (its share of the
    budget, CPU seconds of its own process, ran out), "skipped" (not started:
    no budget, or a looser setting of the same family was stopped),
    "refused", "failed" or "diverged".
    """

    method: str
    setting: str
    error: float
    seconds: float
    status: str
    message: str = ""
    cpu: float = math.nan
    runs: int = 0


@dataclass(frozen=True)
class Reference:
    """The reference solution and how it was checked."""

    outputs: np.ndarray
    method: str
    check: str
    agreement: float
    seconds: float = math.nan  # wall time of the reference runs (s)


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
    budget: float = math.nan
    elapsed: float = math.nan


def _error(outputs: np.ndarray, reference: np.ndarray) -> float:
    peak = np.max(np.abs(reference[1:]), axis=0)
    peak = np.where(peak > 0, peak, 1.0)
    return float(np.max(np.abs(outputs[1:] - reference[1:]) / peak))


@dataclass(frozen=True, slots=True)
class _Run:
    """One timed run in a child process.

    ``outputs`` on the grid (None unless it produced numbers), ``seconds`` its
    reported wall time, ``cpu`` its CPU time, ``spent`` the CPU time it cost
    the budget (its process's, start included).
    """

    outputs: np.ndarray | None
    seconds: float
    cpu: float
    status: str
    setting: str
    message: str = ""
    spent: float = 0.0


class Clock:
    """The bench's budget in CPU seconds (its own and its rows' processes'), and what is left.

    Parameters
    ----------
    budget : float
        CPU seconds for the whole bench.
    started : float, optional
        :func:`netlistdyn.base.processes.cpu_seconds` at the start (default:
        now), so that loading and compiling the netlist count too.
    """

    def __init__(self, budget: float, started: float | None = None) -> None:
        self.budget = budget
        self.started = cpu_seconds() if started is None else started
        reserve = min(RESERVE[0] + RESERVE[1] * budget, 0.25 * budget) if math.isfinite(budget) else 0.0
        self.deadline = self.started + budget - reserve

    def elapsed(self) -> float:
        """CPU seconds since the start."""
        return cpu_seconds() - self.started

    def left(self) -> float:
        """CPU seconds left for runs (the report's reserve excluded)."""
        return self.deadline - cpu_seconds()


class _CpuOut(Exception):
    """The child's CPU time ran out."""


def _cpu_out(signum: int, frame: object) -> None:
    raise _CpuOut


def _our_child(
    conn: Any,
    model: StateSpaceModel,
    signals: InputSignals,
    times: np.ndarray,
    method: str,
    rtol: float,
    cpu_limit: float,
) -> None:
    """Run in the child: stopped by its own CPU time (a profiling timer, the kernel's RLIMIT_CPU a
    second later as a backstop for a long call in C), it sends ``None`` then."""
    used = time.process_time()
    signal.signal(signal.SIGPROF, _cpu_out)
    signal.setitimer(signal.ITIMER_PROF, max(cpu_limit, 1e-3))
    backstop = math.ceil(used + cpu_limit) + 1
    resource.setrlimit(resource.RLIMIT_CPU, (backstop, backstop + 5))
    try:
        result = integrators.run(model, signals, times, method, rtol=rtol if rtol else 1e-10)
    except _CpuOut:
        conn.send(None)
    else:
        signal.setitimer(signal.ITIMER_PROF, 0)
        conn.send((result.outputs, result.seconds, result.status, result.message, result.setting))
    conn.close()


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _stopped(limit: float, cpu: float) -> str:
    if cpu >= 0.9 * limit:
        return f"its CPU time ran out: {cpu:.3g} s of its own CPU (share {limit:.3g} s), stopped"
    wall = WALL_FACTOR * limit + WALL_SLACK
    return f"its wall time ran out: {wall:.3g} s with {cpu:.3g} s of CPU (share {limit:.3g} s), stopped"


def _run_ours(
    model: StateSpaceModel, signals: InputSignals, times: np.ndarray, method: str, rtol: float, limit: float
) -> _Run:
    """Our ``method`` at ``rtol`` (0: none) in a child stopped after ``limit`` s of its own CPU."""
    setting = f"rtol={rtol:g}" if rtol else ""
    cpu0, wall0 = _children_cpu(), time.perf_counter()
    args = (model, signals, times, method, rtol, limit)
    result, how = run_in_child_status(_our_child, args, WALL_FACTOR * limit + WALL_SLACK)
    cpu, wall = _children_cpu() - cpu0, time.perf_counter() - wall0
    if how == "timeout" or (result is None and cpu >= 0.9 * limit):
        return _Run(None, limit, cpu, "stopped", setting, _stopped(limit, cpu), cpu)
    if result is None:
        return _Run(None, wall, cpu, "failed", setting, "its process died (out of memory?)", cpu)
    outputs, seconds, status, message, setting = result
    keep = outputs if status in ("ok", "unverified") else None
    return _Run(keep, seconds, cpu, status, setting, message, cpu)


def _spice_setting(settings: SpiceSettings) -> str:
    text = settings.describe().split("; .options ")[-1]
    return text + (f" tmax={settings.tmax:g}" if settings.tmax else "")


def _run_spice(
    netlist: Netlist, probes: list[Probe], settings: SpiceSettings, times: np.ndarray, limit: float
) -> _Run:
    """Batch ngspice on the grid, stopped after ``limit`` s of its own CPU; outputs at ``times[1:]``
    (row 0 unused)."""
    setting = _spice_setting(settings)
    run = run_batch(netlist, probes, settings, WALL_FACTOR * limit + WALL_SLACK, limit)
    spent = run.cpu
    if run.status == "timeout":
        return _Run(None, limit, run.cpu, "stopped", setting, _stopped(limit, run.cpu), spent)
    if not run.ok:
        return _Run(None, run.seconds, run.cpu, run.status, setting, run.message, spent)
    picked = np.searchsorted(run.time, times[1:] - 1e-9 * times[-1])
    picked = np.minimum(picked, run.time.size - 1)
    if np.max(np.abs(run.time[picked] - times[1:])) > 1e-9 * times[-1]:
        return _Run(None, run.seconds, run.cpu, "failed", setting, "ngspice skipped grid points", spent)
    outputs = np.zeros((times.size, len(probes)))
    outputs[1:] = np.column_stack([run.outputs[p.name][picked] for p in probes])
    return _Run(outputs, run.seconds, run.cpu, "ok", setting, "", spent)


def compute_reference(
    model: StateSpaceModel,
    signals: InputSignals,
    times: np.ndarray,
    rtol: float = 1e-12,
    limit: float | None = None,
    runs: dict[tuple[str, float], _Run] | None = None,
    spare: float | None = None,
) -> Reference:
    """A reference solution on ``times``, checked by an independent computation, within ``limit`` s.

    Up to 400 states: ``exact`` checked against ``rational`` at ``rtol``.
    Above: ``rational`` at 1e-10, then ``krylov``, then ``rational`` at
    ``rtol``, each in the time left; the reference is ``krylov`` (else the
    tightest ``rational`` that finished), checked against the tightest other
    run, and against the DC solution when the horizon reaches steady state.

    Parameters
    ----------
    rtol : float
        Tolerance of the ``rational`` check run.
    limit : float, optional
        CPU seconds for all the reference runs (None: no limit).
    runs : dict, optional
        Receives every run made, keyed by (method, rtol), for reuse as rows.
    spare : float, optional
        Seconds beyond ``limit`` for a last check (``rational`` at 1e-8) when no
        other check finished (large models).

    Raises
    ------
    UsageError
        When no candidate finished within ``limit``.
    """
    start, wall = cpu_seconds(), time.perf_counter()
    made = runs if runs is not None else {}

    def run(method: str, r: float) -> _Run:
        left = math.inf if limit is None else limit - (cpu_seconds() - start)
        if left < MIN_RUN:
            made[(method, r)] = _Run(None, 0.0, 0.0, "skipped", "", "no time left in the reference's share")
        else:
            made[(method, r)] = _run_ours(model, signals, times, method, r, left)
        return made[(method, r)]

    def label(method: str, r: float) -> str:
        return {"exact": "exact (dense expm)", "krylov": "krylov (expm_multiply)"}.get(
            method, f"{method} rtol={r:g}"
        )

    if model.nstates <= integrators.EXACT_LIMIT:
        plan = [("exact", 0.0), ("rational", rtol)]
        mains = plan
    else:
        plan = [("rational", 1e-10), ("krylov", 0.0)] + ([("rational", rtol)] if rtol < 1e-10 else [])
        mains = [("krylov", 0.0), ("rational", rtol), ("rational", 1e-10)]
    notes = []
    for method, r in plan:
        done = run(method, r)
        if done.outputs is None:
            notes.append(f"{label(method, r)} {done.status}: {done.message}")
    main = next((key for key in mains if made.get(key) and made[key].outputs is not None), None)
    if main is None:
        share = "" if limit is None else f" within its share of the budget ({limit:.3g} s; raise --budget)"
        raise UsageError(f"bench: no reference run finished{share}: " + "; ".join(notes))
    checks = [key for key in reversed(plan) if key != main and made[key].outputs is not None]
    if not checks and model.nstates > integrators.EXACT_LIMIT and spare:
        # The independent check did not fit: at least the same method 100x looser, from the spare time.
        key = ("rational", 1e-8)
        made[key] = _run_ours(model, signals, times, *key, spare)
        if made[key].outputs is not None:
            plan.append(key)
            checks = [key]
        else:
            notes.append(f"{label(*key)} {made[key].status}: {made[key].message}")
    reference = made[main].outputs
    assert reference is not None
    if checks:
        other = made[checks[0]].outputs
        assert other is not None
        agreement, text = _error(other, reference), label(*checks[0])
        if checks[0][0] == main[0]:
            text += " (the same method at another tolerance: not an independent check)"
    else:
        agreement, text = math.nan, "nothing (no check run finished)"
    if model.nstates > integrators.EXACT_LIMIT:
        steady = _steady_state_gap(model, signals, times, reference)
        if steady is not None and steady < 1e-6:
            text += f"; final value vs exact DC solution: {steady:.2g}"
            agreement = max(agreement, steady) if math.isfinite(agreement) else steady
        elif steady is not None:
            text += f" (the horizon ends {steady:.2g} short of steady state: no DC check)"
    if notes:
        text += " (" + "; ".join(notes) + ")"
    return Reference(reference, label(*main), text, agreement, time.perf_counter() - wall)


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


def ngspice_configs(horizon: Horizon, tight: SpiceSettings) -> list[tuple[str, SpiceSettings]]:
    """ngspice at its defaults (trap and gear), at reltol 1e-6, and at validate's tight settings."""
    base = SpiceSettings(horizon.tstep, horizon.tstop, waveform_step=horizon.tstep)
    configs = []
    for method in ("trap", "gear"):
        configs.append((f"ngspice-{method}", replace(base, method=method, reltol=1e-3)))
        configs.append((f"ngspice-{method}", replace(base, method=method, reltol=1e-6)))
    configs.append((f"ngspice-{tight.method}", replace(tight, tstep=min(tight.tstep, horizon.tstep))))
    return configs


@dataclass(frozen=True, slots=True)
class _Config:
    """One row to run: ours (``arg`` = rtol) or ngspice (``arg`` = settings)."""

    kind: str
    method: str
    arg: Any
    family: str
    main: bool = False
    prior: list[_Run] = field(default_factory=list)  # runs already made (by the reference)


def _plan(
    model: StateSpaceModel,
    methods: tuple[str, ...] | None,
    spice: list[tuple[str, SpiceSettings]],
    runs: dict[tuple[str, float], _Run],
) -> list[_Config]:
    """The rows in the order they run: the main ones first, loosest first within a family."""
    chosen = methods or tuple(
        m
        for m in LADDERS
        if not (m == "exact" and model.nstates > integrators.EXACT_LIMIT)
        and not (m == "krylov" and model.nstates > 2000)
    )
    default = integrators.choose_method(model)
    default_rtol = 0.0 if default == "exact" else 1e-10
    ours = [
        _Config(
            "ours",
            m,
            r,
            m,
            main=(m, r) == (default, default_rtol),
            prior=[runs[(m, r)]] if (m, r) in runs else [],
        )
        for m in chosen
        for r in LADDERS.get(m, (1e-6,))
    ]
    trap_gear = [
        _Config(
            "spice",
            name,
            s,
            "tight" if k == len(spice) - 1 else name,
            main=s.reltol >= 1e-3 or k == len(spice) - 1,
        )
        for k, (name, s) in enumerate(spice)
    ]
    defaults = [c for c in trap_gear if c.main and c.family != "tight"]
    tight = [c for c in trap_gear if c.family == "tight"]
    return (
        [c for c in ours if c.main]
        + defaults
        + tight
        + [c for c in ours if not c.main]
        + [c for c in trap_gear if not c.main]
    )


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
    budget: float = DEFAULT_BUDGET,
    started: float | None = None,
    on_reference: Callable[[BenchReport], None] | None = None,
    on_start: Callable[[str, int, int], None] | None = None,
    on_row: Callable[[BenchRow], None] | None = None,
) -> BenchReport:
    """Run every configuration within ``budget`` and score it against a checked reference.

    Parameters
    ----------
    netlist, model, probes : the circuit, compiled with ``probes`` as outputs
    horizon : Horizon
    tight : SpiceSettings, optional
        validate's reference settings, run as one more ngspice row.
    points : int
        Grid intervals (the grid has points + 1 samples).
    repeats : int
        Timed repetitions at most (median reported); fewer when the row's share is short.
    timeout : float
        CPU seconds allowed to any one run (besides the budget).
    methods : tuple of str, optional
        Our methods to run (default: all that apply to the model size).
    with_ngspice : bool
        Include ngspice rows (one "skipped" row when ngspice is missing).
    reference_rtol : float
        Tolerance of the ``rational`` run that checks the reference.
    budget : float
        CPU seconds for the whole bench, its rows' processes included (``math.inf``: no limit).
    started : float, optional
        :func:`netlistdyn.base.processes.cpu_seconds` when the bench started (default: now).
    on_reference, on_start, on_row : callable, optional
        Called with the report's head once the reference is known (no rows
        yet), with (row label, rows done, rows in all) as a row starts, and
        with each row as it is done.
    """
    clock = Clock(budget, started)
    times = np.linspace(0.0, horizon.tstop, points + 1)
    signals = input_signals(netlist, horizon.tstep, horizon.tstop)
    runs: dict[tuple[str, float], _Run] = {}
    if on_start is not None:
        on_start("reference", 0, 0)
    share = min(clock.left(), REFERENCE_SHARE * budget) if math.isfinite(budget) else None
    spare = None if share is None else 0.25 * share
    reference = compute_reference(model, signals, times, reference_rtol, share, runs, spare)
    head = BenchReport(netlist.path, netlist.title, model.nstates, horizon, points, reference, (), budget)
    if on_reference is not None:
        on_reference(head)
    spice: list[tuple[str, SpiceSettings]] = []
    missing = batch_missing() if with_ngspice else None
    if with_ngspice and missing is None:
        grid_horizon = replace(horizon, tstep=horizon.tstop / points)
        for name, settings in ngspice_configs(
            grid_horizon, tight or SpiceSettings(grid_horizon.tstep, horizon.tstop)
        ):
            spice.append((name, replace(settings, grid=points)))
    plan = _plan(model, methods, spice, runs)
    rows: list[BenchRow] = []
    stopped: dict[str, tuple[float, str]] = {}  # family -> (time limit it was stopped at, row)
    for index, config in enumerate(plan):
        label = f"{config.method} {_config_setting(config)}".strip()
        if on_start is not None:
            on_start(label, index, len(plan))
        # The time left is divided among the rows still to run (a family that was stopped is
        # expected to be skipped), the main rows weighing more.
        later = [c for c in plan[index + 1 :] if c.family not in stopped]
        weight = MAIN_WEIGHT if config.main else 1.0
        limit = min(
            clock.left() * weight / (weight + sum(MAIN_WEIGHT if c.main else 1.0 for c in later)), timeout
        )
        if config.family in stopped and limit <= 2 * stopped[config.family][0]:
            before, name = stopped[config.family]
            row = BenchRow(
                config.method,
                _config_setting(config),
                math.nan,
                math.nan,
                "skipped",
                f"not started: {name} was stopped at {before:.3g} s and this row's share is {limit:.3g} s",
            )
        else:
            row = _run_row(config, model, netlist, probes, signals, times, reference, limit, repeats)
            if row.status == "stopped":
                stopped[config.family] = (limit, label)
        rows.append(row)
        if on_row is not None:
            on_row(row)
    if missing is not None:
        rows.append(BenchRow("ngspice", "-", math.nan, math.nan, "skipped", missing))
        if on_row is not None:
            on_row(rows[-1])
    return replace(head, rows=tuple(rows), elapsed=clock.elapsed())


def _config_setting(config: _Config) -> str:
    if config.kind == "spice":
        return _spice_setting(config.arg)
    return f"rtol={config.arg:g}" if config.arg else ""


def _run_row(
    config: _Config,
    model: StateSpaceModel,
    netlist: Netlist,
    probes: list[Probe],
    signals: InputSignals,
    times: np.ndarray,
    reference: Reference,
    limit: float,
    repeats: int,
) -> BenchRow:
    """Run one row (repeated while its share allows) and score it."""
    runs = list(config.prior)
    spent = 0.0
    while len(runs) < max(repeats, 1):
        if runs and runs[-1].outputs is None:
            break  # a failed or stopped configuration is not retried
        left = limit - spent
        if (runs and 1.2 * runs[-1].spent > left) or left < MIN_RUN:  # CPU seconds
            break
        if config.kind == "ours":
            run = _run_ours(model, signals, times, config.method, config.arg, left)
        else:
            run = _run_spice(netlist, probes, config.arg, times, left)
        runs.append(run)
        spent += run.spent
    if not runs:
        return BenchRow(
            config.method,
            _config_setting(config),
            math.nan,
            math.nan,
            "skipped",
            f"not started: its share of the budget was {limit:.2g} s",
        )
    good = [r for r in runs if r.outputs is not None]
    if not good:
        last = runs[-1]
        return BenchRow(
            config.method,
            last.setting or _config_setting(config),
            math.nan,
            last.seconds,
            last.status,
            last.message,
            last.cpu,
            len(runs),
        )
    first = good[0]
    assert first.outputs is not None
    error, note = _error(first.outputs, reference.outputs), first.message
    if first.outputs is reference.outputs:
        error, note = reference.agreement, "the reference: error is its agreement with the check"
    return BenchRow(
        config.method,
        first.setting,
        error,
        statistics.median(r.seconds for r in good),
        first.status,
        note,
        statistics.median(r.cpu for r in good),
        len(good),
    )
