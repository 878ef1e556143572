"""CPU cost of the eigenvalue report on a small model: the double-precision check against the 40-digit one.

Circuit 2 of the lecture notes (4 states) with R1 and R2 drawn log-uniform
over 1 mΩ…100 Ω (one seeded generator), compiled once per case (not timed).
For each case, the CPU time (``time.process_time``) of

* numpy's ``eigvals(A)`` (no error bars: the floor),
* ``analyze_eigenvalues(A, pencil=...)`` as ``netlistdyn.eigenvalues`` calls
  it (the quick double-precision check where it vouches for the spectrum,
  else the 40-digit path),
* the same with the quick check switched off (the 40-digit Newton path
  every eigenvalue took before),

and, with ``--check``, every reported eigenvalue against the exact roots
of det(G + sC) (tests/exact_pencil.py): the count outside their bars must
be 0 on both paths. Prints one Markdown table::

    python benchmarks/bench_eigen_small.py [--cases 1000] [--seed 1] [--check]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import netlistdyn.analysis.eigen as eigen
from netlistdyn.api import compile as compile_netlist
from netlistdyn.frontend.parser import parse_file
from tests.exact_pencil import bar_violations, exact_natural_frequencies

NETLIST = Path(__file__).resolve().parent.parent / "netlists" / "circuit2.cir"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--check", action="store_true", help="compare with the exact roots")
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    params = [
        {"R1": float(10.0 ** rng.uniform(-3, 2)), "R2": float(10.0 ** rng.uniform(-3, 2))}
        for _ in range(args.cases)
    ]
    models = [compile_netlist(str(NETLIST), params=p) for p in params]
    quick = eigen.quick_spectrum

    def run(label: str, call) -> tuple[float, list]:
        start = time.process_time()
        results = [call(m) for m in models]
        return time.process_time() - start, results

    t_numpy, _ = run("numpy", lambda m: np.linalg.eigvals(m.A))
    t_now, now = run("now", lambda m: eigen.analyze_eigenvalues(m.A_sparse, "auto", pencil=m.pencil))
    eigen.quick_spectrum = lambda pencil, values: None  # the 40-digit path for every case
    try:
        t_full, full = run("full", lambda m: eigen.analyze_eigenvalues(m.A_sparse, "auto", pencil=m.pencil))
    finally:
        eigen.quick_spectrum = quick
    on_quick = sum("in double precision" in e.method for e in now)
    off_now = off_full = 0
    if args.check:
        for p, e_now, e_full in zip(params, now, full, strict=True):
            exact = exact_natural_frequencies(parse_file(NETLIST, p))
            off_now += len(bar_violations(e_now.modes, exact))
            off_full += len(bar_violations(e_full.modes, exact))
    n = args.cases
    print(f"Circuit 2 (4 states), {n} cases, R1 and R2 log-uniform over 1m…100 Ω, seed {args.seed}")
    print(f"quick check vouched for {on_quick} of {n} spectra")
    print("| eigenvalues of a 4-state model | CPU per case [ms] | vs numpy | outside their bars |")
    print("|---|---:|---:|---:|")
    check = (lambda k: str(k)) if args.check else (lambda k: "not checked")
    rows = (
        ("numpy eigvals (no bars)", t_numpy, "—"),
        ("analyze_eigenvalues (quick where it vouches)", t_now, check(off_now)),
        ("analyze_eigenvalues, 40-digit path only", t_full, check(off_full)),
    )
    for label, seconds, outside in rows:
        print(f"| {label} | {1e3 * seconds / n:.3f} | {seconds / t_numpy:.0f} | {outside} |")


if __name__ == "__main__":
    main()
