"""Parameter sweeps: eigenvalues and stability per case, in parallel processes.

``--param R1=1e-3,100`` lists values; ``log:a:b:n`` and ``lin:a:b:n`` give n
log- or linearly spaced values. Parameters with lists of equal length vary
together (R1 and R2 through the seeds' Case 1 and Case 2); otherwise every
combination is run. Cases are independent jobs, so a distributed scheduler
(Dask, ...) could run them; here a process pool does.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np

from .errors import NetlistError, UsageError
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


def _one_case(args: tuple[str, dict[str, float], list[str] | None]) -> dict[str, Any]:
    from .analysis import analyze_eigenvalues
    from .formulate import compile_netlist
    from .parser import parse_file

    path, params, outputs = args
    try:
        model = compile_netlist(parse_file(path, params), outputs)
    except NetlistError as exc:
        return {"params": params, "error": str(exc)}
    eig = analyze_eigenvalues(model.A_sparse)
    return {
        "params": params,
        "eigenvalues": [[m.value.real, m.value.imag] for m in eig.modes],
        "stability": eig.verdict,
        "stiffness_ratio": eig.stiffness_ratio,
    }


def run_sweep(
    path: str, cases: list[dict[str, float]], outputs: list[str] | None, jobs: int
) -> list[dict[str, Any]]:
    """Compile and analyse every case (in ``jobs`` processes)."""
    tasks = [(path, case, outputs) for case in cases]
    if jobs <= 1 or len(tasks) == 1:
        return [_one_case(t) for t in tasks]
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        return list(pool.map(_one_case, tasks))
