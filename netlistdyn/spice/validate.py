"""Validation against ngspice: same netlist, same stimulus, same start (see :mod:`netlistdyn.initial`).

The compiled model is simulated exactly (first-order hold on the union of
ngspice's time points and the input breakpoints, see
:mod:`netlistdyn.simulate`) and compared with ngspice at ngspice's own time
points. ngspice is run tight enough to be a reference (see
:func:`spice_settings_for`); its settings are part of the report.
"""

from __future__ import annotations

import cmath
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from netlistdyn.analysis.eigen import EigenAnalysis
from netlistdyn.circuit.netlist import Netlist
from netlistdyn.circuit.probes import Probe
from netlistdyn.formulation.operating import operating_point
from netlistdyn.simulation.foh import Horizon, input_signals, propagate_foh
from netlistdyn.simulation.initial import around_equilibrium, transient_start
from netlistdyn.simulation.nltransient import NONLINEAR_VALIDATE_RTOL, nonlinear_start
from netlistdyn.simulation.nltransient import run as run_nonlinear
from netlistdyn.spice.ngspice import (
    SpiceRun,
    SpiceSettings,
    ngspice_source_name,
    run_original,
    run_polezero,
    run_transient,
)
from netlistdyn.statespace.model import StateSpaceModel

#: Default pass threshold: max error relative to each waveform's peak (ngspice's default reltol).
DEFAULT_RTOL = 1e-3
#: ngspice's relative tolerance for validation runs, tightest first: where ngspice
#: aborts ("timestep too small") the next is tried and the report says so.
VALIDATION_RELTOLS = (1e-9, 1e-7, 1e-5)
#: Stiffness ratio above which ngspice uses Gear integration.
GEAR_STIFFNESS = 1e3
#: Phase error allowed to ngspice's trapezoidal rule over the horizon (relative).
PHASE_RTOL = 1e-6
#: ngspice's maximum step is at most 1/STEPS_PER_HORIZON of the horizon ...
STEPS_PER_HORIZON = 2000
#: ... and at least 1/MAX_STEPS of it, to bound its run time ...
MAX_STEPS = 2_000_000
#: ... and of steps × states (ngspice keeps every vector at every step: 1e5 points of the
#: 100-section ladder, 200 states, took 0.83 GB), so mid-sized circuits finish.
STEP_STATE_BUDGET = 10_000_000
#: Largest model for which ngspice's .pz poles are compared.
PZ_MAX_STATES = 6
#: Agreement demanded between the model's transfer values and ngspice's op/ac on
#: the original file: both solve the same linear equations in double precision
#: (ngspice prints 16 digits), so 1e-6 leaves room for rounding only, while any
#: misread value or connection changes the answer by far more.
ORIGINAL_RTOL = 1e-6
#: ngspice's tolerances for the original-file check of a nonlinear netlist: vntol (V), abstol (A).
NGSPICE_TIGHT_VNTOL = 1e-12
NGSPICE_TIGHT_ABSTOL = 1e-15
#: ngspice 39's defaults of vntol (V) and abstol (A), when a run does not set them.
NGSPICE_VNTOL = 1e-6
NGSPICE_ABSTOL = 1e-12


@dataclass(frozen=True, slots=True)
class OutputComparison:
    """Errors of one output against ngspice.

    Attributes
    ----------
    name : str
    peak : float
        max |ngspice waveform| (output units).
    max_abs_error : float
        max |ours − ngspice|.
    max_rel_error : float
        max_abs_error / peak.
    rms_error : float
        Root-mean-square difference over ngspice's time points.
    """

    name: str
    peak: float
    max_abs_error: float
    max_rel_error: float
    rms_error: float


@dataclass(frozen=True)
class PoleComparison:
    """ngspice's ``.pz`` poles against the model's eigenvalues (informative only).

    Attributes
    ----------
    poles : tuple of complex
        What ngspice returned (1/s).
    eigenvalues : tuple of complex
        The model's eigenvalues (1/s).
    max_rel_difference : float
        Each ngspice pole against its nearest eigenvalue, relative to
        |eigenvalue|; NaN when ngspice returned nothing.
    message : str
        Eigenvalues ngspice did not return, if any.
    """

    poles: tuple[complex, ...]
    eigenvalues: tuple[complex, ...]
    max_rel_difference: float
    message: str = ""


@dataclass(frozen=True)
class OriginalCheck:
    """The model against ngspice's ``op``/``ac`` on the user's original file.

    Attributes
    ----------
    ran : bool
        False when the check could not be made (``message`` says why); it
        then neither passes nor fails the validation.
    worst : float
        Largest difference over every compared output, relative to the largest
        output of its kind (voltages, currents) at the same frequency.
    compared : int
        Number of (output, frequency) values compared.
    message : str
        One line for the report.
    """

    ran: bool
    worst: float = 0.0
    compared: int = 0
    message: str = ""

    @property
    def passed(self) -> bool:
        """False only when the check ran and found a difference above :data:`ORIGINAL_RTOL`."""
        return not self.ran or self.worst <= ORIGINAL_RTOL


@dataclass(frozen=True)
class ValidationReport:
    """Everything ``validate`` found."""

    netlist: str
    horizon: Horizon
    settings: SpiceSettings
    spice: SpiceRun
    model_seconds: float
    comparisons: tuple[OutputComparison, ...]
    rtol: float
    time: np.ndarray
    ours: np.ndarray
    notes: tuple[str, ...] = ()
    poles: PoleComparison | None = None
    original: OriginalCheck | None = None

    @property
    def passed(self) -> bool:
        """True when ngspice ran, every output is within ``rtol`` of its peak, and
        ngspice's reading of the original file does not contradict the model."""
        ok = self.spice.ok and all(c.max_rel_error <= self.rtol for c in self.comparisons)
        return ok and (self.original is None or self.original.passed)


def _time_scales(eig: EigenAnalysis | None) -> tuple[float, list[tuple[float, float]]]:
    """Fastest time scale (s), and (rate |λ|, duration) of every mode whose error accumulates.

    Errors made on a decaying real mode decay with it and ngspice's local
    error control handles them; on an oscillatory mode (phase) or a growing
    one they accumulate over the time the mode lasts: five time constants
    for a decaying oscillation, the whole horizon otherwise.
    """
    fastest = math.inf
    accumulating = []
    for mode in eig.modes if eig is not None else ():
        lam = mode.value
        if abs(lam):
            fastest = min(fastest, 1.0 / abs(lam))
        if lam.imag or lam.real > 0:
            duration = 5.0 / -lam.real if lam.real < 0 else math.inf
            accumulating.append((abs(lam), duration))
    return fastest, accumulating


def spice_settings_for(
    horizon: Horizon, eig: EigenAnalysis | None, nstates: int | None = None
) -> SpiceSettings:
    """Tight ngspice settings for a reference run.

    * reltol the first of :data:`VALIDATION_RELTOLS`, abstol 1e-15 A, vntol 1e-12 V;
    * ``.tran`` step at most 1/1000 of the fastest time scale: ngspice's
      first step (tstep/100, backward Euler) is then accurate;
    * maximum step from the error that no reltol controls, the trapezoidal
      rule's accumulated phase and growth error: (|λ|h)²·|λ|T/12 ≤
      :data:`PHASE_RTOL` for every oscillatory or growing mode over the time
      T it lasts (shared/README measured 67 % drift over 80 periods at
      ngspice's defaults), and at most 1/:data:`STEPS_PER_HORIZON` of the
      horizon, but at least the horizon over :data:`MAX_STEPS` and over
      :data:`STEP_STATE_BUDGET` / ``nstates`` (default: the number of
      eigenvalues), so that ngspice's memory stays bounded;
    * Gear where the stiffness ratio exceeds :data:`GEAR_STIFFNESS` and no
      mode oscillates with a quality factor above 2 (Gear damps
      oscillations), trapezoidal otherwise.
    """
    fastest, accumulating = _time_scales(eig)
    tmax = horizon.tstop / STEPS_PER_HORIZON
    for rate, duration in accumulating:
        span = min(horizon.tstop, duration)
        tmax = min(tmax, math.sqrt(12 * PHASE_RTOL / (rate**3 * span)))
    states = nstates if nstates is not None else len(eig.modes) if eig is not None else 0
    tmax = max(tmax, horizon.tstop / min(MAX_STEPS, STEP_STATE_BUDGET / max(states, 1)))
    lightly_damped = any(
        m.value.imag and abs(m.value.imag) > 4 * abs(m.value.real) for m in (eig.modes if eig else ())
    )
    stiff = eig is not None and eig.stiffness_ratio is not None and eig.stiffness_ratio > GEAR_STIFFNESS
    step = min(horizon.tstep, fastest / 1000, tmax)
    return SpiceSettings(
        tstep=step,
        tstop=horizon.tstop,
        tmax=tmax,
        method="gear" if stiff and not lightly_damped else "trap",
        reltol=VALIDATION_RELTOLS[0],
        abstol=1e-15,
        vntol=1e-12,
        waveform_step=horizon.tstep,
    )


def _impulse_notes(model: StateSpaceModel, signals: Any) -> list[str]:
    """Outputs that depend on du/dt of an input that steps at t = 0 hold an impulse there."""
    if not model.has_input_derivative:
        return []
    start = signals(np.array([0.0]))[0]
    notes = []
    for i, name in enumerate(model.outputs):
        stepped = [model.inputs[j] for j in range(model.ninputs) if model.D1[i, j] and start[j] != 0]
        if stepped:
            notes.append(
                f"{name} depends on d/dt of {', '.join(stepped)}, which steps at t = 0: it holds an "
                "impulse there that no sampled waveform represents; ramp the source to compare it"
            )
    return notes


def compare(
    netlist: Netlist,
    model: StateSpaceModel,
    probes: Sequence[Probe],
    horizon: Horizon,
    settings: SpiceSettings,
    rtol: float = DEFAULT_RTOL,
    timeout: float | None = None,
) -> ValidationReport:
    """Run ngspice and the model on the same stimulus and compare every output.

    Parameters
    ----------
    netlist : Netlist
    model : StateSpaceModel
        Compiled with ``probes`` as its outputs, in the same order.
    probes : sequence of Probe
    horizon : Horizon
    settings : SpiceSettings
    rtol : float
        Pass threshold on the max error relative to each waveform's peak.
    timeout : float, optional
        Seconds allowed to ngspice.
    """
    notes: list[str] = []
    signals = input_signals(netlist, horizon.tstep, horizon.tstop)  # refuses too many breakpoints first
    u0 = signals(np.array([0.0]))[0]
    nonlinear_x0 = None
    if netlist.is_nonlinear:  # where the nonlinear circuit starts (its own operating point)
        nonlinear_x0, uic, how = nonlinear_start(netlist, u0)
        settings = replace(settings, uic=uic)
        notes.append(f"start: {how}")
    else:
        initial = transient_start(netlist, model, u0)  # ngspice is told the same
        # At rest with every source 0 at t = 0 the operating point is zero: ngspice starts there with
        # UIC too, without solving for it (a mechanical analog's free mass makes that singular).
        at_rest = (
            not np.any(initial.x0)
            and not np.any(u0)
            and not netlist.initial_conditions
            and all(e.ic is None for e in netlist.elements)  # IC= would count for ngspice under UIC
        )
        settings = replace(settings, uic=initial.uic or at_rest)
        if not at_rest:
            notes.append(f"start: {initial.how}")
    run = run_transient(netlist, probes, settings, timeout)
    for reltol in VALIDATION_RELTOLS:
        if run.ok or reltol <= settings.reltol or run.status in ("timeout", "unusable"):
            continue
        notes.append(f"ngspice failed at reltol={settings.reltol:g} ({run.message}); retried at {reltol:g}")
        settings = replace(settings, reltol=reltol)
        run = run_transient(netlist, probes, settings, timeout)
    if not run.ok:
        return ValidationReport(
            netlist.path,
            horizon,
            settings,
            run,
            0.0,
            (),
            rtol,
            run.time,
            np.zeros((0, len(probes))),
            (*notes, f"ngspice failed: {run.message}"),
        )
    start = time.perf_counter()
    if netlist.is_nonlinear:  # the circuit itself, integrated at ngspice's times (not the linearisation)
        names = [p.name for p in probes]
        span = (horizon.tstep, horizon.tstop)
        ours = run_nonlinear(
            netlist, names, run.time, NONLINEAR_VALIDATE_RTOL, nonlinear_x0, span=span
        ).outputs
        notes.append(
            "nonlinear netlist: netlistdyn's side is its nonlinear transient "
            f"(BDF, rtol {NONLINEAR_VALIDATE_RTOL:g})"
        )
    else:
        if initial.uic:
            notes.extend(_impulse_notes(model, signals))
        shifted = None if initial.uic else around_equilibrium(model, signals, initial.x0)
        if shifted is None:
            foh = propagate_foh(model, signals, run.time, initial.x0)
            ours = foh.outputs
        else:  # from the operating point: its constant plus the response to what moves
            foh = propagate_foh(model, shifted[0], run.time)
            ours = foh.outputs + shifted[1][None, :]
        if not foh.verified:
            notes.append(f"the model's own result is not vouched for: {foh.message}")
    model_seconds = time.perf_counter() - start
    comparisons = []
    peaks = {
        p.name: float(np.max(np.abs(run.outputs[p.name]))) if run.outputs[p.name].size else 0.0
        for p in probes
    }
    for j, probe in enumerate(probes):
        diff = ours[:, j] - run.outputs[probe.name]
        peak = peaks[probe.name]
        max_abs = float(np.max(np.abs(diff))) if diff.size else 0.0
        largest = max((peaks[p.name] for p in probes if p.kind == probe.kind), default=0.0)
        scale, note = error_scale(probe.name, probe.kind, peak, largest, max_abs, settings, rtol)
        if note:
            notes.append(note)
        rms = float(np.sqrt(np.mean(diff**2)))
        comparisons.append(OutputComparison(probe.name, peak, max_abs, max_abs / scale, rms))
    return ValidationReport(
        netlist.path,
        horizon,
        settings,
        run,
        model_seconds,
        tuple(comparisons),
        rtol,
        run.time,
        ours,
        tuple(notes),
    )


def error_scale(
    name: str, kind: str, peak: float, largest: float, max_abs: float, settings: SpiceSettings, rtol: float
) -> tuple[float, str]:
    """What an output's error is divided by, and the note that says why when it is not its peak.

    An output far below the others of its kind (a bridge's balanced difference: zero in theory,
    rounding noise in both simulators) is judged against 1e-9 of the largest. ngspice resolves a
    node voltage only to its vntol and a current to its abstol: an error within that is as good as
    ngspice's own answer, however small the output's peak, and is judged against it (the scale
    becomes tolerance/rtol).

    Parameters
    ----------
    name, kind : str
        The output's name and kind (``v``, ``i``...).
    peak, largest : float
        The output's peak and the largest peak of its kind (output units).
    max_abs : float
        Its largest difference from ngspice (output units).
    settings : SpiceSettings
        ngspice's run (its vntol, V, and abstol, A).
    rtol : float
        The pass threshold.
    """
    scale = max(peak, 1e-9 * largest)
    floor = {"v": settings.vntol or NGSPICE_VNTOL, "i": settings.abstol or NGSPICE_ABSTOL}.get(kind)
    if floor is not None and 0 < max_abs <= floor and max_abs > rtol * scale:
        word = "vntol" if kind == "v" else "abstol"
        return floor / rtol, (
            f"{name}: its difference {max_abs:.2g} is within ngspice's own {word} ({floor:g}): "
            "judged against it"
        )
    if scale == 0:
        return 1.0, f"{name} is identically zero in ngspice: its error is absolute"
    if peak < 1e-9 * largest:
        return scale, (
            f"{name} stays below 1e-9 of the largest output of its kind: its error is measured against "
            f"that floor ({scale:.3g})"
        )
    return scale, ""


def compare_poles(netlist: Netlist, eig: EigenAnalysis, probes: Sequence[Probe]) -> PoleComparison | None:
    """Run ngspice's ``.pz`` for models of up to :data:`PZ_MAX_STATES` states.

    ``.pz`` is accurate on small circuits and unreliable beyond a few
    sections (measured: 18 poles for a 10-state ladder), so it is reported,
    never used to fail a validation.
    """
    values = tuple(m.value for m in eig.modes)
    if not values or len(values) > PZ_MAX_STATES:
        return None
    if not netlist.sources:
        return None
    port = set(netlist.sources[0].nodes)
    candidates = [p.nodes for p in probes if p.kind == "v" and set(p.nodes) != port]
    candidates += [(n, "0") for n in netlist.nodes if n not in port]
    if not candidates:
        return None
    output = candidates[0]
    run = run_polezero(netlist, output)
    poles = tuple(complex(p) for p in run.poles)
    if not run.ok or not poles:
        return PoleComparison(poles, values, math.nan, run.message or "ngspice returned no poles")
    worst = 0.0
    unmatched = list(values)
    for pole in poles:
        nearest = min(unmatched or values, key=lambda lam, pole=pole: abs(pole - lam))
        worst = max(worst, abs(nearest - pole) / max(abs(nearest), 1e-300))
        if nearest in unmatched:
            unmatched.remove(nearest)
    note = ""
    if unmatched:
        note = "not among ngspice's poles: " + ", ".join(f"{lam:.6g}" for lam in unmatched)
    return PoleComparison(poles, values, worst, note)


def _original_frequencies(eig: EigenAnalysis | None) -> list[float]:
    """Three ac frequencies (Hz) around the model's own time scales, off its poles."""
    values = np.array([m.value for m in eig.modes], dtype=complex) if eig is not None else np.zeros(0)
    mags = np.abs(values[np.abs(values) > 0])
    omega = float(np.exp(np.mean(np.log(mags)))) if mags.size else 2 * math.pi * 1e3
    freqs = []
    for factor in (0.31, 1.07, 3.3):
        w = factor * omega
        while values.size and np.abs(values - 1j * w).min() < 1e-3 * w:
            w *= 1.13
        freqs.append(w / (2 * math.pi))
    return freqs


def check_original(
    path: str,
    netlist: Netlist,
    model: StateSpaceModel,
    probes: Sequence[Probe],
    eig: EigenAnalysis | None,
    params: dict[str, float] | None = None,
    timeout: float = 60.0,
) -> OriginalCheck:
    """Compare the model with ngspice's own reading of the user's original file.

    ngspice runs ``op`` and ``ac`` (three frequencies around the model's time
    scales) on the file as written, every independent source given its own DC
    value and AC magnitude with ``alter``; the model's transfer matrix
    C(sI − A)⁻¹B + D + sD1 at s = 0 and s = j2πf, applied to the same source
    values, must give the same voltages and currents to :data:`ORIGINAL_RTOL`.
    A netlist misread by netlistdyn's parser (a value, a connection, a global
    node) fails here even though the transient comparison, which feeds ngspice
    netlistdyn's own understanding, passes.

    Parameters
    ----------
    path : str
        The netlist file as the user wrote it.
    netlist : Netlist
        netlistdyn's reading of it (its sources name the model's inputs).
    model : StateSpaceModel
        Compiled with ``probes`` as outputs.
    probes : sequence of Probe
    eig : EigenAnalysis or None
        The model's eigenvalues (to place the frequencies).
    params : dict, optional
        ``--param`` overrides (passed to ngspice with ``alterparam``).
    timeout : float
        Seconds allowed to ngspice.
    """
    if any(e.keyword for e in netlist.elements):
        return OriginalCheck(False, message="original file not run by ngspice: it has mechanical elements")
    inputs = list(model.inputs)
    if not inputs:
        return OriginalCheck(False, message="original file not run by ngspice: no independent source")
    # A behavioural source's constant (B1 1 0 v = {10*10}) is an input of the model that ngspice
    # cannot alter: it keeps its own value at the operating point and 0 in .ac.
    by_name = {e.name: e for e in netlist.sources}
    fixed = [by_name[n].expression is not None if n in by_name else False for n in inputs]
    nonlinear = netlist.is_nonlinear
    dc = np.array(
        [
            by_name[n].value if (nonlinear or fix) and n in by_name else 1.0 + 0.37 * k
            for k, (n, fix) in enumerate(zip(inputs, fixed, strict=True))
        ]
    )
    ac = np.array([0.0 if fix else 0.5 + 0.29 * k for k, fix in enumerate(fixed)])
    # A nonlinear circuit's operating point depends on its sources' values: they keep the file's
    # own (a SIN without DC is its value at t = 0: the reading compared here), only AC is set.
    alter = [
        (ngspice_source_name(n), None if nonlinear else float(dc[k]), float(ac[k]))
        for k, n in enumerate(inputs)
        if not fixed[k]
    ]
    freqs = _original_frequencies(eig)
    # A nonlinear operating point is Newton's, converged to ngspice's tolerances (and its diode
    # breakdown knee to its reltol): ngspice runs at reltol 1e-9 for this check.
    tight = f"reltol=1e-9 abstol={NGSPICE_TIGHT_ABSTOL:g} vntol={NGSPICE_TIGHT_VNTOL:g}" if nonlinear else ""
    run = run_original(path, alter, freqs, params, timeout, separate=nonlinear, options=tight)
    if not run.ok:
        return OriginalCheck(False, message=f"ngspice could not run the original file: {run.message}")
    point = None
    if nonlinear:
        point = operating_point(netlist)

    def vector(probe: Probe, values: dict[str, Any]) -> complex | None:
        if probe.kind == "v":
            total = 0j
            for node, sign in zip(probe.nodes, (1, -1), strict=True):
                if node != "0":
                    if f"v({node})" not in values:
                        return None
                    total += sign * values[f"v({node})"]
            return total
        if probe.kind == "i":
            return values.get(f"i({ngspice_source_name(probe.element)})")
        return None

    worst, compared = 0.0, 0
    cases: list[tuple[complex, np.ndarray, dict[str, Any]]] = [
        (2j * math.pi * f, ac, run.ac[f]) for f in run.ac
    ]
    if run.op:
        cases.append((0j, dc, run.op))
    for s, u, values in cases:
        try:
            if point is not None and s == 0:  # the nonlinear circuit's own operating point
                ours = np.array([_at_point(probe, point) for probe in probes], dtype=complex)
            else:
                ours = model.transfer_function(s) @ u
        except np.linalg.LinAlgError:
            continue  # no DC solution of the model (ngspice's op then has none either)
        pairs: dict[str, list[tuple[complex, complex]]] = {"v": [], "i": []}
        for j, probe in enumerate(probes):
            theirs = vector(probe, values)
            if theirs is not None and probe.kind in pairs and not cmath.isnan(complex(ours[j])):
                pairs[probe.kind].append((complex(ours[j]), complex(theirs)))
        for kind, group in pairs.items():
            scale = max((abs(b) for _, b in group), default=0.0)
            # a nonlinear circuit's operating point is ngspice's Newton, converged to its vntol (V)
            # and abstol (A): a difference within them is agreement (a blocked rectifier at 0 V:
            # 1.5e-22 V in ngspice)
            floor = (NGSPICE_TIGHT_VNTOL if kind == "v" else NGSPICE_TIGHT_ABSTOL) if nonlinear else 0.0
            for a, b in group:
                compared += 1
                if scale > 0 and abs(a - b) > floor:
                    worst = max(worst, abs(a - b) / scale)
    if compared == 0:
        return OriginalCheck(False, message="original file: ngspice printed none of the outputs")
    verdict = "agrees" if worst <= ORIGINAL_RTOL else "DISAGREES (netlistdyn misreads the file?)"
    where = ", ".join(f"{f:.4g}" for f in run.ac)
    message = (
        f"ngspice on the original file (op and ac at {where} Hz): {compared} values, "
        f"worst relative difference {worst:.2g}: {verdict}"
    )
    return OriginalCheck(True, worst, compared, message)


def _at_point(probe: Probe, point: Any) -> complex:
    """A v or i probe's value at a nonlinear operating point (NaN for another kind: not compared)."""
    if probe.kind == "v":
        return complex(
            sum(sign * point.voltages.get(n, 0.0) for n, sign in zip(probe.nodes, (1, -1), strict=True))
        )
    if probe.kind == "i" and probe.element is not None and probe.element.lower() in point.currents:
        return complex(point.currents[probe.element.lower()])
    return complex(math.nan)


def with_original_check(
    report: ValidationReport,
    path: str,
    netlist: Netlist,
    model: StateSpaceModel,
    probes: Sequence[Probe],
    eig: EigenAnalysis | None,
    params: dict[str, float] | None = None,
    timeout: float = 60.0,
) -> ValidationReport:
    """``report`` with :func:`check_original`'s verdict attached (and its line in the notes)."""
    original = check_original(path, netlist, model, probes, eig, params, timeout)
    return replace(report, original=original, notes=(*report.notes, original.message))
