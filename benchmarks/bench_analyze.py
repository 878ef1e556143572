"""How `analyze` scales: compile time and eigenvalue time for RLC ladders.

Runs the pipeline in-process on ladders of 10 to 10,000 sections and prints
a Markdown table (median of repeats, wall-clock seconds). The README's
scaling table comes from::

    python benchmarks/bench_analyze.py

Options: ``--sizes 10,100,1000,10000`` and ``--repeats 3``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from ladder import ladder_netlist

from netlistdyn.analysis.eigen import analyze_eigenvalues
from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.frontend.parser import parse_text


def median_time(func, repeats: int) -> tuple[float, object]:
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = func()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sizes", default="10,100,1000,10000")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    print("| sections | states | parse + compile [s] | eigenvalues [s] | eigen method |")
    print("|---:|---:|---:|---:|---|")
    for n in (int(s) for s in args.sizes.split(",")):
        text = ladder_netlist(n)
        t_compile, model = median_time(
            lambda text=text: compile_netlist(parse_text(text), ["v(n1)"]), args.repeats
        )
        t_eig, eig = median_time(lambda model=model: analyze_eigenvalues(model.A_sparse), 1)
        print(f"| {n} | {model.nstates} | {t_compile:.3f} | {t_eig:.3f} | {eig.method} |", flush=True)


if __name__ == "__main__":
    main()
