"""Time responses of a compiled model: exact first-order-hold propagation.

Between consecutive time points the inputs are taken as linear (first-order
hold); for piecewise-linear waveforms (DC steps, PULSE, PWL) with their
breakpoints on the grid this is exact, so the only error is rounding.

When the (balanced) eigenvector matrix is well conditioned, propagation is
modal: every mode is a scalar equation with φ-function propagators, the state
is stepped along a grid of about :data:`MODAL_GRID_POINTS` points plus the
breakpoints, and every requested time is evaluated from the grid point before
it. SIN and EXP sources are sums of exponentials c·e^{μt} plus a
piecewise-constant rest (:class:`ExponentialTerms`); each exponential is
convolved with each mode in closed form, so they are exact as well.

Otherwise each step uses the exponential of the augmented matrix

    [[A, B, 0],
     [0, 0, I/h],
     [0, 0, 0]] · h

(Van Loan's construction), which yields Φ = e^{Ah} and the two input
integrals in one call; propagators are cached per step length. Smooth
waveforms (SIN, EXP) are then sampled finely enough that the linear
interpolation error of the input is below :data:`SMOOTH_INPUT_RTOL` of its
amplitude; this is that path's stated error.

Zero state means the state (as shifted by the compiler to absorb input
derivatives) is zero at t = 0⁻, with every input 0 before t = 0: a DC source
is a step at t = 0.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import mpmath as mp
import numpy as np
import scipy.linalg as sla
from numpy.typing import ArrayLike, NDArray

from netlistdyn.analysis.eigen import EigenAnalysis
from netlistdyn.circuit.netlist import Netlist
from netlistdyn.circuit.sources import source_waveform
from netlistdyn.circuit.waveforms import Am, Exp, Sffm, Sin, Waveform, check_breakpoints
from netlistdyn.statespace.model import StateSpaceModel

#: Linear interpolation error allowed on smooth inputs, relative to their amplitude.
SMOOTH_INPUT_RTOL = 1e-9


@dataclass(frozen=True)
class ExponentialTerms:
    """Terms c·e^{μ(t − start)}, active from ``start`` on, of the inputs (one row per term).

    What remains of each input after its active terms are subtracted is
    piecewise linear between the breakpoints (constant for SIN and EXP), so a
    first-order hold on the remainder plus the exact convolution of each term
    propagates the state exactly.
    """

    input: NDArray[np.intp]
    start: NDArray[np.float64]
    coef: NDArray[np.complex128]
    rate: NDArray[np.complex128]

    def __len__(self) -> int:
        return int(self.input.size)

    def active(self, t0: NDArray[np.float64]) -> NDArray[np.bool_]:
        """``(len(t0), nterms)``: which terms act on the interval that starts at each t0."""
        return self.start[None, :] <= np.asarray(t0)[:, None]

    def values(self, t: NDArray[np.float64], active: NDArray[np.bool_], ninputs: int) -> NDArray[np.float64]:
        """Sum of the active terms at times t, per input: ``(len(t), ninputs)``."""
        out = np.zeros((t.size, ninputs))
        for j in range(len(self)):
            offset = np.maximum(t - self.start[j], 0.0)
            term = np.where(active[:, j], self.coef[j] * np.exp(self.rate[j] * offset), 0.0)
            out[:, self.input[j]] += term.real  # terms come in conjugate pairs (or are real)
        return out


@dataclass(frozen=True)
class InputSignals:
    """The model's inputs as functions of time.

    Attributes
    ----------
    waveforms : tuple of Waveform
        One per input, with analysis-dependent defaults resolved.
    breakpoints : numpy.ndarray
        Times (s) where some input or its slope jumps, within [0, tstop].
    max_smooth_step : float
        Largest step (s) that keeps the linear interpolation of the smooth
        inputs within :data:`SMOOTH_INPUT_RTOL`; ``inf`` if all are
        piecewise linear.
    """

    waveforms: tuple[Waveform, ...]
    breakpoints: NDArray[np.float64]
    max_smooth_step: float

    def __call__(self, t: ArrayLike) -> NDArray[np.float64]:
        """Input values, shape ``(len(t), ninputs)``, at the times ``t`` (s)."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if not self.waveforms:
            return np.zeros((t.size, 0))
        return np.column_stack([w(t) for w in self.waveforms])

    def left(self, t: ArrayLike) -> NDArray[np.float64]:
        """Limits from the left, shape ``(len(t), ninputs)``: differs from the value only at a jump.

        An interval [a, b] between grid points sees the inputs from
        ``self(a)`` (after any jump at a) to ``self.left(b)`` (before any jump
        at b), so a jump written into a PWL is a breakpoint of the hold.
        """
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if not self.waveforms:
            return np.zeros((t.size, 0))
        return np.column_stack([w.left(t) for w in self.waveforms])

    def exponential_terms(self) -> ExponentialTerms:
        """Every input's exponential parts (SIN, EXP), for exact propagation."""
        rows = [(j, *term) for j, w in enumerate(self.waveforms) for term in w.exponential_terms()]
        return ExponentialTerms(
            np.array([r[0] for r in rows], dtype=np.intp),
            np.array([r[1] for r in rows], dtype=float),
            np.array([r[2] for r in rows], dtype=complex),
            np.array([r[3] for r in rows], dtype=complex),
        )

    def derivative(self, t: NDArray[np.float64], h: float = 1e-12) -> NDArray[np.float64]:
        """Slope of each input (input units per s), for the D1 terms.

        Left-sided (the slope of the interval that ends at t, which is what a
        SPICE integrator reports at a breakpoint), right-sided at t = 0.
        Exact for piecewise-linear inputs.
        """
        t = np.atleast_1d(np.asarray(t, dtype=float))
        step = np.maximum(np.abs(t) * 1e-9, h)
        left = t - step >= 0
        lo = np.where(left, t - step, t)
        hi = np.where(left, t, t + step)
        return (self.left(hi) - self(lo)) / (hi - lo)[:, None]


def input_signals(netlist: Netlist, tstep: float, tstop: float) -> InputSignals:
    """Resolve every source's waveform for a transient of ``tstop`` seconds.

    Parameters
    ----------
    netlist : Netlist
    tstep, tstop : float
        Output step and horizon (s); SPICE uses them as waveform defaults.
    """
    waves = tuple(source_waveform(e).resolved(tstep, tstop) for e in netlist.sources)
    check_breakpoints([(e.name, e.loc, w) for e, w in zip(netlist.sources, waves, strict=True)], tstop)
    points = sorted({0.0, *(p for w in waves for p in w.breakpoints(tstop)), tstop})
    smooth = math.inf
    for w in waves:
        if isinstance(w, Sin) and w.va:
            assert w.freq is not None
            rate = 2 * math.pi * w.freq + abs(w.theta)
            smooth = min(smooth, math.sqrt(8 * SMOOTH_INPUT_RTOL) / rate)
        elif isinstance(w, Exp) and w.v1 != w.v2:
            assert w.tau1 is not None and w.tau2 is not None
            smooth = min(smooth, math.sqrt(8 * SMOOTH_INPUT_RTOL) * min(w.tau1, w.tau2))
        elif isinstance(w, Am | Sffm) and w.rate:
            smooth = min(smooth, math.sqrt(8 * SMOOTH_INPUT_RTOL) / w.rate)
    return InputSignals(waves, np.asarray(points), smooth)


#: Largest condition number of the eigenvector matrix for which propagation is modal.
MODAL_COND_LIMIT = 1e4


def _phi12(z: ArrayLike) -> tuple[NDArray[np.complex128], NDArray[np.complex128]]:
    """φ1(z) = (e^z − 1)/z and φ2(z) = (e^z − 1 − z)/z², without cancellation for small |z|.

    φ1 from ``expm1`` is accurate everywhere; φ2 cancels for small |z| and
    takes its Taylor series there (|z| < 1/2: 16 terms reach 1e-19). ``z`` may be real (a real
    spectrum): it is taken as complex.
    """
    z = np.asarray(z, dtype=complex)
    zero = z == 0
    safe = np.where(zero, 1.0, z)
    em1 = np.expm1(safe)
    phi1 = np.where(zero, 1.0, em1 / safe)
    small = np.abs(z) < 0.5
    phi2 = (em1 - safe) / np.where(small, 1.0, safe) ** 2
    if np.any(small):
        zs = z[small]
        series = np.full_like(zs, 1.0 / math.factorial(17))
        for k in range(16, 1, -1):  # Horner: φ2 = Σ_{k≥0} z^k/(k+2)!
            series = series * zs + 1.0 / math.factorial(k)
        phi2[small] = series
    return phi1, phi2


class FohPropagator:
    """Exact first-order-hold propagation data of one model.

    When the balanced A has a well-conditioned eigenvector matrix (cond below
    :data:`MODAL_COND_LIMIT`) it holds the eigendecomposition, which
    :func:`simulate_foh` uses modally with φ-functions of each λh; these stay
    accurate however stiff the step (the augmented ``expm`` loses about
    eps·‖Ah‖, 2.5e-9 of the response for Circuit 1 with R = 1e-9 over 7 s
    steps). Otherwise :meth:`matrices` gives the cached augmented matrix
    exponential (Van Loan) per step length.

    Parameters
    ----------
    A, B : numpy.ndarray
        State and input matrices.
    """

    def __init__(self, A: NDArray[np.float64], B: NDArray[np.float64]) -> None:
        self.A = np.asarray(A, dtype=float)
        self.B = np.asarray(B, dtype=float)
        self.n, self.m = self.B.shape
        self._cache: dict[float, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._modal: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
        self.balance = np.ones(self.n)  # the diagonal balancing of A (powers of two)
        self.refined = False  # True once the eigendecomposition comes from mpmath
        #: C·V at the refined precision, rounded once (None until :meth:`refine_modal` is given C).
        self.seen: NDArray[np.complex128] | None = None
        if self.n:
            try:
                # Balance first (a diagonal similarity by powers of two, exact): element values
                # spanning many decades otherwise make the eigenvectors look ill-conditioned.
                balanced, scaling = sla.matrix_balance(self.A, permute=False, separate=True)
                t = scaling[0]
                self.balance = np.asarray(t, dtype=float)
                lam, vecs = np.linalg.eig(balanced)
                if np.linalg.cond(vecs) < MODAL_COND_LIMIT:
                    inv = np.linalg.inv(vecs)
                    left = vecs * t[:, None]  # V = T·Vb
                    right = inv / t[None, :]  # V⁻¹ = Vb⁻¹·T⁻¹
                    self._modal = (lam, left, right, right @ self.B)
            except (np.linalg.LinAlgError, ValueError):
                self._modal = None

    def refine_modal(self, C: NDArray[np.float64] | None = None) -> bool:
        """Recompute the eigendecomposition with mpmath at :data:`MODAL_REFINE_DIGITS` digits.

        λ, V, V⁻¹, V⁻¹B and (given the output matrix C) C·V are then each
        rounded once to double, so every entry is right to eps relative — also
        the small components of eigenvectors that double-precision LAPACK gets
        right only normwise, and a C·vᵢ that is a near-cancellation of V's
        entries (v(n4) = 2200·(i(L0) − i(L2) − i(L3)) on a null vector: 5e-14
        formed in double, ~1e-24 exactly, beside a modal coordinate of 2e17).
        False (nothing changed) when mpmath fails or the eigenvectors are not
        independent.
        """
        try:
            with mp.workdps(MODAL_REFINE_DIGITS):
                a = mp.matrix(self.A.tolist())
                values, right = mp.eig(a)
                inv = mp.inverse(right)
                inv_b = inv * mp.matrix(self.B.tolist())
                seen = None
                if C is not None and C.size:
                    cv = mp.matrix(np.asarray(C, dtype=float).tolist()) * right
                    seen = np.array([[complex(cv[i, j]) for j in range(self.n)] for i in range(cv.rows)])
                lam = np.array([complex(v) for v in values])
                vecs = np.array([[complex(right[i, j]) for j in range(self.n)] for i in range(self.n)])
                left = np.array([[complex(inv[i, j]) for j in range(self.n)] for i in range(self.n)])
                forced = np.array([[complex(inv_b[i, j]) for j in range(self.m)] for i in range(self.n)])
        except (ZeroDivisionError, ValueError, ArithmeticError):
            return False
        if not (np.all(np.isfinite(vecs)) and np.all(np.isfinite(left))):
            return False
        if seen is not None and not np.all(np.isfinite(seen)):
            return False
        self._modal = (lam, vecs, left, forced.reshape(self.n, self.m))
        self.seen = seen
        self.balance = np.ones(self.n)
        self.refined = True
        return True

    @property
    def nstates_zero(self) -> bool:
        """True for a model without states."""
        return self.n == 0

    @property
    def modal(self) -> bool:
        """True when propagation uses the eigendecomposition."""
        return self._modal is not None

    def matrices(self, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(Φ, Γ0, Γ1) with x(t+h) = Φ x(t) + Γ0 u(t) + Γ1 u(t+h) for linear u (Van Loan)."""
        key = float(f"{h:.13g}")
        hit = self._cache.get(key)
        if hit is not None:
            return hit
        n, m = self.n, self.m
        big = np.zeros((n + 2 * m, n + 2 * m))
        big[:n, :n] = self.A * key
        big[:n, n : n + m] = self.B * key
        big[n : n + m, n + m :] = np.eye(m)
        expo = sla.expm(big)
        phi = expo[:n, :n]
        g1 = expo[:n, n : n + m]  # ∫ e^{As} ds B
        g2 = expo[:n, n + m :]  # ∫ e^{As}(h−s)/h ds B
        result = (phi, g1 - g2, g2)
        if len(self._cache) < 100_000:
            self._cache[key] = result
        return result


def refine_grid(
    times: NDArray[np.float64], signals: InputSignals, smooth: bool = True
) -> NDArray[np.float64]:
    """Union of the requested times and input breakpoints, with substeps for smooth inputs.

    ``smooth=False`` leaves out the substeps (for propagation that treats
    SIN and EXP exactly).
    """
    tstop = float(times[-1])
    grid = np.union1d(times, signals.breakpoints[signals.breakpoints <= tstop])
    grid = np.union1d(grid, [0.0])
    if smooth and math.isfinite(signals.max_smooth_step):
        gaps = np.diff(grid)
        counts = np.maximum(np.ceil(gaps / signals.max_smooth_step).astype(int), 1)
        if np.any(counts > 1):
            pieces = [grid[:1]]
            for start, end, count in zip(grid[:-1], grid[1:], counts, strict=True):
                # The substeps, then the end point itself: start + gap·count/count can round
                # away from it, and a requested time must stay on the grid exactly.
                pieces.append(start + (end - start) * np.arange(1, count) / count)
                pieces.append(np.array([end]))
            grid = np.concatenate(pieces)
    return grid


#: Error allowed on ``exact``'s result, relative to each output's own peak, by default.
FOH_RTOL = 1e-9


@dataclass(frozen=True)
class FohResult:
    """Outputs and states of the exact first-order-hold propagation, with how far to trust them.

    Attributes
    ----------
    outputs : numpy.ndarray
        ``(len(times), noutputs)``.
    states : numpy.ndarray
        ``(len(times), nstates)``.
    error : float
        Estimated error, relative to each output's own peak (the worst output).
    path : str
        ``"modal"`` or ``"augmented expm"``.
    verified : bool
        True when ``error`` is within the requested tolerance.
    message : str
        What was done and why, when not the plain modal path.
    """

    outputs: NDArray[np.float64]
    states: NDArray[np.float64]
    error: float
    path: str
    verified: bool
    message: str = ""


def simulate_foh(
    model: StateSpaceModel,
    signals: InputSignals,
    times: Sequence[float] | NDArray[np.float64],
    x0: NDArray[np.float64] | None = None,
    progress: Callable[[float], None] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Outputs of ``model`` at ``times`` (sorted, from 0) by exact FOH propagation.

    See :func:`propagate_foh`, which also says how far the result can be trusted.

    Returns
    -------
    y : numpy.ndarray
        ``(len(times), noutputs)`` outputs.
    x : numpy.ndarray
        ``(len(times), nstates)`` states.
    """
    result = propagate_foh(model, signals, times, x0, progress)
    return result.outputs, result.states


def propagate_foh(
    model: StateSpaceModel,
    signals: InputSignals,
    times: Sequence[float] | NDArray[np.float64],
    x0: NDArray[np.float64] | None = None,
    progress: Callable[[float], None] | None = None,
    rtol: float = FOH_RTOL,
) -> FohResult:
    """Exact FOH propagation with an error estimate relative to each output's own peak.

    The modal evaluation is used when its a-priori error estimate (see
    :func:`_modal_error`) is within ``rtol`` of every output's peak: a tiny
    output that is the difference of large modal contributions (v(b) of
    issue 17's reproducer, 1e-9 V beside 1e-3 V modes) can lose every digit
    there. Otherwise, up to :data:`MODAL_REFINE_LIMIT` states, the
    eigendecomposition is recomputed with mpmath and the modal evaluation
    redone (its estimate then holds only the evaluation's rounding). Failing
    that, the state is stepped with the augmented exponential (Van Loan)
    through every requested time and checked against a rerun with every step
    halved: their difference is its error estimate. A result whose estimate
    exceeds ``rtol`` has ``verified`` False.

    Parameters
    ----------
    model : StateSpaceModel
    signals : InputSignals
    times : array of float
        Non-decreasing times (s), starting at or after 0.
    x0 : array, optional
        State at t = 0 (default zero).
    progress : callable, optional
        Called with the fraction done.
    rtol : float
        Error allowed, relative to each output's peak.
    """
    times = np.asarray(times, dtype=float)
    if model.nstates == 0:  # no dynamics: y = D u (+ D1 u') at the requested times, nothing to step
        xs = np.zeros((times.size, 0))
        return FohResult(_outputs_at(model, signals, times, xs), xs, 0.0, "no states", True)
    prop = FohPropagator(model.A, model.B)
    note = ""
    if prop.modal:
        # An unstable model may overflow: the non-finite result is reported by the caller.
        with np.errstate(over="ignore", invalid="ignore"):
            xs, zmax, _ = _modal_at_times(prop, signals, times, x0, progress)
            y = _outputs_at(model, signals, times, xs)
            error = _modal_error(prop, model, signals, times, x0, zmax, y)
        if error <= rtol or not np.all(np.isfinite(y)):
            return FohResult(y, xs, error, "modal", bool(error <= rtol))
        note = f"modal evaluation's error estimate {error:.1g} of the peak exceeds {rtol:g}; "
        if 0 < prop.n <= MODAL_REFINE_LIMIT and prop.refine_modal(model.C):
            with np.errstate(over="ignore", invalid="ignore"):
                xs, zmax, observed = _modal_at_times(prop, signals, times, x0, progress)
                # The outputs from the refined C·V and the modal coordinates, not from the states:
                # C·x in double loses what cancels between large state components.
                y = _outputs_at(model, signals, times, np.zeros_like(xs))
                y = y + (observed if observed is not None else xs @ model.C.T)
                error = _modal_error(prop, model, signals, times, x0, zmax, y)
            message = (
                note + f"eigendecomposition recomputed at {MODAL_REFINE_DIGITS} digits: estimate {error:.1g}"
            )
            if error <= rtol or not np.all(np.isfinite(y)):
                return FohResult(y, xs, error, "modal (extended precision)", bool(error <= rtol), message)
            note = message + "; "
    grid = refine_grid(times, signals)
    xs = _stepped_states(prop, signals, times, x0, progress, grid)
    y = _outputs_at(model, signals, times, xs)
    error = _stepped_error(prop, model, signals, times, x0, y, xs, grid)
    verified = bool(error <= rtol)
    message = (
        f"{note}stepped with the augmented exponential: error estimate {error:.1g} of the peak"
        " (a rerun at half the steps, and expm's rounding)"
    )
    if not verified:
        message += f", above the tolerance {rtol:g}: the result cannot be vouched for"
    return FohResult(y, xs, error, "augmented expm", verified, message)


def _peaks(y: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each output's peak |y| (a floor of the smallest normal number for an all-zero output)."""
    if y.size == 0:
        return np.ones(y.shape[1] if y.ndim == 2 else 0)
    return np.maximum(np.max(np.abs(y), axis=0), np.finfo(float).tiny)


def _trusted_peaks(y: NDArray[np.float64], absolute: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each output's peak less its estimated absolute error (``absolute``, one per output).

    The estimate is relative to the true peak, which the computed one exceeds
    by up to the error itself: a result whose error is its whole peak (a
    cancellation lost) must not be judged against that peak. Zero (the
    relative error infinite) when the error may be the whole peak.
    """
    peaks = _peaks(y)
    with np.errstate(invalid="ignore"):
        trusted = np.where(absolute < peaks, peaks - absolute, 0.0)
    return np.maximum(trusted, np.finfo(float).tiny)


def _modal_error(
    prop: FohPropagator,
    model: StateSpaceModel,
    signals: InputSignals,
    times: NDArray[np.float64],
    x0: NDArray[np.float64] | None,
    zmax: NDArray[np.float64],
    y: NDArray[np.float64],
) -> float:
    """A-priori estimate of the modal evaluation's error, relative to each output's peak.

    In balanced coordinates y = Σᵢ (C vᵢ) zᵢ. Each modal input b̃ᵢ = wᵢᵀB is
    formed with an absolute error of about eps‖wᵢ‖‖B‖ (normwise: the left
    eigenvector's small components are only normwise accurate), each
    eigenvalue with its componentwise backward error times its componentwise
    condition number |wᵢ|ᵀ|A||vᵢ|, which moves zᵢ by |δλ| times the
    mode's memory min(T, 1/|Re λ|); each product C vᵢ carries eps‖C‖‖vᵢ‖.
    The sum over modes of these, weighted by |C vᵢ| and the largest |zᵢ|,
    is compared with each output's own peak. It overestimates (measured 10×
    to 10⁴× on the stress netlists against 40-digit references) but it sees
    the cancellation that loses a tiny output.
    """
    if prop.nstates_zero or y.size == 0:
        return 0.0
    assert prop._modal is not None
    lam, vecs, inv, _ = prop._modal
    eps = np.finfo(float).eps
    horizon = float(times[-1]) if times.size else 0.0
    # The recurrence multiplies each mode by its rounded e^{λh} once per grid step: the same
    # relative error eps every step, so it grows with the steps within the mode's memory (an
    # eigenvalue error of eps/h; for a slow mode, eps times the grid's steps, not eps·|λ|·T).
    steps = refine_grid(np.linspace(0.0, horizon, MODAL_GRID_POINTS), signals, smooth=False).size
    spacing = horizon / max(steps - 1, 1)
    if prop.refined:
        # λ, V, V⁻¹B and CV are the 40-digit values rounded once: each entry is within eps
        # relative, so what remains is rounding in the evaluation and the sum's cancellation.
        # (CV must be the refined one the outputs were formed with: C @ V in double is off by
        # eps‖C‖‖vᵢ‖, which a large |zᵢ| turns into any error at all.) z0 = V⁻¹x0 is formed in
        # double: eps |V⁻¹||x0| per mode.
        seen = prop.seen if prop.seen is not None else model.C @ vecs
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            memory = np.where(lam.real < 0, np.minimum(horizon, 1.0 / np.abs(lam.real)), horizon)
            recurrence = np.minimum(steps, memory / spacing + 1) if spacing > 0 else 0.0
            dz = (8 * eps + eps * np.abs(lam) * memory + eps * recurrence) * zmax
            if x0 is not None:
                dz = dz + 2 * prop.n * eps * (np.abs(inv) @ np.abs(np.asarray(x0, dtype=float)))
            absolute = np.abs(seen) @ dz
            worst = float(np.max(absolute / _trusted_peaks(y, absolute)))
        return worst if math.isfinite(worst) else math.inf
    t = prop.balance
    vb = vecs / t[:, None]  # balanced eigenvectors
    wb = inv * t[None, :]
    bb = model.B / t[:, None]
    cb = model.C * t[None, :]
    vnorm = np.linalg.norm(vb, axis=0)
    wnorm = np.linalg.norm(wb, axis=1)
    ab = prop.A / t[:, None] * t[None, :]
    # Eigenvalue errors componentwise (the entries come from element values): the Oettli–Prager
    # backward error of each pair, at least eps, times |w|ᵀ|A||v| / |wᵀv| (wᵀv = 1 here).
    abs_a = np.abs(ab)
    abs_v = np.abs(vb)
    denom = abs_a @ abs_v + np.abs(lam) * abs_v
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(denom > 0, np.abs(ab @ vb - vb * lam) / denom, 0.0)
    backward = np.maximum(np.max(ratio, axis=0), eps)
    dlam = backward * np.einsum("ij,ij->i", np.abs(wb), (abs_a @ abs_v).T)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        memory = np.where(
            lam.real < 0,
            np.minimum(horizon, 1.0 / np.abs(lam.real)),
            horizon * np.exp(np.maximum(lam.real, 0.0) * horizon),
        )
        u_max = np.max(np.abs(signals(times)), axis=0) if model.ninputs else np.zeros(0)
        forcing = np.linalg.norm(bb, axis=0) @ u_max if model.ninputs else 0.0
        start = np.linalg.norm(np.asarray(x0, dtype=float) / t) if x0 is not None else 0.0
        recurrence = np.minimum(steps, memory / spacing + 1) if spacing > 0 else 0.0
        dz = eps * wnorm * (forcing * memory + start) + (dlam * memory + 8 * eps + eps * recurrence) * zmax
        cv = np.abs(cb @ vb)
        absolute = cv @ dz + eps * (np.linalg.norm(cb, axis=1)[:, None] * vnorm[None, :]) @ zmax
        relative = absolute / _trusted_peaks(y, absolute)
    worst = float(np.max(relative)) if relative.size else 0.0
    return worst if math.isfinite(worst) else math.inf


def _stepped_states(
    prop: FohPropagator,
    signals: InputSignals,
    times: NDArray[np.float64],
    x0: NDArray[np.float64] | None,
    progress: Callable[[float], None] | None,
    grid: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """States at ``times`` stepped with the augmented exponential through ``grid``.

    ``grid`` defaults to the union of ``times`` and the breakpoints (with
    substeps for smooth inputs).
    """
    if grid is None:
        grid = refine_grid(times, signals)
    u = signals(grid)
    u_left = signals.left(grid)
    n = prop.n
    x = np.zeros(n) if x0 is None else np.asarray(x0, dtype=float).copy()
    states = np.empty((grid.size, n))
    states[0] = x
    # A DC source is a step at t = 0: the state is continuous across it and the
    # first interval already sees u(0⁺) = u[0].
    u_prev = u[0]
    for k in range(1, grid.size):
        h = grid[k] - grid[k - 1]
        if h > 0:
            phi, g0, g1 = prop.matrices(h)
            with np.errstate(over="ignore", invalid="ignore"):
                x = phi @ x + g0 @ u_prev + g1 @ u_left[k]
            if not np.all(np.isfinite(x)):  # diverged: the caller reports it, nothing to continue
                states[k:] = np.nan
                break
        states[k] = x
        u_prev = u[k]
        if progress is not None and k % 2000 == 0:
            progress(k / grid.size)
    return states[np.searchsorted(grid, times)]


#: Above this many grid points the stepped path checks itself on a subgrid of about this size.
STEPPED_CHECK_LIMIT = 2000

#: Up to this many states a modal evaluation whose estimate fails is redone from an
#: eigendecomposition computed with mpmath (about 0.1 s at 5 states, 1 s at 12).
MODAL_REFINE_LIMIT = 12
#: Digits of that eigendecomposition.
MODAL_REFINE_DIGITS = 40


def _stepped_error(
    prop: FohPropagator,
    model: StateSpaceModel,
    signals: InputSignals,
    times: NDArray[np.float64],
    x0: NDArray[np.float64] | None,
    y: NDArray[np.float64],
    xs: NDArray[np.float64],
    grid: NDArray[np.float64],
) -> float:
    """Difference, relative to each output's peak, between the stepped result and a rerun
    with every step of its grid halved, times 2 (an error at least first order in the step).

    The propagation is exact either way, so what differs is the rounding and
    truncation of the exponentials (and, for SIN/EXP, the linear pieces). An
    error that does not depend on the step (a systematic error of the
    exponential itself) is not seen: this is an estimate, not a bound.
    """
    if prop.n == 0 or grid.size < 2:
        return 0.0
    if times.size > STEPPED_CHECK_LIMIT:  # every step its own exponential: check fewer times
        # Every stride-th requested time, refined as the run was (breakpoints and the substeps
        # of SIN/EXP), so the check sees the run's linear pieces and not coarser ones.
        stride = -(-times.size // STEPPED_CHECK_LIMIT)
        times = np.union1d(times[::stride], [times[-1]])
        grid = refine_grid(times, signals)
        xs = _stepped_states(prop, signals, times, x0, None, grid)
    fine = np.union1d(grid, (grid[:-1] + grid[1:]) / 2)
    with np.errstate(over="ignore", invalid="ignore"):
        two = _stepped_states(prop, signals, times, x0, None, fine)
        gap = np.max(np.abs((xs - two) @ model.C.T), axis=0) / _peaks(y)
    # The linear pieces follow the input to second order, but an output can see the input's
    # derivative (v = L di/dt across a fast RL branch follows u' quasi-statically), whose error is
    # first order: halving then leaves half of it, and the run's own error is up to twice the
    # difference (Richardson with order 1; 4/3 for order 2 under-estimated the 60 Hz mains case
    # of tests/test_integrators.py). An order of at least 1 is all this assumes.
    # Halving cannot see what every exponential gets wrong alike: Padé scaling and squaring is
    # accurate to about eps·‖Ah‖ relative (seed 683 of tests/test_rtol_bound.py: ‖Ah‖ = 1.4e6,
    # 1.07e-9 of an output's peak while the halving said 3e-14). Each output counts one step's
    # eps·‖Ah‖₁ of the largest |C||x| it sees, A balanced (element values spanning decades make
    # ‖A‖ large where the modes are not: tests/test_sim_accuracy.py's spread circuit).
    eps = np.finfo(float).eps
    steps = np.diff(grid)
    balanced = sla.matrix_balance(prop.A, permute=False)[0]
    reach = float(np.max(steps)) * float(np.max(np.sum(np.abs(balanced), axis=0))) if steps.size else 0.0
    with np.errstate(over="ignore", invalid="ignore"):
        seen = np.max(np.abs(xs) @ np.abs(model.C).T, axis=0) / _peaks(y)
    gap = 2.0 * gap + eps * reach * seen
    worst = float(np.max(gap)) if gap.size else 0.0
    return worst if math.isfinite(worst) else math.inf


def _outputs_at(
    model: StateSpaceModel, signals: InputSignals, times: NDArray[np.float64], xs: NDArray[np.float64]
) -> NDArray[np.float64]:
    """y = C x + D u (+ D1 u') at ``times``."""
    y = xs @ model.C.T + signals(times) @ model.D.T
    if model.has_input_derivative:
        y = y + signals.derivative(times) @ model.D1.T
    return y


#: Modal propagation steps on its own grid of about this many points (plus the input
#: breakpoints) and evaluates every requested time from the grid point before it, vectorised.
MODAL_GRID_POINTS = 2000
#: Runs of equal steps up to this long are stepped in Python; longer ones by lfilter.
FILTER_MIN_RUN = 5000
#: Entries (times × modes) per vectorised block: bounds each temporary array to ~32 MB.
MODAL_BLOCK_ENTRIES = 2_000_000


def _uniform_runs(grid: NDArray[np.float64]) -> list[tuple[int, int, float]]:
    """Maximal runs [a, b] of grid points equally spaced to within a few ulps: (a, b, step).

    The step is the run's mean, (grid[b] − grid[a])/(b − a); a run is kept
    only while every point lies within 8 ulps of grid[a] + j·step, so using
    one step for the run moves no time by more than rounding.
    """
    steps = np.diff(grid)
    if steps.size == 0:
        return []
    breaks = np.flatnonzero(np.abs(np.diff(steps)) > 1e-9 * np.abs(steps[:-1])) + 1
    bounds = [0, *breaks.tolist(), steps.size]
    tol = 8 * np.finfo(float).eps * max(float(np.max(np.abs(grid))), 1e-300)
    runs = []
    for a, b in itertools.pairwise(bounds):
        h = (grid[b] - grid[a]) / (b - a)
        spread = np.max(np.abs(grid[a : b + 1] - (grid[a] + h * np.arange(b - a + 1))))
        if spread <= tol:
            runs.append((a, b, float(h)))
        else:  # not uniform after all: one step at a time
            runs.extend((k, k + 1, float(grid[k + 1] - grid[k])) for k in range(a, b))
    return runs


def _modal_grid_states(
    lam: NDArray[np.complex128],
    grid: NDArray[np.float64],
    left: NDArray[np.complex128],
    right: NDArray[np.complex128],
    forced: NDArray[np.complex128],
    z0: NDArray[np.complex128],
) -> NDArray[np.complex128]:
    """Modal states at every grid point, one linear recurrence per mode and uniform run.

    Within a run of equal steps h every mode obeys z_{k+1} = e^{λh} z_k + w_k
    with w_k = h((φ1 − φ2) b̃r_k⁺ + φ2 b̃r_{k+1}⁻) + f_k (``left``, ``right``:
    the remainder of the inputs at each interval's ends; ``forced``: the
    exponential terms' exact contribution): a first-order recursive filter,
    run by ``scipy.signal.lfilter`` for long runs instead of a Python loop.
    """
    zs = np.empty((grid.size, lam.size), dtype=complex)
    zs[0] = z0
    z = z0
    for a, b, h in _uniform_runs(grid):
        if h <= 0:
            zs[a + 1 : b + 1] = z
            continue
        phi1, phi2 = _phi12(lam * h)
        decay = np.exp(lam * h)
        w = h * ((phi1 - phi2) * left[a:b] + phi2 * right[a:b]) + forced[a:b]
        if b - a <= FILTER_MIN_RUN:
            for k in range(a, b):
                z = decay * z + w[k - a]
                zs[k + 1] = z
            continue
        from scipy.signal import lfilter  # ~1 s to import: only for long runs  # noqa: PLC0415 (deferred, scipy.signal: 0.6 s of CPU to import)

        for j in range(lam.size):
            zs[a + 1 : b + 1, j], _ = lfilter([1.0], [1.0, -decay[j]], w[:, j], zi=[decay[j] * z[j]])
        z = zs[b]
    return zs


def _modal_at_times(
    prop: FohPropagator,
    signals: InputSignals,
    times: NDArray[np.float64],
    x0: NDArray[np.float64] | None,
    progress: Callable[[float], None] | None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64] | None]:
    """States at many times: exact modal propagation along a coarse grid, then to each time.

    Returns the states ``(len(times), n)``, each mode's largest |z| seen, and,
    when the propagator holds a refined C·V (``prop.seen``), Re(C·V z) at the
    times (the outputs without their feedthrough), else None.

    In modal coordinates z = V⁻¹x every mode is a scalar equation. Each input
    is split into exponential terms c·e^{μ(t−start)} (SIN, EXP) and a
    remainder r that is linear between breakpoints; from grid point t_k to
    any t before t_{k+1}, with τ = t − t_k,

        z(t) = e^{λτ} z_k + τ(φ1(λτ) − φ2(λτ)) b̃ r(t_k) + τ φ2(λτ) b̃ r(t)
               + Σ_terms b̃ c e^{μ(t_k − start)} ∫₀^τ e^{λ(τ−s)} e^{μs} ds,

    which is exact, so the grid needs only the breakpoints and about
    :data:`MODAL_GRID_POINTS` points. The cost is a loop over the grid (see
    :func:`_modal_grid_states`) plus array operations over the times.
    """
    assert prop._modal is not None
    lam, vecs, inv, inv_b = prop._modal
    terms = signals.exponential_terms()
    tstop = float(times[-1])
    coarse = np.linspace(0.0, tstop, MODAL_GRID_POINTS) if tstop > 0 else np.zeros(1)
    grid = refine_grid(coarse, signals, smooth=False)
    m = inv_b.shape[1]
    z0 = np.zeros(lam.size, dtype=complex) if x0 is None else inv @ np.asarray(x0, dtype=float)
    seen = prop.seen
    if grid.size == 1:
        zs = np.repeat(z0[None, :].astype(complex), times.size, axis=0)
        return np.real(zs @ vecs.T), np.abs(z0), None if seen is None else np.real(zs @ seen.T)
    starts, ends = grid[:-1], grid[1:]
    active = terms.active(starts)
    left = (signals(starts) - terms.values(starts, active, m)) @ inv_b.T
    right = (signals.left(ends) - terms.values(ends, active, m)) @ inv_b.T
    forced = _forced_response(lam, terms, inv_b, starts, ends - starts, active)
    zs = _modal_grid_states(lam, grid, left, right, forced, z0.astype(complex))
    zmax = np.max(np.abs(zs), axis=0)
    out = np.empty((times.size, lam.size))
    observed = None if seen is None else np.empty((times.size, seen.shape[0]))
    block = max(1, MODAL_BLOCK_ENTRIES // max(lam.size, 1))
    for first in range(0, times.size, block):
        t = times[first : first + block]
        k = np.clip(np.searchsorted(grid, t, side="right") - 1, 0, grid.size - 2)
        tau = t - grid[k]
        zt = lam[None, :] * tau[:, None]
        phi1, phi2 = _phi12(zt)
        now = (signals.left(t) - terms.values(t, active[k], m)) @ inv_b.T
        z_t = (
            np.exp(zt) * zs[k]
            + tau[:, None] * ((phi1 - phi2) * left[k] + phi2 * now)
            + _forced_response(lam, terms, inv_b, grid[k], tau, active[k])
        )
        out[first : first + t.size] = np.real(z_t @ vecs.T)
        if observed is not None and seen is not None:  # both or neither
            observed[first : first + t.size] = np.real(z_t @ seen.T)
        zmax = np.maximum(zmax, np.max(np.abs(z_t), axis=0))
        if progress is not None:
            progress(min(1.0, (first + t.size) / times.size))
    return out, zmax, observed


def _forced_response(
    lam: NDArray[np.complex128],
    terms: ExponentialTerms,
    inv_b: NDArray[np.complex128],
    t0: NDArray[np.float64],
    tau: NDArray[np.float64],
    active: NDArray[np.bool_],
) -> NDArray[np.complex128]:
    """Σ over active terms of b̃ c e^{μ(t0 − start)} ∫₀^τ e^{λ(τ−s)} e^{μs} ds, ``(len(t0), n)``.

    The integral is (e^{μτ} − e^{λτ})/(μ − λ), evaluated as τ e^{λτ} φ1((μ−λ)τ)
    or τ e^{μτ} φ1((λ−μ)τ), whichever has the argument of non-positive real
    part: no cancellation at resonance (μ ≈ λ) and no overflow for stiff modes.
    """
    out = np.zeros((t0.size, lam.size), dtype=complex)
    for j in range(len(terms)):
        mu = terms.rate[j]
        scale = np.where(active[:, j], terms.coef[j] * np.exp(mu * np.maximum(t0 - terms.start[j], 0.0)), 0.0)
        d = (mu - lam[None, :]) * tau[:, None]
        decaying = d.real <= 0
        base = np.where(decaying, lam[None, :], mu) * tau[:, None]
        phi1, _ = _phi12(np.where(decaying, d, -d))
        out += (scale[:, None] * inv_b[:, terms.input[j]][None, :]) * (tau[:, None] * np.exp(base) * phi1)
    return out


@dataclass(frozen=True, slots=True)
class Horizon:
    """Transient horizon and output step (s), and where they came from."""

    tstep: float
    tstop: float
    source: str


def choose_horizon(
    netlist: Netlist, eig: EigenAnalysis | None, tstop: float | None, tstep: float | None
) -> Horizon:
    """``--tstop/--tstep``, else the netlist's ``.tran``, else from the eigenvalues.

    From the eigenvalues: five of the slowest time constants, or ten periods
    of the slowest oscillation if longer, capped at 10⁴ of the fastest time
    scale so that a stiff circuit stays affordable; the step is 1/1000 of
    the horizon.
    """
    if tstop is not None:
        return Horizon(tstep or tstop / 1000, tstop, "command line")
    if netlist.tran is not None:
        return Horizon(tstep or netlist.tran.tstep, netlist.tran.tstop, ".tran in the netlist")
    scales_slow, scales_fast = [], []
    for mode in eig.modes if eig is not None else ():
        lam = mode.value
        if lam.real < 0:
            scales_slow.append(5.0 / -lam.real)
            scales_fast.append(1.0 / -lam.real)
        if lam.imag:
            period = 2 * math.pi / abs(lam.imag)
            scales_slow.append(10 * period)
            scales_fast.append(period)
    if not scales_slow:
        return Horizon(1e-3, 1.0, "default (no eigenvalue to scale by)")
    horizon = min(max(scales_slow), 1e4 * min(scales_fast))
    capped = horizon < max(scales_slow)
    source = "from the eigenvalues" + (" (capped at 1e4 x the fastest time scale)" if capped else "")
    return Horizon(tstep or horizon / 1000, horizon, source)
