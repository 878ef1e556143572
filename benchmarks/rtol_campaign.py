"""Long run of the rtol bound (issue 13): many random realistic circuits, the error of every ok result.

The cases are those of ``tests/test_rtol_bound.py`` (the same builder, the same
independent 50-digit modal reference, the same rule for leaving a case unjudged), one
per seed from ``--start`` on; each judged case runs ``rational`` at 1e-5 and 1e-8
and ``exact`` at 1e-6 and 1e-9, as the property test does. A result that says
ok with an error above its rtol breaks the bound and is printed in full
(seed, rtol, error, netlist).

    nice -n 10 python benchmarks/rtol_campaign.py --count 500

Prints one summary line per method and rtol: results, how many were ok,
unverified or failed, bound violations, the largest error/rtol among ok results.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tests.random_networks import random_network
from tests.test_rtol_bound import judged_case, limited_run, peak_error

#: (method, rtol) pairs run on every judged case, as in tests/test_rtol_bound.py.
RUNS = (("rational", 1e-5), ("rational", 1e-8), ("exact", 1e-6), ("exact", 1e-9))


def campaign(count: int, start: int, log: bool, seconds: float) -> dict[tuple[str, float], dict[str, float]]:
    """Judge ``count`` cases (seeds from ``start``, unjudged ones skipped); print violations.

    A run that takes more than ``seconds`` CPU seconds is stopped and counted (and its seed printed).
    """
    table = {
        run: {"results": 0, "ok": 0, "unverified": 0, "other": 0, "stopped": 0, "violations": 0, "worst": 0.0}
        for run in RUNS
    }
    judged, seed, skipped = 0, start, 0
    while judged < count:
        case = judged_case(seed)
        if case is None:
            skipped += 1
            seed += 1
            continue
        model, times, signals, reference = case
        for method, rtol in RUNS:
            row = table[(method, rtol)]
            result = limited_run(model, signals, times, method, rtol, seconds)
            row["results"] += 1
            if result is None:
                row["stopped"] += 1
                print(f"STOPPED seed {seed} {method} rtol {rtol:g} after {seconds:g} CPU s", flush=True)
            elif result.ok:
                row["ok"] += 1
                ratio = peak_error(result.outputs, reference) / rtol
                row["worst"] = max(row["worst"], ratio)
                if ratio > 1.0:
                    row["violations"] += 1
                    text = random_network(np.random.default_rng(seed), spread=False)
                    print(
                        f"VIOLATION seed {seed} {method} rtol {rtol:g}: error {ratio * rtol:.3g} "
                        f"({ratio:.3g} x rtol), stats {dict(result.stats)}\n{text}",
                        flush=True,
                    )
            elif result.status == "unverified":
                row["unverified"] += 1
            else:
                row["other"] += 1
        judged += 1
        if log and judged % 50 == 0:
            print(f"... {judged} judged (seed {seed})", flush=True)
            report(table)
        seed += 1
    print(
        f"{judged} judged cases from seeds {start}..{seed - 1} ({skipped} left unjudged: no trustworthy "
        "reference, no state, or a growing mode)"
    )
    return table


def report(table: dict[tuple[str, float], dict[str, float]]) -> None:
    """One line per method and rtol (printed every 50 cases too, so a stopped run keeps its counts)."""
    for (method, rtol), row in table.items():
        print(
            f"{method:>8} rtol {rtol:<6g} results {row['results']:>5}  ok {row['ok']:>5}  "
            f"unverified {row['unverified']:>4}  other {row['other']:>3}  stopped {row['stopped']:>3}  "
            f"violations {row['violations']:>3}  max error/rtol among ok {row['worst']:.3g}",
            flush=True,
        )


def main(argv: list[str] | None = None) -> int:
    """Command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=500, help="judged cases")
    parser.add_argument("--start", type=int, default=0, help="first seed")
    parser.add_argument("--seconds", type=float, default=60.0, help="CPU seconds allowed to one run")
    parser.add_argument("--quiet", action="store_true")
    args = parser.parse_args(argv)
    tic, cpu = time.perf_counter(), time.process_time()
    table = campaign(args.count, args.start, not args.quiet, args.seconds)
    report(table)
    print(f"{time.perf_counter() - tic:.0f} s wall, {time.process_time() - cpu:.0f} s CPU")
    violations = sum(row["violations"] for row in table.values())
    return 1 if violations else 0


if __name__ == "__main__":
    sys.exit(main())
