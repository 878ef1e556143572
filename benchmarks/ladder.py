"""Generator of RLC ladder netlists: N sections of series R–L with a shunt C.

    Vin in 0 DC 1
    R1 in m1 1 ; L1 m1 n1 1m ; C1 n1 0 1u
    R2 n1 m2 1 ; L2 m2 n2 1m ; C2 n2 0 1u ...

The ladder has 2N states (N capacitor charges, N inductor currents).
Usage: ``python benchmarks/ladder.py N [R L C] > ladder.cir``.
"""

from __future__ import annotations

import sys


def ladder_netlist(
    sections: int, r: float = 1.0, ind: float = 1e-3, c: float = 1e-6, tstop: float | None = None
) -> str:
    """Netlist text of an N-section RLC ladder driven by a unit step.

    Parameters
    ----------
    sections : int
        Number of R–L–C sections N (2N states).
    r, ind, c : float
        Series resistance (Ω), series inductance (H), shunt capacitance (F).
    tstop : float, optional
        Horizon of the ``.tran`` line (s); default 2 ms per 1000 sections
        scaled as the ladder's delay √(LC)·N, at least 2 ms.
    """
    lines = [f"RLC ladder, {sections} sections (R={r:g}, L={ind:g}, C={c:g})", "Vin in 0 DC 1"]
    prev = "in"
    for k in range(1, sections + 1):
        lines.append(f"R{k} {prev} m{k} {r!r}")
        lines.append(f"L{k} m{k} n{k} {ind!r}")
        lines.append(f"C{k} n{k} 0 {c!r}")
        prev = f"n{k}"
    horizon = tstop if tstop is not None else max(2e-3, 2.0 * sections * (ind * c) ** 0.5)
    lines.append(f".tran {horizon / 1000!r} {horizon!r} uic")  # a step response: start at rest
    lines.append(".end")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    n = int(sys.argv[1])
    values = [float(v) for v in sys.argv[2:5]]
    sys.stdout.write(ladder_netlist(n, *values))
