"""The exact method at many output times: vectorised modal evaluation against stepping.

For each netlist, the outputs at N random times in its .tran horizon, computed
(a) the default way — modal states on a ~2000-point grid, every time evaluated
from the grid point before it, SIN/EXP convolved exactly — and (b) by stepping
through every requested time with Van Loan's augmented exponential (SIN/EXP by
1e-9 linear pieces), an independent algorithm. Prints a
Markdown table of both run times and their largest difference relative to
each output's peak::

    python benchmarks/bench_foh.py [--times 200000]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.frontend.parser import parse_file
from netlistdyn.simulation.foh import FohPropagator, input_signals, simulate_foh

ROOT = Path(__file__).resolve().parent.parent
NAMES = ("circuit2", "dipc", "servo_shaft", "two_blocks", "controlled", "waveforms", "cap_loop")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--times", type=int, default=200_000)
    args = parser.parse_args()
    print("| netlist | states | vectorised [s] | stepwise [s] | ratio | difference / peak |")
    print("|---|---:|---:|---:|---:|---:|")
    for name in NAMES:
        netlist = parse_file(ROOT / "netlists" / f"{name}.cir")
        model = compile_netlist(netlist)
        assert netlist.tran is not None
        tstop = netlist.tran.tstop
        signals = input_signals(netlist, netlist.tran.tstep, tstop)
        rng = np.random.default_rng(1)
        times = np.sort(np.r_[0.0, tstop, rng.uniform(0, tstop, args.times)])
        start = time.perf_counter()
        fast, _ = simulate_foh(model, signals, times)
        middle = time.perf_counter()
        original = FohPropagator.modal
        FohPropagator.modal = property(lambda self: False)  # type: ignore[method-assign]
        try:
            slow, _ = simulate_foh(model, signals, times)
        finally:
            FohPropagator.modal = original  # type: ignore[method-assign]
        end = time.perf_counter()
        peak = np.max(np.abs(slow), axis=0)
        diff = float(np.max(np.abs(fast - slow) / np.where(peak > 0, peak, 1.0)))
        a, b = middle - start, end - middle
        print(f"| {name} | {model.nstates} | {a:.3g} | {b:.3g} | {b / a:.0f} | {diff:.1e} |")


if __name__ == "__main__":
    main()
