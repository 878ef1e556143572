"""Warnings when a linearised model is simulated outside its region of validity.

A ``ROD`` is a pendulum linearised about an equilibrium: sin θ ≈ θ and
cos θ ≈ 1. The larger of the two dropped terms, relative to what is kept,
is 1 − cos θ, which reaches 1 % at θ = arccos(0.99) = 0.1415 rad (8.1°):
:data:`SMALL_ANGLE_LIMIT` (sin θ ≈ θ is then off by only θ²/6 ≈ 0.33 %).
Beyond it the simulated angles are those of the linear model, not of the
pendulum.

An unstable model (an eigenvalue with a positive real part) multiplies any
excitation of its unstable mode by e^{Re λ t}; once that exceeds
:data:`GROWTH_LIMIT` the state has left any neighbourhood in which the
linearisation was made (the seed's double inverted pendulum reaches 5e235
rad after 60 s), and the numbers only say "it falls".
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from netlistdyn.analysis.eigen import EigenAnalysis
from netlistdyn.circuit.netlist import Netlist

#: Rod angle (rad) where 1 − cos θ, dropped by the linearisation, reaches 1 %.
SMALL_ANGLE_LIMIT = math.acos(0.99)
#: Growth factor e^{Re λ t} of an unstable mode beyond which a run is flagged.
GROWTH_LIMIT = 1e3


def rod_angles(netlist: Netlist) -> list[str]:
    """``angle(rod)`` for every rod of the netlist, in netlist order."""
    return [f"angle({e.name})" for e in netlist.elements if e.rod is not None]


def validity_warnings(
    time: NDArray[np.float64],
    outputs: NDArray[np.float64],
    names: Sequence[str],
    angles: Sequence[str],
    eig: EigenAnalysis | None,
) -> list[str]:
    """The warnings for one simulated run.

    Parameters
    ----------
    time : array
        Output times (s).
    outputs : array
        ``(len(time), len(names))`` simulated outputs.
    names : sequence of str
        Output labels.
    angles : sequence of str
        Labels among ``names`` that are rod angles (rad).
    eig : EigenAnalysis, optional
        The model's eigenvalues.

    Returns
    -------
    list of str
    """
    out = []
    for label in angles:
        column = outputs[:, names.index(label)]
        beyond = np.flatnonzero(np.abs(column) > SMALL_ANGLE_LIMIT)
        if beyond.size:
            k = beyond[0]
            peak = float(np.max(np.abs(column)))
            out.append(
                f"{label} leaves the small-angle range at t = {time[k]:.6g} s "
                f"(|angle| > {SMALL_ANGLE_LIMIT:.4f} rad = {math.degrees(SMALL_ANGLE_LIMIT):.1f}°, where "
                f"the linearised rod is 1 % off) and reaches {peak:.3g} rad: beyond that the run shows "
                "the linear model, not the pendulum"
            )
    if eig is not None and eig.verdict == "unstable" and time.size:
        growing = [m for m in eig.modes if m.value.real > 0 and not m.value.real <= m.abs_error]
        if growing:
            rate = max(m.value.real for m in growing)
            horizon = float(time[-1] - time[0])
            decades = rate * horizon / math.log(10)
            if rate * horizon > math.log(GROWTH_LIMIT):
                when = math.log(GROWTH_LIMIT) / rate
                peak = float(np.max(np.abs(outputs))) if outputs.size else 0.0
                out.append(
                    f"the model is unstable (eigenvalue {rate:.6g} 1/s): an excitation of that mode "
                    f"grows {GROWTH_LIMIT:.0e}-fold every {when:.3g} s, by 10^{decades:.0f} "
                    f"over the run (largest output {peak:.3g}); a linearised model holds only near its "
                    "equilibrium"
                )
    return out
