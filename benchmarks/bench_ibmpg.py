"""ibmpg1t end to end: parse, assemble, DC operating point, 10 ns at 10 ps; against the benchmark's
published waveforms, our own tightest run, and (optionally) batch ngspice.

    python benchmarks/bench_ibmpg.py [--rtol 1e-6,pade:1e-10,1e-12] [--ngspice] [--ngspice-log FILE]

Each ``--rtol`` entry is ``[method:]rtol`` (method ``cf``, the default, or ``pade``: see
:func:`netlistdyn.simulation.transient.run_transient`); the last entry is the reference.

The netlist and reference are read from ``../shared/benchmarks/ibmpg/`` (bz2). Every run of ours
happens in a child process (so peak memory is per run); CPU seconds are the child's user+system
time, wall seconds its elapsed time. ``--ngspice`` runs ``ngspice -b`` on the unchanged netlist
(default settings; its ``.print tran`` table is read from the log); ``--ngspice-log`` reads a log of
such a run made earlier. ngspice prints at its own time points: they are interpolated linearly onto
the 10 ps grid for the comparison (the reference waveforms are on that grid).
"""

from __future__ import annotations

import argparse
import bz2
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT.parent / "shared" / "benchmarks" / "ibmpg"


def read_reference(path: Path) -> dict[str, np.ndarray]:
    """The published waveforms: ``Node: name`` blocks of ``time value`` rows."""
    out: dict[str, list[tuple[float, float]]] = {}
    current = None
    for line in path.read_text().splitlines():
        fields = line.split()
        if not fields or fields[0].startswith("END"):
            continue
        if fields[0] == "Node:":
            current = fields[1].lower()
            out[current] = []
        elif current is not None:
            out[current].append((float(fields[0]), float(fields[1])))
    return {k: np.array(v) for k, v in out.items()}


def read_ngspice_print(log: Path) -> tuple[list[str], np.ndarray]:
    """The ``.print tran`` table of an ngspice batch log: names and rows (time first)."""
    names: list[str] = []
    rows: list[list[float]] = []
    for line in log.read_text(errors="replace").splitlines():
        fields = line.split()
        if fields[:2] == ["Index", "time"]:
            names = fields[2:]
            continue
        if names and len(fields) == len(names) + 2 and fields[0].isdigit():
            try:
                rows.append([float(v) for v in fields[1:]])
            except ValueError:
                continue
    return names, np.array(rows)


CHILD = r"""
import json, resource, sys, time
import numpy as np
from netlistdyn.formulation.descriptor import assemble
from netlistdyn.frontend.parser import parse_file
from netlistdyn.circuit.sources import source_waveform
from netlistdyn.simulation.transient import run_transient
path, rtol, outs, method = sys.argv[1], float(sys.argv[2]), sys.argv[3].split(","), sys.argv[5]
marks = [(time.process_time(), time.perf_counter())]
netlist = parse_file(path)
marks.append((time.process_time(), time.perf_counter()))
system = assemble(netlist, outs)
marks.append((time.process_time(), time.perf_counter()))
tran = netlist.tran
times = np.linspace(0.0, tran.tstop, round(tran.tstop / tran.tstep) + 1)
waves = [source_waveform(e).resolved(tran.tstep, tran.tstop) for e in netlist.sources]
run = run_transient(system, waves, times, rtol=rtol, method=method)
marks.append((time.process_time(), time.perf_counter()))
np.save(sys.argv[4], run.outputs)
usage = resource.getrusage(resource.RUSAGE_SELF)
print(json.dumps({
    "status": run.status, "message": run.message, "unknowns": system.size,
    "phases_cpu": [b[0] - a[0] for a, b in zip(marks, marks[1:])],
    "phases_wall": [b[1] - a[1] for a, b in zip(marks, marks[1:])],
    "stats": run.stats, "maxrss_mb": usage.ru_maxrss / 1024,
}))
"""


def run_ours(netlist: Path, rtol: float, outputs: list[str], work: Path, method: str = "cf") -> dict:
    """One run of ours in a child process; returns its report with outputs and times."""
    target = work / f"ours_{method}_{rtol:g}.npy"
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-c", CHILD, str(netlist), repr(rtol), ",".join(outputs), str(target), method],
        capture_output=True,
        text=True,
        env=env,
        check=True,
    )
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    report = json.loads(done.stdout.strip().splitlines()[-1])
    report["cpu"] = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    report["wall"] = wall
    report["outputs"] = np.load(target)
    return report


def run_ngspice(netlist: Path, work: Path) -> tuple[Path, float, float]:
    """``ngspice -b`` with its defaults; (log, CPU s, wall s)."""
    log = work / "ngspice.log"
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run(["ngspice", "-b", "-o", str(log), str(netlist)], capture_output=True, check=False)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return log, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), wall


def main() -> int:
    """Run the comparison and print a Markdown table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rtol", default="1e-10,1e-12", help="our tolerances; the last is the reference")
    parser.add_argument("--ngspice", action="store_true", help="also run ngspice -b (several CPU minutes)")
    parser.add_argument("--ngspice-log", type=Path, default=None, help="log of an earlier ngspice -b run")
    parser.add_argument("--ngspice-seconds", default=None, help="CPU,wall of that earlier run")
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="ibmpg_"))
    netlist = work / "ibmpg1t.spice"
    netlist.write_bytes(bz2.decompress((DATA / "ibmpg1t.spice.bz2").read_bytes()))
    reference_path = work / "ibmpg1t.output"
    reference_path.write_bytes(bz2.decompress((DATA / "ibmpg1t.output.bz2").read_bytes()))
    reference = read_reference(reference_path)
    print_line = next(line for line in netlist.read_text().splitlines() if line.startswith(".print"))
    outputs = [f.lower() for f in print_line.split()[2:]]
    names = [o[2:-1] for o in outputs]
    ref = np.column_stack([reference[n][:, 1] for n in names])
    grid = reference[names[0]][:, 0]
    swing = np.ptp(ref, axis=0)
    specs = [
        (v.split(":")[0], float(v.split(":")[1])) if ":" in v else ("cf", float(v))
        for v in args.rtol.split(",")
    ]
    runs = {spec: run_ours(netlist, spec[1], outputs, work, spec[0]) for spec in specs}
    best = runs[specs[-1]]["outputs"]

    finite = np.isfinite(best).all(axis=1)  # a failed reference run counts up to where it stopped
    digit = 10.0 ** (np.floor(np.log10(np.abs(ref))) - 6)  # one unit of the 7th printed digit

    def score(values: np.ndarray) -> tuple[float, float, float, float]:
        """(max |error| vs published [V], / swing, vs our tightest / swing, share within a digit)."""
        err = np.abs(values - ref)
        own = np.abs(values[finite] - best[finite])
        return (
            float(err.max()),
            float((err.max(axis=0) / swing).max()),
            float((own.max(axis=0) / swing).max()),
            float((err <= digit).mean()),
        )

    rows = []
    for (method, rtol), run in runs.items():
        stats = run["stats"]
        rows.append(
            {
                "run": f"netlistdyn descriptor {method}, rtol {rtol:g}",
                "cpu": run["cpu"],
                "wall": run["wall"],
                "memory_mb": run["maxrss_mb"],
                "score": score(run["outputs"]),
                "note": f"{stats['steps']} steps, {stats['checks']} checks, {stats['rejected']} rejected; "
                f"parse {run['phases_cpu'][0]:.1f} s, assemble {run['phases_cpu'][1]:.1f} s, "
                f"DC + transient {run['phases_cpu'][2]:.1f} s CPU; {run['unknowns']} unknowns",
            }
        )
    log, cpu, wall = None, float("nan"), float("nan")
    if args.ngspice:
        log, cpu, wall = run_ngspice(netlist, work)
    elif args.ngspice_log is not None:
        log = args.ngspice_log
        if args.ngspice_seconds:
            cpu, wall = (float(v) for v in args.ngspice_seconds.split(","))
    if log is not None:
        ng_names, table = read_ngspice_print(log)
        ng = np.column_stack(
            [np.interp(grid, table[:, 0], table[:, 1 + ng_names.index(f"v({n})"[:15])]) for n in names]
        )
        rows.append(
            {
                "run": "ngspice -b, default settings",
                "cpu": cpu,
                "wall": wall,
                "memory_mb": float("nan"),
                "score": score(ng),
                "note": f"{table.shape[0]} time points (interpolated onto the 10 ps grid)",
            }
        )
    print(f"published waveforms: {len(names)} nodes, swing {swing.min():.3g}..{swing.max():.3g} V")
    print(f"DC operating point vs published t = 0 (7 digits): {np.abs(best[0] - ref[0]).max():.2g} V")
    status = runs[specs[-1]]["status"]
    print(
        f"our {specs[-1][0]} rtol {specs[-1][1]:g} run: {status}, compared up to t = {grid[finite].max():g} s"
    )
    print()
    print(
        "| run | CPU [s] | wall [s] | peak memory [MB] | max err vs published [V] | / swing | vs our "
        f"{specs[-1][0]} rtol {specs[-1][1]:g}, / swing | within 1 printed digit | notes |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---|")
    for row in rows:
        abs_err, rel_err, own, share = row["score"]
        print(
            f"| {row['run']} | {row['cpu']:.1f} | {row['wall']:.1f} | {row['memory_mb']:.0f} | {abs_err:.2g} "
            f"| {rel_err:.2g} | {own:.2g} | {share:.0%} | {row['note']} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
