"""Synthetic on-chip power grids: RC and RLC meshes with supply pads and PWL loads.

``python benchmarks/powergrid.py --size 100 --kind rlc -o grid.cir`` writes an
N×N mesh: resistors between neighbouring nodes, a capacitor from every node
to ground, supply pads every ``pitch`` nodes (a voltage source behind a pad
resistance, and for ``rlc`` a package inductance), and PWL current loads at
random nodes whose corners lie on the output grid (10 ps), ``.tran 10p 10n``.
Values are drawn from the ranges of on-chip grids (segment resistance
20–100 mΩ, node capacitance 10–100 fF, pad 0.25 Ω and 0.5–1 nH, loads up to
10 mA). The same arguments always give the same netlist.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

TSTEP = 1e-11
TSTOP = 1e-8


def grid_netlist(
    size: int, kind: str = "rc", pitch: int = 10, loads: int | None = None, seed: int = 1
) -> str:
    """The netlist text of a ``size``×``size`` power grid.

    Parameters
    ----------
    size : int
        Nodes per side.
    kind : {"rc", "rlc"}
        Without or with package inductance at the pads.
    pitch : int
        Pad spacing (nodes) in both directions.
    loads : int, optional
        Number of PWL current loads (default size²/10, at least 2).
    seed : int
        Random stream for the values (same seed, same netlist).
    """
    if kind not in ("rc", "rlc"):
        raise ValueError(f"kind must be rc or rlc, not {kind!r}")
    rng = np.random.default_rng(seed)
    lines = [f"{kind.upper()} power grid {size}x{size}, pads every {pitch} nodes"]

    def node(i: int, j: int) -> str:
        return f"n{i}_{j}"

    count = 0
    for i in range(size):
        for j in range(size):
            if j + 1 < size:
                count += 1
                lines.append(f"R{count} {node(i, j)} {node(i, j + 1)} {rng.uniform(0.02, 0.1):.6g}")
            if i + 1 < size:
                count += 1
                lines.append(f"R{count} {node(i, j)} {node(i + 1, j)} {rng.uniform(0.02, 0.1):.6g}")
            lines.append(f"C{i}_{j} {node(i, j)} 0 {rng.uniform(10e-15, 100e-15):.6g}")
    offset = pitch // 2 if size > pitch // 2 else 0
    pads = [(i, j) for i in range(offset, size, pitch) for j in range(offset, size, pitch)]
    for k, (i, j) in enumerate(pads):
        if kind == "rc":
            lines.append(f"Vdd{k} vdd{k} 0 1.8")
            lines.append(f"Rpad{k} vdd{k} {node(i, j)} 0.25")
        else:
            lines.append(f"Vdd{k} vdd{k} 0 1.8")
            lines.append(f"Rpad{k} vdd{k} p{k} 0.25")
            lines.append(f"Lpad{k} p{k} {node(i, j)} {rng.uniform(0.5e-9, 1e-9):.6g}")
    nloads = loads if loads is not None else max(2, size * size // 10)
    steps = round(TSTOP / TSTEP)
    for k in range(nloads):
        i, j = (int(v) for v in rng.integers(0, size, 2))
        corners = np.sort(rng.choice(np.arange(1, steps), size=6, replace=False))
        peak = rng.uniform(1e-3, 10e-3)
        values = [0.0, peak, peak * rng.uniform(0.2, 1.0), 0.0, peak * rng.uniform(0.2, 1.0), 0.0]
        pairs = " ".join(f"{c * TSTEP:.6g} {v:.6g}" for c, v in zip(corners, values, strict=True))
        lines.append(f"Iload{k} {node(i, j)} 0 PWL(0 0 {pairs})")
    lines.append(f".tran {TSTEP:g} {TSTOP:g}")
    lines.append(".end")
    return "\n".join(lines) + "\n"


def probe_nodes(size: int, count: int = 4) -> list[str]:
    """A few node names spread over the grid (for outputs)."""
    picks = np.linspace(0, size - 1, count + 2)[1:-1].round().astype(int)
    return [f"n{i}_{j}" for i, j in zip(picks, picks[::-1], strict=True)]


def main(argv: list[str] | None = None) -> int:
    """Command line: write one grid netlist."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=30)
    parser.add_argument("--kind", choices=["rc", "rlc"], default="rc")
    parser.add_argument("--pitch", type=int, default=10)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("-o", "--out", default="-")
    args = parser.parse_args(argv)
    text = grid_netlist(args.size, args.kind, args.pitch, seed=args.seed)
    if args.out == "-":
        sys.stdout.write(text)
    else:
        with open(args.out, "w") as handle:
            handle.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
