"""Every source of a circuit as a function of time.

Waveforms resolved with SPICE's defaults, evaluated together, and the times where their slopes jump.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from netlistdyn.circuit.netlist import Element, Netlist
from netlistdyn.circuit.waveforms import Dc, Pulse, Pwl, Waveform, pulse_values


class SourceValues:
    """All source waveforms of a circuit, evaluated together (vectorised by kind).

    Parameters
    ----------
    waveforms : sequence of Waveform
        One per input, SPICE defaults already resolved.
    """

    def __init__(self, waveforms: Sequence[Waveform]) -> None:
        self.count = len(waveforms)
        dc = [(j, w.value) for j, w in enumerate(waveforms) if isinstance(w, Dc)]
        self.dc_index = np.array([j for j, _ in dc], dtype=np.intp)
        self.dc_value = np.array([v for _, v in dc], dtype=float)
        pulses = [(j, w) for j, w in enumerate(waveforms) if isinstance(w, Pulse)]
        self.pulse_index = np.array([j for j, _ in pulses], dtype=np.intp)
        fields = ("v1", "v2", "td", "tr", "tf", "pw", "per")
        self.pulse = {f: np.array([float(getattr(w, f)) for _, w in pulses]) for f in fields}
        self.pulse["ncycles"] = np.array([math.inf if w.ncycles is None else w.ncycles for _, w in pulses])
        # PWL tables side by side (padded with +inf times holding the last value), evaluated
        # together: one waveform at a time cost 1.2 ms per step with 100 loads on a 10x10 grid.
        pwls = [(j, w) for j, w in enumerate(waveforms) if type(w) is Pwl]
        self.pwl_index = np.array([j for j, _ in pwls], dtype=np.intp)
        width = max((len(w.times) for _, w in pwls), default=1)
        self.pwl_t = np.full((len(pwls), width), np.inf)
        self.pwl_v = np.empty((len(pwls), width))
        for row, (_, w) in enumerate(pwls):
            self.pwl_t[row, : len(w.times)] = w.times
            self.pwl_v[row, : len(w.values)] = w.values
            self.pwl_v[row, len(w.values) :] = w.values[-1]
        self.rows = np.arange(len(pwls))
        self.other = [
            (j, w) for j, w in enumerate(waveforms) if not isinstance(w, Dc | Pulse) and type(w) is not Pwl
        ]

    def __call__(self, t: float) -> NDArray[np.float64]:
        """Every input's value at time ``t`` (s)."""
        out = np.empty(self.count)
        out[self.dc_index] = self.dc_value
        if self.pulse_index.size:
            out[self.pulse_index] = pulse_values(t, self.pulse)
        if self.pwl_index.size:
            out[self.pwl_index] = self._pwl(t)
        for j, w in self.other:
            out[j] = float(np.asarray(w(np.array([t])))[0])
        return out

    def _pwl(self, t: float) -> NDArray[np.float64]:
        """Every PWL at t, as :meth:`netlistdyn.circuit.waveforms.Pwl.__call__` (after a jump)."""
        lo = np.count_nonzero(self.pwl_t <= t, axis=1) - 1  # last corner at or before t
        start = np.maximum(lo, 0)
        stop = np.minimum(start + 1, self.pwl_t.shape[1] - 1)
        t_lo, t_hi = self.pwl_t[self.rows, start], self.pwl_t[self.rows, stop]
        v_lo, v_hi = self.pwl_v[self.rows, start], self.pwl_v[self.rows, stop]
        with np.errstate(invalid="ignore"):
            inside = (lo >= 0) & (t_hi > t_lo) & np.isfinite(t_hi)
            frac = np.where(inside, (t - t_lo) / np.where(inside, t_hi - t_lo, 1.0), 0.0)
        return np.where(lo < 0, self.pwl_v[:, 0], v_lo + frac * (v_hi - v_lo))

    def piecewise_linear(self) -> bool:
        """True when every input is linear between breakpoints."""
        return all(w.piecewise_linear for _, w in self.other)


def breakpoints(waveforms: Sequence[Waveform], tstop: float) -> NDArray[np.float64]:
    """Sorted distinct times in (0, tstop) where some input's slope jumps (s)."""
    chunks: list[NDArray[np.float64]] = [np.zeros(0)]
    for w in waveforms:
        if isinstance(w, Pulse | Pwl) or not isinstance(w, Dc):
            chunks.append(np.asarray(w.breakpoints(tstop), dtype=float))
    points = np.unique(np.concatenate(chunks))
    return points[(points > 0) & (points < tstop)]


def source_waveform(element: Element) -> Waveform:
    """The transient waveform of a source: its own, or its DC value as a step."""
    return element.waveform if element.waveform is not None else Dc(element.value)


def resolved_waveforms(netlist: Netlist, span: tuple[float, float] | None = None) -> list[Waveform]:
    """Every source's waveform with SPICE's defaults for ``span`` = (TSTEP, TSTOP) (see NonlinearSystem)."""
    if span is None:
        span = (netlist.tran.tstep, netlist.tran.tstop) if netlist.tran is not None else (1.0, 1.0)
    return [source_waveform(e).resolved(*span) for e in netlist.sources]
