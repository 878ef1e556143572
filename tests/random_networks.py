"""Random linear networks for property tests and the long campaign (benchmarks/spread_campaign.py).

A network has a grounded voltage source, 3–8 random R, L, C branches between
random nodes, a resistor from every node to ground (no floating node),
sometimes a VCCS and a coupling between two inductors. Values are either
realistic (E12 mantissas over mΩ…GΩ, pF…mF, pH…H) or log-uniform over
1e-15…1e6 (wide spreads).
"""

from __future__ import annotations

import numpy as np

E12 = (1.0, 1.2, 1.5, 1.8, 2.2, 2.7, 3.3, 3.9, 4.7, 5.6, 6.8, 8.2)
#: Decades of realistic values per kind: R in mΩ…GΩ, C in pF…mF, L in pH…H.
DECADES = {"R": (-3, 9), "C": (-12, -3), "L": (-12, 0)}


def random_network(rng: np.random.Generator, spread: bool) -> str:
    """Netlist text of one random network (output of interest: v(n1))."""

    def value(kind: str) -> float:
        if spread:
            return float(10.0 ** rng.uniform(-15, 6))
        low, high = DECADES[kind]
        return float(rng.choice(E12)) * 10.0 ** int(rng.integers(low, high + 1))

    n_nodes = int(rng.integers(2, 6))
    nodes = ["0", *[f"n{i}" for i in range(1, n_nodes + 1)]]
    lines = ["random network", "Vin n1 0 1"]
    inductors = []
    for k in range(int(rng.integers(3, 9))):
        kind = str(rng.choice(["R", "L", "C"]))
        a, b = rng.choice(nodes, size=2, replace=False)
        lines.append(f"{kind}{k} {a} {b} {value(kind):.17g}")
        if kind == "L":
            inductors.append(f"L{k}")
    for node in nodes[1:]:
        lines.append(f"Rg{node} {node} 0 {value('R'):.17g}")
    if rng.random() < 0.5:
        a, b = rng.choice(nodes, size=2, replace=False)
        c, d = rng.choice(nodes, size=2, replace=False)
        gain = rng.uniform(-1, 1) * (1e3 if spread else 1e-2)
        lines.append(f"G1 {a} {b} {c} {d} {gain:.17g}")
    if len(inductors) >= 2 and rng.random() < 0.5:
        lines.append(f"K1 {inductors[0]} {inductors[1]} {rng.uniform(0.05, 0.95):.17g}")
    lines.append(".end")
    return "\n".join(lines) + "\n"
