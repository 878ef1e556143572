"""An independent reference for the RC power grids: the exact modal solution.

    python benchmarks/modal_reference.py --size 100 [--store benchmarks/results/grid]

Nothing of netlistdyn is used: the grid netlist of ``benchmarks/powergrid.py`` (``R``, ``C``, DC
``V`` and ``PWL`` current loads, nothing else) is read by a few lines here; the nodal equations
``C v' + G v = b_V − P i(t)`` are written directly; ``S = C^-1/2 G C^-1/2`` is symmetric, so LAPACK's
``eigh`` gives ``S = Q Λ Qᵀ`` and each mode is integrated in closed form over each 10 ps output step,
during which every load is linear in time (its corners lie on the output grid):

    d(t + h) = e^{−λh} d(t) − h·φ1(−λh)·b(t) − h·φ2(−λh)·(b(t + h) − b(t)),   b = Qᵀ C^-1/2 P i,

from the DC operating point (all loads start at 0). φ1 and φ2 are evaluated without cancellation
(Taylor series near 0). The error is rounding only: ``eigh`` is backward stable (exact for S plus
a perturbation of about eps·‖S‖₂ = eps·λ_max), which moves the deviation from the DC point by
about κ(S)·eps = eps·λ_max/λ_min of its size (the quasi-static response G⁻¹P i has that
sensitivity; a decaying mode's e^{−λt} moves by at most eps·λ_max/(e·λ_min)). The script prints
this rounding scale: an estimate up to a modest constant, not a rigorous bound. The result is
stored as ``rc<size>_modal.npy`` (the 1001 × 4 probe voltages) with a ``.json`` record, next to
``bench_grid.py``'s runs, and each stored run of the same grid is compared with it;
``python benchmarks/bench_grid.py --sizes 100 --kinds rc --runs none --reference modal`` then
prints the grid's table against it.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))

from powergrid import TSTEP, TSTOP, grid_netlist, probe_nodes  # noqa: E402


def read_grid(text: str) -> tuple[list[str], list[tuple[str, ...]]]:
    """The element lines of a generated grid (title and ``.`` lines skipped); anything else is refused."""
    lines = text.splitlines()[1:]
    elements = []
    for line in lines:
        if not line.strip() or line.startswith(("*", ".")):
            continue
        fields = tuple(line.replace("PWL(", "PWL ( ").replace(")", " )").split())
        if fields[0][0].upper() not in "RCVI":
            raise ValueError(f"not an RC grid line: {line}")
        elements.append(fields)
    nodes = sorted({f for e in elements for f in e[1:3]} - {"0"})
    return nodes, elements


def nodal_system(
    nodes: list[str], elements: list[tuple[str, ...]]
) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[tuple[np.ndarray, np.ndarray]]]:
    """G, C (diagonal, F), the DC right-hand side b_V and the load matrix P with the PWL tables."""
    supplies = {e[1]: float(e[3]) for e in elements if e[0][0].upper() == "V" and e[2] == "0"}
    unknown = [n for n in nodes if n not in supplies]
    index = {n: k for k, n in enumerate(unknown)}
    size = len(unknown)
    # Resistors through the incidence matrix: G = N diag(g) Nᵀ over every node, supplies included.
    every = {n: k for k, n in enumerate([*unknown, *supplies])}
    ends: list[tuple[int, int]] = []
    conductance: list[float] = []
    cap = np.zeros(size)
    loads: list[tuple[int, np.ndarray, np.ndarray]] = []
    for e in elements:
        kind = e[0][0].upper()
        a, b = e[1], e[2]
        if kind == "R":
            if "0" in (a, b):
                raise ValueError(f"a grid resistor joins two nodes: {' '.join(e)}")
            ends.append((every[a], every[b]))
            conductance.append(1.0 / float(e[3]))
        elif kind == "C":
            if b != "0" or a not in index:
                raise ValueError(f"a grid capacitor goes from a node to ground: {' '.join(e)}")
            cap[index[a]] += float(e[3])
        elif kind == "I":
            if b != "0" or e[3].upper() != "PWL":
                raise ValueError(f"a load is a PWL current from a node to ground: {' '.join(e)}")
            pairs = np.array([float(v) for v in e[5:-1]]).reshape(-1, 2)
            loads.append((index[a], pairs[:, 0], pairs[:, 1]))
    if np.any(cap <= 0):
        raise ValueError("every grid node needs a capacitor for the modal form")
    branches = np.arange(len(ends))
    incidence = sp.csr_array(
        (np.repeat([1.0, -1.0], len(ends)), (np.concatenate(np.array(ends).T), np.tile(branches, 2))),
        shape=(len(every), len(ends)),
    )
    full = (incidence @ sp.diags_array(np.array(conductance)) @ incidence.T).tocsr()
    G = full[:size, :size].toarray()
    b_v = -full[:size, size:] @ np.array(list(supplies.values()))
    P = np.zeros((size, len(loads)))
    for j, (k, _, _) in enumerate(loads):
        P[k, j] = 1.0  # the load's current leaves its node
    return unknown, G, cap, b_v, P, [(t, v) for _, t, v in loads]


def phi12(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """φ1(x) = (eˣ − 1)/x and φ2(x) = (eˣ − 1 − x)/x² for x ≤ 0, to rounding."""
    small = np.abs(x) < 1e-2
    xs = np.where(small, 1.0, x)
    em1 = np.expm1(xs)
    phi1 = np.where(small, 1 + x / 2 + x**2 / 6 + x**3 / 24 + x**4 / 120 + x**5 / 720, em1 / xs)
    series2 = 0.5 + x / 6 + x**2 / 24 + x**3 / 120 + x**4 / 720 + x**5 / 5040
    phi2 = np.where(small, series2, (em1 - xs) / xs**2)
    return phi1, phi2


def modal_run(size: int) -> tuple[np.ndarray, dict]:
    """Probe voltages (1001 × 4) of the size×size RC grid, and a record of the run."""
    nodes, elements = read_grid(grid_netlist(size, "rc"))
    unknown, G, cap, b_v, P, tables = nodal_system(nodes, elements)
    where = {n: k for k, n in enumerate(unknown)}
    probes = [where[p] for p in probe_nodes(size)]
    scale = 1.0 / np.sqrt(cap)
    S = scale[:, None] * G * scale[None, :]
    start = time.process_time()
    lam, Q = sla.eigh(S, overwrite_a=True, check_finite=False)
    eig_seconds = time.process_time() - start
    del S
    eps = float(np.finfo(float).eps)
    if lam.min() <= 0:
        raise ValueError("the grid's G is not positive definite (a node without a path to a supply)")
    W = scale[probes, None] * Q[probes, :]  # probe voltages from the modal coordinates
    v_dc = np.linalg.solve(G, b_v)  # every load is 0 at t = 0
    Bm = Q.T @ (scale[:, None] * P)  # modal load matrix
    del Q
    h = TSTEP
    times = np.linspace(0.0, TSTOP, round(TSTOP / TSTEP) + 1)
    currents = np.column_stack([np.interp(times, t, v) for t, v in tables])
    corners = np.concatenate([t for t, _ in tables])
    off_grid = np.abs(corners / h - np.round(corners / h)).max()
    if off_grid > 1e-6:
        raise ValueError("a load corner is off the output grid: the loads are not linear over a step")
    decay = np.exp(-lam * h)
    phi1, phi2 = phi12(-lam * h)
    d = np.zeros(lam.size)
    out = np.empty((times.size, len(probes)))
    out[0] = v_dc[probes]
    b_now = Bm @ currents[0]
    for k in range(1, times.size):
        b_next = Bm @ currents[k]
        d = decay * d - h * phi1 * b_now - h * phi2 * (b_next - b_now)
        b_now = b_next
        out[k] = v_dc[probes] + W @ d
    bound = eps * float(lam.max()) / float(lam.min())
    record = {
        "status": "ok",
        "unknowns": len(unknown),
        "lambda_min": float(lam.min()),
        "lambda_max": float(lam.max()),
        "eigh_cpu": eig_seconds,
        "rounding_scale": bound,
        "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }
    return out, record


def main() -> int:
    """Make the modal reference of one grid and compare the stored runs with it."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=100)
    parser.add_argument("--store", type=Path, default=ROOT / "benchmarks" / "results" / "grid")
    args = parser.parse_args()
    name = f"rc{args.size}"
    target = args.store / f"{name}_modal"
    start, wall = time.process_time(), time.perf_counter()
    values, record = modal_run(args.size)
    record.update(cpu=time.process_time() - start, wall=time.perf_counter() - wall, load=os.getloadavg()[0])
    args.store.mkdir(parents=True, exist_ok=True)
    np.save(target.with_suffix(".npy"), values)
    target.with_suffix(".json").write_text(json.dumps(record))
    swing = np.ptp(values, axis=0)
    print(
        f"{name}: modal reference, {record['unknowns']} unknowns, eigenvalues {record['lambda_min']:.3g} … "
        f"{record['lambda_max']:.3g} 1/s, rounding scale κ·eps {record['rounding_scale']:.2g}, "
        f"{record['cpu']:.0f} CPU s ({record['eigh_cpu']:.0f} in eigh), {record['peak_mb']:.0f} MB"
    )
    for run in sorted(args.store.glob(f"{name}_*.npy")):
        if run.stem == target.name:
            continue
        other = np.load(run)
        if other.shape != values.shape:
            continue
        err = float((np.abs(other - values).max(axis=0) / swing).max())
        print(f"  {run.stem:28s} max error / swing {err:.2g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
