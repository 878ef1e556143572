"""Time integration of a compiled model: one function per method, one result type.

``exact``
    Dense first-order hold (:mod:`netlistdyn.simulate`): the matrix
    exponential of the augmented matrix per distinct step; exact for
    piecewise-linear inputs. For models up to :data:`EXACT_LIMIT` states.
``rational``
    For large sparse models. The input, linear on each interval between
    breakpoints, is carried by a nilpotent augmentation (z = [x; u; u']),
    so the only approximation is that of e^{hA}: the [11/12] Padé
    approximant (the stability function of 12-stage Radau IIA; order 23,
    L-stable), applied in product form — one real factor
    1 + 2·Re(α (hA − pI)⁻¹) per conjugate pole pair, each with modulus
    near 1 on the imaginary axis, so no cancellation — with one complex
    sparse LU per pole and step length. Step lengths are the interval
    lengths divided by powers of two (factorisations are reused), chosen by
    step doubling: a step of 2h is compared with two steps of h, whose error
    is about their difference / (2²³ − 1).
``krylov``
    scipy's ``expm_multiply`` (truncated Taylor with scaling) on the same
    augmented system: one call per run of equal intervals over which the
    input is one linear piece, else interval by interval.
``euler``
    Forward Euler with a fixed step h (``step``), x_{k+1} = x_k + h (A x_k +
    B u(t_k)), the method the lecture notes animate with: for teaching, not
    accuracy. The output times must be multiples of h; the result carries its
    error against the default method at the same times (``stats``,
    ``message``).
``RK45``, ``DOP853``, ``Radau``, ``BDF``, ``LSODA``
    scipy's ``solve_ivp`` with the constant Jacobian (sparse for large
    models), ``rtol``/``atol`` as given, evaluated at the output times.
    Explicit methods on stiff models are refused with the reason.

Every method reports a :class:`SimResult` with a status instead of raising
when it fails, diverges or is refused.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import cache

import mpmath as mp
import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray
from scipy.integrate import solve_ivp

from netlistdyn.analysis.eigen import largest_eigenvalues
from netlistdyn.simulation._pade_table import DIAGONAL_12_12, SUBDIAGONAL_11_12
from netlistdyn.simulation.foh import InputSignals, propagate_foh, refine_grid
from netlistdyn.statespace.model import StateSpaceModel

#: Largest model the dense ``exact`` method accepts (and ``auto`` picks).
EXACT_LIMIT = 400
IVP_METHODS = ("RK45", "DOP853", "Radau", "BDF", "LSODA")
EXPLICIT = ("RK45", "DOP853")
METHODS = ("auto", "exact", "rational", "krylov", "euler", *IVP_METHODS)
#: An explicit method is refused when it would need more steps than this for stability.
EXPLICIT_STEP_LIMIT = 2_000_000
#: Order of the Padé denominator used by ``rational``.
PADE_ORDER = 12


@dataclass(frozen=True)
class SimResult:
    """A simulated response.

    Attributes
    ----------
    time : numpy.ndarray
        Output times (s).
    outputs : numpy.ndarray
        ``(len(time), noutputs)``.
    method : str
        Method actually used.
    setting : str
        Its accuracy setting, for reports (``rtol=1e-10``).
    seconds : float
        Wall time of the integration (s).
    status : str
        ``ok``; ``unverified`` (numbers returned, but their error estimate
        exceeds the tolerance: the message says by how much); ``refused``,
        ``diverged``, ``failed`` or ``timeout`` (no usable numbers).
    message : str
        Why, when not ok; notes otherwise.
    stats : dict
        Method-specific counts (steps, factorisations, rejected steps).
    """

    time: NDArray[np.float64]
    outputs: NDArray[np.float64]
    method: str
    setting: str
    seconds: float
    status: str = "ok"
    message: str = ""
    stats: dict[str, float] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """True when the run produced a trustworthy answer."""
        return self.status == "ok"


def spectral_radius(model: StateSpaceModel) -> float:
    """max |λ(A)| (1/s): dense for small models, ARPACK for large ones."""
    n = model.nstates
    if n == 0:
        return 0.0
    if n <= EXACT_LIMIT:
        return float(np.max(np.abs(np.linalg.eigvals(model.A))))
    values = largest_eigenvalues(model.A_sparse, 1, 1e-3)
    if len(values):
        return float(np.max(np.abs(values)))
    return float(sp.linalg.norm(model.A_sparse, 1))  # a bound when ARPACK gives nothing


def choose_method(model: StateSpaceModel) -> str:
    """The default method for a model of this size."""
    return "exact" if model.nstates <= EXACT_LIMIT else "rational"


def _finish(
    times: NDArray[np.float64],
    y: NDArray[np.float64],
    method: str,
    setting: str,
    start: float,
    stats: dict[str, float] | None = None,
    message: str = "",
) -> SimResult:
    seconds = time.perf_counter() - start
    if not np.all(np.isfinite(y)):
        return SimResult(
            times, y, method, setting, seconds, "diverged", "the solution became non-finite", stats or {}
        )
    return SimResult(times, y, method, setting, seconds, "ok", message, stats or {})


def run(
    model: StateSpaceModel,
    signals: InputSignals,
    times: NDArray[np.float64],
    method: str = "auto",
    rtol: float = 1e-10,
    atol: float | None = None,
    x0: NDArray[np.float64] | None = None,
    force: bool = False,
    progress: Callable[[float], None] | None = None,
    step: float | None = None,
) -> SimResult:
    """Simulate ``model`` driven by ``signals`` and return its outputs at ``times``.

    Parameters
    ----------
    model : StateSpaceModel
    signals : InputSignals
    times : array of float
        Sorted output times (s), starting at 0.
    method : str
        One of :data:`METHODS`.
    rtol, atol : float
        Accuracy requested (``rational``, ``solve_ivp`` methods); atol
        defaults to rtol times the input scale.
    x0 : array, optional
        Initial state (default zero).
    force : bool
        Run explicit methods on stiff models anyway.
    progress : callable, optional
        Called with the fraction done.
    step : float, optional
        The fixed step of ``euler`` (s).
    """
    times = np.asarray(times, dtype=float)
    if method == "auto":
        method = choose_method(model)
    start = time.perf_counter()
    if method == "exact":
        if model.nstates > 4 * EXACT_LIMIT and not force:
            return SimResult(
                times,
                np.zeros((times.size, model.noutputs)),
                method,
                "",
                0.0,
                "refused",
                f"exact (dense) method refused for {model.nstates} states: use rational",
            )
        foh = propagate_foh(model, signals, times, x0, progress, rtol)
        stats = {"error_estimate": foh.error}
        result = _finish(times, foh.outputs, method, f"{foh.path}, rtol={rtol:g}", start, stats, foh.message)
        if result.ok and not foh.verified:
            return replace(result, status="unverified")
        return result
    if method == "rational":
        return _rational(model, signals, times, rtol, x0, progress, start)
    if method == "krylov":
        return _krylov(model, signals, times, x0, start)
    if method == "euler":
        return _euler(model, signals, times, step, x0, start)
    if method in IVP_METHODS:
        return _ivp(model, signals, times, method, rtol, atol, x0, force)
    raise ValueError(f"unknown method {method!r}; choose from {', '.join(METHODS)}")


# --- the rational (Padé product form) stepper ------------------------------------------


def pade_factors(diagonal: bool = False) -> tuple[tuple[complex, complex, float], ...]:
    """The stored factors of the [11/12] (or, with ``diagonal``, [12/12]) Padé approximant."""
    return DIAGONAL_12_12 if diagonal else SUBDIAGONAL_11_12


@cache
def pade_factors_exact(
    order: int = PADE_ORDER, diagonal: bool = False
) -> tuple[tuple[complex, complex, float], ...]:
    """Factors (p, α, c) with R(z) = Π (c + α/(z − p) + ᾱ/(z − p̄)), the Padé approximant of e^z.

    ``[order−1/order]`` (L-stable) by default, ``[order/order]`` (modulus 1
    on the imaginary axis) with ``diagonal``. Poles, zeros and residues are
    computed with mpmath at 60 digits; each pole is paired with the zero
    nearest to its mirror image −p̄, so every factor is close to 1 in
    modulus on the imaginary axis.
    """
    with mp.workdps(60):
        num_deg, den_deg = (order, order) if diagonal else (order - 1, order)

        def coefficient(j: int, deg: int) -> mp.mpf:
            return (mp.factorial(num_deg + den_deg - j) * mp.factorial(deg)) / (
                mp.factorial(num_deg + den_deg) * mp.factorial(j) * mp.factorial(deg - j)
            )

        P = [coefficient(j, num_deg) for j in range(num_deg + 1)]
        Q = [coefficient(j, den_deg) * (-1) ** j for j in range(den_deg + 1)]
        poles = [p for p in mp.polyroots(Q[::-1], maxsteps=400, extraprec=400) if mp.im(p) > 0]
        zeros = list(mp.polyroots(P[::-1], maxsteps=400, extraprec=400))
        lead = P[-1] / Q[-1]
        tiny = mp.mpf(10) ** -30
        real_zeros = [z for z in zeros if abs(mp.im(z)) < tiny]
        upper = [z for z in zeros if mp.im(z) >= tiny]
        factors: list[tuple[complex, complex, float]] = []
        used: set[int] = set()
        for p in sorted(poles, key=lambda q: -mp.im(q)):
            if len(used) < len(upper):
                free = (j for j in range(len(upper)) if j not in used)
                j = min(free, key=lambda j: abs(upper[j] + mp.conj(p)))
                used.add(j)
                z = upper[j]
                alpha = (p - z) * (p - mp.conj(z)) / (p - mp.conj(p))
                factors.append((complex(p), complex(alpha), 1.0))
            else:
                (z_real,) = real_zeros
                beta = lead * (p - z_real) / (p - mp.conj(p))
                factors.append((complex(p), complex(beta), 0.0))
                lead = mp.mpf(1)
        if lead != 1:  # diagonal approximants of even order have leading coefficient 1
            factors[0] = (factors[0][0], complex(factors[0][1] * lead), float(lead))
    return tuple(factors)


class _PadeStep:
    """R(hÃ) applied to z = [x; u; s] for one step length h (LUs computed once)."""

    def __init__(self, A: sp.csc_matrix, B: sp.csr_array, h: float, diagonal: bool = False) -> None:
        n = A.shape[0]
        self.h = h
        self.B = B
        eye = sp.identity(n, format="csc", dtype=complex)
        hA = (A * h).astype(complex)
        self.factors = [
            (spla.splu(sp.csc_matrix(hA - p * eye)), p, a, c) for p, a, c in pade_factors(diagonal=diagonal)
        ]

    def __call__(self, x: np.ndarray, u: np.ndarray, s: np.ndarray) -> np.ndarray:
        h = self.h
        for lu, p, alpha, c in self.factors:
            # (hÃ − pI)⁻¹ [x; u; s]: the input rows are upper triangular, then one sparse solve.
            sb = -s / p
            ua = (h * sb - u) / p
            xs = lu.solve((x - h * (self.B @ ua)).astype(complex))
            x = c * x + 2.0 * np.real(alpha * xs)
            u_new = c * u + 2.0 * np.real(alpha * ua)
            s = c * s + 2.0 * np.real(alpha * sb)
            u = u_new
        return x


#: Steps (accepted and rejected) after which ``rational`` stops a model with a growing mode,
#: status ``failed``, unless the input breakpoints call for more (20 per breakpoint).
RATIONAL_STEP_BUDGET = 100_000


def _rational(
    model: StateSpaceModel,
    signals: InputSignals,
    times: NDArray[np.float64],
    rtol: float,
    x0: NDArray[np.float64] | None,
    progress: Callable[[float], None] | None,
    start: float,
    states_out: list[NDArray[np.float64]] | None = None,
) -> SimResult:
    """Adaptive Padé stepping; see the module docstring.

    ``states_out``, when given, receives the states at ``times``.

    Error control compares the L-stable [11/12] step with the diagonal
    [12/12] step from the same state: both are accurate to ~1e-14 wherever
    |hλ| ≲ 4.6, and they differ at O(1) on any mode outside that region
    (the first damps it, the second keeps its modulus), so their difference
    measures the state's content in modes the step does not resolve —
    whether fast and lightly damped (both families fail there alike under
    step doubling) or stiff. The difference is measured against the largest
    state seen (within rtol) and, through C, against each output's own peak
    so far: an output far below the states, a capacitor charge beside an
    inductor current, is judged on its own scale, down to its rounding level
    (:data:`RATIONAL_ROUNDING` of its peak, :data:`OUTPUT_ROUNDING` of the
    magnitudes |C||x| it is summed from).

    For the outputs, rtol bounds the global error, not each step's: the model
    has no growing mode, so a step's error is carried forward undamped at
    most, and the errors add up. Each step may use its share ``rtol·h/T`` of
    the budget (T the horizon). Because the approximant's error grows like
    h²⁴, this costs few extra steps: a budget 1000 times tighter shortens
    them by 1000^(1/24) ≈ 1.3. The result's ``error_estimate`` is the sum of
    the outputs' accepted differences above their rounding level plus that
    level times √(steps) (rounding errors are independent from step to step);
    above rtol the status is ``unverified``. It does not count errors made in
    states the outputs do not see yet (measured below the error by 3.5x on a
    lightly damped line), so it is not a bound.
    """
    n = model.nstates
    d = balance_sparse(model.A_sparse) if n else np.ones(0)
    A = sp.csc_matrix(sp.diags_array(1.0 / d) @ model.A_sparse @ sp.diags_array(d))
    B = sp.csr_array(sp.diags_array(1.0 / d) @ model.B_sparse)
    events = refine_grid(times, signals)
    u_events = signals(events)
    u_left = signals.left(events)  # differs at a jump (a PWL time written twice)
    breakpoint_set = set(signals.breakpoints.tolist())
    x = np.zeros(n) if x0 is None else np.asarray(x0, dtype=float) / d  # balanced coordinates
    cache: dict[tuple[float, bool], _PadeStep] = {}
    stats: dict[str, float] = {"steps": 0, "rejected": 0, "factorisations": 0}  # counts stay ints

    def stepper(h: float, diagonal: bool) -> _PadeStep:
        key = (float(f"{h:.14g}"), diagonal)
        if key not in cache:
            cache[key] = _PadeStep(A, B, h, diagonal)
            stats["factorisations"] += len(pade_factors(diagonal=diagonal))
        return cache[key]

    scale = max(float(np.max(np.abs(x))) if n else 0.0, float(np.max(np.abs(u_events))) * 1e-12, 1e-300)
    # Outputs in balanced coordinates: y = Cb x + D u, and their peaks so far.
    # Sparse: outputs mostly read a state or two (a 1000 x 2000 dense C took a third of a run).
    Cb = sp.csr_array(np.asarray(model.C, dtype=float) * d[None, :] if n else np.zeros((model.noutputs, 0)))
    abs_cb = abs(Cb)
    has_outputs = model.noutputs > 0 and n > 0
    y_peak = np.abs(Cb @ x + model.D @ u_events[0]) if model.noutputs else np.zeros(0)
    # Each output's eventual scale: its DC value at the input's levels (0 where unknown: then
    # its running peak alone). The step check judges an output against its running peak floored
    # at OUTPUT_SCALE_FLOOR of this, not against the running peak of an output that is still ≈ 0
    # (the far end of a line before the wave arrives: there the approximant's relative error is
    # O(1) at every step length, and halving never ended). (What an output reads of the states'
    # scale is no floor: an output far below the states, 1.6e-9 V beside 3.7e-4 V, was then
    # judged against a scale 1e5 times its own.)
    dc_scale = _dc_output_scale(A, B, Cb, np.asarray(model.D, dtype=float), u_events)
    # ‖A‖₁ ≥ |λ|max: at EXACT_STEP / ‖A‖₁ the approximant is exact to rounding.
    norm_a = float(spla.norm(A, 1)) if n else 0.0
    abs_a = abs(sp.csr_array(A))
    a_rows = np.asarray(abs_a.sum(axis=1)).ravel()
    horizon = float(events[-1] - events[0]) if events.size > 1 else 0.0
    abs_estimate = np.zeros(model.noutputs)  # accepted output differences above rounding (units)
    abs_noise = np.zeros(model.noutputs)  # largest rounding level of each output (its units)

    def measure(
        diff: np.ndarray, new: np.ndarray, h: float
    ) -> tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """A difference of two steps relative to the largest state, and relative to each output's
        scale with each output's rounding level (at least RATIONAL_ROUNDING of its scale, and
        OUTPUT_ROUNDING of the magnitudes |C||x| it is summed from); then the outputs' differences
        above that level and the level, in the outputs' units."""
        state_error = float(np.max(np.abs(diff))) / scale
        if not has_outputs:
            empty = np.zeros(0)
            return state_error, empty, empty, empty, empty
        den = np.maximum(np.maximum(y_peak, OUTPUT_SCALE_FLOOR * dc_scale), np.finfo(float).tiny)
        # A state's rounding is relative to what the step couples into it: its own magnitude and,
        # weighted by min(1, h·Σⱼ|aᵢⱼ|), the average magnitude of the states in its row of A.
        magnitude = np.abs(new)
        coupled = np.minimum(1.0, h * a_rows) * (abs_a @ magnitude) / np.where(a_rows > 0, a_rows, 1.0)
        rounding = OUTPUT_ROUNDING * (abs_cb @ (magnitude + coupled))
        noise_abs = np.maximum(rounding, RATIONAL_ROUNDING * den)
        error_abs = np.abs(Cb @ diff)
        above = np.where(error_abs > noise_abs, error_abs, 0.0)
        return state_error, error_abs / den, noise_abs / den, above, rounding

    states = np.empty((events.size, n))
    states[0] = x
    level = 0
    depth_limit = 48
    # Only for a model with a growing mode: a growing fast mode (140 MHz, growing at 1.3e5 1/s
    # over 0.1 s) otherwise steps for tens of minutes before the state overflows; a stable model
    # is never stopped (a lightly damped GHz mode over a millisecond needs millions of steps).
    step_budget = max(RATIONAL_STEP_BUDGET, 20 * events.size)
    # Between input breakpoints nothing re-excites unresolved modes, so in a model with
    # no growing mode their content only decays: the check can be skipped for a few
    # steps of an unchanged length once it has passed with a wide margin.
    growing = _has_growing_mode(model)
    # The trust is keyed to the step length itself: a level is relative to its interval, and a
    # micro-interval (a PWL corner within rounding of an output time) that passed at level 0
    # says nothing about the full interval after it.
    no_outputs = np.zeros(model.noutputs)
    checked_h, unchecked = math.nan, 0
    last: tuple[float, float, np.ndarray, np.ndarray, str, tuple[float, np.ndarray]] = (
        math.inf,
        math.inf,
        no_outputs,
        no_outputs,
        "",
        (0.0, no_outputs),
    )
    stats["checks"] = 0
    for k in range(1, events.size):
        length = events[k] - events[k - 1]
        if length <= 0 or n == 0:
            states[k] = x
            continue
        u0 = u_events[k - 1]
        slope = (u_left[k] - u0) / length
        done = 0.0  # fraction of the interval covered, in units of length
        while done < 1.0 - 1e-15:
            h = length / 2**level
            if done + 1.0 / 2**level > 1.0 + 1e-15:  # keep steps on the power-of-two grid
                level += 1
                continue
            u_here = u0 + slope * (done * length)
            damped = stepper(h, False)(x, u_here, slope)
            scale = max(scale, float(np.max(np.abs(damped))))
            if has_outputs:
                y_peak = np.maximum(y_peak, np.abs(Cb @ damped + model.D @ (u_here + slope * h)))
            tol = rtol * h / horizon if horizon > 0 else rtol
            trusted = not growing and h == checked_h and unchecked < 16 and last[0] < 0.1
            if trusted:
                unchecked += 1
            else:
                kept = stepper(h, True)(x, u_here, slope)
                state_error, errors, noise, above, rounding = measure(damped - kept, damped, h)
                # Passed when the state's difference is within rtol of the largest state and every
                # output's within its share of rtol or at its rounding level; an output's
                # difference above its rounding level counts towards the estimate.
                state_tol = max(rtol, RATIONAL_ROUNDING)
                output_ratio = errors / np.maximum(tol, noise)
                need = (state_error / RATIONAL_ROUNDING, errors / np.maximum(noise, 1e-300))
                worst = ""
                if state_error / state_tol >= float(np.max(output_ratio, initial=0.0)):
                    worst = f"the states' difference ({state_error:.2g} of the largest state)"
                elif output_ratio.size:
                    j = int(np.argmax(output_ratio))
                    worst = f"{model.outputs[j]}'s difference ({errors[j]:.2g} of its scale)"
                last = (
                    max(state_error / state_tol, float(np.max(output_ratio, initial=0))),
                    max(
                        state_error / (state_tol * 1e-3),
                        float(np.max(errors / np.maximum(tol * 1e-3, noise * 0.25), initial=0)),
                    ),
                    above,
                    rounding,
                    worst,
                    need,
                )
                checked_h, unchecked = h, 0
                stats["checks"] += 1
            ratio, comfort, contribution, rounding_here, worst, (state_need, output_need) = last
            at = events[k - 1] + done * length
            if growing and stats["steps"] + stats["rejected"] > step_budget:
                return SimResult(
                    times,
                    np.full((times.size, model.C.shape[0]), np.nan),
                    "rational",
                    f"rtol={rtol:g}",
                    time.perf_counter() - start,
                    "failed",
                    f"stopped after {step_budget:,} steps at t = {at:.6g} s "
                    f"(step {h:.3g} s)" + ": the model has a growing mode, try --method exact",
                    stats,
                )
            # At h·‖A‖ ≤ EXACT_STEP both approximants are e^{hA} far below rounding (the [11/12]
            # error is ~1e-30·‖hA‖²⁴): a difference left there is rounding. Halving stops there.
            at_limit = level >= depth_limit or h * norm_a <= EXACT_STEP
            if ratio > 1.0 and at_limit:
                output_excess = float(np.max(output_need, initial=0.0))
                if max(state_need, output_excess) > ROUNDING_GAIN_LIMIT:
                    return SimResult(
                        times,
                        np.full((times.size, model.C.shape[0]), np.nan),
                        "rational",
                        f"rtol={rtol:g}",
                        time.perf_counter() - start,
                        "failed",
                        f"stopped at t = {at:.6g} s: at a step of {h:.3g} s (h·‖A‖ = {h * norm_a:.2g}, where "
                        f"both approximants are exact to rounding) the step check still fails on {worst}, "
                        f"{max(state_need, output_excess):.2g} times the rounding level",
                        stats,
                    )
                # Rounding: the step is taken, its difference counted as this model's rounding
                # level (random walk in the estimate), and the next step tried twice as long.
                abs_noise = np.maximum(abs_noise, contribution + rounding_here)
                contribution = no_outputs
                ratio, comfort = 0.0, 0.0
                stats["rounding_steps"] = stats.get("rounding_steps", 0) + 1
                if math.isnan(stats.get("rounding_from", math.nan)):
                    stats["rounding_from"] = at
            if ratio > 1.0:
                level += 1
                stats["rejected"] += 1
                continue
            x = damped
            abs_estimate += contribution
            abs_noise = np.maximum(abs_noise, rounding_here)
            done += 1.0 / 2**level
            stats["steps"] += 1
            # Coarsen when comfortably accurate (or at the rounding level, where the difference
            # says no more) and aligned with the coarser grid.
            coarse = done * 2 ** (level - 1)
            if comfort < 1.0 and level > 0 and abs(coarse - round(coarse)) < 1e-9:
                level -= 1
        if not np.all(np.isfinite(x)):
            break
        states[k] = x
        if k < events.size - 1 and events[k] in breakpoint_set:
            checked_h = math.nan  # a kink in the input: check the next step
        if progress is not None and k % 50 == 0:
            progress(k / events.size)
    index = np.searchsorted(events, times)
    xs = states[index] * d  # back to the model's coordinates
    us = u_events[index]
    y = xs @ model.C.T + us @ model.D.T
    if model.has_input_derivative:
        y = y + signals.derivative(times) @ model.D1.T
    if states_out is not None:
        states_out.append(xs)
    # Relative to each output's own peak over the run (the check used a floor while it was still
    # small): truncation errors add up; rounding errors, independent from step to step, like a
    # random walk.
    positive = y_peak > 0
    peak = np.where(positive, y_peak, 1.0)
    noise_rel = np.where(positive, np.maximum(abs_noise / peak, RATIONAL_ROUNDING), RATIONAL_ROUNDING)
    noise_rel = np.where(positive | (abs_noise == 0), noise_rel, np.inf)
    per_output = np.where(positive, abs_estimate / peak, np.where(abs_estimate > 0, np.inf, 0.0))
    per_output = per_output + noise_rel * math.sqrt(stats["steps"])
    estimate = float(np.max(per_output, initial=RATIONAL_ROUNDING * math.sqrt(stats["steps"])))
    noise_level = float(np.max(noise_rel, initial=RATIONAL_ROUNDING))
    stats["error_estimate"] = estimate
    result = _finish(times, y, "rational", f"rtol={rtol:g}", start, stats)
    if result.ok and estimate > rtol:
        message = (
            f"the sum of the step checks, {estimate:.2g} of the outputs' peaks, exceeds rtol {rtol:g} "
            f"(rounding alone is {noise_level:.1g} per step, relative to the smallest output's peak): "
            "the result cannot be vouched for at this tolerance"
        )
        return replace(result, status="unverified", message=message)
    return result


#: The step check judges an output against at least this fraction of its eventual scale (its DC
#: value at the input's levels). An output reaching at
#: least this fraction of that scale over the run has its error sum within rtol of its peak.
OUTPUT_SCALE_FLOOR = 1e-3
#: Steps with h·‖A‖₁ at or below this are exact far below rounding: the step is not halved below
#: it; a check failing there is rounding, counted as such, unless it exceeds ROUNDING_GAIN_LIMIT
#: times the assumed rounding level, which stops the run with a message.
EXACT_STEP = 0.5
ROUNDING_GAIN_LIMIT = 1e4
#: Largest condition number (1-norm estimate) of A for which its DC solution sets output scales.
DC_CONDITION_LIMIT = 1e12
#: Most inputs for which the DC gain is formed (one sparse solve per input).
DC_INPUT_LIMIT = 256


def _dc_output_scale(
    A: sp.csc_matrix,
    B: sp.csr_array,
    Cb: sp.csr_array,
    D: NDArray[np.float64],
    u_events: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Each output's largest |DC value| over the input's values at the events (0 where unknown).

    The DC value of y for a constant input u is (D − C A⁻¹ B) u: one real sparse LU of A. A
    singular or ill-conditioned A (a floating capacitor: an eigenvalue 0), too many inputs, or a
    DC value within rounding of zero (cancelling terms) leave the scale unknown (0).
    """
    p = Cb.shape[0]
    n, m = A.shape[0], B.shape[1]
    if n == 0 or p == 0 or m == 0 or m > DC_INPUT_LIMIT:
        return np.zeros(p)
    try:
        lu = spla.splu(sp.csc_matrix(A))
    except RuntimeError:
        return np.zeros(p)
    inverse_norm = spla.onenormest(spla.LinearOperator(A.shape, lu.solve, rmatvec=lambda v: lu.solve(v, "T")))
    if not inverse_norm * float(spla.norm(A, 1)) < DC_CONDITION_LIMIT:
        return np.zeros(p)
    x_dc = -lu.solve(np.asarray(sp.csr_array(B).toarray(), dtype=float))
    gain = Cb @ x_dc + D  # (outputs, inputs)
    size = abs(Cb) @ np.abs(x_dc) + np.abs(D)
    if not np.all(np.isfinite(gain)):
        return np.zeros(p)
    values = np.abs(u_events @ gain.T)  # (events, outputs)
    magnitudes = np.abs(u_events) @ size.T
    values = np.where(values > 1e-8 * magnitudes, values, 0.0)
    return np.max(values, axis=0, initial=0.0)


#: Below this (relative to the largest state), the two Padé steps differ by rounding.
RATIONAL_ROUNDING = 1e-14
#: The same for an output, relative to the magnitudes |C||x| it is summed from (12 solves).
OUTPUT_ROUNDING = 1e-13


#: Up to this many states the balancing is LAPACK's (dense); above, one sparse sweep.
DENSE_BALANCE_LIMIT = 3000


def balance_sparse(A: sp.sparray) -> np.ndarray:
    """Diagonal scaling d (powers of two) making diag(1/d)·A·diag(d) balanced.

    States mix units that differ by many decades (charges of microfarad
    capacitors next to inductor currents); in balanced coordinates a
    normwise-small rounding error stays small in every state, and so in the
    outputs that read a charge through 1/C. LAPACK's balancing (gebal,
    without permutation) up to :data:`DENSE_BALANCE_LIMIT` states; above, one
    sweep of the Osborne update, d = 2^round(log2 √(column/row norms)).
    """
    n = A.shape[0]
    if n == 0:
        return np.ones(0)
    if n <= DENSE_BALANCE_LIMIT:
        _, (scale, _) = sla.matrix_balance(sp.csr_array(A).toarray(), permute=False, separate=True)
        return np.asarray(scale, dtype=float)
    absA = abs(sp.csr_array(A))
    absA = absA - sp.diags_array(absA.diagonal())
    rows = np.asarray(absA.sum(axis=1)).ravel()
    cols = np.asarray(absA.sum(axis=0)).ravel()
    d = np.ones(n)
    ok = (rows > 0) & (cols > 0)
    d[ok] = np.exp2(np.round(np.log2(np.sqrt(cols[ok] / rows[ok]))))
    return d


def _has_growing_mode(model: StateSpaceModel) -> bool:
    """False when no eigenvalue can have Re λ > 0: a passive network, or computed for small models."""
    if model.nstates == 0 or model.info.passive:
        return False
    if model.nstates <= EXACT_LIMIT:
        return bool(np.max(np.linalg.eigvals(model.A).real) > 0)
    return True


# --- Krylov (scipy expm_multiply) -----------------------------------------------------


def _krylov(
    model: StateSpaceModel,
    signals: InputSignals,
    times: NDArray[np.float64],
    x0: NDArray[np.float64] | None,
    start: float,
) -> SimResult:
    n, m = model.nstates, model.ninputs
    events = refine_grid(times, signals)
    u_events = signals(events)
    u_left = signals.left(events)
    # Augmented generator for z = [x; u; s]: x' = Ax + Bu, u' = s, s' = 0.
    top = sp.hstack([model.A_sparse, model.B_sparse, sp.csr_array((n, m))])
    mid = sp.hstack([sp.csr_array((m, n + m)), sp.identity(m, format="csr")])
    bottom = sp.csr_array((m, n + 2 * m))
    big = sp.csr_array(sp.vstack([top, mid, bottom]))
    x = np.zeros(n) if x0 is None else np.asarray(x0, dtype=float).copy()
    states = np.empty((events.size, n))
    states[0] = x
    lengths = np.diff(events)
    slopes = (u_left[1:] - u_events[:-1]) / np.where(lengths > 0, lengths, 1.0)[:, None]
    k = 1
    while k < events.size:
        length = lengths[k - 1]
        if length <= 0:
            states[k] = x
            k += 1
            continue
        # A run of equal intervals over which the input stays one linear piece (no jump, same
        # slope) is one autonomous stretch of the augmented system: one call for all its times.
        slope, last = slopes[k - 1], k
        tol = 1e-12 * (np.abs(slope) + np.max(np.abs(u_events[k - 1]), initial=0.0) / length)
        while (
            last + 1 < events.size
            and abs(lengths[last] - length) <= 1e-12 * length
            and np.array_equal(u_left[last], u_events[last])
            and np.all(np.abs(slopes[last] - slope) <= tol)
        ):
            last += 1
        z = np.concatenate([x, u_events[k - 1], slope])
        if last == k:
            states[k] = x = spla.expm_multiply(big * length, z)[:n]
        else:
            count = last - k + 1
            run = spla.expm_multiply(big, z, start=0.0, stop=length * count, num=count + 1, endpoint=True)
            states[k : last + 1] = run[1:, :n]
            x = states[last].copy()
        k = last + 1
    index = np.searchsorted(events, times)
    y = states[index] @ model.C.T + u_events[index] @ model.D.T
    if model.has_input_derivative:
        y = y + signals.derivative(times) @ model.D1.T
    return _finish(times, y, "krylov", "expm_multiply", start)


# --- forward Euler (fixed step) -------------------------------------------------------


def _euler(
    model: StateSpaceModel,
    signals: InputSignals,
    times: NDArray[np.float64],
    step: float | None,
    x0: NDArray[np.float64] | None,
    start: float,
) -> SimResult:
    """x_{k+1} = x_k + h (A x_k + B u(t_k)) at t_k = k h, then compared with the default method."""
    empty = np.zeros((times.size, model.noutputs))
    if step is None or not step > 0 or not math.isfinite(step):
        return SimResult(times, empty, "euler", "", 0.0, "refused", "euler needs a fixed step h > 0 (--step)")
    index = np.rint(times / step)
    if np.max(np.abs(index * step - times), initial=0.0) > 1e-9 * step:
        return SimResult(
            times,
            empty,
            "euler",
            f"h={step:g}",
            0.0,
            "refused",
            f"output times are not multiples of h = {step:g} s",
        )
    steps = int(index[-1]) if times.size else 0
    grid = np.arange(steps + 1) * step
    u = signals(grid)
    A = sp.csr_array(model.A_sparse)
    B = model.B
    x = np.zeros(model.nstates) if x0 is None else np.asarray(x0, dtype=float).copy()
    wanted = index.astype(int)
    states = np.empty((times.size, model.nstates))
    slot = 0
    with np.errstate(over="ignore", invalid="ignore"):
        for k in range(steps + 1):
            while slot < wanted.size and wanted[slot] == k:
                states[slot] = x
                slot += 1
            if k < steps:
                x = x + step * (A @ x + B @ u[k])
    y = states @ model.C.T + signals(times) @ model.D.T
    if model.has_input_derivative:
        y = y + signals.derivative(times) @ model.D1.T
    result = _finish(times, y, "euler", f"h={step:g}", start, {"steps": float(steps)})
    if not result.ok:
        return result
    return _against_exact(result, model, signals, times, x0, step)


def _against_exact(
    result: SimResult,
    model: StateSpaceModel,
    signals: InputSignals,
    times: NDArray[np.float64],
    x0: NDArray[np.float64] | None,
    step: float,
) -> SimResult:
    """Euler's error against the default method at the same times: in ``stats`` and the message."""
    exact = run(model, signals, times, choose_method(model), 1e-10, None, x0)
    stats = dict(result.stats)
    if exact.status not in ("ok", "unverified"):
        note = f"its error could not be measured ({exact.method} {exact.status}: {exact.message})"
        return replace(result, message=note, stats=stats)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        peaks = np.max(np.abs(exact.outputs), axis=0)
        gaps = np.abs(result.outputs - exact.outputs)
        relative = np.max(gaps, axis=0) / np.where(peaks > 0, peaks, 1.0)
    parts = []
    for j, name in enumerate(model.outputs):
        at = float(times[int(np.argmax(gaps[:, j]))]) if times.size else 0.0
        stats[f"error_vs_exact {name}"] = float(relative[j])
        parts.append(f"{name} {relative[j]:.2g} (largest at t = {at:.4g} s)")
    stats["error_vs_exact"] = float(np.max(relative)) if relative.size else 0.0
    stats["exact_seconds"] = exact.seconds
    note = f"forward Euler, h = {step:g} s: max |error| / peak against {exact.method} at the same times: "
    note += ", ".join(parts)
    rho = spectral_radius(model)
    if step * rho > 2:
        note += f"; h·max|λ| = {step * rho:.3g} > 2: the fastest modes are unstable at this step"
    return replace(result, message=note, stats=stats)


# --- scipy solve_ivp ------------------------------------------------------------------


def _ivp(
    model: StateSpaceModel,
    signals: InputSignals,
    times: NDArray[np.float64],
    method: str,
    rtol: float,
    atol: float | None,
    x0: NDArray[np.float64] | None,
    force: bool,
) -> SimResult:
    """scipy's solve_ivp with an absolute tolerance per state, checked against a reference.

    solve_ivp's ``atol`` is absolute per state, and states here mix units
    over many decades (fC of a femtofarad next to kA): one number for all of
    them is either far above the small states or far below the large ones.
    Unless ``atol`` is given, state i gets rtol × its own peak |xᵢ| over the
    run, taken from a reference run (``exact`` up to :data:`EXACT_LIMIT`
    states, else ``rational`` at rtol 1e-8) made before the clock starts.
    solve_ivp controls only the local error, so the result is then compared
    with that reference: the error relative to each output's peak is in
    ``stats['error_vs_reference']``, and a result more than
    :data:`IVP_GLOBAL_FACTOR` × rtol off is reported ``unverified``.
    """
    n = model.nstates
    tstop = float(times[-1])
    setting = f"rtol={rtol:g}"
    reference = _ivp_reference(model, signals, times, x0) if n else None
    if method in EXPLICIT and not force and n:
        rho = spectral_radius(model)
        steps = rho * tstop / 3.0  # explicit RK stability boundary ≈ 3 on the negative axis
        if steps > EXPLICIT_STEP_LIMIT:
            return SimResult(
                times,
                np.zeros((times.size, model.noutputs)),
                method,
                setting,
                0.0,
                "refused",
                f"{method} is explicit and the model is stiff: stability alone needs about {steps:.2g} "
                "steps (|λ|max·T/3); use exact, rational, Radau or BDF (or force it)",
            )
    start = time.perf_counter()
    large = n > EXACT_LIMIT
    A = model.A_sparse if large else model.A
    B = model.B
    absolute: float | NDArray[np.float64]
    if atol is not None:
        absolute = atol
        setting += f", atol={atol:g}"
    elif reference is not None:
        peaks = _state_peaks(model, signals, times, x0, reference[1])
        floor = np.min(peaks[peaks > 0]) if np.any(peaks > 0) else 1.0
        absolute = rtol * np.maximum(peaks, floor * 1e-6)
        setting += ", atol=rtol·(peak of each state)"
    else:
        absolute = rtol
    breaks = signals.breakpoints

    piece_end = [math.inf]

    def rhs(t: float, x: np.ndarray) -> np.ndarray:
        # At the end of a piece the input's left limit (a PWL jump belongs to the next piece).
        u = (signals.left if t >= piece_end[0] else signals)(np.array([t]))[0]
        return A @ x + B @ u

    jac = sp.csc_matrix(A) if large else np.asarray(A)
    kwargs: dict[str, object] = {}
    if method in ("Radau", "BDF"):
        kwargs["jac"] = jac  # constant; sparse for large models, so SuperLU factorises it
    elif method == "LSODA" and not large:
        dense_jac = np.asarray(jac)
        kwargs["jac"] = lambda t, x: dense_jac
    x = np.zeros(n) if x0 is None else np.asarray(x0, dtype=float).copy()
    # Integrate piece by piece between breakpoints so kinks in the input are honoured.
    pieces = np.union1d(breaks[(breaks > 0) & (breaks < tstop)], [0.0, tstop])
    out_states = np.empty((times.size, n))
    stats = {"nfev": 0.0, "steps": 0.0}
    for a, b in itertools.pairwise(pieces):
        inside = (times >= a) & (times <= b)
        t_eval = np.union1d(times[inside], [b])
        piece_end[0] = b
        try:
            sol = solve_ivp(rhs, (a, b), x, method=method, t_eval=t_eval, rtol=rtol, atol=absolute, **kwargs)
            message = "" if sol.success else str(sol.message)
        except Exception as exc:
            message = f"{type(exc).__name__}: {exc}"
        if message:
            return SimResult(
                times,
                np.zeros((times.size, model.noutputs)),
                method,
                setting,
                time.perf_counter() - start,
                "failed",
                message,
            )
        stats["nfev"] += sol.nfev
        stats["steps"] += sol.t.size
        out_states[inside] = sol.y[:, np.searchsorted(t_eval, times[inside])].T
        x = sol.y[:, -1]
        if not np.all(np.isfinite(x)):
            return _finish(times, np.full((times.size, model.noutputs), np.nan), method, setting, start)
    u = signals(times)
    y = out_states @ model.C.T + u @ model.D.T
    if model.has_input_derivative:
        y = y + signals.derivative(times) @ model.D1.T
    result = _finish(times, y, method, setting, start, stats)
    if reference is None or not result.ok:
        return result
    ref_y, _, ref_name = reference
    peak = np.maximum(np.max(np.abs(ref_y), axis=0), np.finfo(float).tiny)
    error = float(np.max(np.abs(y - ref_y) / peak)) if y.size else 0.0
    result.stats["error_vs_reference"] = error
    if error > IVP_GLOBAL_FACTOR * rtol:
        return replace(
            result,
            status="unverified",
            message=f"{method} is {error:.2g} of the peak away from {ref_name} (more than "
            f"{IVP_GLOBAL_FACTOR:g} × rtol; solve_ivp's rtol bounds only the local error)",
        )
    return replace(result, message=f"{error:.2g} of the peak from {ref_name}")


def _state_peaks(
    model: StateSpaceModel,
    signals: InputSignals,
    times: NDArray[np.float64],
    x0: NDArray[np.float64] | None,
    states: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Each state's peak |xᵢ|, also between the output times for small models.

    A fast transient after t = 0 or after an input breakpoint can peak far
    above every sampled value (a charge reaching 5e-7 C within nanoseconds
    and 2e-14 C at the samples): the exact solution is also evaluated at 40
    log-spaced times after each of the first 20 breakpoints, down to a
    thousandth of the fastest time constant.
    """
    peaks = np.max(np.abs(states), axis=0)
    if model.nstates > EXACT_LIMIT or times.size < 2:
        return peaks
    tstop = float(times[-1])
    fastest = spectral_radius(model)
    if not fastest > 0:
        return peaks
    offsets = np.geomspace(min(1e-3 / fastest, tstop / 10), tstop, 40)
    starts = np.union1d([0.0], signals.breakpoints[signals.breakpoints < tstop])[:20]
    extra = np.union1d(times, np.clip((starts[:, None] + offsets[None, :]).ravel(), 0.0, tstop))
    foh = propagate_foh(model, signals, extra, x0)
    if np.all(np.isfinite(foh.states)):
        peaks = np.maximum(peaks, np.max(np.abs(foh.states), axis=0))
    return peaks


#: A solve_ivp result further than this many times rtol from the reference is ``unverified``.
IVP_GLOBAL_FACTOR = 1000.0


def _ivp_reference(
    model: StateSpaceModel, signals: InputSignals, times: NDArray[np.float64], x0: NDArray[np.float64] | None
) -> tuple[NDArray[np.float64], NDArray[np.float64], str] | None:
    """(outputs, states, name) of a trusted run at ``times``, for scales and the check."""
    if model.nstates <= EXACT_LIMIT:
        foh = propagate_foh(model, signals, times, x0)
        if not np.all(np.isfinite(foh.states)):
            return None
        return foh.outputs, foh.states, f"exact ({foh.path})"
    states: list[NDArray[np.float64]] = []
    check = _rational(model, signals, times, IVP_REFERENCE_RTOL, x0, None, time.perf_counter(), states)
    if not check.ok:
        return None
    return check.outputs, states[0], f"rational rtol={IVP_REFERENCE_RTOL:g}"


#: Tolerance of the reference that sets solve_ivp's per-state scales above EXACT_LIMIT states.
IVP_REFERENCE_RTOL = 1e-8
