"""Direct against superposed descriptor runs of a power grid (``simulate --superpose``, issue 13).

    nice -n 10 python benchmarks/bench_superpose.py --size 30 --kind rc --jobs 2 --rtols 1e-6,1e-10

Each run is a fresh child process (``simulate --method descriptor`` through the API, as the CLI
runs it); CPU seconds are the child's own plus, for the superposed run, its workers' (the jobs'
``job_cpu_seconds``), wall seconds from start to finish. With ``--reference`` the probed nodes are
compared with a direct run at rtol 1e-11 (the grid benchmark's reference), relative to each node's
swing. The machine's load average is printed before and after.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from powergrid import grid_netlist, probe_nodes


def _run(
    text: str, outputs: list[str], rtol: float, jobs: int, scheduler: str, tstep: float | None, queue
) -> None:
    from netlistdyn.frontend.parser import parse_text
    from netlistdyn.workflows.large import simulate_large
    from netlistdyn.workflows.superpose import simulate_superposed

    wall, cpu = time.perf_counter(), time.process_time()
    netlist = parse_text(text)
    if jobs:
        result = simulate_superposed(
            netlist,
            jobs,
            scheduler,
            jobs,
            outputs=outputs,
            method="descriptor",
            rtol=rtol,
            tstep=tstep,
            tstop=None if tstep is None else 1e-8,
        )
        workers = float(result.stats["cpu_seconds"])
        detail = [
            {
                k: job.get(k)
                for k in ("sources", "breakpoints", "steps", "checks", "rejected", "job_cpu_seconds")
            }
            for job in result.stats["jobs"]
        ]
        for job in detail:
            job["sources"] = len(job["sources"])
    else:
        result = simulate_large(netlist, outputs, None if tstep is None else 1e-8, tstep, (), rtol=rtol)
        workers, detail = 0.0, [{k: result.stats.get(k) for k in ("steps", "checks", "rejected")}]
    queue.put(
        {
            "cpu": time.process_time() - cpu + workers,
            "wall": time.perf_counter() - wall,
            "status": result.status,
            "values": result.values.tolist(),
            "detail": detail,
        }
    )


def run(
    text: str,
    outputs: list[str],
    rtol: float,
    jobs: int = 0,
    scheduler: str = "processes",
    tstep: float | None = None,
) -> dict:
    """One run in a child process: CPU (with its workers'), wall, status, the outputs."""
    context = multiprocessing.get_context("spawn")
    queue = context.Queue()
    child = context.Process(target=_run, args=(text, outputs, rtol, jobs, scheduler, tstep, queue))
    child.start()
    record = queue.get()
    child.join()
    return record


def main(argv: list[str] | None = None) -> int:
    """Command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=30)
    parser.add_argument("--kind", choices=["rc", "rlc"], default="rc")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--scheduler", default="processes")
    parser.add_argument("--rtols", default="1e-6,1e-10")
    parser.add_argument(
        "--tstep", type=float, default=None, help="output step (s; default the .tran's 10 ps)"
    )
    parser.add_argument("--reference", action="store_true", help="errors against a direct run at rtol 1e-11")
    args = parser.parse_args(argv)
    text = grid_netlist(args.size, args.kind)
    outputs = [f"v({n})" for n in probe_nodes(args.size)]
    step = f"output step {args.tstep:g} s" if args.tstep else "output step 10 ps"
    print(
        f"{args.kind.upper()} {args.size}x{args.size}, {step}, outputs {', '.join(outputs)}; "
        f"load {os.getloadavg()}"
    )
    reference = None
    if args.reference:
        ref = run(text, outputs, 1e-11, tstep=args.tstep)
        reference = np.array(ref["values"])
        print(f"reference: direct rtol 1e-11, {ref['cpu']:.2f} s CPU, {ref['wall']:.2f} s wall")
    for rtol in (float(r) for r in args.rtols.split(",")):
        for jobs in (0, args.jobs):
            record = run(text, outputs, rtol, jobs, args.scheduler, args.tstep)
            label = "direct" if not jobs else f"superposed, {jobs} jobs on {args.scheduler}"
            error = ""
            if reference is not None:
                values = np.array(record["values"])
                swing = np.ptp(reference, axis=0)
                error = f", error {np.max(np.abs(values - reference) / swing):.2g} of the swing"
            print(
                f"rtol {rtol:g} {label}: {record['cpu']:.2f} s CPU, {record['wall']:.2f} s wall, "
                f"{record['status']}{error}; {json.dumps(record['detail'])}"
            )
    print(f"load {os.getloadavg()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
