"""The README's ladder ratios with batch ngspice: CPU and wall time of ``ngspice -b`` and of ours.

    python benchmarks/ladder_batch.py [--sizes 10,100,1000] [--timeout 1200]

The ladders of ``benchmarks/run_bench.py`` (N sections of series 1 Ω + 1 mH with a shunt 1 µF,
unit step, horizon 2RC·N², outputs v(nN) and v(nN/2)), on the same 1000-step grid. ngspice runs
as a batch process (``ngspice -b``; no PySpice, whose overhead roughly doubled its times), at its
defaults with trap and with gear, given a 0 V PWL source with a corner at every grid time so that
its own time points include the grid (``wrdata`` then prints them; the grid rows are picked, no
interpolation). Ours is the ``simulate`` command (default method, rtol 1e-10) in a child process.
Each child is limited to ``--timeout`` CPU seconds; CPU = its user + system time, wall = elapsed.
Errors are the largest deviation over both outputs and the grid, relative to each output's peak,
against ``rational`` at rtol 1e-12 (N ≥ 1000) or ``exact`` at rtol 1e-12 (smaller), run in-process.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
from pathlib import Path

# One BLAS thread, as ngspice has one: on a loaded machine idle BLAS threads spin and their CPU
# time counts (the 100-section ladder measured 5.5 s CPU with two threads, 0.15 s with one).
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT))

from ladder import ladder_netlist  # noqa: E402

from netlistdyn.base.processes import run_program  # noqa: E402

POINTS = 1000


def child(args: list[str], timeout: float) -> tuple[float, float, int]:
    """Run a child limited to ``timeout`` CPU seconds; (CPU s, wall s, exit code)."""
    done = run_program(args, None, cpu_limit=timeout, env={**os.environ, "PYTHONPATH": str(ROOT)})
    return done.cpu, done.wall, done.returncode


def ngspice_deck(text: str, outputs: list[str], tstop: float, method: str, data: Path) -> str:
    """The ladder with a grid-forcing 0 V PWL source and a wrdata control block."""
    corners = " ".join(f"{tstop * k / POINTS!r} 0" for k in range(POINTS + 1))
    body = text.replace(".end\n", "")
    body += f"Vgrid grid 0 PWL({corners})\nRgrid grid 0 1\n"
    if method != "trap":
        body += f".options method={method}\n"
    body += ".control\nset wr_singlescale\nset wr_vecnames\noption numdgt=16\nrun\n"
    body += f"wrdata {data} " + " ".join(outputs) + "\nquit\n.endc\n.end\n"
    return body


def on_grid(table: np.ndarray, tstop: float) -> np.ndarray | None:
    """The rows of ngspice's table at the grid times after 0 (ngspice prints no t = 0 row under
    UIC; None if some grid time is missing)."""
    grid = np.linspace(0.0, tstop, POINTS + 1)[1:]
    index = np.searchsorted(table[:, 0], grid - 1e-9 * tstop / POINTS)
    index = np.minimum(index, table.shape[0] - 1)
    if np.max(np.abs(table[index, 0] - grid)) > 1e-6 * tstop / POINTS:
        return None
    return table[index, 1:]


def reference(path: Path, outputs: list[str]) -> tuple[np.ndarray, str, float, float]:
    """Our tight run on the grid, and the default method at rtol 1e-10 timed in-process:
    (reference outputs, method, CPU s, its error)."""
    from netlistdyn.formulation.compile import compile_netlist
    from netlistdyn.frontend.parser import parse_file
    from netlistdyn.simulation import integrators
    from netlistdyn.simulation.foh import input_signals

    net = parse_file(path)
    model = compile_netlist(net, outputs)
    tstop = net.tran.tstop
    times = np.linspace(0.0, tstop, POINTS + 1)
    method = "rational" if model.nstates > integrators.EXACT_LIMIT else "exact"
    signals = input_signals(net, tstop / POINTS, tstop)
    run = integrators.run(model, signals, times, method, rtol=1e-12)
    start = time.process_time()
    default = integrators.run(model, signals, times, "auto", rtol=1e-10)
    seconds = time.process_time() - start
    return run.outputs, default.method, seconds, error(default.outputs, run.outputs)


def error(values: np.ndarray, ref: np.ndarray) -> float:
    """Largest error relative to each output's peak."""
    return float(np.max(np.abs(values - ref) / np.max(np.abs(ref), axis=0)))


def main() -> int:
    """Print one Markdown table over the sizes."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="10,100,1000")
    parser.add_argument("--timeout", type=float, default=1200.0, help="CPU seconds per run")
    parser.add_argument("--no-process", action="store_true", help="skip the simulate command's run")
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="ladder_batch_"))
    print(f"load average at start: {os.getloadavg()[0]:.1f}")
    print(
        "| N | states | ours in-process: CPU [s], error | ours, `simulate` process: CPU / wall [s], error "
        "| ngspice -b trap: CPU / wall [s], error | ngspice -b gear: CPU / wall [s], error "
        "| CPU ratio ours in-process (process) / trap, gear |"
    )
    print("|---:|---:|---|---|---|---|---|")
    for n in (int(v) for v in args.sizes.split(",")):
        tstop = 2e-6 * n * n
        text = ladder_netlist(n, tstop=tstop)
        path = work / f"ladder_{n}.cir"
        path.write_text(text)
        outputs = [f"v(n{n})", f"v(n{max(1, n // 2)})"]
        ref, method, seconds, err = reference(path, outputs)
        cells, cpus = [f"{method}: {seconds:.3f}, {err:.1e}"], []
        ours = work / f"ours_{n}.csv"
        cmd = [
            sys.executable,
            "-m",
            "netlistdyn",
            "simulate",
            str(path),
            "--rtol",
            "1e-10",
            "--csv",
            str(ours),
        ]
        cmd += [a for o in outputs for a in ("--output", o)]
        cpu, wall, code = child(cmd, args.timeout) if not args.no_process else (math.nan, math.nan, -1)
        if args.no_process:
            cells.append("-")
        elif code in (0, 3) and ours.exists():
            values = np.loadtxt(ours, delimiter=",", skiprows=1)[:, 1:]
            cells.append(f"{cpu:.2f} / {wall:.2f}, {error(values, ref):.1e}")
        else:
            cells.append(f"{cpu:.2f} / {wall:.2f}, exit {code}")
        cpus.append(cpu)
        for method in ("trap", "gear"):
            data = work / f"ng_{method}_{n}.out"
            deck = work / f"ng_{method}_{n}.cir"
            deck.write_text(ngspice_deck(text, outputs, tstop, method, data))
            cpu, wall, code = child(["ngspice", "-b", str(deck)], args.timeout)
            values = on_grid(np.loadtxt(data, skiprows=1), tstop) if data.exists() else None
            err = f"{error(values, ref[1:]):.1e}" if values is not None else "grid missed"
            cells.append(f"{cpu:.2f} / {wall:.2f}, {err}" if data.exists() else f"{cpu:.1f} s, exit {code}")
            cpus.append(cpu)
        ratio = f"{seconds / cpus[1]:.2f}, {seconds / cpus[2]:.2f}"
        ratio += f" ({cpus[0] / cpus[1]:.2f}, {cpus[0] / cpus[2]:.2f})"
        print(f"| {n} | {2 * n} | " + " | ".join(cells) + f" | {ratio} |")
        sys.stdout.flush()
    print(f"load average at end: {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
