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

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

EPS = float(np.finfo(float).eps)
#: Above this estimated relative error an eigenvalue is flagged as untrustworthy.
TRUST_RTOL = 1e-6
#: Models with more states than this get extreme eigenvalues only (unless all are asked for).
DENSE_LIMIT = 3000
#: How many eigenvalues of each end ARPACK computes for large models.
EXTREME_COUNT = 6


@dataclass(frozen=True, slots=True)
class Mode:
    """One eigenvalue and the quantities engineers read off it.

    Attributes
    ----------
    value : complex
        Eigenvalue λ (1/s).
    rel_error : float
        Estimated relative error of λ (condition number × unit roundoff × norm).
    """

    value: complex
    rel_error: float

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

    @property
    def frequency_hz(self) -> float:
        """Damped oscillation frequency |Im λ|/(2π) (Hz)."""
        return abs(self.value.imag) / (2 * math.pi)


@dataclass(frozen=True)
class EigenAnalysis:
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


def _eig_with_condition(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues and absolute error bounds eps·‖A‖·κ(λ) (LAPACK geev, balanced)."""
    w, vl, vr = sla.eig(a, left=True, right=True)
    norm = np.linalg.norm(a, 2) if a.shape[0] <= 500 else np.linalg.norm(a, "fro")
    s = np.abs(np.einsum("ij,ij->j", vl.conj(), vr))
    s = s / (np.linalg.norm(vl, axis=0) * np.linalg.norm(vr, axis=0))
    with np.errstate(divide="ignore"):
        bound = np.where(s > 0, EPS * norm / s, np.inf)
    return w, bound


def _accurate_inverse(a: np.ndarray) -> np.ndarray | None:
    """A⁻¹ when it exists with a small backward error, else None.

    Accepted when ‖A·X − I‖ ≤ 1e-10 ‖A‖ ‖X‖ (1-norms), i.e. X is the exact
    inverse of a matrix within 1e-10 of A, relatively.
    """
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


def _dense_modes(a: np.ndarray) -> tuple[list[Mode], str]:
    n = a.shape[0]
    w, bound = _eig_with_condition(a)
    rel = np.where(np.abs(w) > 0, bound / np.maximum(np.abs(w), 1e-300), np.inf)
    method = "LAPACK geev (balanced QR) on A"
    inv = _accurate_inverse(a)
    if inv is not None and np.linalg.cond(a) > 1e4:
        mu, bound_inv = _eig_with_condition(inv)
        with np.errstate(divide="ignore", invalid="ignore"):
            lam_inv = 1.0 / mu  # μ = 0 (unresolved tiny μ) gives ∞ and is never kept
            rel_inv = bound_inv / np.abs(mu)
        order_a = np.argsort(-np.abs(w))
        order_i = np.argsort(-np.abs(lam_inv))
        # Split the spectrum where the two estimates are equally good: keep the large
        # eigenvalues from A and the small ones from A⁻¹ (no cancellation either way).
        split = math.sqrt(np.linalg.norm(a, 2) / np.linalg.norm(inv, 2))
        k = int(np.sum(np.abs(w) >= split))
        w = np.concatenate([w[order_a[:k]], lam_inv[order_i[k:]]])
        rel = np.concatenate([rel[order_a[:k]], rel_inv[order_i[k:]]])
        method = "LAPACK geev (balanced QR): large eigenvalues from A, small ones from A⁻¹"
    return [Mode(complex(v), float(e)) for v, e in zip(w, rel, strict=True)], method


def _sparse_modes(a: sp.sparray) -> tuple[list[Mode], str]:
    n = a.shape[0]
    k = min(EXTREME_COUNT, n - 2)
    op = sp.csc_matrix(a)
    large = spla.eigs(op, k=k, which="LM", return_eigenvectors=False)
    small = spla.eigs(op, k=k, sigma=0.0, which="LM", return_eigenvectors=False)
    values = np.concatenate([large, small])
    modes = [Mode(complex(v), math.nan) for v in values]
    return modes, f"ARPACK: {k} largest and {k} smallest in magnitude (of {n})"


def _verdict(modes: list[Mode], a_norm: float, complete: bool, a: np.ndarray | None) -> str:
    if not complete:
        return "undetermined"
    if not modes:
        return "asymptotically stable"
    tol = [max(abs(m.value) * (m.rel_error if math.isfinite(m.rel_error) else 1.0),
               100 * EPS * abs(m.value)) for m in modes]
    unstable = any(m.value.real > t for m, t in zip(modes, tol, strict=True))
    if unstable:
        return "unstable"
    axis = [m for m, t in zip(modes, tol, strict=True) if abs(m.value.real) <= t]
    if not axis:
        return "asymptotically stable"
    # Marginal only if every eigenvalue on the imaginary axis is semisimple.
    if a is not None:
        scale = max(a_norm, 1.0)
        for mode in axis:
            lam = complex(0.0, mode.value.imag)
            alg = sum(1 for m in axis if abs(m.value - mode.value) <= 1e-8 * scale)
            shifted = a - lam * np.eye(a.shape[0])
            geo = a.shape[0] - np.linalg.matrix_rank(shifted, tol=1e-9 * scale)
            if geo < alg:
                return "unstable"
    return "marginally stable"


def analyze_eigenvalues(a: sp.sparray | np.ndarray, which: str = "auto") -> EigenAnalysis:
    """Eigenvalues of A with stability verdict, stiffness ratio and trust warnings.

    Parameters
    ----------
    a : array or sparse matrix
        Square state matrix (1/s).
    which : {"auto", "all", "extreme"}
        ``auto``: all eigenvalues up to :data:`DENSE_LIMIT` states, extreme
        ones above.

    Returns
    -------
    EigenAnalysis
    """
    n = a.shape[0]
    complete = which == "all" or (which == "auto" and n <= DENSE_LIMIT) or n <= 2 * EXTREME_COUNT + 2
    dense = None
    if complete:
        dense = a.toarray() if sp.issparse(a) else np.asarray(a, dtype=float)
        modes, method = _dense_modes(dense) if n else ([], "no states")
    else:
        modes, method = _sparse_modes(a)
    modes.sort(key=lambda m: (-m.value.real, -m.value.imag))
    a_norm = float(np.linalg.norm(dense, 1)) if dense is not None and n else 0.0
    verdict = _verdict(modes, a_norm, complete, dense)
    decaying = [abs(m.value.real) for m in modes if m.value.real < 0]
    stiffness = max(decaying) / min(decaying) if decaying and complete else None
    warnings = tuple(
        f"eigenvalue {m.value:.6g} may be inaccurate: estimated relative error {m.rel_error:.1e} "
        "(eps·‖A‖ × eigenvalue condition number)"
        for m in modes if math.isfinite(m.rel_error) and m.rel_error > TRUST_RTOL
    ) + tuple(
        f"eigenvalue {m.value:.6g} is defective or ill-conditioned (no error estimate)"
        for m in modes if complete and not math.isfinite(m.rel_error) and m.value != 0
    )
    return EigenAnalysis(tuple(modes), verdict, stiffness, method, complete, warnings)
