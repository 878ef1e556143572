"""Parameter sweeps: eigenvalues and stability per case, in parallel processes.

``--param R1=1e-3,100`` lists values; ``log:a:b:n`` and ``lin:a:b:n`` give n
log- or linearly spaced values. Parameters with lists of equal length vary
together (R1 and R2 through the seeds' Case 1 and Case 2); otherwise every
combination is run. The netlist is compiled once (the first case that compiles): its normal
tree depends only on the topology, so each case re-reads the netlist with
its values and re-evaluates the equations on that tree
(:func:`~netlistdyn.formulate.recompile`) without searching for a tree
again. Cases are independent tasks: a local process pool runs them, or Dask
(``--scheduler dask`` for a local cluster, ``--scheduler tcp://host:8786``
for a running one) when a sweep outgrows one machine.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np

from .errors import NetlistError, UsageError
from .formulate import Formulation
from .values import parse_number


def _values(name: str, text: str) -> list[float]:
    if text.startswith(("log:", "lin:")):
        parts = text.split(":")
        if len(parts) != 4:
            raise UsageError(f"--param {name}={text}: expected log:START:STOP:COUNT")
        a, b, count = parse_number(parts[1]), parse_number(parts[2]), parts[3]
        if a is None or b is None or not count.isdigit() or int(count) < 1:
            raise UsageError(f"--param {name}={text}: expected numbers and a positive count")
        if parts[0] == "log":
            if a <= 0 or b <= 0:
                raise UsageError(f"--param {name}={text}: log ranges need positive ends")
            return list(np.logspace(np.log10(a), np.log10(b), int(count)))
        return list(np.linspace(a, b, int(count)))
    out = []
    for item in text.split(","):
        value = parse_number(item.strip())
        if value is None:
            raise UsageError(f"--param {name}={text}: {item!r} is not a number")
        out.append(value)
    return out


def expand_cases(items: Sequence[str]) -> list[dict[str, float]]:
    """Cases (parameter dictionaries) from ``--param`` values."""
    lists: dict[str, list[float]] = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep or not name.strip():
            raise UsageError(f"--param {item!r}: expected NAME=VALUES")
        lists[name.strip().lower()] = _values(name.strip(), text.strip())
    if not lists:
        raise UsageError("sweep needs at least one --param NAME=VALUES")
    lengths = {len(v) for v in lists.values()}
    if len(lengths) == 1:
        count = lengths.pop()
        return [{k: v[i] for k, v in lists.items()} for i in range(count)]
    keys = list(lists)
    return [dict(zip(keys, combo, strict=True)) for combo in itertools.product(*(lists[k] for k in keys))]


#: ``--scheduler`` values that mean "this machine's process pool".
LOCAL_SCHEDULERS = ("processes", "local")


def _one_case(
    formulation: Formulation | None, path: str, params: dict[str, float], outputs: list[str] | None = None
) -> dict[str, Any]:
    """Re-read the netlist with ``params`` and re-evaluate it on the compiled case's tree.

    Without a compiled case (none compiled) the case is compiled from
    scratch, which reports its own error.
    """
    from .analysis import analyze_eigenvalues
    from .formulate import compile_netlist, recompile
    from .parser import parse_file

    try:
        netlist = parse_file(path, params)
        model = compile_netlist(netlist, outputs) if formulation is None else recompile(formulation, netlist)
    except NetlistError as exc:
        return {"params": params, "error": str(exc)}
    eig = analyze_eigenvalues(model.A_sparse)
    return {
        "params": params,
        "eigenvalues": [[m.value.real, m.value.imag] for m in eig.modes],
        "stability": eig.verdict,
        "stiffness_ratio": eig.stiffness_ratio,
    }


def _first_formulation(
    path: str, cases: list[dict[str, float]], outputs: list[str] | None
) -> Formulation | None:
    """Compile the first case that compiles (its normal tree serves every case)."""
    from .formulate import formulate
    from .parser import parse_file

    for params in cases:
        try:
            return formulate(parse_file(path, params), outputs)
        except NetlistError:
            continue
    return None


def run_sweep(
    path: str,
    cases: list[dict[str, float]],
    outputs: list[str] | None,
    jobs: int,
    scheduler: str = "processes",
) -> list[dict[str, Any]]:
    """Compile once, then re-evaluate and analyse every case.

    Parameters
    ----------
    path : str
        Netlist file.
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

    Returns
    -------
    list of dict
        Per case: params, eigenvalues (1/s), stability verdict, stiffness
        ratio — or the error that case raised.
    """
    formulation = _first_formulation(path, cases, outputs)
    if scheduler in LOCAL_SCHEDULERS:
        if jobs <= 1 or len(cases) == 1:
            return [_one_case(formulation, path, case, outputs) for case in cases]
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            chunk = max(1, len(cases) // (4 * jobs))
            return list(
                pool.map(
                    _one_case,
                    itertools.repeat(formulation),
                    itertools.repeat(path),
                    cases,
                    itertools.repeat(outputs),
                    chunksize=chunk,
                )
            )
    return _run_on_dask(scheduler, jobs, formulation, path, cases, outputs)


def _run_on_dask(
    scheduler: str,
    jobs: int,
    formulation: Formulation | None,
    path: str,
    cases: list[dict[str, float]],
    outputs: list[str] | None,
) -> list[dict[str, Any]]:
    """The same cases as Dask tasks; workers must see ``path`` (a shared file system)."""
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise UsageError(
            f"--scheduler {scheduler} needs Dask: pip install 'dask[distributed]' "
            "(or use --scheduler processes)"
        ) from None
    if scheduler == "dask":
        with (
            LocalCluster(
                n_workers=max(jobs, 1), threads_per_worker=1, processes=True, dashboard_address=None
            ) as cluster,
            Client(cluster) as client,
        ):
            return _dask_map(client, formulation, path, cases, outputs)
    try:
        client = Client(scheduler, timeout="10s")
    except OSError as exc:
        raise UsageError(f"--scheduler {scheduler}: cannot reach the Dask scheduler ({exc})") from None
    with client:
        return _dask_map(client, formulation, path, cases, outputs)


def _dask_map(
    client: Any,
    formulation: Formulation | None,
    path: str,
    cases: list[dict[str, float]],
    outputs: list[str] | None,
) -> list[dict[str, Any]]:
    shared = client.scatter(formulation, broadcast=True) if formulation is not None else None
    n = len(cases)
    futures = client.map(_one_case, [shared] * n, [path] * n, cases, [outputs] * n, pure=False)
    return client.gather(futures)
