"""Parameter sweeps: eigenvalues and stability per case, in parallel processes.

``--param R1=1e-3,100`` lists values; ``log:a:b:n`` and ``lin:a:b:n`` give n
log- or linearly spaced values. Parameters with lists of equal length vary
together (R1 and R2 through the seeds' Case 1 and Case 2); otherwise every
combination is run. The netlist is compiled once (the first case that compiles): its normal
tree depends only on the topology, so each case re-reads the netlist with
its values and re-evaluates the equations on that tree
(:func:`~netlistdyn.formulation.formulate.recompile`) without searching for a tree
again. Cases are independent tasks: a local process pool runs them, or Dask
(``--scheduler dask`` for a local cluster, ``--scheduler tcp://host:8786``
for a running one) when a sweep outgrows one machine.
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np

from netlistdyn.analysis.eigen import analyze_eigenvalues
from netlistdyn.base.errors import NetlistError, SourceLocation, UsageError
from netlistdyn.base.optional import missing
from netlistdyn.base.processes import detached_worker, end_workers
from netlistdyn.base.values import parse_number
from netlistdyn.formulation.compile import Formulation, compile_netlist, formulate, recompile
from netlistdyn.frontend.parser import parse_text

#: Most cases a sweep runs unless ``--max-cases`` raises it (each case is a compile and an
#: eigenvalue analysis; 100 000 cases of Circuit 2 keep a 2-core machine busy for minutes).
MAX_CASES = 100_000
#: Longest text read as one number (a double needs fewer than 30 characters).
_MAX_NUMBER_TEXT = 64


def _number(name: str, text: str, item: str) -> float:
    value = parse_number(item.strip()) if len(item) <= _MAX_NUMBER_TEXT else None
    if value is None:
        raise UsageError(f"--param {name}={text}: {item.strip()!r} is not a number")
    if not np.isfinite(value):
        raise UsageError(f"--param {name}={text}: {item.strip()!r} is not a finite number")
    return value


def _spec(name: str, text: str) -> tuple[int, Callable[[], list[float]]]:
    """The number of values of one ``--param`` and how to make them (counted before made)."""
    if text.startswith(("log:", "lin:")):
        parts = text.split(":")
        if len(parts) != 4:
            raise UsageError(f"--param {name}={text}: expected {parts[0]}:START:STOP:COUNT")
        a, b = _number(name, text, parts[1]), _number(name, text, parts[2])
        count = parts[3].strip()
        if not re.fullmatch(r"[0-9]{1,12}", count) or int(count) < 1:
            raise UsageError(f"--param {name}={text}: COUNT must be a positive whole number")
        n = int(count)
        if parts[0] == "log":
            if a <= 0 or b <= 0:
                raise UsageError(f"--param {name}={text}: log ranges need positive ends")
            return n, lambda: [float(v) for v in np.logspace(np.log10(a), np.log10(b), n)]
        if n > 1 and not np.isfinite(b - a):
            raise UsageError(f"--param {name}={text}: the range overflows")
        return n, lambda: [float(v) for v in np.linspace(a, b, n)]
    items = text.split(",")
    values = [_number(name, text, item) for item in items]
    return len(values), lambda: values


def _values(name: str, text: str) -> list[float]:
    return _spec(name, text)[1]()


def _spec_of(name: str, values: str | float | Sequence[float | str]) -> tuple[int, Callable[[], list[float]]]:
    """:func:`_spec` for a command-line text, a number or a list of either."""
    if isinstance(values, str):
        return _spec(name, values.strip())
    if isinstance(values, int | float):
        value = _number(name, str(values), repr(float(values)))
        return 1, lambda: [value]
    parts = [_spec_of(name, item) for item in values]
    return sum(n for n, _ in parts), lambda: [v for _, make in parts for v in make()]


def expand_cases(
    items: Sequence[str] | Mapping[str, Any], max_cases: int = MAX_CASES
) -> list[dict[str, float]]:
    """Cases (parameter dictionaries) from ``--param`` values.

    Parameters
    ----------
    items : sequence of str or mapping
        ``["R1=1,10", "C1=log:1u:1m:4"]`` as on the command line, or
        ``{"R1": [1, 10], "C1": "log:1u:1m:4"}``. Names keep the user's
        spelling (the parser matches ``.param`` names case-insensitively).
    max_cases : int
        The number of cases is counted before any is made: above it the
        sweep is refused (a :class:`UsageError` saying how to raise it).
    """
    specs: dict[str, tuple[int, Callable[[], list[float]]]] = {}
    pairs = items.items() if isinstance(items, Mapping) else [_split_item(item) for item in items]
    for name, values in pairs:
        specs[name.strip()] = _spec_of(name.strip(), values)
    if not specs:
        raise UsageError("sweep needs at least one --param NAME=VALUES")
    lengths = {n for n, _ in specs.values()}
    total = lengths.copy().pop() if len(lengths) == 1 else math.prod(n for n, _ in specs.values())
    if total > max_cases:
        raise UsageError(
            f"--param: the sweep has {total:,} cases, more than the limit of {max_cases:,} "
            "(raise it with --max-cases)"
        )
    lists = {k: make() for k, (_, make) in specs.items()}
    if len(lengths) == 1:
        return [{k: v[i] for k, v in lists.items()} for i in range(total)]
    keys = list(lists)
    return [dict(zip(keys, combo, strict=True)) for combo in itertools.product(*(lists[k] for k in keys))]


def _split_item(item: str) -> tuple[str, str]:
    name, sep, text = item.partition("=")
    if not sep or not name.strip():
        raise UsageError(f"--param {item!r}: expected NAME=VALUES")
    return name, text


#: ``--scheduler`` values that mean "this machine's process pool".
LOCAL_SCHEDULERS = ("processes", "local")


@dataclass(frozen=True)
class SweepSource:
    """The netlist every case re-reads: its text, read once, and the name used in messages.

    Workers receive the text, so they need not see the file (``.include``
    still resolves relative to ``path``).
    """

    path: str
    text: str

    @classmethod
    def read(cls, path: str) -> SweepSource:
        """Read ``path`` (a ``NetlistError`` names it when it cannot be read)."""
        try:
            with open(path, encoding="utf-8") as handle:
                return cls(path, handle.read())
        except OSError as exc:
            raise NetlistError(
                f"cannot read netlist: {exc.strerror or exc}", SourceLocation(path, 0)
            ) from None
        except UnicodeDecodeError:
            raise NetlistError("cannot read netlist: not a text file", SourceLocation(path, 0)) from None

    def parse(self, params: Mapping[str, float]) -> Any:
        """The netlist with ``params`` applied."""
        return parse_text(self.text, self.path, params)


def _one_case(
    formulation: Formulation | None,
    source: SweepSource | str,
    params: dict[str, float],
    outputs: list[str] | None = None,
    eig: str = "auto",
) -> dict[str, Any]:
    """Re-read the netlist with ``params`` and re-evaluate it on the compiled case's tree.

    Without a compiled case (none compiled) the case is compiled from
    scratch, which reports its own error.
    """

    if isinstance(source, str):
        source = SweepSource.read(source)
    try:
        netlist = source.parse(params)
        model = compile_netlist(netlist, outputs) if formulation is None else recompile(formulation, netlist)
    except NetlistError as exc:
        return {"params": params, "error": str(exc)}
    analysis = analyze_eigenvalues(model.A_sparse, eig, pencil=model.pencil)
    return {
        "params": params,
        "eigenvalues": [[m.value.real, m.value.imag] for m in analysis.modes],
        "stability": analysis.verdict,
        "stiffness_ratio": analysis.stiffness_ratio,
        "eigenvalues_complete": analysis.complete,
    }


def _first_formulation(
    source: SweepSource, cases: list[dict[str, float]], outputs: list[str] | None
) -> Formulation | None:
    """Compile the first case that compiles (its normal tree serves every case)."""
    for params in cases:
        try:
            return formulate(source.parse(params), outputs)
        except NetlistError:
            continue
    return None


def track(
    previous: Sequence[Sequence[float]] | None, current: Sequence[Sequence[float]]
) -> list[list[float]]:
    """Order ``current``'s eigenvalues so that each follows the nearest of ``previous``'s.

    The first case (or one whose count differs from its predecessor's) keeps
    the analysis' order: decreasing real part, then decreasing imaginary
    part. Otherwise the order is the assignment of least total distance
    (``scipy.optimize.linear_sum_assignment``), so column k of a sweep
    table follows one mode through the cases as its parameter moves.
    """
    values = np.array([complex(re, im) for re, im in current], dtype=complex)
    order = sorted(range(values.size), key=lambda k: (-values[k].real, -values[k].imag))
    if previous is not None and len(previous) == values.size and values.size:
        from scipy.optimize import linear_sum_assignment  # noqa: PLC0415 (deferred, scipy.optimize: 0.15 s of CPU to import)

        before = np.array([complex(re, im) for re, im in previous], dtype=complex)
        cost = np.abs(before[:, None] - values[None, :])
        _, order_array = linear_sum_assignment(cost)
        order = [int(k) for k in order_array]
    return [[values[k].real, values[k].imag] for k in order]


def iter_sweep(
    path: str | SweepSource,
    cases: list[dict[str, float]],
    outputs: list[str] | None,
    jobs: int,
    scheduler: str = "processes",
    eig: str = "auto",
) -> Iterator[dict[str, Any]]:
    """Yield each case's result in case order, as soon as it and the ones before it are done.

    Eigenvalues are tracked from case to case (:func:`track`). A caller that
    writes each result as it comes (``sweep --format jsonl``) keeps every
    finished case when the sweep is stopped. Parameters as for
    :func:`run_sweep`.
    """
    source = path if isinstance(path, SweepSource) else SweepSource.read(path)
    formulation = _first_formulation(source, cases, outputs)
    previous: list[list[float]] | None = None
    for index, record in enumerate(_results(formulation, source, cases, outputs, jobs, scheduler, eig)):
        if "eigenvalues" in record:
            record = {**record, "eigenvalues": track(previous, record["eigenvalues"])}
            previous = record["eigenvalues"]
        yield {"index": index, **record}


def _results(
    formulation: Formulation | None,
    source: SweepSource,
    cases: list[dict[str, float]],
    outputs: list[str] | None,
    jobs: int,
    scheduler: str,
    eig: str,
) -> Iterator[dict[str, Any]]:
    calls = [(source, case, outputs, eig) for case in cases]
    yield from map_tasks(_one_case, formulation, calls, jobs, scheduler)


def map_tasks(
    function: Callable[..., Any],
    shared: Any,
    calls: Sequence[tuple[Any, ...]],
    jobs: int,
    scheduler: str = "processes",
) -> Iterator[Any]:
    """``function(shared, *call)`` for every call, yielded in order, wherever ``scheduler`` says.

    Parameters
    ----------
    function : callable
        A module-level function (it is pickled to the workers).
    shared : object
        The first argument of every call, sent once per worker on Dask (broadcast).
    calls : sequence of tuple
        The other arguments, one tuple per task.
    jobs : int
        Worker processes of the local pool or the local Dask cluster (1: run here).
    scheduler : str
        ``"processes"`` (this machine), ``"dask"`` (a local Dask cluster of ``jobs``
        workers) or a Dask scheduler address such as ``tcp://10.0.0.5:8786``.
    """
    if scheduler in LOCAL_SCHEDULERS:
        if jobs <= 1 or len(calls) <= 1:
            yield from (function(shared, *call) for call in calls)
            return
        pool = ProcessPoolExecutor(max_workers=jobs, initializer=detached_worker)
        try:
            # submit, not map: map's clean-up cancels the pending futures, which races with the
            # pool's own clean-up of killed workers (an InvalidStateError traceback in CPython 3.11)
            futures = [pool.submit(function, shared, *call) for call in calls]
            for future in futures:
                yield future.result()
        except BaseException:  # stopped (SIGINT, SIGTERM, the consumer gone): end the workers now
            _stop_pool(pool)
            raise
        pool.shutdown()
        return
    yield from _run_on_dask(scheduler, jobs, function, shared, calls)


def _stop_pool(pool: ProcessPoolExecutor) -> None:
    """Kill a pool's workers and let this process exit at once (not after their tasks).

    ``shutdown`` alone waits for the running tasks, and at exit the pool's queue feeder would
    wait forever to hand tasks to the killed workers; CPython's executor has no public way to
    say either, hence its private ``_processes`` and ``_call_queue`` (present since 3.8).
    """
    end_workers(getattr(pool, "_processes", None))
    queue = getattr(pool, "_call_queue", None)
    if queue is not None:
        queue.cancel_join_thread()
    pool.shutdown(wait=False)


def run_sweep(
    path: str | SweepSource,
    cases: list[dict[str, float]],
    outputs: list[str] | None,
    jobs: int,
    scheduler: str = "processes",
    eig: str = "auto",
    progress: Callable[[], None] | None = None,
) -> list[dict[str, Any]]:
    """Compile once, then re-evaluate and analyse every case.

    Parameters
    ----------
    path : str or SweepSource
        Netlist file (or its text, read once).
    cases : list of dict
        ``.param`` values per case (see :func:`expand_cases`).
    outputs : list of str, optional
        Output specifications.
    jobs : int
        Worker processes for the local pool (1: run in this process).
    scheduler : str
        ``"processes"`` (this machine), ``"dask"`` (a local Dask cluster of
        ``jobs`` workers) or a Dask scheduler address such as
        ``tcp://10.0.0.5:8786`` for a cluster.
    eig : {"auto", "all", "extreme"}
        Which eigenvalues each case computes (as ``analyze --eig``).
    progress : callable, optional
        Called once per finished case.

    Returns
    -------
    list of dict
        Per case, in order: index, params, eigenvalues (1/s, tracked from
        case to case), stability verdict, stiffness ratio — or the error
        that case raised.
    """
    out = []
    for record in iter_sweep(path, cases, outputs, jobs, scheduler, eig):
        out.append(record)
        if progress is not None:
            progress()
    return out


def _run_on_dask(
    scheduler: str,
    jobs: int,
    function: Callable[..., Any],
    shared: Any,
    calls: Sequence[tuple[Any, ...]],
) -> Iterator[Any]:
    """The same tasks on Dask (each call's arguments travel with it, ``shared`` is broadcast)."""
    try:
        from dask.distributed import Client, LocalCluster  # noqa: PLC0415 (deferred, dask: optional dask extra)
    except ImportError:
        raise missing("dask.distributed", f"--scheduler {scheduler}") from None
    if scheduler == "dask":
        with (
            LocalCluster(
                n_workers=max(jobs, 1), threads_per_worker=1, processes=True, dashboard_address=None
            ) as cluster,
            Client(cluster) as client,
        ):
            yield from _dask_map(client, function, shared, calls)
        return
    try:
        client = Client(scheduler, timeout="10s")
    except OSError as exc:
        raise UsageError(f"--scheduler {scheduler}: cannot reach the Dask scheduler ({exc})") from None
    with client:
        yield from _dask_map(client, function, shared, calls)


def _dask_map(
    client: Any, function: Callable[..., Any], shared: Any, calls: Sequence[tuple[Any, ...]]
) -> Iterator[Any]:
    first = client.scatter(shared, broadcast=True) if shared is not None else None
    n = len(calls)
    columns = [list(column) for column in zip(*calls, strict=True)] if n else []
    futures = client.map(function, [first] * n, *columns, pure=False)
    for future in futures:
        yield future.result()
