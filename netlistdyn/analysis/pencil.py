"""Eigenvalues checked against the circuit's own equations.

The state matrix A is reduced from the branch laws ``G w + E w' = 0``
(:class:`~netlistdyn.statespace.model.Pencil`) by sparse eliminations; at wide spreads
of element values (1 fF beside 1 kH) those eliminations can lose digits that
no error estimate computed from A alone can see. The branch laws, on the
other hand, hold the element values themselves. So each eigenvalue λ found
from A is taken to the pencil:

* the pencil is first split into the diagonal blocks of its block
  triangular form (det(G + λE) is their product, exactly), with the zeros
  the topology guarantees divided out; a 1 × 1 block is its root −g/e, and
  each eigenvalue is checked on its own block, where its eigenvector has no
  rounding-level components elsewhere;
* Newton's method on det(G + λE) = 0 (two-sided inverse iteration with an
  equilibrated LU of G + λE) refines λ, and is kept only when it lowers the
  componentwise backward error — the refinement is never worse than its
  input;
* the componentwise backward error η of the final pair — the smallest
  relative change of the element values that makes λ exact — and the
  condition numbers of λ's real and imaginary parts under relative changes
  of every entry give error bars that cover the reduction, the eigensolver
  and the rounding of the values themselves: |δ Re λ| ≤ (η + eps)·κ_re;
* roots that A lost (a 1e20 1/s root beside 1e-17 1/s ones, turned into
  a zero or missing) are found by QZ on the blocks, repeated over frequency
  scalings (G, σE) when the count falls short.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TypeAlias

import mpmath as mp
import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import connected_components, maximum_bipartite_matching, structural_rank

from netlistdyn.statespace.model import Pencil

EPS = float(np.finfo(float).eps)
#: Newton steps at most per eigenvalue (convergence is quadratic for simple eigenvalues).
NEWTON_STEPS = 6
#: Pencils up to this size are factorised densely (LAPACK), larger ones with SuperLU (a ladder's
#: pencil is banded: SuperLU is ten times faster than LAPACK at 150 unknowns).
DENSE_PENCIL = 50
#: First-order error bars are multiplied by this safety factor.
SAFETY = 4.0


@dataclass(frozen=True, slots=True)
class CheckedEigenvalue:
    """An eigenvalue verified against the pencil.

    Attributes
    ----------
    value : complex
        The eigenvalue (1/s): the refined one, or the input when refining
        did not lower the backward error.
    abs_error, re_error, im_error : float
        Bounds on |δλ|, |δ Re λ| and |δ Im λ| (1/s).
    backward_error : float
        Componentwise backward error η of (value, eigenvector) on the pencil.
    refined : bool
        True when ``value`` differs from the input.
    """

    value: complex
    abs_error: float
    re_error: float
    im_error: float
    backward_error: float
    refined: bool


def _equilibration(matrix: sp.csr_array) -> tuple[np.ndarray, np.ndarray]:
    """Row then column scalings (r, c) that bring every row's and column's largest entry to 1."""
    abs_m = abs(matrix)
    row = abs_m.max(axis=1).toarray().ravel()
    r = np.where(row > 0, 1.0 / np.where(row > 0, row, 1.0), 1.0)
    col = (sp.diags_array(r) @ abs_m).max(axis=0).toarray().ravel()
    c = np.where(col > 0, 1.0 / np.where(col > 0, col, 1.0), 1.0)
    return r, c


class _Factor:
    """LU of an equilibrated complex matrix P = R⁻¹ S C⁻¹, solving with P and Pᴴ."""

    def __init__(self, matrix: sp.csr_array) -> None:
        self.r, self.c = _equilibration(matrix)
        scaled = sp.diags_array(self.r) @ matrix @ sp.diags_array(self.c)
        n = matrix.shape[0]
        self.dense = n <= DENSE_PENCIL
        #: LAPACK's (lu, piv) of the dense matrix, or SuperLU of the sparse one.
        self.lu: tuple[np.ndarray, np.ndarray] | spla.SuperLU
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", sla.LinAlgWarning)
            if self.dense:
                dense = scaled.toarray()
                lu, piv = sla.lu_factor(dense, check_finite=False)
                if not np.all(np.isfinite(lu)) or np.min(np.abs(np.diag(lu))) == 0:
                    raise ZeroDivisionError("exactly singular")
                self.lu = (lu, piv)
            else:
                try:
                    self.lu = spla.splu(sp.csc_matrix(scaled), permc_spec="COLAMD")
                except RuntimeError:
                    raise ZeroDivisionError("exactly singular") from None

    def solve(self, b: np.ndarray) -> np.ndarray:
        """P⁻¹ b = C S⁻¹ R b."""
        rhs = self.r * b
        if isinstance(self.lu, tuple):
            x = sla.lu_solve(self.lu, rhs, check_finite=False)
        else:
            x = self.lu.solve(rhs)
        return self.c * x

    def solve_scaled(self, b: np.ndarray, hermitian: bool = False) -> np.ndarray:
        """S⁻¹ b (or S⁻ᴴ b): a solve with the equilibrated matrix itself."""
        if isinstance(self.lu, tuple):
            return sla.lu_solve(self.lu, b, trans=2 if hermitian else 0, check_finite=False)
        return self.lu.solve(b, trans="H" if hermitian else "N")


def _unit(v: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(v)
    return v / norm if norm > 0 and np.isfinite(norm) else v


def _inverse_iteration(
    solve: Callable[[np.ndarray], np.ndarray], apply: Callable[[np.ndarray], np.ndarray], start: np.ndarray
) -> np.ndarray:
    """Two steps of inverse iteration, returning the iterate with the smaller residual ‖S v‖.

    A second step from an iterate that is already a null vector to working
    precision can cancel exactly: the right-hand side then has no component
    left for the small pivot to amplify, and the solve returns a vector of
    the other directions (a left null vector [1e-7, 7e-18, 1] came back as
    [0, 7e-18, 1], and zᴴEw with it was 1e-37 instead of 1e-7). The residual
    tells the two apart; the better iterate is kept.
    """
    best, best_residual = _unit(start), math.inf
    v = best
    for _ in range(2):
        v = _unit(solve(v))
        residual = float(np.linalg.norm(apply(v)))
        if not np.all(np.isfinite(v)) or not math.isfinite(residual):
            break
        if residual < best_residual:
            best, best_residual = v, residual
    return best


def _pair(
    G: sp.csr_array,
    E: sp.csr_array,
    lam: complex,
    start: tuple[np.ndarray, np.ndarray],
    nudged: bool = False,
) -> tuple[np.ndarray, np.ndarray] | None:
    """Right and left (near-)null vectors of G + λE by two steps of inverse iteration."""
    matrix = sp.csr_array(G + lam * E)
    try:
        factor = _Factor(matrix)
    except ZeroDivisionError:
        if matrix.shape[0] > DENSE_PENCIL:
            if lam == 0 or nudged:
                return None
            # λ is an eigenvalue to working precision; inverse iteration from a neighbour finds
            # the same vectors (Newton's method then starts from λ itself).
            return _pair(G, E, lam * (1 + 16 * EPS), start, nudged=True)
        # λ is an eigenvalue to working precision: the singular vectors of the last singular value,
        # taken on the equilibrated matrix (see below) and mapped back.
        r, c = _equilibration(matrix)
        dense = (sp.diags_array(r) @ matrix @ sp.diags_array(c)).toarray()
        if not np.all(np.isfinite(dense)):
            return None
        try:
            u, _, vh = np.linalg.svd(dense)
        except np.linalg.LinAlgError:
            return None
        return _unit(c * vh[-1].conj()), _unit(r * u[:, -1])
    # Inverse iteration on the equilibrated matrix S = R (G + λE) C: its null vectors map back as
    # w = C y and z = R x. In the unscaled matrix, rows of 1e-15 Ω beside 1e28 S (a 1 fF node
    # at a 1e24 1/s eigenvalue) make singular values smaller than the eigenvalue's own, and
    # unscaled inverse iteration converges to those instead.
    scaled = sp.csr_array(sp.diags_array(factor.r) @ matrix @ sp.diags_array(factor.c))
    with np.errstate(all="ignore"):
        y = _inverse_iteration(factor.solve_scaled, lambda v: scaled @ v, start[0])
        x = _inverse_iteration(
            lambda v: factor.solve_scaled(v, hermitian=True), lambda v: scaled.conj().T @ v, start[1]
        )
        w = _unit(factor.c * y)
        z = _unit(factor.r * x)
    if not (np.all(np.isfinite(w)) and np.all(np.isfinite(z))):
        return None
    return w, z


def _deflate(G: sp.csr_array, E: sp.csr_array) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns to keep once the unknowns that a one-entry row fixes to zero are removed.

    Source rows (v = 0, i = 0 with the inputs off) fix their unknown to
    zero. Such a component is exactly zero in every eigenvector, but inverse
    iteration leaves rounding there, and the componentwise backward error of
    a one-entry row is then 1 whatever the quality of the rest. Removing the
    row and its column (repeatedly: removal can leave new one-entry rows)
    changes neither the finite eigenvalues nor their sensitivity.
    """
    rows_kept = np.arange(G.shape[0])
    cols_kept = np.arange(G.shape[1])
    G, E = sp.csr_array(G), sp.csr_array(E)
    while G.shape[0]:
        g_count = np.diff(G.indptr)
        e_count = np.diff(E.indptr)
        rows = np.flatnonzero((g_count == 1) & (e_count == 0))
        if not rows.size:
            break
        cols = np.unique(G.indices[G.indptr[rows]])
        keep_r = np.setdiff1d(np.arange(G.shape[0]), rows)
        keep_c = np.setdiff1d(np.arange(G.shape[1]), cols)
        if len(keep_r) != len(keep_c):  # not square: leave it as it is
            break
        G = sp.csr_array(G[keep_r][:, keep_c])
        E = sp.csr_array(E[keep_r][:, keep_c])
        G.eliminate_zeros()
        E.eliminate_zeros()
        rows_kept, cols_kept = rows_kept[keep_r], cols_kept[keep_c]
    return rows_kept, cols_kept


@dataclass(frozen=True)
class _Prepared:
    """One diagonal block of the pencil in complex arithmetic, with its element-value part."""

    G: sp.csr_array
    E: sp.csr_array
    G_coo: sp.coo_array
    E_coo: sp.coo_array
    data_coo: sp.coo_array  # the element-value entries of G


def _cut(m: sp.csr_array, rows: np.ndarray, cols: np.ndarray) -> sp.csr_array:
    out = sp.csr_array(sp.csr_array(m)[rows][:, cols], dtype=complex)
    out.eliminate_zeros()
    return out


def _block(G: sp.csr_array, E: sp.csr_array, data: sp.csr_array) -> _Prepared:
    return _Prepared(G, E, sp.coo_array(G), sp.coo_array(E), sp.coo_array(data))


def _prepare(pencil: Pencil) -> _Prepared:
    """The deflated pencil as one block."""
    rows, cols = _deflate(pencil.G, pencil.E)
    G, E = _cut(pencil.G, rows, cols), _cut(pencil.E, rows, cols)
    data = _cut(pencil.G_data, rows, cols) if pencil.G_data is not None else G
    return _block(G, E, data)


def _diagonal_blocks(G: sp.csr_array, E: sp.csr_array) -> list[tuple[np.ndarray, np.ndarray]] | None:
    """Block triangular form of G + λE: (rows, columns) of each diagonal block, None if none exists.

    A perfect matching of the sparsity pattern puts a non-zero on the
    diagonal; the strongly connected parts of the graph it induces are the
    diagonal blocks of a block triangular permutation (Dulmage–Mendelsohn).
    det(G + λE) is the product of the blocks' determinants — exactly, since
    the zeros outside the blocks are structural — so every eigenvalue lives
    in one block, where its eigenvector has no rounding-level components in
    the other parts (which make a componentwise backward error meaningless)
    and where a root far from the rest is often alone.
    """
    n = G.shape[0]
    pattern = sp.csr_matrix((abs(G) + abs(E)) > 0, dtype=np.int8)
    if n == 0 or pattern.shape[1] != n:
        return None
    match = maximum_bipartite_matching(pattern, perm_type="column")
    if np.any(match < 0):
        return None
    row_of = np.empty(n, dtype=int)
    row_of[match] = np.arange(n)
    coo = sp.coo_array(pattern)
    graph = sp.csr_matrix((np.ones(coo.nnz), (coo.row, row_of[coo.col])), shape=(n, n))
    count, label = connected_components(graph, directed=True, connection="strong")
    order = np.argsort(label, kind="stable")
    bounds = np.searchsorted(label[order], np.arange(count + 1))
    return [(order[bounds[b] : bounds[b + 1]], match[order[bounds[b] : bounds[b + 1]]]) for b in range(count)]


def _factor_zeros(
    G: sp.csr_array, E: sp.csr_array, data: sp.csr_array
) -> tuple[sp.csr_array, sp.csr_array, sp.csr_array]:
    """Divide the topology's zero eigenvalues out of the pencil.

    A column of G + λE with no entry in G (a flux or a charge the topology
    conserves) is λ times E's column: det(G + λE) = λ·det(G' + λE') with
    that column moved from E to G (its unknown becomes λ times the old one,
    the time derivative). Likewise for a row. The remaining pencil has the
    same non-zero eigenvalues without the exact zero beside them, which
    would otherwise attract Newton's method from a small starting value.
    Moved entries are element values, so they join G's data part.
    """
    G, E, data = sp.lil_array(G), sp.lil_array(E), sp.lil_array(data)
    for _ in range(G.shape[0]):
        g_cols = np.asarray(abs(sp.csr_array(G)).sum(axis=0)).ravel()
        e_cols = np.asarray(abs(sp.csr_array(E)).sum(axis=0)).ravel()
        g_rows = np.asarray(abs(sp.csr_array(G)).sum(axis=1)).ravel()
        e_rows = np.asarray(abs(sp.csr_array(E)).sum(axis=1)).ravel()
        cols = np.flatnonzero((g_cols == 0) & (e_cols > 0))
        rows = np.flatnonzero((g_rows == 0) & (e_rows > 0))
        if cols.size:
            j = int(cols[0])
            G[:, [j]] = E[:, [j]]
            data[:, [j]] = E[:, [j]]
            E[:, [j]] = 0
        elif rows.size:
            i = int(rows[0])
            G[[i], :] = E[[i], :]
            data[[i], :] = E[[i], :]
            E[[i], :] = 0
        else:
            break
    out = []
    for m in (G, E, data):
        m = sp.csr_array(m)
        m.eliminate_zeros()
        out.append(m)
    return out[0], out[1], out[2]


def _blocks(pencil: Pencil) -> tuple[list[_Prepared], list[CheckedEigenvalue]]:
    """The pencil's diagonal blocks with finite eigenvalues, and the roots of its 1 × 1 blocks.

    A 1 × 1 block g + λe is the root −g/e, exact up to the division's
    rounding and the values' own; one with g = 0 is a zero eigenvalue
    (left to :func:`structural_zeros`), one with e = 0 has none.
    """
    rows, cols = _deflate(pencil.G, pencil.E)
    G, E = _cut(pencil.G, rows, cols), _cut(pencil.E, rows, cols)
    data = _cut(pencil.G_data, rows, cols) if pencil.G_data is not None else G
    G, E, data = _factor_zeros(G, E, data)
    parts = _diagonal_blocks(G, E)
    if parts is None:
        return [_block(G, E, data)], []
    blocks: list[_Prepared] = []
    roots: list[CheckedEigenvalue] = []
    for r, c in parts:
        e_block = _cut(E, r, c)
        if e_block.nnz == 0:
            continue  # no finite eigenvalue
        g_block, d_block = _cut(G, r, c), _cut(data, r, c)
        if len(r) > 1:
            blocks.append(_block(g_block, e_block, d_block))
            continue
        g, e = complex(g_block.toarray()[0, 0]), complex(e_block.toarray()[0, 0])
        if g == 0:
            continue
        lam = complex(-g.real / e.real)
        # Relative changes eps of e (an element value) and of g (when it is one) move λ by eps·|λ|
        # each; the division rounds by eps/2.
        kappa = abs(lam) * (1 + (d_block.nnz > 0))
        bar = SAFETY * EPS * kappa + EPS * abs(lam)
        roots.append(CheckedEigenvalue(lam, bar, bar, 0.0, 0.0, refined=False))
    return blocks, roots


def _bars(
    prep: _Prepared, lam: complex, w: np.ndarray, z: np.ndarray
) -> tuple[float, float, float, float, float] | None:
    """Backward error η and condition numbers of λ under relative changes of the entries.

    With d = zᴴ E w, a relative change ε of entry G_ij moves λ by about
    −ε G_ij z̄_i w_j / d, of E_ij by −ε λ E_ij z̄_i w_j / d. Summing the
    magnitudes over every entry gives κ (rounding anywhere in the
    computation); over the element values only, and for the real and
    imaginary parts separately, κ_re and κ_im (a value's rounding is a real
    change of that value).

    Returns
    -------
    tuple or None
        (η, κ, κ_data, κ_re, κ_im), None when zᴴEw = 0 (λ not simple).
    """
    G, E, D = prep.G_coo, prep.E_coo, prep.data_coo
    d = np.vdot(z, E @ w)
    if d == 0 or not np.isfinite(d):
        return None
    u = z.conj() / d
    tg = np.abs(G.data) * np.abs(u[G.row] * w[G.col])
    td = np.abs(D.data) * (u[D.row] * w[D.col])
    te = np.abs(E.data) * (lam * u[E.row] * w[E.col])
    kappa = float(np.sum(tg) + np.sum(np.abs(te)))
    kappa_data = float(np.sum(np.abs(td)) + np.sum(np.abs(te)))
    kappa_re = float(np.sum(np.abs(td.real)) + np.sum(np.abs(te.real)))
    kappa_im = float(np.sum(np.abs(td.imag)) + np.sum(np.abs(te.imag)))
    eta = min(_backward_error(G, E, lam, v) for v in _cleaned(w))
    if not (np.isfinite(kappa) and np.isfinite(eta)):
        return None
    return eta, kappa, kappa_data, kappa_re, kappa_im


def _backward_error(G: sp.coo_array, E: sp.coo_array, lam: complex, w: np.ndarray) -> float:
    """Componentwise backward error maxᵢ |(G + λE) w|ᵢ / ((|G| + |λ||E|)|w|)ᵢ of the pair (λ, w)."""
    residual = (G @ w) + lam * (E @ w)
    scale = (abs(G) @ np.abs(w)) + abs(lam) * (abs(E) @ np.abs(w))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(scale > 0, np.abs(residual) / scale, np.where(residual == 0, 0.0, np.inf))
    return float(np.max(ratio)) if ratio.size else 0.0


def _cleaned(w: np.ndarray) -> list[np.ndarray]:
    """w, and w with its rounding-level components set to zero.

    An eigenvector of a decoupled part of the circuit is exactly zero on the
    other parts; inverse iteration leaves ~1e-50 there, and on those rows the
    componentwise backward error is 1 however good the rest is. Any vector
    is a valid witness, so the smaller backward error of the two is kept.
    """
    top = float(np.max(np.abs(w))) if w.size else 0.0
    out = [w]
    for level in (EPS**2, EPS):
        small = np.abs(w) <= level * top
        if small.any():
            out.append(np.where(small, 0.0, w))
    return out


#: Extended-precision residuals are used while (pencil entries × eigenvalues) stays below this.
EXACT_RESIDUAL_BUDGET = 400_000
#: Digits of the extended-precision residual.
RESIDUAL_DIGITS = 40

#: An eigenvalue during refinement: a complex, or an mpmath ``mpc`` when the residual is exact.
Lam: TypeAlias = complex | mp.mpc
#: Digits of the vector and residual when a first refinement did not verify the eigenvalue.
DEEP_DIGITS = 80


class _Residual:
    """(G + λE) w with λ held in extended precision, the products and sums exact to ~40 digits.

    A Newton step built from a double-precision residual cannot place λ
    better than eps·|λ|, which hides the real part of a lightly damped mode
    (damping ratio below 1e-16); with this residual the step converges to
    ~eps²·|λ|, and the real part is resolved.
    """

    def __init__(self, G: sp.coo_array, E: sp.coo_array, exact: bool, digits: int = 0) -> None:
        self.G, self.E, self.exact = G, E, exact
        self.digits = digits or RESIDUAL_DIGITS
        if exact:
            self.mp = mp
            self.n = G.shape[0]

    def __call__(self, lam: Lam, w: np.ndarray) -> np.ndarray:
        if not self.exact:
            lam_c = complex(lam)
            return (self.G @ w) + lam_c * (self.E @ w)
        mp = self.mp
        with mp.workdps(self.digits):
            acc = [mp.mpc(0) for _ in range(self.n)]
            wm = list(w) if w.dtype == object else [mp.mpc(complex(v)) for v in w]
            for i, j, g in zip(self.G.row, self.G.col, self.G.data, strict=True):
                acc[i] += mp.mpf(float(g.real)) * wm[j]
            for i, j, e in zip(self.E.row, self.E.col, self.E.data, strict=True):
                acc[i] += lam * mp.mpf(float(e.real)) * wm[j]
            return np.array([complex(v) for v in acc])

    def add(self, lam: Lam, step: complex) -> Lam:
        """λ + step, kept in extended precision when the residual is."""
        if not self.exact:
            return complex(lam) + step
        with self.mp.workdps(self.digits):
            return lam + self.mp.mpc(step)

    def start(self, value: complex) -> Lam:
        if not self.exact:
            return complex(value)
        with self.mp.workdps(self.digits):
            return self.mp.mpc(value)


def _start_vectors(n: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(12345)  # fixed: the same netlist always gives the same digits
    return (
        rng.standard_normal(n) + 1j * rng.standard_normal(n),
        rng.standard_normal(n) + 1j * rng.standard_normal(n),
    )


def check_eigenvalue(
    pencil: Pencil | _Prepared, value: complex, exact_residual: bool = True
) -> CheckedEigenvalue | None:
    """Refine one eigenvalue on the pencil and bound its error.

    Newton's method on the eigenpair: the bordered system
    [[G + λE, E w], [e_kᵀ, 0]] [δw; δλ] = −[(G + λE) w; 0] with the
    residual in extended precision refines λ and every component of w
    (whose entries may span 20 decades) to working accuracy — iterative
    refinement, so the double-precision factorisation only has to be
    roughly right.

    Parameters
    ----------
    pencil : Pencil
    value : complex
        An eigenvalue of A (1/s).
    exact_residual : bool
        Residuals in extended precision (resolves real parts far below
        eps·|λ|); otherwise in double.

    Returns
    -------
    CheckedEigenvalue or None
        None when the eigenvalue is not simple on the pencil (zᴴEw = 0, as
        for a defective eigenvalue), is exactly 0 (the caller's structural
        analysis applies), or the pencil cannot be factorised; the caller
        then keeps its own estimate.
    """
    if value == 0:
        return None
    prep = pencil if isinstance(pencil, _Prepared) else _prepare(pencil)
    G, E = prep.G, prep.E
    n = G.shape[0]
    residual = _Residual(prep.G_coo, prep.E_coo, exact_residual)
    lam0 = complex(value)
    vectors = _pair(G, E, lam0, _start_vectors(n))
    if vectors is None:
        return None
    w, z = vectors
    k = int(np.argmax(np.abs(w)))
    w = w / w[k]
    lam = residual.start(lam0)
    history = _newton(prep, residual, lam, w, z, k, EPS * EPS)
    result = _finish(history, prep, residual, lam0)
    if result is None and exact_residual and history:
        # Not verified: the eigenvector may have components far below its largest (a 1 fF charge
        # beside a 1 kH current, 30 decades apart), which a double vector cannot resolve through
        # the solve's mixing. Continue from the last iterate with the vector itself in extended
        # precision and a deeper residual.
        deep = _Residual(prep.G_coo, prep.E_coo, True, DEEP_DIGITS)
        lam, _, w, z = history[-1][:4]
        with deep.mp.workdps(DEEP_DIGITS):
            w_ext = np.array([deep.mp.mpc(complex(v)) for v in w], dtype=object)
        more = _newton(prep, deep, deep.start(lam), w_ext, z, k, 10.0 ** (10 - DEEP_DIGITS))
        result = _finish(history + more, prep, deep, lam0)
    return result


def _newton(
    prep: _Prepared, residual: _Residual, lam: Lam, w: np.ndarray, z: np.ndarray, k: int, tol: float
) -> list[tuple[Lam, float, np.ndarray, np.ndarray, np.ndarray]]:
    """Newton steps on the bordered system; the iterates (λ, |step|, w, z, residual).

    ``w`` may be an object array of extended-precision numbers; it is then
    updated in that precision (the solve itself is in double).
    """
    G, E = prep.G, prep.E
    n = G.shape[0]
    extended = w.dtype == object
    history: list[tuple[Lam, float, np.ndarray, np.ndarray, np.ndarray]] = []
    for _ in range(NEWTON_STEPS + 1):
        r = residual(lam, w)
        lam_c = complex(lam)
        w_d = np.array([complex(v) for v in w]) if extended else w
        border = sp.csr_array(
            sp.block_array(
                [
                    [G + lam_c * E, sp.csr_array((E @ w_d)[:, None])],
                    [sp.csr_array((np.array([1.0 + 0j]), ([0], [k])), shape=(1, n)), None],
                ],
                format="csr",
            )
        )
        try:
            factor = _Factor(border)
        except ZeroDivisionError:
            break
        with np.errstate(all="ignore"):
            delta = factor.solve(-np.concatenate([r, [0.0]]))
        if not np.all(np.isfinite(delta)):
            break
        step = complex(delta[-1])
        history.append((lam, abs(step), w, z, r))
        if step == 0 and len(history) == 1:
            # λ is a root to the last bit (R/L = 1 mΩ/1 H): the vector from the singular factorisation
            # still carries rounding where it is exactly zero, and one correction removes it.
            pass
        elif step == 0 or abs(step) <= tol * abs(lam_c):
            break
        if len(history) >= 3 and abs(step) >= history[-2][1]:
            break  # at the rounding floor
        lam = residual.add(lam, step)
        if extended:
            with residual.mp.workdps(residual.digits):
                w = w + np.array([residual.mp.mpc(complex(v)) for v in delta[:-1]], dtype=object)
        else:
            w = w + delta[:-1]
    return history


def _finish(
    history: list[tuple[Lam, float, np.ndarray, np.ndarray, np.ndarray]],
    prep: _Prepared,
    residual: _Residual,
    lam0: complex,
) -> CheckedEigenvalue | None:
    """Keep the iterate with the smallest backward error (the input included: never worse).

    Its bars add the data's part — each element value's rounding to a
    double, a real relative change of at most eps — and the computation's:
    the remaining Newton correction and the floor set by the residual's
    precision through the eigenvectors' rounding.
    """
    best: tuple[float, float, complex, np.ndarray, np.ndarray] | None = None
    for lam, step, w, z, r in history:
        lam_c = complex(lam)
        if w.dtype == object:
            w = np.array([complex(v) for v in w])
        if not np.all(np.isfinite(w)):
            continue
        scale = (abs(prep.G_coo) @ np.abs(w)) + abs(lam_c) * (abs(prep.E_coo) @ np.abs(w))
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(scale > 0, np.abs(r) / scale, np.where(r == 0, 0.0, np.inf))
        eta_double = min(_backward_error(prep.G_coo, prep.E_coo, lam_c, v) for v in _cleaned(w))
        eta = min(float(np.max(ratio)) if ratio.size else 0.0, eta_double)
        if math.isfinite(eta) and (best is None or eta <= best[0]):
            best = (eta, step, lam_c, w, z)
    if best is None or best[0] > 1e-6:
        return None  # not an eigenvalue of the pencil to any useful accuracy
    eta, step, lam, w, z = best
    bars = _bars(prep, lam, w, z)
    if bars is None:
        return None  # zᴴEw = 0: not a simple eigenvalue
    _, kappa, kappa_data, kappa_re, kappa_im = bars
    # With an extended-precision residual the Newton correction bounds the remaining error; with a
    # double one, the backward error times the full condition number does.
    floor = EPS * EPS * kappa if residual.exact else eta * kappa + EPS * kappa
    computation = SAFETY * (step + floor)
    if not residual.exact:
        kappa_re = kappa_im = kappa_data
    data = SAFETY * EPS
    if _zero_as_good(prep, residual, w, eta):
        computation += abs(lam)
    # The reported value is a double: its own rounding (half an ulp of each part, and as much
    # again for a reference rounded the same way) belongs in the bar too.
    return CheckedEigenvalue(
        lam,
        data * kappa_data + computation + EPS * abs(lam),
        data * kappa_re + computation + EPS * abs(lam.real),
        data * kappa_im + computation + EPS * abs(lam.imag),
        eta,
        refined=lam != lam0,
    )


#: λ = 0 is "as good" an eigenvalue for the same vector when its backward error is within this factor.
ZERO_FACTOR = 1e3


def _zero_as_good(prep: _Prepared, residual: _Residual, w: np.ndarray, eta: float) -> bool:
    """True when (0, w) has a backward error as small as (λ, w)'s: the data cannot tell λ from 0.

    A root at exactly 0 that the topology does not guarantee (coupled parallel inductors) has a
    condition number near 0 under relative changes of the entries, so first-order bars around a tiny
    iterate (Newton's method stalled at 1.7e-79 on its way to 0, backward error 3e-27) do not reach
    0. The bar must then cover 0.
    """
    wd = np.array([complex(v) for v in w]) if w.dtype == object else w
    if min(_backward_error(prep.G_coo, prep.E_coo, 0j, v) for v in _cleaned(wd)) > ZERO_FACTOR * EPS:
        return False  # 0 is clearly not an eigenvalue for this vector (the common case: no extra work)
    r0 = residual(residual.start(0j), w)
    scale = abs(prep.G_coo) @ np.abs(wd)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(scale > 0, np.abs(r0) / scale, np.where(r0 == 0, 0.0, np.inf))
    eta_zero = float(np.max(ratio)) if ratio.size else 0.0
    return eta_zero <= ZERO_FACTOR * max(eta, EPS * EPS if residual.exact else EPS)


#: Pencils up to this size also give starting values of their own (QZ), for when A is poor.
QZ_LIMIT = 400


def check_spectrum(
    pencil: Pencil, values: np.ndarray, bounds: np.ndarray | None = None
) -> list[tuple[int, CheckedEigenvalue | None]]:
    """Verify and refine a whole spectrum on the pencil.

    The pencil is split into its diagonal blocks (block triangular form:
    det(G + λE) is their product); 1 × 1 blocks give their root directly.
    Each eigenvalue of A starts Newton's method on the block where it
    settles closest to its start. When A itself is poor — at wide spreads
    the reduction can misplace an eigenvalue by orders of magnitude, and
    Newton's method then lands on a neighbour that another start already
    found — the blocks' own QZ eigenvalues (equilibrated, for blocks up to
    :data:`QZ_LIMIT`) are starting values too. Verified eigenvalues equal
    within their bars form one group, counted as often as QZ found it (the
    pencil's own multiplicity), or, where QZ did not see it, as often as A's
    starts reached it without jumping. When fewer eigenvalues are verified
    than A has (less the zeros the topology guarantees), QZ is repeated on
    the frequency-scaled blocks (G, σE) over the range of σ the entries
    span, which resolves roots that the unscaled QZ sends to zero or to
    infinity (a 1e-17 1/s root beside a 1e20 1/s one).

    Parameters
    ----------
    pencil : Pencil
    values : numpy.ndarray
        Eigenvalues of A (1/s).
    bounds : numpy.ndarray, optional
        Their error estimates from A (1/s); a start "jumped" when Newton's
        method moved it further than both bounds.

    Returns
    -------
    list of (int, CheckedEigenvalue or None)
        One entry per eigenvalue of A: ``(-1, verified)``, or ``(k, None)``:
        input k keeps its own estimate (the smallest of A's eigenvalues
        first, which the caller's structural zeros replace).
    """
    blocks, roots = _blocks(pencil)
    n = len(values)
    bounds = np.zeros(n) if bounds is None else np.asarray(bounds, dtype=float)
    nnz = sum(b.G.nnz + b.E.nnz for b in blocks)
    exact = nnz * max(n, 1) <= EXACT_RESIDUAL_BUDGET
    qz_values = [_qz(block) if block.G.shape[0] <= QZ_LIMIT else [] for block in blocks]
    from_a = [_on_blocks(blocks, qz_values, v, _finite(bounds[k]), exact) for k, v in enumerate(values)]
    jumped = [
        r is not None and abs(r.value - values[k]) > 2 * max(r.abs_error, _finite(bounds[k]))
        for k, r in enumerate(from_a)
    ]
    from_qz: list[CheckedEigenvalue] = list(roots)
    for block, starts in zip(blocks, qz_values, strict=True):
        from_qz += [r for r in (_checked_or_none(block, v, exact) for v in starts) if r is not None]
    zeros = structural_zeros(pencil)
    if zeros:
        # The topology's zeros are exact and counted by the caller: a start that converged to
        # 0 (within its bars) found one of them, not a root of its own.
        from_a = [None if r is not None and abs(r.value) <= r.abs_error else r for r in from_a]
        from_qz = [r for r in from_qz if abs(r.value) > r.abs_error]
    # An A start counts towards a root's multiplicity only when it did not jump there and A's own
    # bound makes its value meaningful (a bound above |λ| says A did not resolve it).
    reliable = [
        r is not None and not jumped[k] and bool(np.isfinite(bounds[k])) and bounds[k] < abs(values[k])
        for k, r in enumerate(from_a)
    ]
    # The topology's zeros leave at most n − zeros non-zero roots (a QZ start near such a zero
    # that Newton's method carried to a small neighbour must not count that neighbour twice).
    plan = _plan(blocks, from_a, from_qz, reliable, n - zeros)
    if sum(p[2] for p in plan) + zeros < n:
        known = [r for r in from_a if r is not None] + from_qz
        extra = _sweep(blocks, known, exact, [float(abs(v)) for v in values])
        if extra:
            plan = _plan(blocks, from_a, from_qz + extra, reliable, n - zeros)
    slots: list[tuple[int, CheckedEigenvalue | None]] = []
    done: set[int] = set()
    for ks, qs, count, represented, _ in plan:
        if count <= 0:
            continue
        members = [from_a[k] for k in ks] + qs
        best = min((r for r in members if r is not None), key=lambda r: r.abs_error)
        slots.extend((-1, best) for _ in range(count))
        done |= set(represented)
    # Unverified places keep A's values: first those of starts that reached no verified root (or an
    # ambiguous one), not copies of roots already reported; smallest first within each.
    grouped = {k for ks, *_ in plan for k in ks}
    spare = sorted((k for k in range(n) if k not in done), key=lambda k: (k in grouped, abs(values[k])))
    slots.extend((k, None) for k in spare[: n - len(slots)])
    return slots


def _plan(
    blocks: list[_Prepared],
    from_a: list[CheckedEigenvalue | None],
    from_qz: list[CheckedEigenvalue],
    reliable: list[bool],
    n: int,
) -> list[tuple[list[int], list[CheckedEigenvalue], int, list[int], int]]:
    """Groups of equal verified eigenvalues with their counts, at most n in all.

    Each entry: (A starts, QZ results, count, A starts it stands for, evidence).
    """
    plan = []
    for ks, qs in _group(from_a, from_qz):
        kept = [k for k in ks if reliable[k]]
        # QZ works on the pencil itself, so its count is the multiplicity where it saw the root;
        # otherwise A's reliable starts that reached it.
        count = len(qs) if qs else max(len(kept), 1)
        starts = [r for r in (from_a[k] for k in ks) if r is not None]
        head = min(starts + qs, key=lambda r: r.abs_error)
        if count > 1 and head.abs_error <= DEFECTIVE_RTOL * abs(head.value):
            # Several starts reached this root and its bar is first-order tight, which a defective
            # root's never is (it moves by eps^(1/m)): it counts more than once only if the circuit
            # equations are singular to that order there (a semisimple multiple root); starts that
            # converged to one simple root are one root.
            count = min(count, max(1, _nullity(blocks, head.value)))
        represented = (kept + [k for k in ks if not reliable[k]])[:count]
        plan.append((ks, qs, count, represented, len(kept) + len(qs)))
    while sum(p[2] for p in plan) > n:
        # Over-counted: first a group with no reliable evidence, then one counted above its evidence.
        j = max(range(len(plan)), key=lambda i: (plan[i][4] == 0, plan[i][2] > plan[i][4], plan[i][2]))
        ks, qs, count, represented, evidence = plan[j]
        plan[j] = (ks, qs, count - 1, represented[: count - 1], evidence)
    return plan


def _on_blocks(
    blocks: list[_Prepared], qz_values: list[list[complex]], value: complex, bound: float, exact: bool
) -> CheckedEigenvalue | None:
    """:func:`check_eigenvalue` on the block where ``value`` settles closest to itself (in its bars).

    Blocks are tried nearest first (by their QZ eigenvalues); the first
    result that stays within twice its bars of the start is taken.
    """

    def nearness(i: int) -> float:
        return min((abs(q - value) for q in qz_values[i]), default=0.0)

    best: tuple[float, CheckedEigenvalue] | None = None
    for i in sorted(range(len(blocks)), key=nearness):
        result = _checked_or_none(blocks[i], value, exact)
        if result is None:
            continue
        distance = abs(result.value - value) / max(result.abs_error, bound, EPS * abs(value), 1e-300)
        if best is None or distance < best[0]:
            best = (distance, result)
        if distance <= 2:
            break
    return None if best is None else best[1]


#: Frequency scalings σ of the QZ sweep are this many decades apart.
SWEEP_STEP = 3
#: QZ eigenvalues μ of (G, σE) are taken as starting values σμ when 10^-w <= |μ| <= 10^w, w = this.
SWEEP_WINDOW = 2.5


def _sweep(
    blocks: list[_Prepared], known: list[CheckedEigenvalue], exact: bool, scales: Sequence[float] = ()
) -> list[CheckedEigenvalue]:
    """Eigenvalues not yet found, from QZ on the frequency-scaled blocks (G, σE).

    QZ's error is relative to the pencil's norm in its own scaling, so a
    root far from the bulk of the spectrum comes out as 0 or ∞. Scaling E by
    σ brings roots near |λ| = σ to order one; σ steps over the range the
    ratios of the entries span, each QZ contributing the eigenvalues within
    its window, each verified by Newton's method on the block. A result
    equal (within the bars) to one already known, or to another found here,
    is dropped: the sweep adds roots, never multiplicity. ``scales`` adds
    σ values of its own — the magnitudes of A's eigenvalues: the ratios of
    the entries do not bound the roots when a branch law mixes resistances
    and conductances (a 1e24 1/s root from a 9 fΩ resistor and a 3 fF
    capacitor lies outside them), A's estimate of a root does, roughly.
    """
    found: list[CheckedEigenvalue] = []
    for block in blocks:
        if block.G.shape[0] > QZ_LIMIT:
            continue
        g = np.abs(block.G.data[block.G.data != 0])
        e = np.abs(block.E.data[block.E.data != 0])
        if not (g.size and e.size):
            continue
        low = math.floor(math.log10(g.min() / e.max())) - SWEEP_STEP
        high = math.ceil(math.log10(g.max() / e.min())) + SWEEP_STEP
        starts: list[complex] = []
        sigmas = [10.0**power for power in range(low, high + 1, SWEEP_STEP)]
        sigmas += [v for v in scales if np.isfinite(v) and v > 0 and not low <= math.log10(v) <= high]
        for sigma in sigmas:
            for mu in _qz(block, sigma, scaled=True):
                if 10.0**-SWEEP_WINDOW <= abs(mu) <= 10.0**SWEEP_WINDOW:
                    lam = sigma * mu
                    if all(abs(lam - v) > 1e-8 * abs(lam) for v in starts):
                        starts.append(lam)
        for lam in starts:
            if any(abs(lam - r.value) <= max(r.abs_error, 1e-8 * abs(lam)) for r in known + found):
                continue
            result = _checked_or_none(block, lam, exact)
            if result is None:
                continue
            if abs(result.value) <= result.abs_error or any(
                abs(result.value - r.value) <= r.abs_error + result.abs_error for r in known + found
            ):
                continue  # a zero (the caller's), or a root already known
            found.append(result)
    return found


def _checked_or_none(prep: _Prepared, value: complex, exact: bool) -> CheckedEigenvalue | None:
    """:func:`check_eigenvalue`, or None when the linear algebra fails (the caller keeps A's estimate).

    At extreme values G + λE can overflow or defeat LAPACK's SVD; the check
    is then not available for that eigenvalue, which is never an error.
    """
    if not np.isfinite(value):
        return None
    try:
        with np.errstate(all="ignore"):
            return check_eigenvalue(prep, value, exact)
    except (np.linalg.LinAlgError, ValueError, ZeroDivisionError, OverflowError, RuntimeError):
        return None


def _finite(value: float) -> float:
    return value if np.isfinite(value) else 0.0


def _group(
    from_a: list[CheckedEigenvalue | None], from_qz: list[CheckedEigenvalue]
) -> list[tuple[list[int], list[CheckedEigenvalue]]]:
    """Verified results equal within their bars: (indices of A starts, results of QZ starts).

    Each result says "a root lies in this disc". Results are taken tightest
    first; one whose disc meets no group's tightest disc starts a group, one
    that meets exactly one joins it, and one that meets several is dropped:
    it may be any of them and is evidence for none. (Grouping by overlap
    with whichever came first let one loose bar — 1.2e15 on a 9.9e12 1/s
    root — swallow four tight, mutually disjoint roots, reported as five
    copies of the tightest.) The heads are pairwise disjoint, so the groups
    are distinct roots.
    """
    items: list[tuple[int, CheckedEigenvalue]] = [(k, r) for k, r in enumerate(from_a) if r is not None]
    items += [(-1, r) for r in from_qz]
    items.sort(key=lambda item: item[1].abs_error)
    groups: list[tuple[list[int], list[CheckedEigenvalue], CheckedEigenvalue]] = []
    for k, result in items:
        hits = [g for g in groups if abs(g[2].value - result.value) <= g[2].abs_error + result.abs_error]
        if not hits:
            groups.append(([k], [], result) if k >= 0 else ([], [result], result))
        elif len(hits) == 1:
            ks, qs, _ = hits[0]
            (ks.append(k) if k >= 0 else qs.append(result))
    return [(ks, qs) for ks, qs, _ in groups]


#: A verified root whose relative bar is above this may be defective (critical damping: −1 1/s twice,
#: bars 2e-7) and keeps the count of the starts that reached it; below it, its multiplicity is capped
#: by the nullity of G + λE.
DEFECTIVE_RTOL = 1e-10
#: A singular value of the equilibrated G + λE below this fraction of the largest counts as zero when
#: the multiplicity of a verified root is judged (a double root computed to rounding level has two
#: near 1e-15; a simple root's second smallest is far above).
MULTIPLE_TOL = 1e-10


def _nullity(blocks: list[_Prepared], lam: complex) -> int:
    """Numerical nullity of G + λE summed over the diagonal blocks (equilibrated, dense SVD).

    det(G + λE) is the product of the blocks' determinants, so a root's
    multiplicity is the sum of its multiplicities on the blocks, and each is
    at least its nullity there. Returns a large number when a block is too
    big to decompose (no cap is then applied).
    """
    total = 0
    for block in blocks:
        size = block.G.shape[0]
        if size > QZ_LIMIT:
            return size + total + 1
        matrix = sp.csr_array(block.G + lam * block.E)
        r, c = _equilibration(matrix)
        dense = (sp.diags_array(r) @ matrix @ sp.diags_array(c)).toarray()
        try:
            with np.errstate(all="ignore"):
                values = sla.svdvals(dense, check_finite=True)
        except (np.linalg.LinAlgError, ValueError):
            return size + total + 1
        if values.size and values[0] > 0:
            total += int(np.sum(values <= MULTIPLE_TOL * values[0]))
    return total


def _qz(prep: _Prepared, sigma: float = 1.0, scaled: bool = False) -> list[complex]:
    """Finite non-zero generalized eigenvalues of the (equilibrated) pencil, as extra starting values.

    With ``sigma``, those of (G, σE): μ with det(G + μσE) = 0, returned as
    μ (``scaled``) or λ = σμ.
    """
    g, e = prep.G.toarray(), prep.E.toarray() * sigma
    scale_r = 1.0 / np.maximum(np.max(np.abs(g), axis=1), np.max(np.abs(e), axis=1)).clip(min=1e-300)
    g, e = g * scale_r[:, None], e * scale_r[:, None]
    scale_c = 1.0 / np.maximum(np.max(np.abs(g), axis=0), np.max(np.abs(e), axis=0)).clip(min=1e-300)
    g, e = g * scale_c[None, :], e * scale_c[None, :]
    try:
        with np.errstate(all="ignore"):
            alpha, beta = sla.eigvals(-g, e, homogeneous_eigvals=True)
    except (sla.LinAlgError, ValueError):
        return []
    finite = np.abs(beta) > 1e-14 * np.abs(alpha)
    mu = [complex(v) for v in alpha[finite] / beta[finite] if v != 0 and np.isfinite(v)]
    return mu if scaled else [sigma * v for v in mu]


def structural_zeros(pencil: Pencil) -> int:
    """Number of zero eigenvalues that the topology alone guarantees.

    G (the pencil at λ = 0) is singular for every choice of element values
    when its sparsity pattern has no perfect matching — a loop of inductors
    (a conserved flux) or a cutset of capacitors (a conserved charge). Its
    structural rank deficiency is a lower bound on the multiplicity of the
    eigenvalue 0, decided exactly, independent of units and rounding.
    """
    rows, cols = _deflate(pencil.G, pencil.E)
    G = sp.csr_array(sp.csr_array(pencil.G)[rows][:, cols])
    G.eliminate_zeros()
    if G.shape[0] == 0:
        return 0
    return int(G.shape[0] - structural_rank(sp.csr_matrix(G)))


#: The quick check (:func:`quick_spectrum`) is tried up to this many states ...
QUICK_STATES = 40
#: ... and this many unknowns of the deflated pencil.
QUICK_PENCIL = 120
#: Rayleigh-quotient steps at most per eigenvalue in the quick check.
QUICK_STEPS = 4
#: The quick check is kept only when every relative error bar is below this: at rounding level, as
#: the 40-digit path would give (Circuit 1's −2000 1/s comes out at 1.8e-12 in double precision and
#: takes the 40-digit path, which gives 1e-16).
QUICK_RTOL = 1e-13


def quick_spectrum(pencil: Pencil, values: np.ndarray) -> list[CheckedEigenvalue] | None:
    """Verify a whole spectrum on the pencil in double precision, or None when that cannot vouch for it.

    The cheap path for small, well-conditioned models (a sweep's thousand
    cases): per eigenvalue λ of A, two-sided Rayleigh-quotient iteration on
    the dense, equilibrated G + λE (inverse iteration for the right and
    left null vectors w, z; λ ← λ − zᴴ(G + λE)w / zᴴEw), then the same bars
    as :func:`check_eigenvalue` with a double-precision residual:
    (η + eps)·κ for the computation, eps·κ_data for the element values'
    rounding, plus the last correction, each times :data:`SAFETY`.

    The result stands only when it accounts for the whole spectrum: every
    eigenvalue verified with a relative bar below :data:`QUICK_RTOL`, the
    bars pairwise disjoint (so n distinct simple roots of det(G + λE),
    whose degree is n), every real part's sign resolved by its bar (the
    verdict then needs nothing more), and no zero the topology guarantees.
    Anything else — a multiple or clustered root, a tiny damping ratio, a
    bar that the 40-digit path would shrink — returns None, and the caller
    runs :func:`check_spectrum`.
    """
    n = len(values)
    if n == 0 or n > QUICK_STATES or not np.all(np.isfinite(values)) or np.any(values == 0):
        return None
    if pencil.G.shape[0] > 2 * QUICK_PENCIL:
        return None
    G, E = pencil.G.toarray().real.astype(float), pencil.E.toarray().real.astype(float)
    D = pencil.G_data.toarray().real.astype(float) if pencil.G_data is not None else G
    rows, cols = _dense_deflate(G, E)
    if len(rows) > QUICK_PENCIL:
        return None
    G, E, D = G[np.ix_(rows, cols)], E[np.ix_(rows, cols)], D[np.ix_(rows, cols)]

    if G.shape[0] == 0 or structural_rank(sp.csr_matrix(G != 0)) < G.shape[0]:
        return None  # zeros the topology guarantees: the full check counts them
    # Each eigenvalue on its own diagonal block (as in check_spectrum): an eigenvector is exactly zero
    # on the other blocks, where inverse iteration would leave rounding that no backward error excuses.
    parts = _diagonal_blocks(sp.csr_array(G), sp.csr_array(E)) or [(np.arange(len(G)), np.arange(len(G)))]
    blocks = []
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", sla.LinAlgWarning)
        for r, c in parts:
            g, e, d = G[np.ix_(r, c)], E[np.ix_(r, c)], D[np.ix_(r, c)]
            if np.any(e != 0):
                roots = _dense_qz(g, e)
                if roots is None:
                    return None
                blocks.append((g, e, np.abs(g), np.abs(e), np.abs(d), roots))
    # The blocks' finite roots must number the states (the pencil's degree); each eigenvalue of A is
    # then checked on the block holding the nearest unclaimed one.
    if sum(len(b[5]) for b in blocks) != n:
        return None
    unclaimed = [list(b[5]) for b in blocks]
    results: list[CheckedEigenvalue] = []
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", sla.LinAlgWarning)
        for value in values:
            lam = complex(value)
            i, j = min(
                ((i, j) for i, roots in enumerate(unclaimed) for j in range(len(roots))),
                key=lambda ij: abs(unclaimed[ij[0]][ij[1]] - lam),
            )
            unclaimed[i].pop(j)
            result = _quick_one(*blocks[i][:5], lam)
            if result is None or not result.abs_error <= QUICK_RTOL * abs(result.value):
                return None
            if not abs(result.value.real) > result.re_error:
                return None  # the sign of the real part is not resolved in double precision
            results.append(result)
    for i, a in enumerate(results):
        for b in results[i + 1 :]:
            if abs(a.value - b.value) <= a.abs_error + b.abs_error:
                return None  # possibly one root twice, or a multiple root: the full check decides
    return results


def _dense_qz(g: np.ndarray, e: np.ndarray) -> list[complex] | None:
    """Finite roots of det(g + λe) of one small dense block (equilibrated QZ), None on failure."""
    if g.shape[0] == 1:
        return [complex(-g[0, 0] / e[0, 0])] if e[0, 0] != 0 else []
    scale_r = 1.0 / np.maximum(np.abs(g).max(axis=1), np.abs(e).max(axis=1)).clip(min=1e-300)
    g, e = g * scale_r[:, None], e * scale_r[:, None]
    scale_c = 1.0 / np.maximum(np.abs(g).max(axis=0), np.abs(e).max(axis=0)).clip(min=1e-300)
    g, e = g * scale_c[None, :], e * scale_c[None, :]
    try:
        alpha, beta = sla.eigvals(-g, e, homogeneous_eigvals=True, check_finite=False)
    except (sla.LinAlgError, ValueError):
        return None
    finite = np.abs(beta) > 1e-14 * np.abs(alpha)
    roots = alpha[finite] / beta[finite]
    if not np.all(np.isfinite(roots)):
        return None
    return [complex(v) for v in roots]


def _dense_deflate(G: np.ndarray, E: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_deflate` on dense matrices: rows and columns kept once one-entry rows are removed."""
    rows, cols = np.arange(G.shape[0]), np.arange(G.shape[1])
    while rows.size:
        g, e = G[np.ix_(rows, cols)] != 0, E[np.ix_(rows, cols)] != 0
        single = np.flatnonzero((g.sum(axis=1) == 1) & (e.sum(axis=1) == 0))
        if not single.size:
            break
        drop_c = np.unique(np.argmax(g[single], axis=1))
        keep_r = np.setdiff1d(np.arange(rows.size), single)
        keep_c = np.setdiff1d(np.arange(cols.size), drop_c)
        if keep_r.size != keep_c.size:
            break
        rows, cols = rows[keep_r], cols[keep_c]
    return rows, cols


def _quick_vectors(G: np.ndarray, E: np.ndarray, lam: complex) -> tuple[np.ndarray, np.ndarray] | None:
    """Right and left null vectors of the dense, equilibrated G + λE by inverse iteration."""
    m = G + lam * E
    abs_m = np.abs(m)
    row = abs_m.max(axis=1)
    r = np.where(row > 0, 1.0 / np.where(row > 0, row, 1.0), 1.0)
    col = (abs_m * r[:, None]).max(axis=0)
    c = np.where(col > 0, 1.0 / np.where(col > 0, col, 1.0), 1.0)
    s = m * r[:, None] * c[None, :]
    lu, piv = sla.lu_factor(s, check_finite=False)
    diag = np.abs(np.diag(lu))
    if not np.all(np.isfinite(lu)):
        return None
    if np.min(diag) == 0:  # λ is a root to the last bit: factorise a neighbour instead
        lu, piv = sla.lu_factor(s + (4 * EPS) * np.eye(len(s)), check_finite=False)
    rng_w, rng_z = _start_vectors(len(s))
    y = _inverse_iteration(lambda v: sla.lu_solve((lu, piv), v, check_finite=False), lambda v: s @ v, rng_w)
    x = _inverse_iteration(
        lambda v: sla.lu_solve((lu, piv), v, trans=2, check_finite=False), lambda v: s.conj().T @ v, rng_z
    )
    w, z = _unit(c * y), _unit(r * x)
    if not (np.all(np.isfinite(w)) and np.all(np.isfinite(z))):
        return None
    return w, z


def _quick_one(
    G: np.ndarray, E: np.ndarray, abs_g: np.ndarray, abs_e: np.ndarray, abs_d: np.ndarray, lam0: complex
) -> CheckedEigenvalue | None:
    """One eigenvalue of the quick check: Rayleigh-quotient iteration, then the double-precision bars."""
    lam = lam0
    step = math.inf
    for iteration in range(QUICK_STEPS):
        vectors = _quick_vectors(G, E, lam)
        if vectors is None:
            return None
        w, z = vectors
        d = np.vdot(z, E @ w)
        if d == 0 or not np.isfinite(d):
            return None
        correction = np.vdot(z, (G + lam * E) @ w) / d
        step = abs(correction)
        if not math.isfinite(step):
            return None
        if step <= 4 * EPS * abs(lam) or iteration == QUICK_STEPS - 1:
            break  # settled, or at the rounding floor: the last correction joins the bar
        lam = lam - complex(correction)
    # Bars at λ with its own vectors (those of the last iteration); a λ that did not settle has a
    # large last correction, and its bar says so.
    u = z.conj() / d
    au, aw = np.abs(u), np.abs(w)
    e_part = abs(lam) * float(au @ abs_e @ aw)
    kappa = float(au @ abs_g @ aw) + e_part
    kappa_data = float(au @ abs_d @ aw) + e_part
    w_norm = w / w[int(np.argmax(aw))]
    eta = min(_dense_backward_error(G, E, abs_g, abs_e, lam, v) for v in _cleaned(w_norm))
    if not (math.isfinite(kappa) and math.isfinite(eta)) or eta > 1e-10:
        return None
    computation = SAFETY * (step + eta * kappa + EPS * kappa)
    data = SAFETY * EPS * kappa_data
    return CheckedEigenvalue(
        lam,
        data + computation + EPS * abs(lam),
        data + computation + EPS * abs(lam.real),
        data + computation + EPS * abs(lam.imag),
        eta,
        refined=lam != lam0,
    )


def _dense_backward_error(
    G: np.ndarray, E: np.ndarray, abs_g: np.ndarray, abs_e: np.ndarray, lam: complex, w: np.ndarray
) -> float:
    """:func:`_backward_error` for dense matrices."""
    residual = G @ w + lam * (E @ w)
    aw = np.abs(w)
    scale = abs_g @ aw + abs(lam) * (abs_e @ aw)
    ratio = np.where(
        scale > 0, np.abs(residual) / np.where(scale > 0, scale, 1.0), np.where(residual == 0, 0.0, np.inf)
    )
    return float(np.max(ratio)) if ratio.size else 0.0
