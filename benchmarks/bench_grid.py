"""Error against run time on synthetic power grids: netlistdyn's descriptor transient, batch ngspice
(default and tight settings) and scipy's Radau, side by side.

    python benchmarks/bench_grid.py [--sizes 30,100] [--kinds rc,rlc] [--timeout 900]

Grids come from ``benchmarks/powergrid.py`` (10 ns at 10 ps, PWL loads); four probed nodes. The
reference is our own run at rtol 1e-13, checked against ngspice tight where that finishes. Errors are
the largest deviation over the probes and the 1001 output times, relative to each probe's swing.
Every run is a child process: CPU = its user + system seconds, wall = elapsed. ngspice prints at its
own time points (``wrdata``): they are interpolated linearly onto the 10 ps grid. scipy's Radau runs
on ``x' = E⁻¹(A x + B u)`` with the sparse Jacobian, piece by piece between the PWL corners, for the
RC grids only (with the supplies eliminated every node has a capacitor; the RLC pads' nodes are
algebraic, which ``solve_ivp`` cannot take).
"""

from __future__ import annotations

import argparse
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
sys.path.insert(0, str(Path(__file__).resolve().parent))

from powergrid import grid_netlist, probe_nodes  # noqa: E402

OURS = r"""
import json, sys, time
import numpy as np
from netlistdyn.descriptor import assemble
from netlistdyn.parser import parse_file
from netlistdyn.simulate import source_waveform
from netlistdyn.transient import run_transient
path, rtol, outs, target = sys.argv[1], float(sys.argv[2]), sys.argv[3].split(","), sys.argv[4]
netlist = parse_file(path)
system = assemble(netlist, outs)
tran = netlist.tran
times = np.linspace(0.0, tran.tstop, round(tran.tstop / tran.tstep) + 1)
waves = [source_waveform(e).resolved(tran.tstep, tran.tstop) for e in netlist.sources]
run = run_transient(system, waves, times, rtol=rtol)
np.save(target, run.outputs)
print(json.dumps({"status": run.status, "steps": run.stats["steps"], "unknowns": system.size}))
"""

RADAU = r"""
import json, sys
import numpy as np, scipy.sparse as sp
from scipy.integrate import solve_ivp
from netlistdyn.descriptor import assemble
from netlistdyn.parser import parse_file
from netlistdyn.simulate import source_waveform
from netlistdyn.transient import SourceValues, breakpoints, dc_operating_point
path, rtol, outs, target = sys.argv[1], float(sys.argv[2]), sys.argv[3].split(","), sys.argv[4]
netlist = parse_file(path)
system = assemble(netlist, outs)
tran = netlist.tran
times = np.linspace(0.0, tran.tstop, round(tran.tstop / tran.tstep) + 1)
waves = [source_waveform(e).resolved(tran.tstep, tran.tstop) for e in netlist.sources]
values = SourceValues(waves)
einv = sp.diags_array(1.0 / system.E.diagonal())
J = sp.csr_array(einv @ system.A)
EB = sp.csr_array(einv @ system.B)
x = dc_operating_point(system, values(0.0), path)
out = np.empty((times.size, system.C.shape[0]))
out[0] = system.C @ x + system.D @ values(0.0)
edges = np.unique(np.concatenate([[0.0], breakpoints(waves, tran.tstop), [tran.tstop]]))
k = 1
for t0, t1 in zip(edges[:-1], edges[1:]):
    inside = times[(times > t0) & (times <= t1)]
    t_eval = inside if inside.size and inside[-1] == t1 else np.append(inside, t1)
    sol = solve_ivp(lambda t, y: J @ y + EB @ values(t), (t0, t1), x, method="Radau", rtol=rtol,
                    atol=rtol * 1e-3, jac=J, t_eval=t_eval)
    x = sol.y[:, -1]
    for j, t in enumerate(sol.t):
        if k < times.size and abs(t - times[k]) < 1e-6 * tran.tstep:
            out[k] = system.C @ sol.y[:, j] + system.D @ values(t)
            k += 1
np.save(target, out)
print(json.dumps({"status": "ok" if k == times.size else "incomplete"}))
"""

NGSPICE_TIGHT = ".options reltol=1e-9 abstol=1e-15 vntol=1e-12 chgtol=1e-20\n"


def child(args: list[str], timeout: float) -> tuple[dict | None, float, float, str]:
    """Run a child; (its JSON line or None, CPU s, wall s, status)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    try:
        done = subprocess.run(args, capture_output=True, text=True, env=env, timeout=timeout, check=False)
    except subprocess.TimeoutExpired:
        return None, float("nan"), time.perf_counter() - start, "timeout"
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    report = json.loads(lines[-1]) if lines else None
    status = "ok" if done.returncode == 0 else f"exit {done.returncode}"
    return report, cpu, wall, status


def ngspice(netlist_text: str, probes: list[str], work: Path, tight: bool, timeout: float) -> tuple:
    """Batch ngspice on the grid; (outputs on the grid or None, CPU, wall, status)."""
    body = netlist_text.replace(".end\n", "")
    if tight:
        body = body.replace(".tran 1e-11 1e-08", ".tran 1e-11 1e-8 0 1e-13") + NGSPICE_TIGHT
    data = work / f"ng_{'tight' if tight else 'default'}.out"
    body += ".control\nset wr_singlescale\nset wr_vecnames\noption numdgt=16\nrun\n"
    body += f"wrdata {data} " + " ".join(f"v({p})" for p in probes) + "\n.endc\n.end\n"
    deck = work / f"ng_{'tight' if tight else 'default'}.cir"
    deck.write_text(body)
    _, cpu, wall, status = child(["ngspice", "-b", str(deck)], timeout)
    if status == "timeout" or not data.exists():
        return None, cpu, wall, status
    status = "ok"  # batch ngspice exits 1 after a .control block without quit
    table = np.loadtxt(data, skiprows=1)
    grid = np.linspace(0.0, 1e-8, 1001)
    return (
        np.column_stack([np.interp(grid, table[:, 0], table[:, j]) for j in range(1, table.shape[1])]),
        cpu,
        wall,
        status,
    )


def main() -> int:
    """Print one Markdown table per grid."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="30,100")
    parser.add_argument("--kinds", default="rc,rlc")
    parser.add_argument("--rtols", default="1e-6,1e-10")
    parser.add_argument("--timeout", type=float, default=900.0)
    parser.add_argument("--no-tight", action="store_true", help="skip ngspice at tight settings")
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="grid_"))
    for size in (int(v) for v in args.sizes.split(",")):
        for kind in args.kinds.split(","):
            text = grid_netlist(size, kind)
            path = work / f"{kind}{size}.cir"
            path.write_text(text)
            probes = probe_nodes(size)
            outs = ",".join(f"v({p})" for p in probes)
            ref_file = work / f"{kind}{size}_ref.npy"
            report, cpu, wall, status = child(
                [sys.executable, "-c", OURS, str(path), "1e-13", outs, str(ref_file)], args.timeout
            )
            if report is None:
                print(f"{kind} {size}: reference run {status}")
                continue
            reference = np.load(ref_file)
            swing = np.ptp(reference, axis=0)
            rows = [("netlistdyn descriptor, rtol 1e-13 (reference)", cpu, wall, 0.0, status)]

            def error(values: np.ndarray | None, reference=reference, swing=swing) -> float:
                if values is None:
                    return float("nan")
                return float((np.abs(values - reference).max(axis=0) / swing).max())

            for rtol in args.rtols.split(","):
                target = work / f"{kind}{size}_{rtol}.npy"
                rep, cpu, wall, status = child(
                    [sys.executable, "-c", OURS, str(path), rtol, outs, str(target)], args.timeout
                )
                rows.append(
                    (
                        f"netlistdyn descriptor, rtol {rtol}",
                        cpu,
                        wall,
                        error(np.load(target)) if rep else None,
                        status,
                    )
                )
            for tight in (False, True) if not args.no_tight else (False,):
                values, cpu, wall, status = ngspice(text, probes, work, tight, args.timeout)
                label = "ngspice -b, reltol 1e-9, TMAX 0.1 ps" if tight else "ngspice -b, default"
                rows.append((label, cpu, wall, error(values), status))
            if kind == "rc":
                target = work / f"{kind}{size}_radau.npy"
                rep, cpu, wall, status = child(
                    [sys.executable, "-c", RADAU, str(path), "1e-8", outs, str(target)], args.timeout
                )
                rows.append(
                    ("scipy Radau, rtol 1e-8", cpu, wall, error(np.load(target)) if rep else None, status)
                )
            unknowns = report["unknowns"]
            print(f"\n{kind.upper()} grid {size}x{size} ({unknowns} unknowns), swing {swing.min():.3g} V")
            print("| run | CPU [s] | wall [s] | max error / swing | status |")
            print("|---|---:|---:|---:|---|")
            for label, cpu, wall, err, status in rows:
                err_text = "-" if err is None or err != err else f"{err:.2g}"
                print(f"| {label} | {cpu:.2f} | {wall:.2f} | {err_text} | {status} |")
            sys.stdout.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
