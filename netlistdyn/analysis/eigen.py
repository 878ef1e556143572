"""Eigenvalue analysis of a state matrix: modes, stability verdict, stiffness, trust.

Dense models use LAPACK's balanced QR algorithm twice — on A for the
large-magnitude eigenvalues and on A⁻¹ for the small ones — because the
absolute error of an eigenvalue from A is about eps·‖A‖·κ, which swamps an
eigenvalue far smaller than ‖A‖ (Circuit 1 with R = 1e-12 has |λ| from
5e-13 to 2e12). Each eigenvalue is reported with an estimated relative
error from its condition number. Large sparse models get their extreme
eigenvalues from ARPACK (largest magnitude, and smallest by shift-invert).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mpmath as mp
import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from netlistdyn.analysis.pencil import check_spectrum, quick_spectrum, structural_zeros
from netlistdyn.analysis.views import eigen_html, eigen_latex, eigen_text
from netlistdyn.base.formatting import Rendered
from netlistdyn.statespace.model import Pencil

EPS = float(np.finfo(float).eps)
#: Above this estimated relative error an eigenvalue is flagged as untrustworthy.
TRUST_RTOL = 1e-6
#: Models with more states than this get extreme eigenvalues only (unless all are asked for).
DENSE_LIMIT = 1000
#: Up to this many states each eigenvalue gets an error estimate (needs both eigenvector sets).
ESTIMATE_LIMIT = 600
#: Up to this many states, eigenvalues the double-precision estimate cannot vouch for are
#: recomputed in extended precision.
REFINE_LIMIT = 40
#: Digits used for the extended-precision recomputation.
REFINE_DIGITS = 50
#: How many eigenvalues of each end ARPACK computes for large models.
EXTREME_COUNT = 6


@dataclass(frozen=True, slots=True)
class Mode:
    """One eigenvalue and the quantities engineers read off it.

    Attributes
    ----------
    value : complex
        Eigenvalue λ (1/s). A real or imaginary part smaller than
        ``abs_error`` is reported as exactly zero.
    abs_error : float
        Estimated absolute error of λ (1/s): componentwise backward error of
        its residual × componentwise condition number, against the circuit
        equations when the model carries them (:mod:`netlistdyn.pencil`),
        else against A (``_error_estimates``); NaN when not estimated
        (sparse eigensolver).
    re_error, im_error : float
        Bounds on the errors of the real and imaginary parts (1/s), NaN
        when only ``abs_error`` is known. The stability verdict uses the
        real part's.
    """

    value: complex
    abs_error: float
    re_error: float = math.nan
    im_error: float = math.nan

    @property
    def real_error(self) -> float:
        """Bound on the error of Re λ (1/s): ``re_error`` when known, else ``abs_error``."""
        return self.re_error if math.isfinite(self.re_error) else self.abs_error

    @property
    def imag_error(self) -> float:
        """Bound on the error of Im λ (1/s): ``im_error`` when known, else ``abs_error``."""
        return self.im_error if math.isfinite(self.im_error) else self.abs_error

    @property
    def rel_error(self) -> float:
        """Estimated relative error |δλ|/|λ| (∞ for λ = 0)."""
        mag = abs(self.value)
        return self.abs_error / mag if mag else math.inf

    @property
    def natural_frequency(self) -> float:
        """ωn = |λ| (rad/s)."""
        return abs(self.value)

    @property
    def damping(self) -> float:
        """ζ = −Re λ / |λ| (dimensionless); NaN for λ = 0."""
        mag = abs(self.value)
        return -self.value.real / mag if mag else math.nan

    @property
    def time_constant(self) -> float:
        """τ = −1/Re λ (s); infinite when Re λ = 0, negative for growing modes."""
        return -1.0 / self.value.real if self.value.real else math.inf


@dataclass(frozen=True, repr=False)
class EigenAnalysis(Rendered):
    """Result of :func:`analyze_eigenvalues`.

    Attributes
    ----------
    modes : tuple of Mode
        Sorted by decreasing real part (slowest/least stable first).
    verdict : str
        ``"asymptotically stable"``, ``"marginally stable"``, ``"unstable"``
        or ``"undetermined"``.
    stiffness_ratio : float or None
        max |Re λ| / min |Re λ| over the decaying modes.
    method : str
        How the eigenvalues were computed.
    complete : bool
        False when only extreme eigenvalues were computed.
    warnings : tuple of str
        Eigenvalues that cannot be vouched for, and why.
    """

    modes: tuple[Mode, ...]
    verdict: str
    stiffness_ratio: float | None
    method: str
    complete: bool
    warnings: tuple[str, ...] = ()

    #: ``repr()``: the verdict and a table of the modes (λ, ωn in rad/s, fn in Hz, ζ, τ); HTML; LaTeX.
    RENDERERS = (eigen_text, eigen_html, eigen_latex)


def _eig(a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eigenvalues with left and right eigenvectors (LAPACK geev, balanced)."""
    w, vl, vr = sla.eig(a, left=True, right=True)
    return w, vl, vr


def _error_estimates(a: np.ndarray, w: np.ndarray, vl: np.ndarray, vr: np.ndarray) -> np.ndarray:
    """Absolute error estimate of each eigenvalue of ``a``, measured against ``a`` itself.

    Each entry of A comes from element values, so relative perturbations of
    the entries are the meaningful ones. Where the computed pair has a small
    componentwise (Oettli–Prager) backward error η = maxᵢ |A x − λ x|ᵢ /
    (|A||x| + |λ||x|)ᵢ, the estimate is max(η, eps) times the componentwise
    condition number |y|ᵀ|A||x| / |yᴴx|. Otherwise it falls back to the
    normwise estimate max(‖r‖/(‖A‖‖x‖), eps) · ‖A‖ / s with
    s = |yᴴx| / (‖y‖‖x‖). Never below eps·|λ|.
    """
    abs_a = np.abs(a)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        # An eigenvalue from A⁻¹ whose μ was 0 is ∞ here: its estimate comes out non-finite, and the
        # caller treats that as "no estimate" (not a warning on the user's terminal).
        residual = a @ vr - vr * w
        abs_x = np.abs(vr)
        denom = abs_a @ abs_x + np.abs(w) * abs_x
        ratio = np.where(denom > 0, np.abs(residual) / denom, np.where(residual == 0, 0.0, np.inf))
        eta_cw = np.max(ratio, axis=0)
        overlap = np.abs(np.einsum("ij,ij->j", vl.conj(), vr))
        cond_cw = np.einsum("ij,ij->j", np.abs(vl), abs_a @ abs_x) / overlap
        norm_a = np.linalg.norm(a, 2) if a.shape[0] <= 500 else np.linalg.norm(a, "fro")
        x_norm = np.linalg.norm(vr, axis=0)
        s = overlap / (np.linalg.norm(vl, axis=0) * x_norm)
        eta_nw = np.linalg.norm(residual, axis=0) / (norm_a * x_norm)
        normwise = np.maximum(eta_nw, EPS) * norm_a / s
        componentwise = np.maximum(eta_cw, EPS) * cond_cw
        estimate = np.where(eta_cw <= 1e-10, componentwise, normwise)
        return np.maximum(estimate, EPS * np.abs(w))


def _extended_precision(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues of the stored matrix in 50-digit arithmetic, with their data error.

    The computation itself is then exact to far below a double; what remains
    is the effect of the matrix entries' own rounding: eps times the
    componentwise condition number |y|ᵀ|A||x| / |yᵀx|, evaluated in the same
    extended precision (for a defective eigenvalue yᵀx cancels to ~1e-48,
    which double precision cannot see).
    """
    n = a.shape[0]
    # Balancing (a diagonal similarity by powers of 2: exact) shrinks ‖A‖, the computation's own
    # rounding level, without changing eigenvalues or componentwise condition numbers.
    a, _ = sla.matrix_balance(a, permute=False)
    with mp.workdps(REFINE_DIGITS):
        values, left, right = mp.eig(mp.matrix(a.tolist()), left=True, right=True)
        abs_a = mp.matrix([[abs(mp.mpf(v)) for v in row] for row in a.tolist()])
        w = np.array([complex(v) for v in values])
        abs_err = np.empty(n)
        for k in range(n):
            y = left[k, :]
            x = right[:, k]
            overlap = abs(sum(y[i] * x[i] for i in range(n)))
            weight = sum(abs(y[i]) * sum(abs_a[i, j] * abs(x[j]) for j in range(n)) for i in range(n))
            cond = weight / overlap if overlap > 0 else mp.inf
            abs_err[k] = float(mp.mpf(EPS) * cond) if cond != mp.inf else math.inf
        # A repeated eigenvalue has no meaningful per-vector condition number. When its cluster
        # is semisimple (A − λI loses exactly as much rank as the cluster has members, as for
        # parallel inductors' conserved currents), its error is first order: eps·‖A‖·n.
        norm = mp.mpf(float(np.max(np.sum(np.abs(a), axis=1))))
        first_order = EPS * float(norm) * n
        # A multiple root perturbed at 50 digits splits by up to ~10^-25: cluster at that level.
        tol = mp.mpf(10) ** (5 - REFINE_DIGITS // 2) * (1 + norm)
        for k in np.flatnonzero(~(abs_err <= first_order)).tolist():
            lam = values[k] if mp.im(values[k]) else mp.re(values[k])  # real: an mpf, for svd_r
            members = [j for j in range(n) if abs(values[j] - lam) <= tol]
            if len(members) < 2:
                continue
            shifted = mp.matrix(a.tolist()) - lam * mp.eye(n)
            singular = (
                mp.svd_c(shifted, compute_uv=False) if mp.im(lam) else mp.svd_r(shifted, compute_uv=False)
            )
            if sum(1 for v in singular if v <= tol) >= len(members):
                bound = first_order  # semisimple: first order
            else:  # defective at rounding level: a size-m block moves by (eps·‖A‖)^(1/m) (Hölder)
                m = len(members)
                bound = (EPS * float(norm)) ** (1.0 / m) * max(1.0, float(norm)) ** (1.0 - 1.0 / m)
            for j in members:
                abs_err[j] = min(abs_err[j], bound)
    # The extended-precision computation has its own rounding, ~10^-(digits-5)·‖A‖ (a structural
    # zero eigenvalue comes out as ±1e-52 at 50 digits): no eigenvalue is more accurate than that.
    computation = 10.0 ** (5 - REFINE_DIGITS) * float(np.max(np.sum(np.abs(a), axis=1)))
    return w, np.maximum(abs_err, computation)


def _accurate_inverse(a: np.ndarray) -> np.ndarray | None:
    """A⁻¹ when LAPACK can form it with a small backward error, else None."""
    n = a.shape[0]
    if n == 0:
        return None
    try:
        with np.errstate(all="ignore"):
            inv = np.linalg.inv(a)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(inv)):
        return None
    residual = np.linalg.norm(a @ inv - np.eye(n), 1)
    scale = np.linalg.norm(a, 1) * np.linalg.norm(inv, 1)
    return inv if residual <= 1e-10 * scale else None


#: Up to this many states each eigenvalue is checked against the circuit equations (the pencil).
PENCIL_LIMIT = 600


def _dense_modes(a: np.ndarray, pencil: Pencil | None = None) -> tuple[list[Mode], str, tuple[str, ...]]:
    n = a.shape[0]
    if pencil is not None and pencil.nstates < n:
        # Displacement integrators: A = [[A0, 0], [Cv, 0]], eigenvalues those of A0 and exact zeros.
        k, n0 = n - pencil.nstates, pencil.nstates
        modes, method, inner = _dense_modes(a[:n0, :n0], pencil) if n0 else ([], "no states", ())
        modes = modes + [Mode(0j, 0.0, 0.0, 0.0) for _ in range(k)]
        return modes, f"{method}; {k} displacement integrator(s): eigenvalue 0, exact", inner
    if n > ESTIMATE_LIMIT:
        values = np.linalg.eigvals(a)
        method = f"LAPACK geev (balanced QR) on A; no error estimates above {ESTIMATE_LIMIT} states"
        return [Mode(complex(v), math.nan) for v in values], method, ()
    w, vl, vr = _eig(a)
    method = "LAPACK geev (balanced QR) on A"
    inv = _accurate_inverse(a)
    if inv is not None and np.linalg.cond(a) > 1e4:
        # Small eigenvalues from A carry an absolute error of about eps·‖A‖; from A⁻¹
        # they come out without that cancellation. Keep the large ones from A and the
        # small ones from A⁻¹ (same eigenvectors), split at the geometric middle.
        mu, ul, ur = _eig(inv)
        with np.errstate(divide="ignore", invalid="ignore"):
            lam_inv = 1.0 / mu  # μ = 0 (unresolved) gives ∞ and is never kept
        order_a = np.argsort(-np.abs(w))
        order_i = np.argsort(-np.abs(lam_inv))
        split = math.sqrt(np.linalg.norm(a, 2) / np.linalg.norm(inv, 2))
        k = int(np.sum(np.abs(w) >= split))
        take_a, take_i = order_a[:k], order_i[k:]
        small_w = lam_inv[take_i].astype(complex)
        small_l, small_r = ul[:, take_i].astype(complex), ur[:, take_i].astype(complex)
        # An unresolved μ = 0 among the small ones (possible when no eigenvalue of A reaches the
        # split, k = 0) keeps A's own value for that place rather than ∞.
        lost = ~np.isfinite(small_w)
        if np.any(lost):
            from_a = order_a[k:][lost]
            small_w[lost], small_l[:, lost], small_r[:, lost] = w[from_a], vl[:, from_a], vr[:, from_a]
        w = np.concatenate([w[take_a].astype(complex), small_w])
        vl = np.concatenate([vl[:, take_a], small_l], axis=1)
        vr = np.concatenate([vr[:, take_a], small_r], axis=1)
        method = "LAPACK geev (balanced QR): large eigenvalues from A, small ones from A⁻¹"
    abs_err = _error_estimates(a, w, vl, vr)
    abs_err = np.where(np.isfinite(abs_err), abs_err, np.inf)
    re_err = np.full(n, math.nan)
    im_err = np.full(n, math.nan)
    checked = np.zeros(n, dtype=bool)
    notes: list[str] = []
    quick = quick_spectrum(pencil, w) if pencil is not None and n <= PENCIL_LIMIT else None
    if quick is not None:
        # Small and well conditioned: n distinct roots of the circuit equations, verified in double
        # precision with bars far below TRUST_RTOL (no 40-digit Newton needed).
        for k, quick_result in enumerate(quick):
            w[k], abs_err[k] = quick_result.value, quick_result.abs_error
            re_err[k], im_err[k] = quick_result.re_error, quick_result.im_error
        checked[:] = True
        method += (
            "; each checked and refined against the circuit equations in double precision "
            "(error bars in the element values)"
        )
    elif pencil is not None and n <= PENCIL_LIMIT:
        slots = check_spectrum(pencil, w, abs_err)
        w0, err0 = w.copy(), abs_err.copy()
        for k, (index, result) in enumerate(slots):
            if result is not None:
                w[k], abs_err[k] = result.value, result.abs_error
                re_err[k], im_err[k] = result.re_error, result.im_error
                checked[k] = True
            else:
                w[k], abs_err[k] = w0[index], err0[index]
        method += (
            "; each checked and refined against the circuit equations (error bars in the element values)"
        )
        # Zeros the topology guarantees (inductor loops, capacitor cutsets) are exact: the
        # smallest unverified eigenvalues are those.
        zeros = structural_zeros(pencil)
        if zeros:
            candidates = sorted(np.flatnonzero(~checked), key=lambda k: abs(w[k]))[:zeros]
            for k in candidates:
                w[k], abs_err[k], re_err[k], im_err[k] = 0.0, 0.0, 0.0, 0.0
                checked[k] = True
            method += f"; {len(candidates)} zero(s) exact by topology (conserved fluxes or charges)"
    with np.errstate(over="ignore"):  # a tiny eigenvalue's relative error may be inf, correctly
        rel = np.where(np.abs(w) > 0, abs_err / np.maximum(np.abs(w), 1e-300), np.inf)
    untrusted = ~checked & (rel > TRUST_RTOL)
    if n <= REFINE_LIMIT and np.any(untrusted):
        mp_w, mp_err = _extended_precision(a)
        free = list(range(n))
        for k in np.flatnonzero(untrusted):
            j = min(free, key=lambda i: abs(mp_w[i] - w[k]))
            free.remove(j)
            if mp_err[j] < abs_err[k]:  # never worse than its input
                w[k], abs_err[k] = mp_w[j], mp_err[j]
        method += f"; unverified ones recomputed in {REFINE_DIGITS}-digit arithmetic (mpmath)"
    if pencil is not None and n <= PENCIL_LIMIT:
        unchecked = [k for k in range(n) if not checked[k] and w[k] != 0]
        if unchecked:
            method += (
                f"; {len(unchecked)} not verified on the circuit equations (a multiple root, or Newton's "
                "method did not settle): bound from A alone"
            )
            # A's entries come out of the reduction with errors of about eps·‖A‖, not eps of each
            # entry: the componentwise bound covers the eigensolver only. An eigenvalue the circuit
            # equations could not confirm gets at least the normwise bound eps·‖A‖₂/s (s: the cosine
            # of its left and right vectors) — a second exact zero beside 1e11 1/s modes came out of
            # A as −1.36e-7 1/s with a componentwise bar of 3.6e-13.
            norm_a = np.linalg.norm(a, 2)
            for k in unchecked:
                overlap = abs(np.vdot(vl[:, k], vr[:, k])) / (
                    np.linalg.norm(vl[:, k]) * np.linalg.norm(vr[:, k])
                )
                normwise = EPS * norm_a / overlap if overlap > 0 else math.inf
                abs_err[k] = max(abs_err[k], normwise)
                re_err[k], im_err[k] = (
                    max(_finite_or(re_err[k], 0.0), normwise),
                    max(_finite_or(im_err[k], 0.0), normwise),
                )
        # Every eigenvalue the circuit equations did not confirm is named, whatever its bar: the
        # bar then comes from A alone, which cannot see what the reduction to A lost.
        notes.extend(
            f"eigenvalue {w[k]:.6g} ± {abs_err[k]:.1g} could not be verified on the circuit equations "
            "(a multiple root, or Newton's method did not settle): its bound is A's normwise one"
            for k in unchecked
        )
    # Parts below their own error bound are zero as far as the data can tell.
    re_bar = np.where(np.isfinite(re_err), re_err, abs_err)
    im_bar = np.where(np.isfinite(im_err), im_err, abs_err)
    re = np.where(np.abs(w.real) <= re_bar, 0.0, w.real)
    im = np.where(np.abs(w.imag) <= im_bar, 0.0, w.imag)
    modes = [
        Mode(complex(r, i), float(e), float(er), float(ei))
        for r, i, e, er, ei in zip(re, im, abs_err, re_err, im_err, strict=True)
    ]
    return modes, method, tuple(notes)


def largest_eigenvalues(a: sp.sparray, k: int, tol: float) -> np.ndarray:
    """The k largest-magnitude eigenvalues by ARPACK with a wide Krylov space.

    Returns what converged when ARPACK stops early (possibly nothing).
    """
    n = a.shape[0]
    try:
        return spla.eigs(
            sp.csc_matrix(a),
            k=k,
            which="LM",
            ncv=min(n - 1, 40),
            tol=tol,
            maxiter=5000,
            return_eigenvectors=False,
        )
    except spla.ArpackNoConvergence as exc:
        return np.asarray(exc.eigenvalues)


def _sparse_modes(a: sp.sparray) -> tuple[list[Mode], str]:
    """Slowest modes by shift-invert at 0 (one sparse LU), plus the spectral radius.

    The largest-magnitude end of an RLC ladder's spectrum is tightly
    clustered, which makes ARPACK crawl for many of them; two, with a wide
    Krylov space and rtol 1e-8, cost about as much as the shift-invert.
    """
    n = a.shape[0]
    k = min(EXTREME_COUNT, n - 2)
    op = sp.csc_matrix(a)
    small = spla.eigs(op, k=k, sigma=0.0, which="LM", return_eigenvectors=False)
    large = largest_eigenvalues(op, 2, 1e-8)
    values = np.concatenate([large, small])
    modes = [Mode(complex(v), math.nan) for v in values]
    method = (
        f"ARPACK: the {k} smallest in magnitude (shift-invert at 0) and the 2 largest "
        f"(of {n}); use --eig all for every eigenvalue"
    )
    return modes, method


def _verdict(modes: list[Mode], complete: bool, a: np.ndarray | None) -> str:
    """Stability from each eigenvalue's real part against that part's own error bound."""
    if not complete:
        return "undetermined"
    if not modes:
        return "asymptotically stable"
    if any(m.value.real > m.real_error for m in modes):
        return "unstable"
    axis = [m for m in modes if abs(m.value.real) <= m.real_error]
    if not axis:
        return "asymptotically stable"
    if _unresolved_zeros(modes):
        return "undetermined"
    # Marginal only if every eigenvalue on the imaginary axis is semisimple. Eigenvalues are
    # told apart by their own error bars (not by a fraction of ‖A‖, which would merge a 1 rad/s
    # mode with a 1e10 rad/s one's neighbourhood).
    if a is not None:
        for cluster in _clusters(axis):
            if len(cluster) < 2:
                continue
            if _nullity(a, complex(0.0, float(np.mean([m.value.imag for m in cluster]))), cluster) < len(
                cluster
            ):
                return "unstable"
    return "marginally stable"


def _clusters(modes: list[Mode]) -> list[list[Mode]]:
    """Groups of eigenvalues whose error discs overlap (transitively)."""
    parent = list(range(len(modes)))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, mi in enumerate(modes):
        for j in range(i + 1, len(modes)):
            mj = modes[j]
            bound = _finite_or(mi.abs_error, 0.0) + _finite_or(mj.abs_error, 0.0)
            if abs(mi.value - mj.value) <= bound:
                parent[root(i)] = root(j)
    groups: dict[int, list[Mode]] = {}
    for i, m in enumerate(modes):
        groups.setdefault(root(i), []).append(m)
    return list(groups.values())


def _finite_or(value: float, default: float) -> float:
    return value if math.isfinite(value) else default


def _nullity(a: np.ndarray, lam: complex, cluster: list[Mode]) -> int:
    """Dimension of the null space of A − λI, judged on the balanced matrix.

    A singular value counts as zero below the cluster's own error bound or
    the rounding level n·eps·‖A_bal‖, whichever is larger.
    """
    balanced, _ = sla.matrix_balance(a, permute=False)
    n = a.shape[0]
    shifted = balanced - lam * np.eye(n)
    values = sla.svdvals(shifted)
    tol = max(
        max(_finite_or(m.abs_error, 0.0) for m in cluster) * len(cluster),
        n * EPS * float(np.linalg.norm(balanced, 2)),
    )
    return int(np.sum(values <= tol))


def _unresolved_zeros(modes: list[Mode]) -> list[Mode]:
    """Eigenvalues reported as 0 whose error could hide a real eigenvalue.

    A zero is vouched for when its error estimate is below 1e-6 of the
    smallest nonzero eigenvalue's magnitude (an exact structural zero, as
    for two inductors in parallel, has an error near the roundoff of the
    others); otherwise the spectrum near 0 is not resolved.
    """
    nonzero = [abs(m.value) for m in modes if m.value != 0]
    floor = min(nonzero) if nonzero else 1.0
    return [
        m for m in modes if m.value == 0 and (not math.isfinite(m.abs_error) or m.abs_error > 1e-6 * floor)
    ]


def _cover_data_error(modes: list[Mode], a: np.ndarray, data_error: float) -> list[Mode]:
    """Widen each error estimate to data_error / s (s = |yᴴx| / (‖y‖‖x‖)), then re-zero small parts.

    ``data_error`` is a normwise perturbation the matrix itself may carry
    (for instance from a model reduction): first-order perturbation theory
    moves a simple eigenvalue by up to data_error / s.
    """
    w, vl, vr = _eig(a)
    norms = np.linalg.norm(vl, axis=0) * np.linalg.norm(vr, axis=0)
    s = np.abs(np.einsum("ij,ij->j", vl.conj(), vr)) / norms
    out = []
    for m in modes:
        k = int(np.argmin(np.abs(w - m.value)))
        err = max(m.abs_error, data_error / s[k] if s[k] > 0 else math.inf)
        re_err = max(m.real_error, err)
        im_err = max(m.imag_error, err)
        re = 0.0 if abs(m.value.real) <= re_err else m.value.real
        im = 0.0 if abs(m.value.imag) <= im_err else m.value.imag
        out.append(Mode(complex(re, im), err, re_err, im_err))
    return out


def analyze_eigenvalues(
    a: sp.sparray | np.ndarray,
    which: str = "auto",
    data_error: float = 0.0,
    pencil: Pencil | None = None,
) -> EigenAnalysis:
    """Eigenvalues of A with stability verdict, stiffness ratio and trust warnings.

    Parameters
    ----------
    a : array or sparse matrix
        Square state matrix (1/s).
    which : {"auto", "all", "extreme"}
        ``auto``: all eigenvalues up to :data:`DENSE_LIMIT` states, extreme
        ones above.
    data_error : float
        Normwise error (1/s) that the entries of ``a`` already carry, e.g.
        from a model reduction (:func:`netlistdyn.analysis.control.minimal_realisation`);
        every eigenvalue's error estimate is widened to cover it.
    pencil : Pencil, optional
        The circuit equations A was reduced from (``model.pencil``). When
        given, each eigenvalue is checked and refined against them, so its
        error bar covers the reduction to A as well as the eigensolver.

    Returns
    -------
    EigenAnalysis
    """
    n = a.shape[0]
    complete = which == "all" or (which == "auto" and n <= DENSE_LIMIT) or n <= 2 * EXTREME_COUNT + 2
    dense = None
    notes: tuple[str, ...] = ()
    if complete:
        dense = a.toarray() if isinstance(a, sp.sparray | sp.spmatrix) else np.asarray(a, dtype=float)
        modes, method, notes = _dense_modes(dense, pencil) if n else ([], "no states", ())
        if data_error > 0 and n:
            modes = _cover_data_error(modes, dense, data_error)
    else:
        modes, method = _sparse_modes(a)
    modes.sort(key=lambda m: (-m.value.real, -m.value.imag))
    verdict = _verdict(modes, complete, dense)
    decaying = [abs(m.value.real) for m in modes if m.value.real < 0]
    stiffness = max(decaying) / min(decaying) if decaying and complete else None
    warnings = (
        tuple(
            f"eigenvalue {m.value:.6g} may be inaccurate: estimated relative error {m.rel_error:.1e} "
            "(residual backward error × componentwise condition number)"
            for m in modes
            if math.isfinite(m.rel_error) and m.rel_error > TRUST_RTOL
        )
        + tuple(
            f"eigenvalue {m.value:.6g} is defective or ill-conditioned (no error estimate)"
            for m in modes
            if complete and not math.isfinite(m.rel_error) and m.value != 0
        )
        + notes
    )
    return EigenAnalysis(tuple(modes), verdict, stiffness, method, complete, warnings)
