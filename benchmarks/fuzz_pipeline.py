"""Long fuzz run of parse → compile → eigenvalues (the strategy of tests/test_fuzz_pipeline.py).

Usage::

    taskset -c 0 python benchmarks/fuzz_pipeline.py --examples 100000 [--minutes 60]

Prints how many netlists were tried, how many compiled (and their largest state count), how many
were refused with a NetlistError/UsageError, and stops at the first other failure (hypothesis
is not asked to shrink: the failing netlist is printed as found). Progress goes to stderr.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from pathlib import Path

from hypothesis import HealthCheck, Phase, given, settings

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tests.test_fuzz_pipeline import check_netlist, netlists


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--examples", type=int, default=100_000)
    parser.add_argument("--minutes", type=float, default=float("inf"))
    args = parser.parse_args()
    counts: Counter[str] = Counter()
    largest = 0
    start = time.perf_counter()

    @settings(
        max_examples=args.examples,
        deadline=None,
        suppress_health_check=list(HealthCheck),
        database=None,
        phases=(Phase.generate,),  # no shrinking: a failing netlist is printed as found
    )
    @given(netlists())
    def run(text: str) -> None:
        nonlocal largest
        if time.perf_counter() - start > 60 * args.minutes:
            return  # out of time: the remaining examples are skipped
        counts["tried"] += 1
        try:
            nstates = check_netlist(text)
        except BaseException:
            print(f"FAILED on this netlist:\n{text}", file=sys.stderr)
            raise
        if nstates is None:
            counts["refused"] += 1
        else:
            counts["compiled"] += 1
            largest = max(largest, nstates)
        if counts["tried"] % 1000 == 0:
            seconds = time.perf_counter() - start
            print(f"{counts['tried']} tried, {seconds:.0f} s", file=sys.stderr, flush=True)

    run()
    outcome = "no failure" + (" (time budget reached)" if counts["tried"] < args.examples else "")
    print(
        f"{counts['tried']} netlists in {time.perf_counter() - start:.0f} s: {counts['compiled']} compiled "
        f"(up to {largest} states), {counts['refused']} refused with NetlistError/UsageError; {outcome}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
