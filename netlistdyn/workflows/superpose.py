"""Linear superposition across independent sources: one large simulation as independent jobs.

A linear circuit's response is the sum of its responses to each source alone
plus its response to the initial state with every source at zero. ``simulate
--superpose --jobs N`` splits the independent sources into N groups
(:func:`source_groups`), runs the same circuit once per group with only that
group's sources (the others at 0: a 0 V source is a short, a 0 A source an
open), and sums the outputs at the same times (:func:`combine`). The jobs are
independent tasks on the scheduler the sweeps use (:func:`netlistdyn.workflows.sweep.map_tasks`:
this machine's processes, a local Dask cluster, or a running Dask scheduler).

Grouping
    Sources whose waveforms share their breakpoints (the corners of PWL and PULSE)
    go together, and each group of such sources goes where the union of
    breakpoints grows least, so that every job has fewer breakpoints to step
    through than the whole circuit. DC sources form one group of their own kind.

Initial state
    Without ``UIC`` the DC operating point is linear in the sources' values at
    t = 0, so each job starts from its own operating point; ``.ic`` node voltages
    held during that solution are held at 0 V in the source jobs and at their
    values in one more job whose sources are all zero (the held system is linear
    in both). With ``UIC``, element ``IC=`` and ``.ic`` values, and with ``--ic``
    the given state, go to that one job; the source jobs start from zero.

Error accounting
    Each job runs at rtol / (number of jobs) and reports its own error estimate
    (relative to each of its outputs' peaks). Errors of a sum add: the estimate of
    the superposed result is the sum of the jobs' estimates in absolute terms,
    stated relative to each summed output's peak (cancellation between jobs can make
    it larger than any job's). Above rtol the result is ``unverified``, as a direct
    run's would be. The descriptor transient reports no global estimate; there the
    superposed result has none either.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from netlistdyn.analysis.eigen import analyze_eigenvalues
from netlistdyn.base.errors import NetlistError, UsageError
from netlistdyn.circuit.netlist import NONLINEAR_KINDS, Kind, Netlist
from netlistdyn.circuit.sources import source_waveform
from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.simulation.foh import choose_horizon
from netlistdyn.simulation.initial import uses_uic
from netlistdyn.workflows.large import descriptor_horizon, descriptor_wanted, simulate_large
from netlistdyn.workflows.pipelines import simulation_pipeline
from netlistdyn.workflows.sweep import map_tasks

#: Breakpoints closer than this fraction of the horizon count as the same time when grouping.
SAME_TIME = 1e-12


@dataclass(frozen=True)
class Job:
    """One job of a superposition.

    Attributes
    ----------
    index : int
        Position in the plan (0-based).
    sources : tuple of str
        Names of the sources active in this job (the others are zero).
    breakpoints : int
        Number of distinct breakpoints of those sources within the horizon.
    initial : bool
        True for the job that carries the initial state (its sources are all zero
        unless it is the only job).
    """

    index: int
    sources: tuple[str, ...]
    breakpoints: int
    initial: bool = False

    @property
    def label(self) -> str:
        """How reports name the job."""
        if not self.sources:
            return f"job {self.index + 1} (initial state, every source zero)"
        shown = ", ".join(self.sources[:4]) + (
            f", ... ({len(self.sources)} sources)" if len(self.sources) > 4 else ""
        )
        return f"job {self.index + 1} ({shown})"


def check_linear(netlist: Netlist) -> None:
    """Refuse a nonlinear netlist (superposition does not hold), naming its first nonlinear element."""
    for element in netlist.elements:
        if element.kind in NONLINEAR_KINDS:
            raise NetlistError(
                f"{element.label}: --superpose needs a linear circuit (superposition does not hold "
                "for a nonlinear element)",
                element.loc,
            )


def source_breakpoints(netlist: Netlist, tstep: float, tstop: float) -> list[frozenset[float]]:
    """Each independent source's breakpoints in (0, tstop), rounded to :data:`SAME_TIME` of tstop."""
    quantum = SAME_TIME * tstop
    out = []
    for element in netlist.sources:
        wave = source_waveform(element).resolved(tstep, tstop)
        points = (float(p) for p in wave.breakpoints(tstop))
        out.append(frozenset(round(p / quantum) * quantum for p in points if 0 < p < tstop))
    return out


def source_groups(points: Sequence[frozenset[float]], count: int) -> list[list[int]]:
    """Split sources (given by their breakpoint sets) into at most ``count`` groups.

    Sources with the same breakpoints form a cluster; clusters are placed largest first,
    each in the group whose union of breakpoints would be smallest after adding it (ties:
    the group with fewer sources). Empty groups are dropped.

    Returns
    -------
    list of list of int
        Source indices per group, each in increasing order.
    """
    if count < 1:
        raise UsageError("--jobs must be at least 1")
    clusters: dict[frozenset[float], list[int]] = {}
    for k, p in enumerate(points):
        clusters.setdefault(p, []).append(k)
    order = sorted(clusters.items(), key=lambda item: (-len(item[0]), item[1][0]))
    unions: list[set[float]] = [set() for _ in range(count)]
    members: list[list[int]] = [[] for _ in range(count)]
    for bps, sources in order:
        best = min(range(count), key=lambda g: (len(unions[g] | bps), len(members[g]), g))
        unions[best] |= bps
        members[best].extend(sources)
    return [sorted(m) for m in members if m]


def initial_state_given(netlist: Netlist, x0_given: bool) -> bool:
    """True when the initial state is not the sources' own (a job of its own carries it)."""
    if x0_given:
        return True
    if uses_uic(netlist):
        return bool(netlist.initial_conditions) or any(
            e.ic is not None and e.ic != 0
            for e in netlist.elements
            if e.kind in (Kind.CAPACITOR, Kind.INDUCTOR)
        )
    return bool(netlist.initial_conditions)  # .ic held during the operating point


def plan(netlist: Netlist, count: int, tstep: float, tstop: float, x0_given: bool = False) -> list[Job]:
    """The jobs of a superposition: source groups, plus one for the initial state when needed."""
    points = source_breakpoints(netlist, tstep, tstop)
    names = [e.name for e in netlist.sources]
    initial = initial_state_given(netlist, x0_given)
    groups = source_groups(points, count) if names else []
    jobs = [
        Job(k, tuple(names[i] for i in group), len(frozenset().union(*(points[i] for i in group))))
        for k, group in enumerate(groups)
    ]
    if initial:
        jobs.append(Job(len(jobs), (), 0, initial=True))
    if not jobs:
        raise UsageError("--superpose: the netlist has no independent source and no initial state to split")
    return jobs


def job_netlist(netlist: Netlist, job: Job) -> Netlist:
    """The netlist of one job: the sources outside it at 0, the initial conditions only in the initial job.

    In the other jobs ``IC=`` values are dropped and ``.ic`` voltages set to 0 V (held at
    0 V during the operating point without ``UIC``; a zero start with it).
    """
    active = {name.lower() for name in job.sources}
    elements = []
    for element in netlist.elements:
        if element.is_source and element.key not in active:
            element = replace(element, value=0.0, waveform=None)
        if not job.initial and element.ic is not None:
            element = replace(element, ic=None)
        elements.append(element)
    conditions = netlist.initial_conditions
    if not job.initial:
        conditions = tuple(replace(ic, value=0.0) for ic in conditions)
    return replace(netlist, elements=tuple(elements), initial_conditions=conditions, warnings=())


@dataclass(frozen=True)
class Task:
    """What every job shares: the circuit, the path that simulates it and its settings.

    ``path`` is ``"descriptor"`` (:func:`netlistdyn.workflows.large.simulate_large`, ``model``
    unused, ``ics`` the ``--ic`` texts) or ``"explicit"``
    (:func:`netlistdyn.api.simulation_pipeline` on the compiled ``model``, ``x0`` the
    given state).
    """

    netlist: Netlist
    path: str
    outputs: tuple[str, ...] | None
    tstop: float
    tstep: float
    rtol: float
    model: Any = None
    method: str = "auto"
    atol: float | None = None
    force: bool = False
    ics: tuple[str, ...] = ()
    x0: NDArray[np.float64] | None = field(default=None, repr=False)


def run_job(task: Task, job: Job) -> tuple[Any, list[str]]:
    """Simulate one job (in a worker): its :class:`~netlistdyn.api.Simulation` and its warnings."""
    started = time.process_time()
    net = job_netlist(task.netlist, job)
    warnings: list[str] = []
    if task.path == "descriptor":
        ics = task.ics if job.initial else tuple(f"{item.partition('=')[0]}=0" for item in task.ics)
        result = simulate_large(
            net,
            task.outputs,
            task.tstop,
            task.tstep,
            ics,
            None,
            task.rtol,
            warn=lambda w: warnings.append(str(w)),
        )
    else:
        x0 = task.x0
        if x0 is not None and not job.initial:
            x0 = np.zeros_like(x0)
        result = simulation_pipeline(
            net,
            task.model,
            task.tstop,
            task.tstep,
            task.method,
            task.rtol,
            task.atol,
            x0,
            task.force,
            None,
            warn=lambda w: warnings.append(str(w)),
        )
    stats = {**result.stats, "job_cpu_seconds": time.process_time() - started}
    return replace(result, stats=stats), warnings


#: Statuses from worst to best: the superposed result takes the worst of its jobs'.
_SEVERITY = ("refused", "failed", "diverged", "unverified", "ok")


def combine(parts: Sequence[Any], jobs: Sequence[Job], horizon: Any, rtol: float, seconds: float) -> Any:
    """The superposed :class:`~netlistdyn.api.Simulation`: the jobs' outputs summed at the same times.

    Parameters
    ----------
    parts : sequence of Simulation
        One per job, same outputs and times.
    jobs : sequence of Job
    horizon : Horizon
        The horizon of the whole run (reported).
    rtol : float
        The tolerance asked for the sum.
    seconds : float
        Wall time of the whole superposition (s).
    """
    first = parts[0]
    for part in parts[1:]:
        if part.outputs != first.outputs or part.time.shape != first.time.shape:
            raise RuntimeError("superposition: the jobs returned different outputs or times")
    values = np.sum([p.values for p in parts], axis=0)
    worst = min(range(len(parts)), key=lambda k: _SEVERITY.index(parts[k].status))
    status = parts[worst].status
    message = f"{jobs[worst].label}: {parts[worst].message}" if status != "ok" else ""
    estimates = [p.stats.get("error_estimate") for p in parts]
    stats: dict[str, Any] = {
        "jobs": [
            {
                "sources": list(job.sources),
                "initial_state": job.initial,
                "breakpoints": job.breakpoints,
                "status": part.status,
                "seconds": part.seconds,
                **{k: v for k, v in part.stats.items() if isinstance(v, int | float)},
            }
            for job, part in zip(jobs, parts, strict=True)
        ],
        "cpu_seconds": float(sum(p.stats.get("job_cpu_seconds", 0.0) for p in parts)),
    }
    if all(e is not None for e in estimates):
        summed = summed_estimate(parts, values)
        stats["error_estimate"] = summed
        if status == "ok" and summed > rtol:
            status = "unverified"
            message = (
                f"the jobs' error estimates sum to {summed:.2g} of the outputs' peaks, above rtol {rtol:g} "
                "(the jobs' outputs cancel in the sum)"
            )
    starts = sorted({getattr(p, "start", "") or "" for p in parts} - {""})
    return replace(
        first,
        values=values,
        status=status,
        message=message,
        seconds=seconds,
        horizon=horizon,
        setting=f"{len(parts)} superposed jobs, each {first.setting}; rtol {rtol:g} for the sum",
        stats=stats,
        start="; ".join(starts) if starts else getattr(first, "start", ""),
    )


def summed_estimate(parts: Sequence[Any], values: NDArray[np.float64]) -> float:
    """The sum of the jobs' error estimates, relative to each summed output's peak.

    A job's estimate e is relative to each of its outputs' peaks, so output i of job j
    is within e_j · peak_ji; the sum is within Σ_j e_j · peak_ji, stated against the
    summed output's own peak (the largest over outputs).
    """
    if values.size == 0:
        return 0.0
    absolute = np.zeros(values.shape[1])
    for part in parts:
        peak = np.max(np.abs(part.values), axis=0) if part.values.size else np.zeros(values.shape[1])
        absolute += float(part.stats["error_estimate"]) * np.nan_to_num(peak)
    peaks = np.max(np.abs(values), axis=0)
    relative = np.where(absolute > 0, absolute / np.maximum(peaks, np.finfo(float).tiny), 0.0)
    return float(np.max(relative))


def superpose(
    task: Task,
    jobs: Sequence[Job],
    horizon: Any,
    workers: int,
    scheduler: str = "processes",
    progress: Callable[[], None] | None = None,
) -> tuple[Any, list[str]]:
    """Run ``jobs`` on ``scheduler`` with ``workers`` workers and sum them (see the module docstring).

    ``task.rtol`` is the tolerance of the sum; each job runs at ``task.rtol / len(jobs)``.
    Returns the superposed :class:`~netlistdyn.api.Simulation` (its ``stats`` hold each
    job's, and ``cpu_seconds`` the jobs' CPU time together) and the jobs' warnings, each once.

    Raises
    ------
    NetlistError, UsageError
        The first job that raised one (they name the netlist, not the job).
    """
    wall = time.perf_counter()
    share = replace(task, rtol=task.rtol / len(jobs))
    parts: list[Any] = []
    warnings: list[str] = []
    for result, said in map_tasks(run_job, share, [(job,) for job in jobs], workers, scheduler):
        parts.append(result)
        warnings.extend(w for w in said if w not in warnings)
        if progress is not None:
            progress()
    combined = combine(parts, jobs, horizon, task.rtol, time.perf_counter() - wall)
    return combined, warnings


def descriptor_task(
    netlist: Netlist,
    outputs: Sequence[str] | None,
    tstop: float | None,
    tstep: float | None,
    ics: Sequence[str],
    rtol: float,
) -> tuple[Task, Any]:
    """The shared task of a superposed descriptor simulation, and its horizon."""
    check_linear(netlist)
    horizon = descriptor_horizon(netlist, tstop, tstep)
    task = Task(
        netlist,
        "descriptor",
        tuple(outputs) if outputs else None,
        horizon.tstop,
        horizon.tstep,
        rtol,
        ics=tuple(ics),
    )
    return task, horizon


def explicit_task(
    netlist: Netlist,
    model: Any,
    tstop: float | None,
    tstep: float | None,
    method: str,
    rtol: float,
    atol: float | None,
    x0: NDArray[np.float64] | None,
    force: bool,
) -> tuple[Task, Any]:
    """The shared task of a superposed simulation of the explicit model, and its horizon."""

    check_linear(netlist)
    if method == "euler":
        raise UsageError("--superpose: --method euler reports every fixed step; run it directly")
    eig = None
    if tstop is None and netlist.tran is None:
        eig = analyze_eigenvalues(model.A_sparse, "auto" if model.nstates <= 1000 else "extreme")
    horizon = choose_horizon(netlist, eig, tstop, tstep)
    task = Task(
        netlist,
        "explicit",
        None,
        horizon.tstop,
        horizon.tstep,
        rtol,
        model=model,
        method=method,
        atol=atol,
        force=force,
        x0=None if x0 is None else np.asarray(x0, dtype=float),
    )
    return task, horizon


def simulate_superposed(
    netlist: Netlist,
    jobs: int = 2,
    scheduler: str = "processes",
    workers: int | None = None,
    *,
    outputs: Sequence[str] | None = None,
    tstop: float | None = None,
    tstep: float | None = None,
    method: str = "auto",
    rtol: float = 1e-10,
    atol: float | None = None,
    x0: NDArray[np.float64] | None = None,
    ics: Sequence[str] = (),
    force: bool = False,
) -> Any:
    """``simulate --superpose`` from Python: the summed :class:`~netlistdyn.api.Simulation`.

    Parameters
    ----------
    netlist : Netlist
        A parsed linear netlist.
    jobs : int
        Source groups (plus one job for a given initial state).
    scheduler : str
        ``"processes"``, ``"dask"`` or ``"tcp://HOST:PORT"``
        (see :func:`~netlistdyn.workflows.sweep.map_tasks`).
    workers : int, optional
        Local workers (default ``jobs``).
    outputs, tstop, tstep, method, rtol, atol, force
        As for ``simulate``; ``method="descriptor"`` (or ``auto`` on a large circuit)
        takes the sparse descriptor form.
    x0 : numpy.ndarray, optional
        Initial state of the explicit model (``--ic``).
    ics : sequence of str
        ``--ic`` texts of the descriptor form (``v(n1)=0.5``).
    """
    check_linear(netlist)
    if descriptor_wanted(netlist, method):
        task, horizon = descriptor_task(netlist, outputs, tstop, tstep, ics, rtol)
    else:
        model = compile_netlist(netlist, list(outputs) if outputs else None)
        task, horizon = explicit_task(netlist, model, tstop, tstep, method, rtol, atol, x0, force)
    planned = plan(netlist, jobs, task.tstep, task.tstop, bool(task.ics) or task.x0 is not None)
    result, _ = superpose(task, planned, horizon, workers or len(planned), scheduler)
    return result
