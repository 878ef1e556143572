"""Error against run time of the nonlinear transient, beside batch ngspice (issue #14).

A diode-RC ladder of N stages (each: 1 kΩ in series, then a diode with
capacitances and 1 nF to ground), driven by a 3 V pulse, 50 µs. Every run is
scored by its largest error on v(n1), v(n2) and v(nN) over 101 grid times,
relative to the largest peak, against a reference: ngspice at tight settings (Gear, reltol
1e-8, maximum step tstop/50000). ngspice is given a 0 V PWL source with a
corner at every grid time, so its own time points include the grid (no
interpolation). ngspice runs in batch (``ngspice -b``), as a child whose own CPU time
(``processes.run_program``) and wall time are reported, start-up included; netlistdyn's
are those of ``nltransient.run`` in this process (CPU: ``time.process_time``).

    python benchmarks/nonlinear_ladder.py [--stages 10,100,1000]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from netlistdyn.base.processes import run_program
from netlistdyn.frontend.parser import parse_text
from netlistdyn.simulation.nltransient import run

MODEL = ".model dm D(IS=2.52n N=1.752 RS=0.568 CJO=4p M=0.4 TT=20n)\n"
TSTOP = 50e-6
POINTS = 100


def ladder(stages: int) -> str:
    """The netlist text (without .end)."""
    lines = [f"diode-RC ladder, {stages} stages", MODEL.strip(), "V1 n0 0 PULSE(0 3 1u 1u 1u 20u 50u)"]
    for k in range(1, stages + 1):
        lines += [f"R{k} n{k - 1} n{k} 1k", f"D{k} n{k} 0 dm", f"C{k} n{k} 0 1n"]
    return "\n".join(lines) + "\n"


def ngspice(
    text: str, outputs: list[str], grid: np.ndarray, options: str, maxstep: float
) -> tuple[np.ndarray, float, float]:
    """ngspice -b on the ladder; (values at the grid, CPU seconds, wall seconds)."""
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "out.txt"
        pwl = " ".join(f"{t:.12g} 0" for t in grid)
        deck = (
            text
            + f"Vgrid grid 0 PWL({pwl})\nRgrid grid 0 1\n"
            + f".options {options}\n.tran {TSTOP / POINTS:g} {TSTOP:g} 0 {maxstep:g} uic\n"
            + f".control\nrun\nwrdata {data} {' '.join(outputs)}\n.endc\n.end\n"
        )
        path = Path(tmp) / "deck.cir"
        path.write_text(deck)
        done = run_program(["ngspice", "-b", str(path)], timeout=3600)
        table = np.loadtxt(data)
    times = table[:, 0]
    rows = [int(np.argmin(np.abs(times - t))) for t in grid]
    return np.column_stack([table[rows, 2 * k + 1] for k in range(len(outputs))]), done.cpu, done.wall


def score(values: np.ndarray, ref: np.ndarray) -> float:
    """Largest error over the outputs, relative to the largest peak (the far end of a long ladder
    stays near zero: its own peak is no scale)."""
    return float(np.abs(values - ref).max() / np.abs(ref).max())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stages", default="10,100,1000")
    args = parser.parse_args()
    grid = np.linspace(0.0, TSTOP, POINTS + 1)
    print(f"load: {os.getloadavg()[0]:.1f} (2 cores)")
    print("| stages | run | setting | error / peak | CPU [s] | wall [s] |")
    print("|---:|---|---|---:|---:|---:|")
    for stages in (int(s) for s in args.stages.split(",")):
        text = ladder(stages)
        outputs = ["v(n1)", "v(n2)", f"v(n{stages})"]
        ref, ref_cpu, ref_wall = ngspice(
            text,
            outputs,
            grid,
            "method=gear reltol=1e-8 abstol=1e-15 vntol=1e-12 chgtol=1e-20",
            TSTOP / 50000,
        )
        print(
            f"| {stages} | ngspice (reference) | gear, reltol 1e-8, max step tstop/50000 | — "
            f"| {ref_cpu:.3g} | {ref_wall:.3g} |"
        )
        for label, options, maxstep in (
            ("trap, defaults", "", TSTOP / POINTS),
            (
                "gear, reltol 1e-6",
                "method=gear reltol=1e-6 abstol=1e-15 vntol=1e-12 chgtol=1e-20",
                TSTOP / 5000,
            ),
        ):
            values, cpu, wall = ngspice(text, outputs, grid, options or "reltol=1e-3", maxstep)
            print(f"| {stages} | ngspice -b | {label} | {score(values, ref):.2g} | {cpu:.3g} | {wall:.3g} |")
        netlist = parse_text(text + ".end\n")
        for rtol in (1e-3, 1e-5, 1e-7):
            if stages >= 1000 and rtol < 1e-5:
                continue
            start, start_cpu = time.perf_counter(), time.process_time()
            result = run(netlist, outputs, grid, rtol=rtol)
            wall, cpu = time.perf_counter() - start, time.process_time() - start_cpu
            print(
                f"| {stages} | netlistdyn (BDF) | rtol {rtol:g} | {score(result.outputs, ref):.2g} "
                f"| {cpu:.3g} | {wall:.3g} |"
            )
        sys.stdout.flush()


if __name__ == "__main__":
    main()
