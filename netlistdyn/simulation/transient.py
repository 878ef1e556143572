"""Transient and DC solution of a sparse descriptor system ``E x' = A x + B u``.

For large linear circuits (power grids): nothing dense, memory bounded by a
few sparse LU factors plus the requested outputs.

DC operating point
    ``A x = −B u(0)`` (capacitors open, inductors shorted), one real sparse
    LU. The transient starts there unless ``.tran ... UIC`` (then from zero,
    or from a given state), as SPICE does.

Time stepping (``descriptor``)
    The inputs are linear between breakpoints, and are carried exactly by a
    nilpotent augmentation ``[x; u; u']``, so the only approximation is that
    of the exponential ``e^{hM}``. ``cf``: the near-best type
    (14, 14) rational approximation of e^x on the whole negative real axis
    (CF poles, :mod:`netlistdyn._cf_table`; within 2.6e-14 of e^x there,
    exact at 0), in partial fractions — one complex factor per conjugate
    pole pair, applied as ``(hA − zE)⁻¹E`` — so on an RC circuit (real,
    non-positive spectrum) a step of any length is accurate and the step is
    the output step. ``pade``: the L-stable [k−1/k] Padé approximant
    (k = 12: order 23), accurate only for small ``|hλ|``, in product form
    ``c + 2·Re(α (hM − p)⁻¹)`` per conjugate pole pair. ``auto`` (the
    default): CF, and Padé from the first step where CF's check fails and
    Padé's passes (modes off the real axis that Padé resolves); an explicit
    ``cf`` never switches (see :func:`run_transient`). Either
    way ``(hM − p)⁻¹ y = (hA − pE)⁻¹ E y`` needs no inverse of the singular
    ``E``, and, both approximants being strictly proper, the algebraic
    unknowns (nodes without a capacitor, source currents) come out
    consistent with the input at the end of every step. One
    complex sparse LU per pole pair and step length (ordering: see
    :func:`_lu`), kept for at most :data:`CACHE_LENGTHS` step lengths; only
    the outputs are stored. Steps are checked and adapted: see
    :func:`run_transient`.

Breakpoints closer than :data:`SNAP` (relative to the output step) to an
output time are moved onto it: the input then differs from the true one only
on that sliver, by less than slope × sliver, a change in charge below
``|Δslope|·(SNAP·h)²``.
"""

from __future__ import annotations

import contextlib
import time
from collections import OrderedDict
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

from netlistdyn.base.errors import NetlistError, SourceLocation
from netlistdyn.circuit.sources import SourceValues, breakpoints
from netlistdyn.circuit.waveforms import Waveform
from netlistdyn.formulation.descriptor import DescriptorSystem
from netlistdyn.simulation._cf_table import CF
from netlistdyn.simulation.integrators import pade_factors as stored
from netlistdyn.simulation.integrators import pade_factors_exact

#: Breakpoints within this fraction of the output step from an output time are put on it.
SNAP = 1e-6
#: Number of factorised steps (length and kind) kept; the least recently used goes first.
CACHE_LENGTHS = 4
#: Default Padé denominator degree.
DEFAULT_ORDER = 12
#: Kinds of step: the main L-stable one, the diagonal and the lower-order checks.
MAIN, DIAGONAL, LOW = "main", "diagonal", "low"
#: Denominator degree of the lower-order check after breakpoints.
CHECK_ORDER = 8
#: Stepping methods: ``cf``, near-best rational approximations of e^x on the whole negative real
#: axis (one step per output interval on RC circuits, whatever their stiffness), and ``pade``.
METHODS = ("cf", "pade", "auto")
#: Default stepping method: ``auto`` (CF, Padé from where CF's check fails and Padé's passes).
#: Measured: on RC/RLC grids CF never fails (auto = cf, 4-30x faster than Padé at rtol 1e-10);
#: on ibmpg1t at rtol 1e-12 auto took 40 s CPU against cf's 55 s (Padé 28 s).
DEFAULT_METHOD = "auto"
#: Degrees of the CF approximants: the step, and its check (see :class:`CFStep`).
CF_DEGREE, CF_CHECK_DEGREE = 14, 12
#: Default step check tolerance (relative to the largest voltage, or current, seen).
DEFAULT_RTOL = 1e-10
#: Tighter tolerances are raised to this: below it the two approximants differ by rounding
#: (ibmpg1t at rtol 1e-13 kept halving its steps into ill-conditioned pencils and 3.2 GB of LUs).
MIN_RTOL = 1e-12
#: Steps between checks away from breakpoints.
CHECK_INTERVAL = 16
#: Steps are at least 1/2**MAX_LEVEL of the piece between output times and breakpoints.
MAX_LEVEL = 48


@contextlib.contextmanager
def single_thread() -> Iterator[None]:
    """Limit BLAS to one thread (SuperLU's dense kernels are slower with two on small blocks)."""
    try:
        from threadpoolctl import threadpool_limits  # noqa: PLC0415 (deferred, threadpoolctl: optional scale extra)
    except ImportError:  # pragma: no cover - optional
        yield
        return
    with threadpool_limits(limits=1, user_api="blas"):
        yield


def _lu(matrix: sp.sparray) -> spla.SuperLU:
    """Sparse LU: minimum degree on A + Aᵀ with diagonal pivots preferred when no diagonal
    entry is zero (about 1.4x less fill and 2.6x faster solves than COLAMD on ibmpg1t); COLAMD
    with partial pivoting otherwise (the zero diagonal of voltage-source rows defeats a
    symmetric order: 39 M entries against 1.2 M)."""
    csc = sp.csc_matrix(matrix)
    if np.all(csc.diagonal() != 0):
        return spla.splu(
            csc, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.1, options={"SymmetricMode": True}
        )
    return spla.splu(csc, permc_spec="COLAMD")


def dc_operating_point(system: DescriptorSystem, u0: NDArray[np.float64], where: str) -> NDArray[np.float64]:
    """Solve ``A x = −B u0``: the DC operating point (capacitors open, inductors shorted).

    Parameters
    ----------
    system : DescriptorSystem
    u0 : numpy.ndarray
        Source values (V, A).
    where : str
        File name for the error message.

    Returns
    -------
    numpy.ndarray
        Node voltages (V) and branch currents (A).

    Raises
    ------
    NetlistError
        The DC matrix is singular (a node that only capacitors reach, a loop
        of inductors and voltage sources...).
    """
    try:
        lu = _lu(system.A)
    except RuntimeError:
        raise NetlistError(
            "no DC operating point: the DC matrix is singular (a node reached only through capacitors "
            "or current sources, or a loop of inductors and voltage sources); use .tran ... UIC",
            SourceLocation(where, 0),
        ) from None
    x = lu.solve(-(system.B @ u0))
    residual = np.linalg.norm(system.A @ x + system.B @ u0)
    scale = abs(system.A) @ np.abs(x) + abs(system.B) @ np.abs(u0)
    if not np.all(np.isfinite(x)) or residual > 1e-8 * max(float(np.linalg.norm(scale)), 1e-300):
        raise NetlistError(
            "no DC operating point: the DC matrix is numerically singular", SourceLocation(where, 0)
        )
    return x


def pade_factors(order: int, diagonal: bool = False) -> tuple[tuple[complex, complex, float], ...]:
    """Factors (p, α, c) of the [order−1/order] (or [order/order]) Padé approximant of e^z.

    R(z) = Π (c + α/(z − p) + ᾱ/(z − p̄)); computed with mpmath in
    :mod:`netlistdyn.integrators` (stored there for order 12).
    """

    return stored(diagonal) if order == 12 else pade_factors_exact(order, diagonal)


class PadeStep:
    """One step of length h of ``E x' = A x + B u`` with u linear on the step.

    Parameters
    ----------
    system : DescriptorSystem
    h : float
        Step (s).
    order : int
        Padé denominator degree (even).
    diagonal : bool
        The [order/order] approximant (modulus 1 on the imaginary axis)
        instead of the L-stable [order−1/order]: used only to check steps.
    """

    def __init__(self, system: DescriptorSystem, h: float, order: int, diagonal: bool = False) -> None:
        self.h = h
        self.E = sp.csr_array(system.E)
        self.B = sp.csr_array(system.B)
        hA = sp.csc_array(system.A * h, dtype=complex)
        E = sp.csc_array(system.E, dtype=complex)
        self.factors = [(_lu(hA - p * E), p, a, c) for p, a, c in pade_factors(order, diagonal)]

    def __call__(self, x: NDArray[np.float64], u: NDArray[np.float64], s: NDArray[np.float64]) -> NDArray:
        """State after the step from x, with input u at its start and slope s (units/s)."""
        h = self.h
        for lu, p, alpha, c in self.factors:
            # (hM − p)⁻¹ on [x; u; s]: the input rows are upper triangular, then one sparse solve
            sb = -s / p
            ua = (h * sb - u) / p
            xs = lu.solve((self.E @ x) - h * (self.B @ ua))
            x = c * x + 2.0 * np.real(alpha * xs)
            u_new = c * u + 2.0 * np.real(alpha * ua)
            s = c * s + 2.0 * np.real(alpha * sb)
            u = u_new
        return x


class CFStep:
    """One step of ``E x' = A x + B u`` (u linear on the step) with a near-best approximant of e^x.

    ``r(z) = Σ 2·Re(c_j/(z − z_j))`` (:mod:`netlistdyn._cf_table`: CF poles,
    residues for the best maximum error on (−∞, 0] with ``r(0) = 1`` and
    ``r(−∞) = 0`` exactly) is within 2.3e-12 (degree 12) or 2.7e-14 (degree
    14) of e^z on the whole negative real axis, so on an RC circuit (real, non-positive
    spectrum of the pencil) a step of any length is accurate; off the axis
    (inductors) it is accurate only near 0, and the check halves the step.
    Applied in partial fractions: ``r(hM) y = r∞ y + Σ 2·Re(c_j (hA − z_j E)⁻¹ E y)``
    on the augmented ``[x; u; s]`` (input rows upper triangular as in
    :class:`PadeStep`), one complex sparse LU per conjugate pole pair.
    Strictly proper (``r∞ = 0``): the algebraic unknowns come out consistent
    with the input, as with the L-stable Padé approximant (a nonzero ``r∞``
    would carry ``r∞`` times their previous value, and two degrees would
    disagree by the difference whatever the step). A table entry with
    ``r∞ ≠ 0`` is still applied as written.

    Parameters
    ----------
    system : DescriptorSystem
    h : float
        Step (s).
    degree : int
        Type (degree, degree); one of :data:`netlistdyn.simulation._cf_table.CF`.
    """

    def __init__(
        self, system: DescriptorSystem, h: float, degree: int, steady: _Steady | None = None
    ) -> None:
        r_inf, pairs, _ = CF[degree]
        self.h = h
        self.r_inf = r_inf
        self.steady = steady
        self.E = sp.csr_array(system.E)
        self.B = sp.csr_array(system.B)
        hA = sp.csc_array(system.A * h, dtype=complex)
        E = sp.csc_array(system.E, dtype=complex)
        self.factors = [(_lu(hA - z * E), z, c) for z, c in pairs]

    def __call__(self, x: NDArray[np.float64], u: NDArray[np.float64], s: NDArray[np.float64]) -> NDArray:
        """State after the step from x, with input u at its start and slope s (units/s).

        With a steady-state solver, the step is taken on the deviation from the operating
        point ``x_u`` of the input u (``A x_u + B u = 0``, a fixed point of the exponential and
        of r, r(0) = 1): ``x_u + r(hM) [x − x_u; 0; s]``. The partial-fraction sum cancels
        terms ~30x its result; on the deviation (mV on a grid) instead of the supply level
        (1.8 V) its rounding shrinks in proportion (ibmpg1t: 2e-12 of 1.8 V at algebraic nodes,
        whatever the step, the floor of the check's rtol 1e-12).
        """
        h = self.h
        base = None if self.steady is None else self.steady(u)
        if base is not None:
            x = x - base
            u = np.zeros_like(u)
        Ex = self.E @ x
        out = self.r_inf * x
        for lu, z, c in self.factors:
            ua = (-h * s / z - u) / z
            out = out + 2.0 * np.real(c * lu.solve(Ex - h * (self.B @ ua)))
        return out if base is None else base + out


class _Steady:
    """Operating points ``x_u = −A⁻¹ B u`` from one real sparse LU of A (None where A is singular)."""

    def __init__(self, system: DescriptorSystem) -> None:
        self.B = sp.csr_array(system.B)
        try:
            self.lu: spla.SuperLU | None = _lu(system.A)
        except RuntimeError:
            self.lu = None
        self.last: tuple[bytes, NDArray[np.float64] | None] = (b"", None)

    def __call__(self, u: NDArray[np.float64]) -> NDArray[np.float64] | None:
        if self.lu is None:
            return None
        key = u.tobytes()
        if self.last[0] != key:  # the step and its check share u
            x = self.lu.solve(-(self.B @ u))
            self.last = (key, x if np.all(np.isfinite(x)) else None)
        return self.last[1]


class _Steppers:
    """Factorised steps by length (and kind), the least recently used dropped beyond a bound."""

    def __init__(
        self,
        system: DescriptorSystem,
        order: int,
        stats: dict[str, float],
        method: str = "pade",
        lengths: int = CACHE_LENGTHS,
    ) -> None:
        self.system = system
        self.order = order
        self.stats = stats
        self.method = method
        self.lengths = lengths
        #: For ``auto`` (CF first): the Padé steps tried where a CF check fails.
        self.fallback: _Steppers | None = None
        self.steady = _Steady(system) if method == "cf" else None
        self.cache: OrderedDict[tuple[float, str], PadeStep | CFStep] = OrderedDict()

    def __call__(self, h: float, kind: str = MAIN) -> PadeStep | CFStep:
        if self.method == "cf" and kind != MAIN:
            kind = LOW  # one check approximant for cf
        key = (float(f"{h:.13g}"), kind)
        step = self.cache.get(key)
        if step is None:
            tic = time.process_time()
            if self.method == "cf":  # one check for every kind: the lower degree
                step = CFStep(self.system, h, CF_DEGREE if kind == MAIN else CF_CHECK_DEGREE, self.steady)
            else:
                order = CHECK_ORDER if kind == LOW else self.order
                step = PadeStep(self.system, h, order, diagonal=kind == DIAGONAL)
            self.stats["factor_seconds"] += time.process_time() - tic
            self.stats["factorisations"] += len(step.factors)
            self.cache[key] = step
            if len(self.cache) > self.lengths:
                self.cache.popitem(last=False)
        else:
            self.cache.move_to_end(key)
        return step


@dataclass(frozen=True)
class TransientResult:
    """Outputs of a descriptor transient.

    Attributes
    ----------
    time : numpy.ndarray
        Output times (s).
    outputs : numpy.ndarray
        ``(len(time), noutputs)``; NaN from where the run failed.
    x_final : numpy.ndarray
        Unknowns at the last time reached.
    stats : dict
        Steps, checks, rejections, factorisations, CPU seconds by phase.
    status : str
        ``ok``, or ``failed`` with ``message`` saying why.
    message : str
        Why the run stopped early.
    """

    time: NDArray[np.float64]
    outputs: NDArray[np.float64]
    x_final: NDArray[np.float64]
    stats: dict[str, float]
    status: str = "ok"
    message: str = ""


def run_transient(
    system: DescriptorSystem,
    waveforms: Sequence[Waveform],
    times: NDArray[np.float64],
    x0: NDArray[np.float64] | None = None,
    *,
    uic: bool = False,
    rtol: float = DEFAULT_RTOL,
    order: int = DEFAULT_ORDER,
    where: str = "<netlist>",
    progress: Callable[[float], None] | None = None,
    method: str = DEFAULT_METHOD,
) -> TransientResult:
    """Simulate from the DC operating point (or x0 / zero with ``uic``) to ``times[-1]``.

    Each output interval is split at the breakpoints inside it; each piece
    is stepped with its length / 2^level. A step is checked against a second
    approximant from the same state, on the first step after a breakpoint
    (or an inconsistent UIC start) and every :data:`CHECK_INTERVAL`-th step.
    ``cf``: against the degree-:data:`CF_CHECK_DEGREE` CF approximant; both
    are near-exact on the real axis, so they disagree only where the step
    puts modes off the axis (inductors: lightly damped oscillations) at
    ``|hλ|`` they do not resolve. ``pade``: after a breakpoint against the
    [7/8] approximant (both L-stable, they damp the stiff modes the inputs
    excite by different factors, and agree to ~1e-13 where |hλ| ≲ 2),
    otherwise against the diagonal [12/12] one (it keeps the modulus of
    unresolved modes that the [11/12] damps). A difference above ``rtol`` of
    the largest voltage seen (currents through a typical node conductance,
    see :class:`_Scale`) halves the step and repeats it; a check passed by a
    factor 10 lets the step double again.

    Parameters
    ----------
    system : DescriptorSystem
    waveforms : sequence of Waveform
        One per input, resolved; piecewise linear (DC, PULSE, PWL).
    times : numpy.ndarray
        Increasing output times (s), starting at 0.
    x0 : numpy.ndarray, optional
        Initial unknowns (used as given, with ``uic`` semantics).
    uic : bool
        Start from zero (or x0) instead of the DC operating point.
    rtol : float
        Step check tolerance (0: no check, one step per piece); at least
        :data:`MIN_RTOL`.
    order : int
        Padé denominator degree (even).
    where : str
        File name for messages.
    progress : callable, optional
        Called with the fraction done.
    method : {"cf", "pade", "auto"}
        ``cf``: steps with the degree-:data:`CF_DEGREE` CF approximant
        (:class:`CFStep`), every check against degree :data:`CF_CHECK_DEGREE`;
        ``pade``: the [order−1/order] Padé approximant, checked as above;
        ``auto``: CF until a CF check fails where the same step with Padé
        passes Padé's own check; Padé from there on (checked as ``pade``).
        That is the only switch between methods: an explicit ``cf`` (or
        ``pade``) whose check fails down to steps of 2^-:data:`MAX_LEVEL` of
        an interval stops there with ``status`` "failed" and a message
        naming the time (for ``cf``, suggesting ``auto`` or ``pade``).

    Returns
    -------
    TransientResult
    """
    if method not in METHODS:
        raise ValueError(f"unknown stepping method {method!r}; choose from {', '.join(METHODS)}")
    values = SourceValues(waveforms)
    if not values.piecewise_linear():
        raise NetlistError(
            "the descriptor transient needs piecewise-linear sources (DC, PULSE, PWL)",
            SourceLocation(where, 0),
        )
    rtol = max(rtol, MIN_RTOL) if rtol > 0 else 0.0
    stats = {"steps": 0, "checks": 0, "rejected": 0, "factorisations": 0, "factor_seconds": 0.0}
    started = time.process_time()
    wall = time.perf_counter()
    status, message = "ok", ""
    with single_thread():
        u_start = values(0.0)
        if x0 is not None:
            x = np.asarray(x0, dtype=float).copy()
        elif uic:
            x = np.zeros(system.size)
        else:
            x = dc_operating_point(system, u_start, where)
        stats["dc_seconds"] = time.process_time() - started
        out = np.full((times.size, system.C.shape[0]), np.nan)
        jump = x0 is not None or uic
        first = _consistent(system, x, u_start, float(times[1] - times[0]), order) if jump else x
        out[0] = system.C @ first + system.D @ u_start
        steppers = _Steppers(system, order, stats, "pade" if method == "pade" else "cf")
        if method == "auto":
            steppers.fallback = _Steppers(system, order, stats, "pade", lengths=2)
            stats["fallback_steps"] = 0
        points = breakpoints(waveforms, float(times[-1]))
        ctl = _Control(rtol, _Scale(first, system))
        bp_index = 0
        for k in range(1, times.size):
            t_a, t_b = float(times[k - 1]), float(times[k])
            span = t_b - t_a
            lo = bp_index
            while bp_index < points.size and points[bp_index] < t_b - SNAP * span:
                bp_index += 1
            inner = points[lo:bp_index]
            inner = inner[inner > t_a + SNAP * span]
            at_break = jump or (lo > 0 and abs(points[lo - 1] - t_a) <= SNAP * span)
            while bp_index < points.size and points[bp_index] <= t_b + SNAP * span:
                bp_index += 1  # a corner on t_b: the next interval starts at a breakpoint
            pieces = np.concatenate([[t_a], inner, [t_b]])
            try:
                for j in range(pieces.size - 1):
                    check = at_break if j == 0 else True
                    x = _piece(x, float(pieces[j]), float(pieces[j + 1]), check, values, steppers, stats, ctl)
            except _CheckFailed as exc:
                status, message = "failed", _failure(method, float(exc.args[0]), rtol)
                break
            jump = False
            out[k] = system.C @ x + system.D @ values(t_b)
            if not np.all(np.isfinite(out[k])):
                status, message = "diverged", f"non-finite values at t = {t_b:g} s"
                break
            if progress is not None:
                progress(k / (times.size - 1))
    stats["seconds"] = time.perf_counter() - wall
    stats["cpu_seconds"] = time.process_time() - started
    stats["step_seconds"] = stats["cpu_seconds"] - stats["factor_seconds"] - stats["dc_seconds"]
    return TransientResult(times, out, x, stats, status, message)


class _Scale:
    """The yardstick of the step check: the largest voltage and current seen.

    Voltages and currents are made comparable through a typical node
    conductance G (the median of the nonzero diagonal of A on node rows): a
    current difference counts against max(|i|, G·|v|), a voltage difference
    against max(|v|, |i|/G), so a class that is still zero (no current
    flows at the operating point) is not judged against rounding noise.
    """

    def __init__(self, x: NDArray[np.float64], system: DescriptorSystem) -> None:
        self.current_rows = np.arange(system.size) >= system.nnodes
        diag = np.abs(system.A.diagonal()[: system.nnodes])
        diag = diag[diag > 0]
        self.g = float(np.median(diag)) if diag.size else 1.0
        self.v = 0.0
        self.i = 0.0
        self.update(x)

    def update(self, x: NDArray[np.float64]) -> None:
        ax = np.abs(x)
        if (~self.current_rows).any():
            self.v = max(self.v, float(ax[~self.current_rows].max()))
        if self.current_rows.any():
            self.i = max(self.i, float(ax[self.current_rows].max()))

    def error(self, dx: NDArray[np.float64]) -> float:
        """Largest difference relative to the yardstick of its kind."""
        ad = np.abs(dx)
        v_ref = max(self.v, self.i / self.g, 1e-300)
        i_ref = max(self.i, self.v * self.g, 1e-300)
        worst = 0.0
        for rows, ref in ((~self.current_rows, v_ref), (self.current_rows, i_ref)):
            if rows.any():
                worst = max(worst, float(ad[rows].max()) / ref)
        return worst


@dataclass
class _Control:
    """Step-size state carried from piece to piece."""

    rtol: float
    scale: _Scale
    since_check: int = 0
    level: int = 0
    coarser: bool = False
    wait: int = 0
    patience: int = 1
    #: ``auto``: Padé from the first step where CF failed its check and Padé passed its own.
    pade: bool = False


def _piece(
    x: NDArray[np.float64],
    t0: float,
    t1: float,
    check_first: bool,
    values: SourceValues,
    steppers: _Steppers,
    stats: dict[str, float],
    ctl: _Control,
) -> NDArray[np.float64]:
    """Step from t0 to t1 (no breakpoint inside) with steps (t1 − t0)/2^level, adapted by the check.

    A failed check halves the step and retries; a check passed by a factor
    10 doubles it at the next position a double step can start from (the
    doubled step is checked).

    Raises
    ------
    _CheckFailed
        The step would have to be shorter than (t1 − t0)/2^MAX_LEVEL.
    """
    span = t1 - t0
    pos = 0  # position in units of span / 2**MAX_LEVEL
    end = 1 << MAX_LEVEL
    level = 0 if check_first else ctl.level
    must_check = kind_first = check_first
    u0 = values(t0)
    while pos < end:
        trying = False
        if ctl.coarser and ctl.wait <= 0 and level > 0 and pos % (1 << (MAX_LEVEL - level + 1)) == 0:
            level -= 1  # the last checks passed by a wide margin: try a step twice as long
            must_check = trying = True
            ctl.coarser = False
        n_units = 1 << (MAX_LEVEL - level)
        h = span / (1 << level)
        s1 = t1 if pos + n_units >= end else t0 + (pos + n_units) * span / end
        u1 = values(s1)
        slope = (u1 - u0) / h
        active = steppers.fallback if ctl.pade and steppers.fallback is not None else steppers
        x_new = active(h)(x, u0, slope)
        stats["steps"] += 1
        ctl.since_check += 1
        if ctl.rtol > 0 and (must_check or ctl.since_check >= CHECK_INTERVAL):
            stats["checks"] += 1
            ctl.since_check = 0
            # After a breakpoint: the lower-order L-stable approximant (the stiff modes the
            # inputs excite are damped by both, by different factors); otherwise the diagonal
            # one (an unresolved, lightly damped oscillation keeps its modulus there only).
            other = active(h, LOW if kind_first else DIAGONAL)(x, u0, slope)
            ctl.scale.update(x_new)
            err = ctl.scale.error(x_new - other)
            if not err <= ctl.rtol and steppers.fallback is not None and not ctl.pade:
                # auto: the same step with Padé, checked as in the pade method, before halving;
                # if it passes, Padé from here on (CF failed at this step length: the steps
                # between checks would otherwise go on with CF unchecked)
                x_pade = steppers.fallback(h)(x, u0, slope)
                other = steppers.fallback(h, LOW if kind_first else DIAGONAL)(x, u0, slope)
                err_pade = ctl.scale.error(x_pade - other)
                if err_pade <= ctl.rtol:
                    x_new, err = x_pade, err_pade
                    ctl.pade = True
                    stats["fallback_steps"] += 1
            if not err <= ctl.rtol:
                stats["rejected"] += 1
                if trying:  # wait twice as long before the next attempt
                    ctl.patience = min(2 * ctl.patience, 1024)
                    ctl.wait = ctl.patience
                level += 1
                if level > MAX_LEVEL:
                    raise _CheckFailed(t0 + pos * span / end)
                must_check = True
                continue
            must_check = kind_first = False
            ctl.coarser = err < 0.1 * ctl.rtol
            ctl.wait -= 1
        x, u0, pos = x_new, u1, pos + n_units
    ctl.scale.update(x)
    ctl.level = level
    return x


class _CheckFailed(Exception):
    """The step check kept failing down to the shortest step allowed."""


def _failure(method: str, t: float, rtol: float) -> str:
    """The one-line message of a run whose step check failed down to 2^-MAX_LEVEL of an interval.

    An explicitly chosen ``cf`` is not switched to Padé behind the user's back
    (as ngspice's ``method=gear`` stops with "timestep too small" rather than
    going on with trap): the message says where and what to use instead.
    """
    where = f"at t = {t:.9g} s, down to steps of 2^-{MAX_LEVEL} of an interval"
    if method == "cf":
        return (
            f"CF's step check fails {where} (its rounding floor there is above rtol {rtol:g}): "
            "method 'auto' switches to Padé where CF fails, or use 'pade'"
        )
    return f"step check failing {where} (rtol {rtol:g})"


def _consistent(
    system: DescriptorSystem, x: NDArray[np.float64], u: NDArray[np.float64], h: float, order: int
) -> NDArray[np.float64]:
    """Unknowns at t = 0⁺ from a given (UIC) start, for the output at t = 0.

    One L-stable step of 1e-9·h at constant input: the approximant vanishes
    at infinity, so the algebraic unknowns come out consistent with the
    inputs, while charges and fluxes move by 1e-9·h times their rate. (The
    time stepping starts from the given unknowns themselves.)
    """
    return PadeStep(system, 1e-9 * h, order)(x, u, np.zeros_like(u))
