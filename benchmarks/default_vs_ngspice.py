"""``simulate``'s defaults against ``ngspice -b``'s: whole processes, CPU seconds, in one run.

    python benchmarks/default_vs_ngspice.py [--cases ladder100,ladder1000,rc30,rlc30]
                                            [--cpu-limit 300] [--extra "--rtol 1e-6"]

Each case is a netlist of ``benchmarks/ladder.py`` (an RLC ladder, unit step, its own ``.tran``) or
``benchmarks/powergrid.py`` (an RC or RLC power grid, 10 ns at 10 ps, PWL loads). Both programs are
child processes with one BLAS thread; their CPU seconds are their own (user + system, from
``wait4``: a loaded machine does not stretch them), limited to ``--cpu-limit``. ``simulate`` runs
with no ``--method`` and no ``--rtol`` (``--extra`` adds options) and writes its default outputs
(every node voltage, which its step check sees) as CSV, of which the probes are scored; ngspice
runs the same deck with a ``.control`` block that writes them (``wrdata``), and its time points are
interpolated linearly onto the output grid. The error of each is the largest deviation over the
probes and the output times, relative to each probe's peak, against a reference independent of
netlistdyn's steppers: ``bench_grid.py``'s ``EXACT``, scipy's dense ``expm`` of Van Loan's
augmented matrix on the descriptor model with its algebraic unknowns eliminated, one matrix per
output step (exact for inputs linear between the output times; the ladders start at rest, the grids
at their DC operating point).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT))

from bench_grid import EXACT  # noqa: E402
from ladder import ladder_netlist  # noqa: E402
from powergrid import grid_netlist, probe_nodes  # noqa: E402

from netlistdyn.base.processes import run_program  # noqa: E402

ENV = {
    **os.environ,
    "OPENBLAS_NUM_THREADS": "1",
    "OMP_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "PYTHONPATH": str(ROOT),
}


def case_netlist(name: str) -> tuple[str, list[str]]:
    """(netlist text, probed nodes) of a case name: ladderN, rcN or rlcN."""
    if name.startswith("ladder"):
        n = int(name[6:])
        return ladder_netlist(n), [f"n{max(1, n // 10)}", f"n{n // 2}", f"n{n}"]
    kind = "rlc" if name.startswith("rlc") else "rc"
    size = int(name[len(kind) :])
    return grid_netlist(size, kind), probe_nodes(size)


def ours(
    path: Path, probes: list[str], extra: list[str], limit: float, work: Path, key: str, package: str
) -> tuple:
    """``simulate`` of the netlistdyn in ``package`` on the file: (outputs or None, CPU s, status)."""
    csv = work / f"{key}.csv"
    # simulate's default outputs (every node voltage: the step check sees them all), then the probes.
    args = [sys.executable, "-m", "netlistdyn", "simulate", "-q", str(path), "--csv", str(csv), *extra]
    # From the work folder: python -m puts the current folder first on the path, before PYTHONPATH.
    run = run_program(args, None, cwd=str(work), cpu_limit=limit, env={**ENV, "PYTHONPATH": package})
    if run.how != "ok" or not csv.exists():
        return None, run.cpu, f"{run.how} ({run.stderr.strip()[-200:]})"
    with csv.open() as handle:
        header = [name.strip().split(" ")[0] for name in handle.readline().split(",")]
    columns = [header.index(f"v({p})") for p in probes]
    table = np.loadtxt(csv, delimiter=",", skiprows=1, usecols=columns, ndmin=2)
    status = "ok" if run.returncode == 0 else f"exit {run.returncode}: {run.stderr.strip()[-160:]}"
    return table, run.cpu, status


def ngspice(text: str, probes: list[str], times: np.ndarray, limit: float, work: Path, key: str) -> tuple:
    """``ngspice -b`` at its defaults: (outputs on ``times`` or None, CPU s, status)."""
    data = work / f"{key}.out"
    body = text.replace(".end\n", "")
    body += ".control\nset wr_singlescale\nset wr_vecnames\noption numdgt=16\nrun\n"
    body += f"wrdata {data} " + " ".join(f"v({p})" for p in probes) + "\n.endc\n.end\n"
    deck = work / f"{key}_deck.cir"
    deck.write_text(body)
    run = run_program(["ngspice", "-b", str(deck)], None, cpu_limit=limit, env=ENV)
    if run.how != "ok" or not data.exists():
        return None, run.cpu, run.how
    table = np.loadtxt(data, skiprows=1)
    values = np.column_stack([np.interp(times, table[:, 0], table[:, j]) for j in range(1, table.shape[1])])
    return values, run.cpu, "ok"


def error(values: np.ndarray | None, reference: np.ndarray) -> float:
    """Largest |deviation| over probes and times, relative to each probe's peak."""
    if values is None:
        return float("nan")
    peak = np.max(np.abs(reference), axis=0)
    return float(np.max(np.abs(values - reference) / peak))


def reference(name: str, path: Path, probes: list[str], limit: float, work: Path) -> tuple[np.ndarray, str]:
    """(reference outputs, how it was made and its own accuracy)."""
    target = work / f"{name}_exact.npy"
    # The ladders start at rest (.tran ... uic); the grids at their DC operating point.
    script = EXACT.replace(
        "x = -np.linalg.solve(Ad, Bd @ u)", "x = np.zeros(n) if UIC else -np.linalg.solve(Ad, Bd @ u)"
    )
    script = script.replace(".max() < 1e-6", ".max(initial=0.0) < 1e-6")
    script = script.replace("import json, sys", f"import json, sys\nUIC = {name.startswith('ladder')}")
    run = run_program(
        [sys.executable, "-c", script, str(path), ",".join(f"v({p})" for p in probes), str(target)],
        None,
        cpu_limit=limit,
        env=ENV,
    )
    if run.how != "ok" or not target.exists():
        raise SystemExit(f"{name}: the exact reference did not finish ({run.how}: {run.stderr[-300:]})")
    return np.load(target), "dense Van Loan on the descriptor model, algebraic unknowns eliminated"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default="ladder100,ladder1000,rc30,rlc30")
    parser.add_argument("--cpu-limit", type=float, default=300.0)
    parser.add_argument("--extra", default="", help="Options added to simulate (e.g. '--rtol 1e-6').")
    parser.add_argument(
        "--package", default=str(ROOT), help="Directory whose netlistdyn simulate runs (another checkout)."
    )
    args = parser.parse_args()
    extra = args.extra.split()
    print("| case | ours CPU s | ours error | ngspice -b CPU s | ngspice error | ratio | reference |")
    print("|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for name in args.cases.split(","):
            text, probes = case_netlist(name)
            path = work / f"{name}.cir"
            path.write_text(text)
            ref, how = reference(name, path, probes, args.cpu_limit, work)
            mine, cpu, status = ours(path, probes, extra, args.cpu_limit, work, name, args.package)
            tran = next(line for line in text.splitlines() if line.startswith(".tran")).split()
            times = np.linspace(0.0, float(tran[2]), ref.shape[0])
            spice, spice_cpu, spice_status = ngspice(text, probes, times, args.cpu_limit, work, name)
            note = "" if status == "ok" else f" ({status})"
            spice_note = "" if spice_status == "ok" else f" ({spice_status})"
            print(
                f"| {name} | {cpu:.2f}{note} | {error(mine, ref):.2g} | {spice_cpu:.2f}{spice_note} | "
                f"{error(spice, ref):.2g} | {cpu / spice_cpu:.2f}x | {how} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
