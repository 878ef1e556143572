"""The data behind ``--bode``: G(jω) of every input→output pair over a frequency grid, as CSV or JSON.

The grid is the netlist's ``.ac`` range when it has one (400 points, logarithmic), else two decades
beyond the eigenvalues' magnitudes (:func:`~netlistdyn.analysis.control.frequency_grid`). A pair that
the input does not reach (G ≡ 0) is left out, as the plot leaves it out.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from netlistdyn.analysis.control import frequency_grid, frequency_response
from netlistdyn.base.errors import UsageError
from netlistdyn.statespace.model import StateSpaceModel

#: Largest model whose frequency response ``--bode`` evaluates (one dense solve per frequency).
BODE_STATE_LIMIT = 400
#: Points of a grid over the netlist's ``.ac`` range.
AC_POINTS = 400


@dataclass(frozen=True)
class Bode:
    """A frequency response on a grid.

    Attributes
    ----------
    omega : numpy.ndarray
        Angular frequencies (rad/s), shape ``(k,)``.
    pairs : tuple of (str, str)
        (output, input) of each column of ``response``: the pairs the input reaches.
    response : numpy.ndarray
        Complex G(jω), shape ``(k, len(pairs))``.
    source : str
        Where the grid came from.
    """

    omega: NDArray[np.float64]
    pairs: tuple[tuple[str, str], ...]
    response: NDArray[np.complex128]
    source: str

    @property
    def frequency_hz(self) -> NDArray[np.float64]:
        """Frequencies (Hz)."""
        return self.omega / (2 * np.pi)

    def magnitude_db(self) -> NDArray[np.float64]:
        """20 log10 |G| (dB); −inf where G = 0 at a frequency."""
        with np.errstate(divide="ignore"):
            return np.asarray(20 * np.log10(np.abs(self.response)))

    def phase_deg(self) -> NDArray[np.float64]:
        """arg G in degrees, unwrapped along frequency (continuous across ±180°)."""
        return np.asarray(np.degrees(np.unwrap(np.angle(self.response), axis=0)))


def bode(model: StateSpaceModel, hz_range: tuple[float, float] | None = None) -> Bode:
    """G(jω) of ``model`` over the ``.ac`` range ``hz_range`` (Hz), else around its eigenvalues.

    Raises
    ------
    UsageError
        Above :data:`BODE_STATE_LIMIT` states.
    """
    if model.nstates > BODE_STATE_LIMIT:
        raise UsageError(f"--bode is for models of up to {BODE_STATE_LIMIT} states")
    if hz_range is not None:
        low, high = hz_range
        omega = 2 * np.pi * np.logspace(np.log10(low), np.log10(high), AC_POINTS)
        source = ".ac range of the netlist"
    else:
        omega = frequency_grid(model)
        source = "two decades beyond the eigenvalues"
    full = frequency_response(model, omega)
    pairs = []
    columns = []
    for i, out in enumerate(model.outputs):
        for j, inp in enumerate(model.inputs):
            if np.any(full[:, i, j]):
                pairs.append((out, inp))
                columns.append(full[:, i, j])
    response = np.stack(columns, axis=1) if columns else np.zeros((omega.size, 0), dtype=complex)
    return Bode(omega, tuple(pairs), response, source)


def bode_csv(data: Bode) -> str:
    """One row per frequency: Hz, rad/s, then re, im, dB and phase (deg) of each pair."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    head = ["frequency_hz", "omega_rad_s"]
    for out, inp in data.pairs:
        ratio = f"{out}/{inp}"
        head += [f"re({ratio})", f"im({ratio})", f"db({ratio})", f"phase_deg({ratio})"]
    writer.writerow(head)
    db, phase = data.magnitude_db(), data.phase_deg()
    for k, (hz, w) in enumerate(zip(data.frequency_hz, data.omega, strict=True)):
        row = [repr(float(hz)), repr(float(w))]
        for p in range(len(data.pairs)):
            z = data.response[k, p]
            row += [repr(float(z.real)), repr(float(z.imag)), repr(float(db[k, p])), repr(float(phase[k, p]))]
        writer.writerow(row)
    return buffer.getvalue()


def bode_dict(data: Bode) -> dict[str, Any]:
    """The response for ``--format json``: the grid, then per pair its re/im, dB and phase lists."""
    db, phase = data.magnitude_db(), data.phase_deg()
    return {
        "source": data.source,
        "frequency_hz": data.frequency_hz.tolist(),
        "pairs": [
            {
                "output": out,
                "input": inp,
                "re": data.response[:, p].real.tolist(),
                "im": data.response[:, p].imag.tolist(),
                "magnitude_db": [None if not np.isfinite(v) else float(v) for v in db[:, p]],
                "phase_deg": phase[:, p].tolist(),
            }
            for p, (out, inp) in enumerate(data.pairs)
        ],
    }
