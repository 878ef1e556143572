"""Entry-by-entry accuracy of the compiled A, and the cost of the exact reduction.

    python benchmarks/entrywise_accuracy.py [--count 200] [--seed 1]

For random networks of E12 values (``tests/random_networks.py``, the property tests' generator),
the floating-point reduction (``formulate.reduce`` over ``algebra.NUMERIC``) and the exact one
(``algebra.EXACT``: the parsed doubles as rationals, rounded once) are run on the same normal tree.
Printed: the largest relative error of any nonzero entry of the floating-point A against the exact
A, how many networks have an entry whose 6 printed digits differ, and the CPU time of the exact
reduction against the circuit's branch count (netlists/ and the agreeing corpus files as well).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from netlistdyn import formulate  # noqa: E402
from netlistdyn.circuit.netlist import Netlist  # noqa: E402
from netlistdyn.formulation.algebra import EXACT, NUMERIC  # noqa: E402
from netlistdyn.frontend.parser import parse_file, parse_text  # noqa: E402
from tests.random_networks import random_network  # noqa: E402


def both(netlist: Netlist) -> tuple[np.ndarray, np.ndarray, float, int]:
    """(floating-point A, exact A rounded, exact CPU s, branches) on the numeric compile's tree."""
    form = formulate.formulate(netlist)
    args = (form.netlist, form.circuit, form.tree, form.probes)
    numeric = formulate.reduce(NUMERIC, formulate.NUMERIC_VALUES, *args).A.toarray()
    start = time.process_time()
    exact = formulate.reduce(EXACT, formulate.EXACT_VALUES, *args).A.to_float().toarray()
    return numeric, exact, time.process_time() - start, form.circuit.nbranches


def main() -> int:
    """Print the accuracy and the cost tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=200)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    rng = np.random.default_rng(args.seed)
    worst, misprinted, compared = 0.0, 0, 0
    for _ in range(args.count):
        try:
            numeric, exact, _, _ = both(parse_text(random_network(rng, spread=False)))
        except Exception:
            continue
        if not exact.size:
            continue
        compared += 1
        nonzero = exact != 0
        if nonzero.any():
            worst = max(worst, float((np.abs(numeric - exact)[nonzero] / np.abs(exact[nonzero])).max()))
        misprinted += any(f"{a:.6g}" != f"{b:.6g}" for a, b in zip(numeric.flat, exact.flat, strict=True))
    print(
        f"random E12 networks: {compared} compared; floating-point A, largest relative error of an "
        f"entry {worst:.2g}; networks with an entry misprinted at 6 digits: {misprinted}"
    )
    files = sorted(ROOT.glob("netlists/*.cir"))
    manifest = json.loads((ROOT / "tests/corpus/manifest.json").read_text())
    files += [ROOT / "tests/corpus" / f["file"] for f in manifest["files"] if f["expect"] == "agree"]
    costs: dict[int, list[float]] = {}
    for path in files:
        try:
            _, _, seconds, branches = both(parse_file(path))
        except Exception:
            continue
        costs.setdefault(branches, []).append(seconds)
    print("| branches | netlists | exact reduction, largest CPU [s] |")
    print("|---:|---:|---:|")
    for branches in sorted(costs):
        print(f"| {branches} | {len(costs[branches])} | {max(costs[branches]):.4f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
