"""What compiling once saves in a sweep: per-case compile time, from scratch against re-evaluation.

A sweep re-reads the netlist for every case and re-evaluates the equations
on the normal tree of the first case (``formulate.recompile``) instead of
searching for a tree again (``formulate.compile_netlist``). This prints a
Markdown table of the median per-case seconds of each, for RLC ladders with
the series resistance swept over 5 values, and their ratio::

    python benchmarks/bench_sweep.py [--sizes 100,1000,5000] [--repeats 3]

Parsing is timed separately (both paths need it); eigenvalues are not
included (they cost the same either way).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from ladder import ladder_netlist

from netlistdyn.formulation.compile import compile_netlist, formulate, recompile
from netlistdyn.frontend.parser import parse_text

RESISTANCES = (0.1, 0.3, 1.0, 3.0, 10.0)


def seconds(func) -> float:
    start = time.perf_counter()
    func()
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="100,1000,5000")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    header = "| sections | states | parse [s] | compile from scratch [s] | re-evaluate on the tree [s] |"
    print(header + " ratio |")
    print("|---:|---:|---:|---:|---:|---:|")
    for n in (int(s) for s in args.sizes.split(",")):
        texts = [ladder_netlist(n, r=r) for r in RESISTANCES]
        netlists = [parse_text(t) for t in texts]
        first = formulate(netlists[0])
        parse_t, scratch_t, again_t = [], [], []
        for _ in range(args.repeats):
            for text, netlist in zip(texts, netlists, strict=True):
                parse_t.append(seconds(lambda text=text: parse_text(text)))
                scratch_t.append(seconds(lambda netlist=netlist: compile_netlist(netlist)))
                again_t.append(seconds(lambda netlist=netlist, first=first: recompile(first, netlist)))
        p, s, a = (statistics.median(x) for x in (parse_t, scratch_t, again_t))
        print(f"| {n} | {first.model.nstates} | {p:.3g} | {s:.3g} | {a:.3g} | {s / a:.2f} |")


if __name__ == "__main__":
    main()
