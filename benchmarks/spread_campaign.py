"""Long campaign: random networks at realistic values and at wide spreads against exact roots.

For each network (tests/random_networks.py) the model is compiled and every
eigenvalue, with its reported error bounds, is compared with the roots of
det(G + sC) expanded in exact rational arithmetic (tests/exact_pencil.py).
Counts: networks compiled and refused, eigenvalues outside their own
bounds, state counts different from the exact order, wrong verdicts, and
crashes of the analysis (any exception).

    python benchmarks/spread_campaign.py --count 2000 --spread both --seed 1

Prints one summary line per value regime, and each failure in full.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from netlistdyn.analysis.eigen import analyze_eigenvalues
from netlistdyn.base.errors import NetlistError
from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.frontend.parser import parse_text
from tests.exact_pencil import bar_violations, exact_natural_frequencies, expected_verdict
from tests.random_networks import random_network


def campaign(count: int, spread: bool, seed: int) -> dict[str, int]:
    """Run ``count`` networks; print failures; return the counts."""
    rng = np.random.default_rng(seed)
    counts = dict.fromkeys(
        (
            "networks",
            "compiled",
            "refused",
            "singular",
            "eigenvalues",
            "off_bar",
            "order",
            "verdict",
            "crash",
        ),
        0,
    )
    for _ in range(count):
        text = random_network(rng, spread)
        counts["networks"] += 1
        try:
            netlist = parse_text(text)
            model = compile_netlist(netlist, ["v(n1)"])
        except NetlistError:
            counts["refused"] += 1
            continue
        try:
            exact = exact_natural_frequencies(netlist)
        except ValueError:
            counts["singular"] += 1
            continue
        counts["compiled"] += 1
        try:
            eig = analyze_eigenvalues(model.A_sparse, "all", pencil=model.pencil)
        except Exception as exc:  # a crash is a finding: count it, show the network, go on
            counts["crash"] += 1
            print(f"CRASH {type(exc).__name__}: {exc}\n{text}", flush=True)
            continue
        counts["eigenvalues"] += len(eig.modes)
        if len(eig.modes) != len(exact):
            counts["order"] += 1
            print(f"ORDER {len(eig.modes)} vs {len(exact)}\n{text}")
            continue
        violations = bar_violations(eig.modes, exact)
        counts["off_bar"] += len(violations)
        if violations:
            print("OFF BAR", violations, "\n" + text)
        expected = expected_verdict(exact)
        if expected is not None and eig.verdict not in (expected, "undetermined"):
            counts["verdict"] += 1
            print(f"VERDICT {eig.verdict} vs {expected}\n{text}")
    return counts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=200, help="networks per value regime")
    parser.add_argument("--spread", choices=("realistic", "wide", "both"), default="both")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    regimes = {"realistic": [False], "wide": [True], "both": [False, True]}[args.spread]
    for spread in regimes:
        start = time.perf_counter()
        counts = campaign(args.count, spread, args.seed)
        label = "wide (1e-15…1e6)" if spread else "realistic (E12)"
        summary = ", ".join(f"{k} {v}" for k, v in counts.items())
        print(f"{label}: {summary}; {time.perf_counter() - start:.0f} s", flush=True)


if __name__ == "__main__":
    main()
