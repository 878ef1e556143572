"""Error against run time on synthetic power grids: netlistdyn's descriptor transient, batch ngspice
(default and tight settings) and scipy's Radau, side by side.

    python benchmarks/bench_grid.py [--sizes 30,100] [--kinds rc,rlc] [--runs ref,ours,ngspice]
                                    [--rtols 1e-6,1e-10] [--timeout CPU_SECONDS]

Grids come from ``benchmarks/powergrid.py`` (10 ns at 10 ps, PWL loads); four probed nodes. The
reference is our own run at rtol 1e-11. Errors are the largest deviation over the probes and the
1001 output times, relative to each probe's swing. Every run is a child process limited to
``--timeout`` CPU seconds: CPU = its user + system seconds, wall = elapsed. Each run's record (and
outputs) is kept in ``--store`` (``benchmarks/results/grid``): a recorded run is not repeated, and
the tables are printed from the records (``--runs none`` only prints). ngspice prints at its own
time points (``wrdata``): they are interpolated linearly onto the 10 ps grid. scipy's Radau runs
on ``x' = E⁻¹(A x + B u)`` with the sparse Jacobian, piece by piece between the PWL corners, for the
RC grids only (with the supplies eliminated every node has a capacitor; the RLC pads' nodes are
algebraic, which ``solve_ivp`` cannot take).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(ROOT))

from powergrid import grid_netlist, probe_nodes  # noqa: E402

from netlistdyn.base.processes import run_program  # noqa: E402

OURS = r"""
import json, sys, time
import numpy as np
from netlistdyn.formulation.descriptor import assemble
from netlistdyn.frontend.parser import parse_file
from netlistdyn.circuit.sources import source_waveform
from netlistdyn.simulation.transient import run_transient
import resource
path, rtol, outs, target = sys.argv[1], float(sys.argv[2]), sys.argv[3].split(","), sys.argv[4]
method, _, sub = sys.argv[5].partition("/")
sub = int(sub or 1)
netlist = parse_file(path)
system = assemble(netlist, outs)
tran = netlist.tran
times = np.linspace(0.0, tran.tstop, sub * round(tran.tstop / tran.tstep) + 1)
waves = [source_waveform(e).resolved(tran.tstep, tran.tstop) for e in netlist.sources]
run = run_transient(system, waves, times, rtol=rtol, method=method)
np.save(target, run.outputs[::sub])
keys = ("steps", "checks", "rejected", "factorisations", "factor_seconds", "step_seconds")
print(json.dumps({"status": run.status, "unknowns": system.size, "method": method,
                  "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  **{k: run.stats[k] for k in keys}}))
"""

RADAU = r"""
import json, sys
import numpy as np, scipy.sparse as sp
from scipy.integrate import solve_ivp
from netlistdyn.formulation.descriptor import assemble
from netlistdyn.frontend.parser import parse_file
from netlistdyn.circuit.sources import source_waveform
from netlistdyn.simulation.transient import dc_operating_point
from netlistdyn.circuit.sources import SourceValues, breakpoints
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

EXACT = r"""
import json, sys
import numpy as np, scipy.linalg as sl
from netlistdyn.formulation.descriptor import assemble
from netlistdyn.frontend.parser import parse_file
from netlistdyn.circuit.sources import source_waveform
from netlistdyn.circuit.sources import SourceValues, breakpoints
path, outs, target = sys.argv[1], sys.argv[2].split(","), sys.argv[3]
netlist = parse_file(path)
system = assemble(netlist, outs)
tran = netlist.tran
h = tran.tstep
times = np.linspace(0.0, tran.tstop, round(tran.tstop / h) + 1)
waves = [source_waveform(e).resolved(h, tran.tstop) for e in netlist.sources]
points = breakpoints(waves, tran.tstop)
assert np.abs(points / h - np.round(points / h)).max() < 1e-6, "corners off the output grid"
E, A, B = (m.toarray() for m in (system.E, system.A, system.B))
C, D = system.C.toarray(), system.D.toarray()
dyn = np.flatnonzero(np.abs(E).sum(axis=0) + np.abs(E).sum(axis=1) > 0)
alg = np.setdiff1d(np.arange(E.shape[0]), dyn)
# eliminate the algebraic unknowns: x_a = -A_aa^-1 (A_ad x_d + B_a u)
K = np.linalg.solve(A[np.ix_(alg, alg)], np.hstack([A[np.ix_(alg, dyn)], B[alg]])) if alg.size else None
Ad, Bd = A[np.ix_(dyn, dyn)], B[dyn]
Cd, Dd = C[:, dyn], D.copy()
if alg.size:
    Kx, Ku = -K[:, : dyn.size], -K[:, dyn.size :]
    Ad = Ad + A[np.ix_(dyn, alg)] @ Kx
    Bd = Bd + A[np.ix_(dyn, alg)] @ Ku
    Cd = Cd + C[:, alg] @ Kx
    Dd = Dd + C[:, alg] @ Ku
Einv = np.linalg.inv(E[np.ix_(dyn, dyn)])
Ad, Bd = Einv @ Ad, Einv @ Bd
n, m = Ad.shape[0], Bd.shape[1]
M = np.zeros((n + 2 * m, n + 2 * m))
M[:n, :n], M[:n, n : n + m], M[n : n + m, n + m :] = Ad * h, Bd * h, np.eye(m)
F = sl.expm(M)
Phi, G0, G1 = F[:n, :n], F[:n, n : n + m], F[:n, n + m :]
values = SourceValues(waves)
u = values(0.0)
x = -np.linalg.solve(Ad, Bd @ u)
out = np.empty((times.size, C.shape[0]))
out[0] = Cd @ x + Dd @ u
for k in range(1, times.size):
    u_new = values(times[k])
    x = Phi @ x + G0 @ u + G1 @ (u_new - u)
    u = u_new
    out[k] = Cd @ x + Dd @ u
np.save(target, out)
print(json.dumps({"status": "ok", "states": n}))
"""

NGSPICE_TIGHT = ".options reltol=1e-9 abstol=1e-15 vntol=1e-12 chgtol=1e-20\n"


def child(args: list[str], timeout: float) -> tuple[dict | None, float, float, str]:
    """Run a child limited to ``timeout`` CPU seconds (the machine is shared: wall time is not
    the measure), BLAS on one thread; (its JSON line or None, CPU s, wall s, status)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    done = run_program(args, None, cpu_limit=timeout, env=env)
    cpu, wall = done.cpu, done.wall
    if done.how == "cpu limit":
        return None, cpu, wall, f"stopped at the {timeout:g} s CPU limit"
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    report = json.loads(lines[-1]) if lines else None
    status = "ok" if done.returncode == 0 else f"exit {done.returncode}"
    return report, cpu, wall, status


def ngspice(netlist_text: str, probes: list[str], work: Path, key: str, tight: bool, timeout: float) -> tuple:
    """Batch ngspice on the grid; (outputs on the grid or None, CPU, wall, status)."""
    body = netlist_text.replace(".end\n", "")
    if tight:
        body = body.replace(".tran 1e-11 1e-08", ".tran 1e-11 1e-8 0 1e-13") + NGSPICE_TIGHT
    data = work / f"{key}.out"
    body += ".control\nset wr_singlescale\nset wr_vecnames\noption numdgt=16\nrun\n"
    body += f"wrdata {data} " + " ".join(f"v({p})" for p in probes) + "\n.endc\n.end\n"
    deck = work / f"{key}_deck.cir"
    deck.write_text(body)
    _, cpu, wall, status = child(["ngspice", "-b", str(deck)], timeout)
    if status.startswith("stopped") or not data.exists():
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


RUNS = ("ref", "exact", "ours", "ngspice", "tight", "radau")
#: Reference runs: key -> (method, rtol). ``ref`` is the Padé run of earlier tables.
REFERENCES = {"ref": ("pade", "1e-11")}
#: Runs an error can be measured against, in order of preference (``modal``: the independent
#: closed-form modal solution of an RC grid, benchmarks/modal_reference.py; ``exact``: dense Van
#: Loan discretisation, small grids; then our CF run at the tightest rtol).
REFERENCE_KEYS = ("modal", "exact", "cf_rtol1e-12", "ref")
METHOD_KEY = {"pade": "", "cf": "_cf", "cf/2": "_cf2"}
METHOD_LABEL = {"pade": "Padé", "cf": "CF", "cf/2": "CF, 2 steps per output step"}


def stored_run(store: Path, key: str, make: Callable[[], tuple]) -> dict:
    """The stored record of one run (``store/key.json`` plus ``key.npy``), made when missing."""
    record_file = store / f"{key}.json"
    if record_file.exists():
        return json.loads(record_file.read_text())
    values, cpu, wall, status, extra = make()
    if values is not None:
        np.save(store / f"{key}.npy", values)
    record = {"cpu": cpu, "wall": wall, "status": status, "load": os.getloadavg()[0], **extra}
    record_file.write_text(json.dumps(record))
    return record


def main() -> int:
    """Run what is asked and missing from the store, then print one Markdown table per grid."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="30,100")
    parser.add_argument("--kinds", default="rc,rlc")
    parser.add_argument("--rtols", default="1e-6,1e-8,1e-10")
    parser.add_argument("--runs", default=",".join(RUNS), help=f"which runs to make (of {', '.join(RUNS)})")
    parser.add_argument(
        "--methods",
        default="cf",
        help="stepping methods of our runs (cf, pade; cf/2: output step split in 2)",
    )
    parser.add_argument(
        "--reference",
        default="modal",
        help="reference for the errors (modal, exact, cf_rtol1e-12 or ref; else the first found)",
    )
    parser.add_argument("--store", type=Path, default=ROOT / "benchmarks" / "results" / "grid")
    parser.add_argument("--timeout", type=float, default=900.0, help="CPU seconds per run")
    args = parser.parse_args()
    runs = set(args.runs.split(","))
    store = args.store
    store.mkdir(parents=True, exist_ok=True)
    for size in (int(v) for v in args.sizes.split(",")):
        for kind in args.kinds.split(","):
            text = grid_netlist(size, kind)
            name = f"{kind}{size}"
            path = store / f"{name}.cir"
            path.write_text(text)
            probes = probe_nodes(size)
            outs = ",".join(f"v({p})" for p in probes)

            def ours(rtol: str, key: str, method: str, path: Path = path, outs: str = outs) -> tuple:
                target = store / f"{key}.npy"
                rep, cpu, wall, status = child(
                    [sys.executable, "-c", OURS, str(path), rtol, outs, str(target), method], args.timeout
                )
                values = np.load(target) if rep and target.exists() else None
                return values, cpu, wall, status if rep is None else rep["status"], rep or {}

            plan: list[tuple[str, str, Callable[[], tuple]]] = []
            for ref_key, (method, rtol) in REFERENCES.items():
                key = f"{name}_{ref_key}"
                if "ref" in runs or (store / f"{key}.json").exists():
                    label = f"netlistdyn {METHOD_LABEL[method]}, rtol {rtol} (reference)"
                    plan.append((label, key, partial(ours, rtol, key, method)))
            key = f"{name}_exact"
            if "exact" in runs or (store / f"{key}.json").exists():
                label = "dense exact discretisation (expm, Van Loan)"
                plan.append((label, key, partial(exact_run, path, outs, store, key, args.timeout)))
            for method in args.methods.split(","):
                for rtol in args.rtols.split(","):
                    key = f"{name}{METHOD_KEY[method]}_rtol{rtol}"
                    if "ours" in runs or (store / f"{key}.json").exists():
                        plan.append(
                            (
                                f"netlistdyn {METHOD_LABEL[method]}, rtol {rtol}",
                                key,
                                partial(ours, rtol, key, method),
                            )
                        )
            for tight in (False, True):
                key = f"{name}_ng_{'tight' if tight else 'default'}"
                if ("tight" if tight else "ngspice") in runs or (store / f"{key}.json").exists():
                    label = "ngspice -b, reltol 1e-9, TMAX 0.1 ps" if tight else "ngspice -b, default"
                    plan.append(
                        (label, key, partial(ngspice_run, text, probes, store, key, tight, args.timeout))
                    )
            key = f"{name}_radau"
            if kind == "rc" and ("radau" in runs or (store / f"{key}.json").exists()):
                plan.append(
                    ("scipy Radau, rtol 1e-8", key, partial(radau_run, path, outs, store, key, args.timeout))
                )
            records = [(label, key, stored_run(store, key, make)) for label, key, make in plan]
            refs = {
                k: store / f"{name}_{k}.npy" for k in REFERENCE_KEYS if (store / f"{name}_{k}.npy").exists()
            }
            if not refs:
                print(f"\n{kind} {size}: no reference run yet")
                continue
            ref_key = args.reference if args.reference in refs else next(iter(refs))
            reference = np.load(refs[ref_key])
            swing = np.ptp(reference, axis=0)
            unknowns = next((r.get("unknowns") for _, _, r in records if r.get("unknowns")), "?")
            print(f"\n{kind.upper()} grid {size}x{size} ({unknowns} unknowns), swing {swing.min():.3g} V,")
            print(f"errors against the {ref_key} run")
            print("| run | CPU [s] | wall [s] | load | steps | max error / swing | status |")
            print("|---|---:|---:|---:|---:|---:|---|")
            for label, key, record in records:
                values_file = store / f"{key}.npy"
                err = "-"
                if values_file.exists() and key != f"{name}_{ref_key}":
                    values = np.load(values_file)
                    err = f"{float((np.abs(values - reference).max(axis=0) / swing).max()):.2g}"
                cpu, wall, load = record["cpu"], record["wall"], record["load"]
                steps = record.get("steps", "")
                status = record["status"]
                print(f"| {label} | {cpu:.2f} | {wall:.2f} | {load:.1f} | {steps} | {err} | {status} |")
            sys.stdout.flush()
    return 0


def ngspice_run(text: str, probes: list[str], store: Path, key: str, tight: bool, timeout: float) -> tuple:
    """One batch ngspice run for :func:`stored_run`."""
    values, cpu, wall, status = ngspice(text, probes, store, key, tight, timeout)
    return values, cpu, wall, status, {}


def exact_run(path: Path, outs: str, store: Path, key: str, timeout: float) -> tuple:
    """The dense exact discretisation (small grids only) for :func:`stored_run`."""
    target = store / f"{key}.npy"
    rep, cpu, wall, status = child([sys.executable, "-c", EXACT, str(path), outs, str(target)], timeout)
    values = np.load(target) if rep and target.exists() else None
    return values, cpu, wall, status if rep is None else rep["status"], rep or {}


def radau_run(path: Path, outs: str, store: Path, key: str, timeout: float) -> tuple:
    """scipy's Radau for :func:`stored_run`."""
    target = store / f"{key}.npy"
    rep, cpu, wall, status = child(
        [sys.executable, "-c", RADAU, str(path), "1e-8", outs, str(target)], timeout
    )
    values = np.load(target) if rep and target.exists() else None
    return values, cpu, wall, status if rep is None else rep["status"], {}


if __name__ == "__main__":
    sys.exit(main())
