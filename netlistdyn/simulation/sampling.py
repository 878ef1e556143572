"""Output grids that show what the outputs do: the fastest visible mode and every source corner.

A uniform grid of ``.tran``'s TSTEP can step over a resonance (a 159 kHz ring sampled every 4 µs is a
zigzag, and its reported maximum is just the largest sample) or over a short pulse (every sample of a
1 ms grid can land in a 10 µs pulse train's low phase). The model knows its modes and the sources know
their corners, so the grid is checked against both:

- a mode is *visible* when its share of the outputs' step response, |C vᵢ| |wᵢᴴ B| / |λᵢ| (vᵢ, wᵢ the
  right and left eigenvectors), is at least :data:`VISIBLE_SHARE` of the largest one and it lives
  longer than one output step;
- a visible oscillation is *undersampled* below :data:`SAMPLES_PER_PERIOD` samples per period;
- a source's pulse is *missed* when a high or low phase is shorter than the output step.

A grid that the netlist's ``.tran`` chose is refined (the source waveforms keep their TSTEP-based
defaults: only the output times change) and the refinement is reported; a grid the user gave on the
command line is kept and a warning names the mode or the source.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from netlistdyn.base.errors import SourceLocation
from netlistdyn.base.formatting import eng
from netlistdyn.circuit.netlist import Diagnostic, Netlist
from netlistdyn.circuit.sources import breakpoints, resolved_waveforms
from netlistdyn.circuit.waveforms import Waveform
from netlistdyn.statespace.model import StateSpaceModel

#: A mode whose share of the outputs' step response is below this fraction of the largest is not shown.
VISIBLE_SHARE = 1e-3
#: Fewer samples than this per period of a visible oscillation draw a zigzag, not the waveform.
SAMPLES_PER_PERIOD = 4
#: A refined grid puts this many samples on the period of the fastest visible oscillation.
REFINED_SAMPLES_PER_PERIOD = 20
#: Eigenvector matrices worse conditioned than this give no trustworthy modal shares (no check).
EIGENVECTOR_CONDITION_LIMIT = 1e10
#: Largest model whose modes are found by a dense eigendecomposition for this check.
DENSE_MODES_LIMIT = 400


@dataclass(frozen=True)
class Grid:
    """Output times and what was found about them.

    Attributes
    ----------
    times : numpy.ndarray
        Output times (s), increasing, from 0 to the horizon.
    step : float
        The largest spacing of ``times`` (s).
    warnings : tuple of Diagnostic
        One per undersampled mode or missed pulse, or per refinement made: at the ``.tran`` line
        when the netlist chose the grid, else at the netlist as a whole (the command line chose it).
    """

    times: NDArray[np.float64]
    step: float
    warnings: tuple[Diagnostic, ...]


def visible_periods(model: StateSpaceModel, tstep: float) -> list[tuple[float, float]]:
    """(period in s, damping ratio) of every oscillation the outputs show that lives past one step.

    Parameters
    ----------
    model : StateSpaceModel
    tstep : float
        Output step (s): a mode that decays by e⁻¹⁰ within it leaves no trace in any sample.

    Returns
    -------
    list of (float, float)
        Empty for models above :data:`DENSE_MODES_LIMIT` states (not checked).
    """
    n = model.nstates
    if n == 0 or n > DENSE_MODES_LIMIT or model.noutputs == 0 or model.ninputs == 0:
        return []
    values, right = np.linalg.eig(model.A)
    # A defective or nearly defective A (a free cart's double zero) has no modal split worth the
    # name: no check rather than a guess.
    if not np.all(np.isfinite(right)) or np.linalg.cond(right) > EIGENVECTOR_CONDITION_LIMIT:
        return []
    left = np.linalg.inv(right)  # rows: left eigenvectors scaled so that wᵢᴴ vᵢ = 1
    observed = np.linalg.norm(model.C @ right, axis=0)
    excited = np.linalg.norm(left @ model.B, axis=1)
    magnitude = np.abs(values)
    share = np.where(magnitude > 0, observed * excited / np.where(magnitude > 0, magnitude, 1.0), 0.0)
    if not np.all(np.isfinite(share)) or np.max(share) <= 0:
        return []
    top = np.max(share)
    found = []
    for lam, part in zip(values, share, strict=True):
        if lam.imag <= 0 or not part >= VISIBLE_SHARE * top or -lam.real * tstep > 10:
            continue
        found.append((2 * math.pi / lam.imag, -lam.real / abs(lam)))
    return found


def shortest_phase(netlist: Netlist, waveforms: Sequence[Waveform], tstop: float) -> tuple[str, float] | None:
    """The source with the shortest interval between two of its corners, and that interval (s).

    ``waveforms`` are the netlist's sources' waveforms, resolved for the transient, in order.
    """
    best: tuple[str, float] | None = None
    for element, waveform in zip(netlist.sources, waveforms, strict=True):
        corners = breakpoints([waveform], tstop)
        if corners.size < 2:
            continue
        gaps = np.diff(corners)
        gaps = gaps[gaps > 0]
        if gaps.size and (best is None or gaps.min() < best[1]):
            best = (element.name, float(gaps.min()))
    return best


def output_grid(
    netlist: Netlist,
    model: StateSpaceModel,
    tstep: float,
    tstop: float,
    refine: bool,
    max_points: int,
) -> Grid:
    """The output times of a transient, checked (and, with ``refine``, made fine enough).

    Parameters
    ----------
    netlist : Netlist
        For its sources' corners.
    model : StateSpaceModel
        For the modes its outputs show (the linearisation of a nonlinear netlist).
    tstep, tstop : float
        The chosen output step and horizon (s).
    refine : bool
        Whether the grid may be made finer (it came from the netlist's ``.tran``, not the user).
    max_points : int
        Most output points a refinement may make.

    Returns
    -------
    Grid
    """
    count = round(tstop / tstep)
    times = np.linspace(0.0, tstop, count + 1)
    notes: list[str] = []
    periods = visible_periods(model, tstep)
    fastest = min(periods, default=None)
    wanted = tstep
    if fastest is not None and fastest[0] < SAMPLES_PER_PERIOD * tstep:
        period, zeta = fastest
        mode = f"the {eng(1 / period, 'Hz')} mode (ζ = {zeta:.3g}) the outputs show"
        finer = period / REFINED_SAMPLES_PER_PERIOD
        if refine and tstop / finer <= max_points:
            wanted = finer
            notes.append(
                f"output step refined from {eng(tstep, 's')} to {eng(finer, 's')} to resolve {mode} "
                f"(.tran's step gave {period / tstep:.2g} samples per period)"
            )
        else:
            notes.append(
                f"output step {eng(tstep, 's')} undersamples {mode}: {period / tstep:.2g} samples per "
                f"period; values between samples (and the reported extremes) can be far off — use "
                f"--tstep {eng(period / REFINED_SAMPLES_PER_PERIOD, 's')} or less"
            )
    waveforms = resolved_waveforms(netlist, (tstep, tstop))
    phase = shortest_phase(netlist, waveforms, tstop)
    corners: NDArray[np.float64] = np.zeros(0)
    if phase is not None and phase[1] < tstep:
        name, gap = phase
        if refine:
            corners = breakpoints(waveforms, tstop)
            if corners.size + count > max_points:
                corners = np.zeros(0)
        if corners.size:
            notes.append(
                f"output times include {name}'s corners: it changes within {eng(gap, 's')}, faster than "
                f"the output step {eng(tstep, 's')}"
            )
        else:
            notes.append(
                f"{name} changes within {eng(gap, 's')} (between two of its corners), faster than the "
                f"output step {eng(tstep, 's')}: samples can miss its pulses (and the reported extremes)"
            )
    if wanted < tstep:
        times = np.linspace(0.0, tstop, round(tstop / wanted) + 1)
    if corners.size:
        times = _merged(times, corners, tstop)
    step = float(np.max(np.diff(times))) if times.size > 1 else tstep
    tran_loc = netlist.tran.loc if refine and netlist.tran is not None else None
    where = tran_loc if tran_loc is not None else SourceLocation(netlist.path, 0)
    return Grid(times, step, tuple(Diagnostic(where, note) for note in notes))


def _merged(
    times: NDArray[np.float64], corners: Sequence[float] | NDArray[np.float64], tstop: float
) -> NDArray[np.float64]:
    """``times`` with ``corners`` added, dropping corners within rounding of a time already there."""
    merged = np.unique(np.concatenate([times, np.asarray(corners, dtype=float)]))
    keep = np.concatenate([[True], np.diff(merged) > 1e-12 * tstop])
    return merged[keep]
