"""Control analysis of a compiled model: controllability, observability, minimal
realisation, transfer functions and canonical forms.

Tolerance policy
----------------
Every rank decision here is invariant under diagonal scaling of the states,
inputs and outputs (any choice of units) and under scaling of time (all time
constants × 10^k), because each one is made on an equilibrated problem:

* The eigenvalues come from :func:`netlistdyn.analysis.eigen.analyze_eigenvalues`
  with their error estimates; eigenvalues closer than their errors form one
  cluster (a repeated eigenvalue).
* For each cluster λ the Hautus (PBH) matrix [A − λI, B] is equilibrated by
  rows and columns (Curtis–Reid: the diagonal scaling that brings the
  logarithms of the entries' magnitudes, with |A_kk| + |λ| on the diagonal,
  closest to zero in the least-squares sense). The scaled problem is the
  same whatever units the model is written in, and its rank is unchanged.
* The left singular vectors of the scaled A − λI for its smallest singular
  values span the left eigenspace; a mode is uncontrollable when the cosine
  between such a vector and every scaled column of B, |wᴴb| / (‖w‖‖b‖), is
  below ``max(RANK_RTOL, 100·n·eps / gap)``, gap being the next singular
  value of the scaled A − λI relative to the largest (the eigenvector's own
  rounding error). Observability is the dual test on [A − λI; C].
* A Jordan chain shows one vector at a time, so the modes found are deflated
  (projected out orthogonally in Curtis–Reid-scaled state coordinates) and
  the test repeated on the rest until nothing more is found. ``minimal``
  deflates with the same tests, so ``--minimal`` removes exactly the modes
  that ``--control`` reports.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import connected_components

from netlistdyn.analysis.eigen import analyze_eigenvalues
from netlistdyn.base.errors import UsageError
from netlistdyn.statespace.model import CompileInfo, StateSpaceModel

EPS = float(np.finfo(float).eps)
#: Smallest cosine tolerance of the PBH tests (scale-free: see the module docstring).
RANK_RTOL = 1e-11
#: Largest model for --control and --minimal (one SVD of the equilibrated A − λI per eigenvalue).
CONTROL_STATE_LIMIT = 200
#: Singular values of the equilibrated A − λI below this fraction of the largest span the eigenspace.
NULL_RTOL = 1e-9


# --- scale-free building blocks -----------------------------------------------------------------


def _solve_log_system(system: sp.csr_array, rhs: np.ndarray) -> np.ndarray:
    """Least-squares solution of a scaling problem in logarithms, with the gauge fixed at zero mean.

    The normal equations are a graph Laplacian (singular along one constant
    vector per connected part); a ridge of 1e-12 of its largest diagonal entry
    picks the minimum-norm solution to that relative accuracy. One sparse LU.
    """
    normal = (system.T @ system).tocsc()
    ridge = 1e-12 * float(normal.diagonal().max())
    normal = normal + ridge * sp.identity(normal.shape[0], format="csc")
    return np.asarray(spla.splu(normal).solve(system.T @ rhs))


def _log_least_squares(
    rows: np.ndarray, cols: np.ndarray, values: np.ndarray, nrow: int, ncol: int
) -> tuple[np.ndarray, np.ndarray]:
    """Minimise Σ (log|v| + x_row + y_col)² over the given entries; return exp(x), exp(y).

    These are row and column scalings that equilibrate a matrix (Curtis–Reid);
    the minimiser shifts exactly with any prior diagonal scaling, so the
    scaled matrix does not depend on it.
    """
    k = rows.size
    if k == 0:
        return np.ones(nrow), np.ones(ncol)
    index = np.arange(k)
    system = sp.csr_array(
        (np.ones(2 * k), (np.concatenate([index, index]), np.concatenate([rows, nrow + cols]))),
        shape=(k, nrow + ncol),
    )
    x = _solve_log_system(system, -np.log(values))
    return np.exp(x[:nrow]), np.exp(x[nrow:])


def equilibrate(magnitude: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Row and column scalings r, c of a non-negative matrix (Curtis–Reid, in logarithms).

    ``r[:, None] * magnitude * c[None, :]`` has entries as close to 1 as a
    diagonal scaling allows; the result is the same for every diagonally
    scaled version of ``magnitude``.
    """
    i, j = np.nonzero(magnitude)
    return _log_least_squares(i, j, magnitude[i, j], *magnitude.shape)


def state_scaling(A: np.ndarray, B: np.ndarray, C: np.ndarray) -> np.ndarray:
    """Diagonal state scaling S (x = S x̃) that equilibrates S⁻¹AS, S⁻¹B·U, Y⁻¹·C S.

    The least-squares problem in logarithms has one unknown per state, input
    and output (inputs and outputs may be rescaled freely, so only the
    relative sizes within a column of B or a row of C constrain S). The
    diagonal of A is unaffected and takes no part.
    """
    n, m, p = A.shape[0], B.shape[1], C.shape[0]
    rows, cols, vals = [], [], []
    k, q = np.nonzero(A)
    off = k != q
    rows.append(k[off])
    cols.append(q[off])
    vals.append(np.abs(A[k[off], q[off]]))
    k, j = np.nonzero(B)
    rows.append(k)
    cols.append(n + j)
    vals.append(np.abs(B[k, j]))
    i, q = np.nonzero(C)
    rows.append(n + m + i)
    cols.append(q)
    vals.append(np.abs(C[i, q]))
    r, c = np.concatenate(rows), np.concatenate(cols)
    v = np.concatenate(vals)
    if r.size == 0:
        return np.ones(n)
    # entry scale factor exp(x_col − x_row): one unknown per node of a graph on n + m + p nodes
    total = n + m + p
    index = np.arange(r.size)
    system = sp.csr_array(
        (
            np.concatenate([-np.ones(r.size), np.ones(r.size)]),
            (np.concatenate([index, index]), np.concatenate([r, c])),
        ),
        shape=(r.size, total),
    )
    x = _solve_log_system(system, -np.log(v))
    return np.exp(x[:n] - np.mean(x[:n]))


def _scaled(A: np.ndarray, B: np.ndarray, C: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    S = state_scaling(A, B, C)
    return A * S[None, :] / S[:, None], B / S[:, None], C * S[None, :]


@dataclass(frozen=True)
class _Mode:
    value: complex
    error: float
    multiplicity: int
    states: np.ndarray  # indices of the states of the connected parts of A it lives in


def _clusters(A: np.ndarray) -> list[_Mode]:
    """Distinct eigenvalues of A (upper half plane and real axis) with multiplicities.

    A is split into its independent parts (connected components of the graph
    of its off-diagonal entries); each part's eigenvalues come from
    :func:`~netlistdyn.analysis.eigen.analyze_eigenvalues` with error estimates.
    Eigenvalues closer than ten times the sum of their errors (and never
    closer than 1e-12 relative) are one repeated eigenvalue, which may span
    several parts.
    """
    n = A.shape[0]
    if n == 0:
        return []
    count, label = connected_components(sp.csr_array(A != 0), directed=True, connection="weak")
    values, errors, owner = [], [], []
    for part in range(count):
        idx = np.flatnonzero(label == part)
        for mode in analyze_eigenvalues(A[np.ix_(idx, idx)], "all").modes:
            values.append(mode.value)
            errors.append(mode.abs_error if math.isfinite(mode.abs_error) else 0.0)
            owner.append(part)
    vals, errs = np.array(values, dtype=complex), np.array(errors)
    parent = list(range(n))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i in range(n):
        for j in range(i + 1, n):
            gap = abs(vals[i] - vals[j])
            if gap <= 10 * (errs[i] + errs[j]) + 1e-12 * max(abs(vals[i]), abs(vals[j])):
                parent[find(i)] = find(j)
    groups: dict[int, list[int]] = {}
    for i in range(n):
        groups.setdefault(find(i), []).append(i)
    out = []
    for members in groups.values():
        lam = complex(np.mean(vals[members]))
        err = float(errs[members].max(initial=0.0))
        if lam.imag < -err:
            continue  # the conjugate cluster stands for both
        if abs(lam.imag) <= err:
            lam = complex(lam.real, 0.0)
        states = np.flatnonzero(np.isin(label, [owner[i] for i in members]))
        out.append(_Mode(lam, err, len(members), states))
    return sorted(out, key=lambda m: (-m.value.real, -m.value.imag))


def _cleaned(M: np.ndarray, n: int, scale: np.ndarray | None = None) -> np.ndarray:
    """Entries at the rounding level of an orthogonal transformation set to 0.

    The level is 10·n·eps times ``scale`` (broadcast against M: the norms of
    B's columns or C's rows before the transformation mixed them), or for A
    the larger norm of the entry's row and column.
    """
    if scale is None:
        scale = np.maximum(np.linalg.norm(M, axis=1)[:, None], np.linalg.norm(M, axis=0)[None, :])
    return np.where(np.abs(M) <= 10 * max(n, 1) * EPS * scale, 0.0, M)


def _complement(W: np.ndarray) -> np.ndarray:
    """Orthonormal basis of the complement of span(W) that stays close to the coordinate axes.

    Householder QR of W with its rows ordered by importance (QR with column
    pivoting of Wᵀ): a vector concentrated on a few states removes those and
    leaves the other states nearly untouched, so the reduced model keeps the
    sparsity and scaling of the original.
    """
    n, k = W.shape
    if k >= n:
        return np.zeros((n, 0))
    _, _, perm = sla.qr(W.T, mode="economic", pivoting=True)
    order = np.concatenate([perm, np.setdiff1d(np.arange(n), perm, assume_unique=False)])
    Q, _ = sla.qr(W[order], mode="full")
    out = np.empty((n, n - k))
    out[order] = Q[:, k:]
    return out


@dataclass(frozen=True)
class _Test:
    """Outcome of one PBH test at one eigenvalue cluster."""

    deficiency: int
    vectors: np.ndarray  # left (controllability) null vectors, original coordinates, one per column
    margin: float  # smallest kept cosine / tolerance (> 1: decided with room)


def _deficient(basis: np.ndarray, targets: np.ndarray, tol: float) -> tuple[int, np.ndarray, float]:
    """Combinations of the basis orthogonal to every (normalised) target column.

    Returns how many there are, the combined vectors and the margin of the
    smallest kept cosine over ``tol``.
    """
    k = basis.shape[1]
    norms = np.linalg.norm(targets, axis=0)
    used = norms > 0
    if not np.any(used):
        return k, basis, math.inf
    cosines = basis.conj().T @ (targets[:, used] / norms[used])
    P, sv, _ = sla.svd(cosines)  # P: k × k
    rank = int(np.sum(sv > tol))
    margin = float(sv[:rank].min() / tol) if rank else math.inf
    return k - rank, basis @ P[:, rank:], margin


def _pbh(
    A: np.ndarray, B: np.ndarray, C: np.ndarray, lam: complex, multiplicity: int, tol: float
) -> tuple[_Test, _Test]:
    """Both PBH tests at one eigenvalue cluster, on the equilibrated [A − λI, B; C, 0].

    Returns the controllability test (left null vectors w of A − λI with
    wᴴB = 0) and the observability test (right null vectors v with Cv = 0),
    vectors in the model's coordinates.
    """
    n = A.shape[0]
    magnitude = np.block(
        [[np.abs(A) + abs(lam) * np.eye(n), np.abs(B)], [np.abs(C), np.zeros((C.shape[0], B.shape[1]))]]
    )
    r, c = equilibrate(magnitude)
    r, c = r[:n], c[:n]
    shifted = (A - lam * np.eye(n)) if lam.imag else (A - lam.real * np.eye(n))
    U, s, Vh = sla.svd(shifted * r[:, None] * c[None, :])
    # Null is relative to the size of the entries (the equilibrated |A| + |λ|I), not to the largest
    # singular value of A − λI: when A is λI up to rounding (equal time constants in decoupled
    # parts), every singular value is rounding and all of them span the eigenspace.
    scale = float(np.linalg.norm(magnitude[:n, :n] * r[:, None] * c[None, :], 2))
    top = max(s[0], scale) if max(s[0], scale) > 0 else 1.0
    k = int(np.clip(np.sum(s <= NULL_RTOL * top), 1, max(1, multiplicity)))
    gap = s[n - k - 1] / top if n - k - 1 >= 0 else 1.0
    tol = max(tol, 100 * n * EPS / max(gap, 1e-300))
    left, right = U[:, n - k :], Vh[n - k :].conj().T
    dc, wc, mc = _deficient(left, B * r[:, None], tol)
    do, vo, mo = _deficient(right, (C * c[None, :]).conj().T, tol)
    return _Test(dc, wc * r[:, None], mc), _Test(do, vo * c[:, None], mo)


def _real_basis(vectors: Sequence[np.ndarray], n: int) -> np.ndarray:
    """Orthonormal real basis of the span of the vectors and their conjugates."""
    if not vectors:
        return np.zeros((n, 0))
    stacked = np.hstack([np.hstack([v.real, v.imag]) if np.iscomplexobj(v) else v for v in vectors])
    stacked = stacked[:, np.linalg.norm(stacked, axis=0) > 0]
    if stacked.shape[1] == 0:
        return np.zeros((n, 0))
    stacked = stacked / np.linalg.norm(stacked, axis=0)
    U, s, _ = sla.svd(stacked, full_matrices=False)
    return U[:, : int(np.sum(s > 1e-8 * s[0]))]


@dataclass(frozen=True)
class Reduction:
    """What a deflation removed, and the model that remains.

    Attributes
    ----------
    A, B, C : numpy.ndarray
        The remaining realisation (states are orthonormal combinations of
        scaled original states).
    uncontrollable, unobservable : tuple of complex
        The removed eigenvalues (1/s), one entry per state removed, conjugates
        listed separately.
    backward_error : float
        Relative size (to ‖A‖) of the couplings the deflation treated as zero,
        plus its rounding: the reduced A is the exact reduction of a model
        within this relative distance.
    margin : float
        Smallest ratio of a kept cosine to its tolerance over all tests
        (close to 1: the decision was close).
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    uncontrollable: tuple[complex, ...]
    unobservable: tuple[complex, ...]
    backward_error: float
    margin: float

    @property
    def data_error(self) -> float:
        """Normwise error (1/s) of the reduced A: backward_error · ‖A‖₂ (for eigenvalue estimates)."""
        return self.backward_error * float(np.linalg.norm(self.A, 2)) if self.A.size else 0.0


def _copies(mode: _Mode, count: int) -> list[complex]:
    if mode.value.imag:
        return [mode.value, mode.value.conjugate()] * count
    return [mode.value] * count


def deflate(
    A: np.ndarray,
    B: np.ndarray,
    C: np.ndarray,
    controllable: bool,
    observable: bool,
    tol: float = RANK_RTOL,
) -> Reduction:
    """Remove uncontrollable (``controllable=True``) and/or unobservable modes until none is left.

    Parameters
    ----------
    A, B, C : numpy.ndarray
        The realisation (any units).
    controllable, observable : bool
        Which kinds of mode to remove.
    tol : float
        Smallest cosine tolerance of the PBH tests.

    Returns
    -------
    Reduction
    """
    unc: list[complex] = []
    uno: list[complex] = []
    error = 0.0
    margin = math.inf
    A, B, C = (np.array(M, dtype=float) for M in (A, B, C))
    for _ in range(2 * A.shape[0] + 2):
        n = A.shape[0]
        if n == 0:
            break
        A, B, C = _scaled(A, B, C)
        clusters = _clusters(A)
        tests = []
        for mode in clusters:
            idx = mode.states
            tests.append(_pbh(A[np.ix_(idx, idx)], B[idx], C[:, idx], mode.value, mode.multiplicity, tol))
        found = False
        for kind in ("c", "o"):
            if (kind == "c" and not controllable) or (kind == "o" and not observable):
                continue
            vectors, removed = [], []
            for mode, pair in zip(clusters, tests, strict=True):
                test = pair[0] if kind == "c" else pair[1]
                if test.deficiency:
                    full = np.zeros((n, test.vectors.shape[1]), dtype=test.vectors.dtype)
                    full[mode.states] = test.vectors
                    vectors.append(full)
                    removed += _copies(mode, test.deficiency)
                else:
                    margin = min(margin, test.margin)
            if not removed:
                continue
            W = _real_basis(vectors, n)
            if W.shape[1] == 0:
                continue
            Q = _complement(W)
            norm_a = max(float(np.linalg.norm(A, 2)), 1e-300)
            coupling = W.T @ A @ Q if kind == "c" else Q.T @ A @ W
            error += (np.linalg.norm(coupling, 2) if coupling.size else 0.0) / norm_a + 10 * n * EPS
            b_norms = np.linalg.norm(B, axis=0)[None, :]
            c_norms = np.linalg.norm(C, axis=1)[:, None]
            A, B, C = _cleaned(Q.T @ A @ Q, n), _cleaned(Q.T @ B, n, b_norms), _cleaned(C @ Q, n, c_norms)
            (unc if kind == "c" else uno).extend(removed[: W.shape[1]])
            found = True
            break
        if not found:
            break
    return Reduction(A, B, C, tuple(unc), tuple(uno), error, margin)


# --- structure and minimal realisation ------------------------------------------------------------


@dataclass(frozen=True)
class Structure:
    """Controllability and observability of a model.

    Attributes
    ----------
    uncontrollable, unobservable : tuple of complex
        Eigenvalues (1/s) that fail the PBH test, one entry per state that
        cannot be reached (or seen).
    ranks : tuple of int
        Dimensions of the controllable and the observable subspaces.
    nstates : int
    tolerance : float
        The smallest cosine tolerance of the PBH tests (module docstring).
    margin : float
        Smallest ratio of a passing mode's cosine to its tolerance: how far
        the closest "controllable/observable" decision was from the other
        answer (above 1e3 is a clear decision).
    """

    uncontrollable: tuple[complex, ...]
    unobservable: tuple[complex, ...]
    ranks: tuple[int, int]
    nstates: int
    tolerance: float = RANK_RTOL
    margin: float = math.inf

    @property
    def controllable(self) -> bool:
        """True when every mode passes the PBH controllability test."""
        return not self.uncontrollable

    @property
    def observable(self) -> bool:
        """True when every mode passes the PBH observability test."""
        return not self.unobservable


def structure(model: StateSpaceModel, tol: float = RANK_RTOL) -> Structure:
    """PBH controllability and observability of ``model`` (scale-free, module docstring).

    Parameters
    ----------
    model : StateSpaceModel
    tol : float
        Smallest cosine tolerance (default :data:`RANK_RTOL`).
    """
    n = model.nstates
    both = deflate(model.A, model.B, model.C, controllable=True, observable=True, tol=tol)
    if both.uncontrollable or both.unobservable:  # then each kind on its own (a mode may be both)
        ctrl = deflate(model.A, model.B, model.C, controllable=True, observable=False, tol=tol)
        obs = deflate(model.A, model.B, model.C, controllable=False, observable=True, tol=tol)
    else:
        ctrl = obs = both
    return Structure(
        ctrl.uncontrollable,
        obs.unobservable,
        (n - len(ctrl.uncontrollable), n - len(obs.unobservable)),
        n,
        tol,
        min(ctrl.margin, obs.margin),
    )


def minimal_realisation(model: StateSpaceModel, tol: float = RANK_RTOL) -> tuple[StateSpaceModel, Reduction]:
    """Minimal realisation and what was removed (see :func:`minimal`)."""
    red = deflate(model.A, model.B, model.C, controllable=True, observable=True, tol=tol)
    dropped = model.nstates - red.A.shape[0]
    if dropped == 0:
        return model, red
    names = tuple(f"z{k + 1}" for k in range(red.A.shape[0]))
    info = CompileInfo(order=red.A.shape[0], warnings=model.info.warnings)
    reduced = StateSpaceModel(
        sp.csr_array(red.A),
        sp.csr_array(red.B),
        sp.csr_array(red.C),
        model.D_sparse,
        model.D1_sparse,
        names,
        model.inputs,
        model.outputs,
        model.title,
        info,
    )
    return reduced, red


def minimal(model: StateSpaceModel, tol: float = RANK_RTOL) -> tuple[StateSpaceModel, int]:
    """Minimal realisation: remove the uncontrollable, then the unobservable modes.

    The modes are found by the same scale-free PBH tests as :func:`structure`
    and projected out orthogonally in Curtis–Reid-scaled state coordinates.
    The states of the result are combinations of the original ones, named
    ``z1``, ``z2``...

    Returns
    -------
    model : StateSpaceModel
        The reduced model (the original when it is already minimal).
    dropped : int
        Number of states removed.
    """
    reduced, _ = minimal_realisation(model, tol)
    return reduced, model.nstates - reduced.nstates


# --- transfer functions ---------------------------------------------------------------------------


@dataclass(frozen=True)
class TransferFunction:
    """One input–output transfer function G(s) = num(s)/den(s) (coefficients, highest power first).

    ``den`` is the characteristic polynomial of A (monic) and ``num`` the
    matching numerator, as the lecture notes write them; ``poles`` and
    ``zeros`` are those of G after cancelling the modes the pair does not see.
    Coefficients and parts of roots smaller than their own rounding error
    bound are exactly 0. ``dc_gain`` is G(0) (∞ for a pole at 0).
    """

    output: str
    input: str
    num: tuple[float, ...]
    den: tuple[float, ...]
    poles: tuple[complex, ...]
    zeros: tuple[complex, ...]
    dc_gain: float

    def text(self, digits: int = 6) -> str:
        """``(a·s^2 + b·s + c) / (s^3 + ...)`` with every non-zero coefficient."""

        def poly(coeffs: tuple[float, ...]) -> str:
            deg = len(coeffs) - 1
            terms = []
            for k, c in enumerate(coeffs):
                if c == 0:
                    continue
                power = deg - k
                mono = "" if power == 0 else ("s" if power == 1 else f"s^{power}")
                terms.append(f"{c:+.{digits}g}{'·' + mono if mono else ''}")
            return " ".join(terms) if terms else "0"

        return f"{self.output}/{self.input} = ({poly(self.num)}) / ({poly(self.den)})"

    @property
    def cancelled(self) -> int:
        """How many modes of A this pair does not see (factors common to ``num`` and ``den``)."""
        return len(self.den) - 1 - len(self.poles)

    def minimal(self) -> TransferFunction:
        """The same G(s) with the cancelled factors divided out: ``den`` = ∏(s − pole).

        ``num`` keeps its leading coefficient (the cancelled factors are monic).
        """
        if self.cancelled <= 0:
            return self
        lead = next((c for c in self.num if c != 0), 0.0)
        num = tuple(float(c) for c in np.atleast_1d(lead * np.poly(self.zeros)).real) if lead else (0.0,)
        den = tuple(float(c) for c in np.atleast_1d(np.poly(self.poles)).real)
        return TransferFunction(self.output, self.input, num, den, self.poles, self.zeros, self.dc_gain)


def _poly(roots: Sequence[complex], errors: Sequence[float], gain: float = 1.0) -> np.ndarray:
    """Real coefficients of gain·∏(s − r); those below their rounding bound are exactly 0.

    The bound of each coefficient is propagated alongside it: the roots' own
    errors, plus eps per operation on the magnitudes.
    """
    coeffs = np.array([1.0 + 0j])
    bound = np.array([0.0])
    for r, e in zip(roots, errors, strict=True):
        mag = np.abs(coeffs)
        coeffs = np.convolve(coeffs, [1.0, -r])
        bound = np.convolve(bound, [1.0, abs(r)]) + np.convolve(mag, [0.0, e])
        bound += 4 * EPS * np.convolve(mag, [1.0, abs(r)])
    coeffs = coeffs.real * gain
    bound = bound * abs(gain) + 4 * EPS * np.abs(coeffs)
    coeffs[np.abs(coeffs) <= 10 * bound] = 0.0
    return coeffs


def _relative_degree(A: np.ndarray, b: np.ndarray, c: np.ndarray) -> int | None:
    """First k ≥ 1 with c A^(k−1) b ≠ 0 beyond its rounding bound; None if all vanish."""
    n = A.shape[0]
    v, mag = b.astype(float), np.abs(b)
    for k in range(1, n + 1):
        value, size = float(c @ v), float(np.abs(c) @ mag)
        if abs(value) > 100 * n * k * EPS * size:
            return k
        v, mag = A @ v, np.abs(A) @ mag
    return None


def _zeros_at_origin(
    A: np.ndarray, b: np.ndarray, c: np.ndarray, d: float, d1: float, data_error: float = 0.0
) -> int:
    """How many leading moments of G at s = 0 vanish (A invertible): the zeros at the origin.

    G(s) = (d − c A⁻¹ b) + s (d1 − c A⁻² b) − Σ_{k≥2} s^k c A^{−(k+1)} b. Each
    vector v_k = A⁻¹ v_{k−1} carries a first-order rounding bound
    |A⁻¹| (|A| |v_k| + |v_{k−1}| + bound_{k−1}) (in units of eps); a moment
    within 100·n·k·eps of its bound is zero. ``data_error`` is the relative
    normwise error the realisation itself carries (from a deflation); it
    adds data_error·‖c‖‖b‖‖A⁻¹‖^{k+1}·(1 + (k+1)‖A‖‖A⁻¹‖) to each moment's bound.
    """
    n = A.shape[0]
    inv = np.linalg.inv(A)
    abs_inv, abs_a = np.abs(inv), np.abs(A)
    norm_inv, norm_a = np.linalg.norm(inv, 2), np.linalg.norm(A, 2)
    outer = float(np.linalg.norm(c) * np.linalg.norm(b))
    prev, prev_bound = b.astype(float), np.zeros(n)
    count = 0
    for k in range(n + 2):
        v = np.linalg.solve(A, prev)
        bound = abs_inv @ (abs_a @ np.abs(v) + np.abs(prev) + prev_bound)
        extra = d if k == 0 else (d1 if k == 1 else 0.0)
        value = extra - float(c @ v)
        size = abs(extra) + float(np.abs(c) @ (np.abs(v) + bound))
        data = data_error * outer * norm_inv ** (k + 1) * (1 + (k + 1) * norm_a * norm_inv)
        if abs(value) > 100 * (n + 1) * (k + 1) * EPS * size + 10 * data:
            return count
        count += 1
        prev, prev_bound = v, bound
    return count


def _zeros(A: np.ndarray, b: np.ndarray, c: np.ndarray, d: float, d1: float, count: int) -> np.ndarray:
    """The ``count`` finite transmission zeros: eigenvalues of the equilibrated Rosenbrock pencil."""
    if count <= 0:
        return np.zeros(0, dtype=complex)
    n = A.shape[0]
    M = np.block([[A, b[:, None]], [-c[None, :], np.array([[-d]])]])
    N = np.zeros((n + 1, n + 1))
    N[:n, :n] = np.eye(n)
    N[n, n] = d1
    r, col = equilibrate(np.abs(M) + np.abs(N))
    alpha, beta = sla.eig(M * r[:, None] * col, N * r[:, None] * col, right=False, homogeneous_eigvals=True)
    finiteness = np.abs(beta) / np.maximum(np.abs(alpha) + np.abs(beta), 1e-300)
    order = np.argsort(-finiteness)[:count]
    with np.errstate(divide="ignore", invalid="ignore"):
        zeros = alpha[order] / beta[order]
    return zeros[np.isfinite(zeros)]


def _match_remove(values: list[complex], remove: Sequence[complex]) -> list[complex]:
    left = list(values)
    for r in remove:
        if not left:
            break
        j = int(np.argmin([abs(v - r) for v in left]))
        left.pop(j)
    return left


def _gain_point(roots: Sequence[complex]) -> complex:
    """A complex frequency away from every root, at the roots' typical magnitude."""
    mags = [abs(r) for r in roots if r != 0]
    scale = math.exp(float(np.mean(np.log(mags)))) if mags else 1.0
    best, best_dist = complex(0.3 * scale, 1.1 * scale), -1.0
    for angle in np.linspace(0.2, 1.4, 7):
        for factor in (0.7, 1.3, 2.1):
            s0 = factor * scale * complex(math.cos(angle), math.sin(angle))
            dist = min((abs(s0 - r) / max(abs(s0), 1e-300) for r in roots), default=1.0)
            if dist > best_dist:
                best, best_dist = s0, dist
    return best


def _siso(
    A: np.ndarray,
    b: np.ndarray,
    c: np.ndarray,
    d: float,
    d1: float,
    modes: list[complex],
    errors: list[float],
) -> tuple[np.ndarray, list[complex], list[complex], float]:
    """Numerator over the characteristic polynomial, reduced poles and zeros, DC gain."""
    red = deflate(A, b[:, None], c[None, :], controllable=True, observable=True)
    Ar, br, cr = red.A, red.B[:, 0], red.C[0]
    removed = list(red.uncontrollable) + list(red.unobservable)
    poles = _match_remove(modes, removed)
    cancelled = _match_remove(modes, poles)
    nr = Ar.shape[0]
    if d1:
        degree = nr + 1
    elif d:
        degree = nr
    else:
        rel = _relative_degree(Ar, br, cr) if nr else None
        degree = -1 if rel is None else nr - rel
    if degree < 0:  # G ≡ 0
        return np.array([0.0]), poles, [], 0.0
    singular = any(p == 0 for p in poles)
    at_origin = 0
    if not singular and nr:
        at_origin = min(degree, _zeros_at_origin(Ar, br, cr, d, d1, red.backward_error))
    zeros = list(_zeros(Ar, br, cr, d, d1, degree))
    zeros.sort(key=abs)
    zeros = [0j] * at_origin + zeros[at_origin:]
    scale = max((abs(p) for p in modes), default=1.0)
    zero_err = [100 * (nr + 1) * EPS * max(abs(z), 1e-300) if z != 0 else 0.0 for z in zeros]
    zeros = [
        complex(z.real if abs(z.real) > e else 0.0, z.imag if abs(z.imag) > e else 0.0)
        for z, e in zip(zeros, zero_err, strict=True)
    ]
    s0 = _gain_point([*poles, *zeros] or [complex(scale)])
    value = d + s0 * d1 + (cr @ np.linalg.solve(s0 * np.eye(nr) - Ar, br) if nr else 0.0)
    shape = np.prod([s0 - z for z in zeros]) / np.prod([s0 - p for p in poles]) if poles or zeros else 1.0
    gain = float((value / shape).real)
    pole_err = [errors[modes.index(p)] if p in modes else 0.0 for p in cancelled]
    num = _poly([*zeros, *cancelled], [*zero_err, *pole_err], gain)
    if singular:
        dc = math.inf
    elif nr == 0:
        dc = d
    elif any(z == 0 for z in zeros):
        dc = 0.0
    else:
        dc = float(d - cr @ np.linalg.solve(Ar, br))
    return num, poles, zeros, dc


def transfer_functions(model: StateSpaceModel) -> list[TransferFunction]:
    """G(s) = c (sI − A)⁻¹ b + d + s·d1 for every input–output pair.

    Each pair's minimal realisation comes from the scale-free deflation of
    :func:`deflate`; its zeros are the finite eigenvalues of the equilibrated
    Rosenbrock pencil (zeros at the origin counted exactly from the vanishing
    moments c A^−k b), its poles the model's eigenvalues that survive. The
    printed numerator is that of the notes: over the characteristic
    polynomial of A, i.e. multiplied by the cancelled factors.
    """
    n = model.nstates
    if n:
        eig = analyze_eigenvalues(model.A, "all")
        modes = [m.value for m in eig.modes]
        errors = [m.abs_error if math.isfinite(m.abs_error) else 0.0 for m in eig.modes]
    else:
        modes, errors = [], []
    den = _poly(modes, errors)
    out = []
    for j, name_in in enumerate(model.inputs):
        for i, name_out in enumerate(model.outputs):
            num, poles, zeros, dc = _siso(
                model.A, model.B[:, j], model.C[i], float(model.D[i, j]), float(model.D1[i, j]), modes, errors
            )
            out.append(
                TransferFunction(
                    name_out,
                    name_in,
                    tuple(float(x) for x in num),
                    tuple(float(x) for x in den),
                    tuple(complex(p) for p in poles),
                    tuple(complex(z) for z in zeros),
                    dc,
                )
            )
    return out


def frequency_grid(model: StateSpaceModel, points: int = 400) -> np.ndarray:
    """Angular frequencies (rad/s), log-spaced two decades beyond the model's eigenvalue magnitudes."""
    magnitudes = np.abs(np.linalg.eigvals(model.A)) if model.nstates else np.zeros(0)
    magnitudes = magnitudes[magnitudes > 0]
    low, high = (magnitudes.min() / 100, magnitudes.max() * 100) if magnitudes.size else (1e-2, 1e2)
    return np.logspace(np.log10(low), np.log10(high), points)


def frequency_response(model: StateSpaceModel, omega: np.ndarray) -> np.ndarray:
    """H(jω) = C (jωI − A)⁻¹ B + D + jω·D1 at each angular frequency.

    Parameters
    ----------
    model : StateSpaceModel
    omega : numpy.ndarray
        Angular frequencies (rad/s).

    Returns
    -------
    numpy.ndarray
        Complex array of shape ``(len(omega), noutputs, ninputs)``: output
        units per input unit (V/V, A/V, (m/s)/N, …).
    """
    return np.stack([model.transfer_function(1j * w) for w in np.asarray(omega, dtype=float)])


#: Largest model for which canonical forms are formed (Krylov matrices grow ill-conditioned).
CANONICAL_STATE_LIMIT = 12


@dataclass(frozen=True)
class CanonicalForm:
    """A companion-form realisation x̃ = T x of a model, as the seeds build them.

    Attributes
    ----------
    kind : str
        ``"controller"`` (Ã has the characteristic polynomial's coefficients
        in its last row, B̃ = e_n for the chosen input) or ``"observer"``
        (Â has them in its last column, Ĉ's chosen row = e_nᵀ).
    signal : str
        The input (controller form) or output (observer form) used.
    T : numpy.ndarray
        The state transformation (x̃ = T x).
    A, B, C : numpy.ndarray
        T A T⁻¹, T B, C T⁻¹ (all inputs and outputs).
    condition : float
        2-norm condition number of T: the transformation amplifies relative
        errors by up to this factor.
    residual : float
        Largest deviation of the computed T A T⁻¹ from the exact companion
        pattern (its structural zeros and ones), as computed.
    """

    kind: str
    signal: str
    T: np.ndarray
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    condition: float
    residual: float


def _check_canonical_size(model: StateSpaceModel) -> None:
    n = model.nstates
    if n == 0 or n > CANONICAL_STATE_LIMIT:
        raise UsageError(
            f"canonical forms are for models of 1 to {CANONICAL_STATE_LIMIT} states; this has {n}"
        )


def _krylov(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """[B AB … Aⁿ⁻¹B]."""
    blocks, block = [], B
    for _ in range(A.shape[0]):
        blocks.append(block)
        block = A @ block
    return np.hstack(blocks) if blocks else np.zeros((A.shape[0], 0))


def _controller_transform(A: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """T = [q; qA; …; qAⁿ⁻¹] with q the last row of [b Ab … Aⁿ⁻¹b]⁻¹; None if (A, b) is uncontrollable."""
    if deflate(A, b[:, None], np.zeros((0, A.shape[0])), controllable=True, observable=False).uncontrollable:
        return None
    try:
        rows = [np.linalg.inv(_krylov(A, b[:, None]))[-1]]
    except np.linalg.LinAlgError:
        return None  # the Krylov matrix is exactly singular: (A, b) is not controllable
    for _ in range(A.shape[0] - 1):
        rows.append(rows[-1] @ A)
    return np.array(rows)


def controller_form(model: StateSpaceModel, input: int | None = None) -> CanonicalForm:
    """Controller canonical form from one input: T = [q; qA; …; qAⁿ⁻¹], q = last row of 𝒞⁻¹.

    Parameters
    ----------
    model : StateSpaceModel
    input : int, optional
        Input column; default: the first input from which the model is controllable.

    Raises
    ------
    UsageError
        When no (or the chosen) input controls every state, or the model is too large.
    """
    _check_canonical_size(model)
    for j in [input] if input is not None else range(model.ninputs):
        T = _controller_transform(model.A, model.B[:, j])
        if T is not None:
            return _companion("controller", model.inputs[j], T, model, transpose=False)
    raise UsageError("controller form: no input controls every state (see --control)")


def observer_form(model: StateSpaceModel, output: int | None = None) -> CanonicalForm:
    """Observer canonical form from one output, the dual of :func:`controller_form`.

    With (Aᵀ, cᵀ) in controller form through T_c, the observer form uses
    T = (T_cᵀ)⁻¹, so that Â = T A T⁻¹ = (Aᵀ in controller form)ᵀ: the
    characteristic polynomial's coefficients fill Â's last column and the
    chosen row of Ĉ is [0 … 0 1].
    """
    _check_canonical_size(model)
    for i in [output] if output is not None else range(model.noutputs):
        T_c = _controller_transform(model.A.T, model.C[i])
        if T_c is not None:
            return _companion("observer", model.outputs[i], np.linalg.inv(T_c.T), model, transpose=True)
    raise UsageError("observer form: no output observes every state (see --control)")


def _luenberger_columns(A: np.ndarray, C: np.ndarray) -> list[tuple[int, int]]:
    """(output, power) of the columns (Aᵀ)^k cᵢᵀ kept, scanned as c₁ᵀ, c₂ᵀ, …, Aᵀc₁ᵀ, Aᵀc₂ᵀ, ….

    A column is kept when it is independent of those kept before (relative
    residual of its orthogonal projection above 1e-8, in Curtis–Reid-scaled
    state coordinates, so the choice does not depend on the units); once
    (Aᵀ)^k cᵢᵀ is dependent, the higher powers of that output are skipped.
    """
    n, p = A.shape[0], C.shape[0]
    S = state_scaling(A, np.zeros((n, 0)), C)
    A_s, C_s = A * S[None, :] / S[:, None], C * S[None, :]
    kept: list[tuple[int, int]] = []
    basis = np.zeros((n, 0))
    active = [bool(np.any(C_s[i])) for i in range(p)]
    vectors = [C_s[i].copy() for i in range(p)]
    for power in range(n):
        for i in range(p):
            if not active[i] or len(kept) == n:
                continue
            v = vectors[i]
            residual = v - basis @ (basis.T @ v)
            if np.linalg.norm(residual) > 1e-8 * np.linalg.norm(v):
                kept.append((i, power))
                basis = np.hstack([basis, (residual / np.linalg.norm(residual))[:, None]])
                vectors[i] = A_s.T @ v
            else:
                active[i] = False
    return kept


def observer_form_multi(model: StateSpaceModel) -> CanonicalForm:
    """Observer canonical form from all outputs, built as the lecture notes build it.

    The columns of the controllability matrix of (Aᵀ, Cᵀ) are scanned in the
    order c₁ᵀ, c₂ᵀ, …, Aᵀc₁ᵀ, … and the independent ones kept (Luenberger
    indices d₁, d₂, …); L = [c₁ᵀ, Aᵀc₁ᵀ, …, (Aᵀ)^(d₁−1)c₁ᵀ, c₂ᵀ, …] (for the
    double inverted pendulum on a cart: [c₁ᵀ, Aᵀc₁ᵀ, c₂ᵀ, Aᵀc₂ᵀ, c₃ᵀ, Aᵀc₃ᵀ]). With q the last
    row of L⁻¹ and T_c = [q; qAᵀ; …; q(Aᵀ)ⁿ⁻¹], Â = (T_cᵀ)⁻¹ A T_cᵀ is a
    companion matrix (characteristic polynomial in its last column) and
    Ĉ = C T_cᵀ. Here x̂ = T x with T = (T_cᵀ)⁻¹.

    Raises
    ------
    UsageError
        When the outputs do not observe every state, or T_c is singular
        (A has a repeated eigenvalue with more than one eigenvector).
    """
    _check_canonical_size(model)
    A, C = model.A, model.C
    n = model.nstates
    kept = _luenberger_columns(A, C)
    if len(kept) < n:
        raise UsageError("multi-output observer form: the outputs do not observe every state (see --control)")
    order = sorted(kept)  # by output, then power: [c1, A'c1, ..., c2, A'c2, ...]
    L = np.column_stack([np.linalg.matrix_power(A.T, k) @ C[i] for i, k in order])
    q = np.linalg.inv(L)[-1]
    rows = [q]
    for _ in range(n - 1):
        rows.append(rows[-1] @ A.T)
    T_c = np.array(rows)
    if deflate(A, q[:, None], np.zeros((0, n)), controllable=True, observable=False).uncontrollable:
        raise UsageError("multi-output observer form: [q; qAᵀ; …] is singular (A is not cyclic)")
    indices = ", ".join(
        f"{model.outputs[i]}: {sum(1 for j, _ in kept if j == i)}" for i in sorted({i for i, _ in kept})
    )
    return _companion(
        "observer", f"all outputs (indices {indices})", np.linalg.inv(T_c.T), model, True, T_c.T
    )


def _companion(
    kind: str,
    signal: str,
    T: np.ndarray,
    model: StateSpaceModel,
    transpose: bool,
    T_inv: np.ndarray | None = None,
) -> CanonicalForm:
    """The form x̃ = T x; ``T_inv`` when known exactly (a Krylov matrix), else inverted here."""
    n = model.nstates
    T_inv = np.linalg.inv(T) if T_inv is None else T_inv
    A_t = T @ model.A @ T_inv
    pattern = np.eye(n, k=1)  # controller: superdiagonal ones, free last row
    free = np.zeros((n, n), dtype=bool)
    free[-1, :] = True
    if transpose:
        pattern, free = pattern.T, free.T
    residual = float(np.max(np.abs(np.where(free, 0.0, A_t - pattern)))) if n > 1 else 0.0
    exact = np.where(free, A_t, pattern)
    return CanonicalForm(
        kind, signal, T, exact, T @ model.B, model.C @ T_inv, float(np.linalg.cond(T)), residual
    )
