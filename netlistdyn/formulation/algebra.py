"""The matrix algebra the reduction to state space is written over, and its sparse-float form.

:func:`netlistdyn.formulation.formulate.reduce` eliminates everything but the states
once, over an :class:`Algebra`: the few matrix operations it needs besides
``+``, ``-`` and ``@``. Two algebras implement it:

* :class:`SparseFloats` (here): scipy sparse float matrices with the
  element values. Its operations know about rounding: a difference that
  cancels to rounding level is exactly zero (:data:`CANCELLATION`), a
  product of solved matrices below :data:`PRODUCT_ZERO` of its terms is
  zero, solves are equilibrated LU refusing pivots spread beyond
  :data:`SINGULAR_RCOND`, and derivatives of resistive unknowns are found
  through a least-squares solution and an SVD null space.
* :class:`netlistdyn.formulation.symbolic.RationalFunctions`: sympy matrices over the
  field of rational functions in the element symbols — exact LU with
  ``cancel``, ``rref``, plain subtraction, and no rounding tests (the
  numeric compile has already decided them on the same tree).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import Any, Protocol

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

from netlistdyn.base.errors import NetlistError, SingularCircuitError
from netlistdyn.circuit.netlist import Netlist

#: A factorisation whose pivots span more than this ratio is treated as singular.
SINGULAR_RCOND = 1e-14

#: Positions of rows or columns: a sequence of ints or an integer array (the classes' ``np.intp`` arrays).
Index = Sequence[int] | NDArray[np.integer[Any]]


class NotSupportedError(NetlistError):
    """The circuit needs a formulation this compiler does not have (higher index)."""


@dataclass(frozen=True)
class Block:
    """Rows of equations after eliminating s and d: coefficients of x, y, x', y', u, u'."""

    x: Any
    y: Any
    dx: Any
    dy: Any
    u: Any
    du: Any


class Algebra(Protocol):
    """What the reduction needs of a matrix type besides ``+``, ``-``, ``@``.

    (The reduction is :func:`~netlistdyn.formulation.formulate.reduce`.)

    Matrices have a ``shape`` and support slicing ``m[:, a:b]``.
    """

    def triplets(self, entries: Sequence[tuple[int, int, Any]], shape: tuple[int, int]) -> Any:
        """A matrix from ``(row, column, coefficient)`` triplets (repeated positions add)."""

    def topology(self, matrix: sp.csr_array) -> Any:
        """A sparse matrix of small integers (the tree's ±1) in this algebra."""

    def zeros(self, rows: int, cols: int) -> Any:
        """The zero matrix."""

    def rows(self, matrix: Any, index: Index) -> Any:
        """The rows ``index`` of ``matrix``."""

    def cols(self, matrix: Any, index: Index) -> Any:
        """The columns ``index`` of ``matrix``."""

    def hstack(self, blocks: Sequence[Any]) -> Any:
        """Blocks side by side."""

    def vstack(self, blocks: Sequence[Any]) -> Any:
        """Blocks one above the other."""

    def diag(self, values: Sequence[Any], inverse: bool = False) -> Any:
        """diag(values), or diag(1/values)."""

    def clean(self, matrix: Any) -> Any:
        """The matrix in canonical form (sparse floats: CSR without stored zeros)."""

    def nonzero(self, matrix: Any) -> bool:
        """True when some entry is not zero."""

    def cancelled(self, base: Any, left: Any, right: Any) -> Any:
        """base − left @ right, entries that cancel set to exactly zero."""

    def negligible(self, left: Any, right: Any) -> bool:
        """True when left @ right is zero (to rounding, for floats)."""

    def solve(self, matrix: Any, rhs: Any, what: str) -> Any:
        """matrix⁻¹ rhs; :class:`SingularCircuitError` ``what`` when matrix is singular."""

    def algebraic_derivatives(self, block: Block, involved: Sequence[str], netlist: Netlist) -> Block:
        """The block with derivatives of resistive unknowns replaced by those of x and u."""

    def check_finite(self, netlist: Netlist, matrices: dict[str, Any]) -> None:
        """Refuse a model whose entries overflowed."""


@dataclass(frozen=True)
class SparseFloats:
    """The numeric algebra: scipy sparse float matrices (CSR), rounding-aware."""

    def triplets(self, entries: Sequence[tuple[int, int, Any]], shape: tuple[int, int]) -> sp.csr_array:
        if not entries:
            return sp.csr_array(shape)
        rows, cols, vals = zip(*entries, strict=True)
        return sp.csr_array((np.asarray(vals, dtype=float), (rows, cols)), shape=shape)

    def topology(self, matrix: sp.csr_array) -> sp.csr_array:
        return matrix

    def zeros(self, rows: int, cols: int) -> sp.csr_array:
        return sp.csr_array((rows, cols))

    def rows(self, matrix: sp.csr_array, index: Index) -> sp.csr_array:
        return sp.csr_array(matrix[index, :]) if len(index) else sp.csr_array((0, matrix.shape[1]))

    def cols(self, matrix: sp.csr_array, index: Index) -> sp.csr_array:
        return sp.csr_array(matrix[:, index]) if len(index) else sp.csr_array((matrix.shape[0], 0))

    def hstack(self, blocks: Sequence[sp.csr_array]) -> sp.csr_array:
        return sp.hstack(list(blocks), format="csr")

    def vstack(self, blocks: Sequence[sp.csr_array]) -> sp.csr_array:
        return sp.vstack(list(blocks), format="csr")

    def diag(self, values: Sequence[float], inverse: bool = False) -> sp.csr_array:
        if not len(values):
            return sp.csr_array((0, 0))
        array = np.asarray(values, dtype=float)
        return sp.csr_array(sp.diags_array(1.0 / array if inverse else array))

    def clean(self, matrix: sp.sparray) -> sp.csr_array:
        return _clean(matrix)

    def nonzero(self, matrix: sp.csr_array) -> bool:
        return bool(matrix.nnz)

    def cancelled(self, base: sp.csr_array, left: sp.csr_array, right: sp.csr_array) -> sp.csr_array:
        return _cancelled(base, left, right)

    def negligible(self, left: sp.csr_array, right: sp.csr_array) -> bool:
        return _negligible(left, right)

    def solve(self, matrix: sp.csr_array, rhs: sp.csr_array, what: str) -> sp.csr_array:
        return _solve(matrix, rhs, what)

    def algebraic_derivatives(self, block: Block, involved: Sequence[str], netlist: Netlist) -> Block:
        return _substitute_algebraic_derivatives(block, involved, netlist)

    def check_finite(self, netlist: Netlist, matrices: dict[str, sp.csr_array]) -> None:
        _check_finite(netlist, matrices)


#: The numeric algebra (stateless).
NUMERIC = SparseFloats()


def _clean(matrix: sp.sparray) -> sp.csr_array:
    """CSR copy without explicit zeros.

    Only exact zeros go: element values span many decades (1 fF beside
    1 kH), so no threshold relative to a matrix's largest entry can tell a
    small coefficient from rounding noise, and dropping a real one would
    silently change the model.
    """
    out = sp.csr_array(matrix, dtype=float)
    out.eliminate_zeros()
    return out


#: A sum is exactly zero when it is below this multiple of eps times the sum of its terms' magnitudes.
CANCELLATION = 16 * float(np.finfo(float).eps)


def _cancelled(base: sp.csr_array, left: sp.csr_array, right: sp.csr_array) -> sp.csr_array:
    """base − left @ right, with entries that cancel to rounding level set to exactly zero."""
    value = sp.coo_array(sp.csr_array(base - left @ right))
    if value.nnz == 0:
        return sp.csr_array(value.shape)
    bound = sp.csr_array(abs(sp.csr_array(base)) + abs(sp.csr_array(left)) @ abs(sp.csr_array(right)))
    magnitude = np.asarray(bound[value.row, value.col]).ravel()
    keep = np.abs(value.data) > CANCELLATION * magnitude
    return sp.csr_array((value.data[keep], (value.row[keep], value.col[keep])), shape=value.shape)


def _negligible(left: sp.csr_array, right: sp.csr_array) -> bool:
    """True when every entry of left @ right is rounding noise relative to |left| @ |right|.

    ``right`` comes from a sparse solve, so its entries carry relative errors
    up to about the condition number times eps; a product that cancels to
    below :data:`PRODUCT_ZERO` of its terms' magnitudes is zero. The test is
    relative entry by entry, so it does not depend on units.
    """
    product = sp.coo_array(sp.csr_array(left @ right))
    if product.nnz == 0:
        return True
    bound = sp.csr_array(abs(sp.csr_array(left)) @ abs(sp.csr_array(right)))
    magnitude = np.asarray(bound[product.row, product.col]).ravel()
    return bool(np.all(np.abs(product.data) <= PRODUCT_ZERO * magnitude))


#: Relative level below which a product of solved matrices is taken as zero (see _negligible).
PRODUCT_ZERO = 1e-8


#: Largest resistive system for which derivatives of algebraic unknowns are resolved (dense SVD).
ALGEBRAIC_DERIVATIVE_LIMIT = 3000


def _substitute_algebraic_derivatives(yb: Block, involved: Sequence[str], netlist: Netlist) -> Block:
    """Replace derivatives of resistive unknowns that the derivative-free rows fix.

    An excess capacitor in a loop with a controlled voltage-type branch (a
    VCVS, or a transformer port: rigidly geared inertias) puts the
    derivative of that branch's voltage into the resistive equations. When
    the rows without derivatives determine those unknowns from states and
    inputs alone (y_Z = S_x x + S_u u, checked through the null space), their
    derivatives are S_x x' + S_u u' and the system stays first order.
    """
    dy = yb.dy.tocsc()
    z = np.flatnonzero(np.diff(dy.indptr))
    dynamic = (np.diff(yb.dx.indptr) + np.diff(yb.dy.indptr) + np.diff(yb.du.indptr)) > 0
    rows = np.flatnonzero(~dynamic)
    n_y = yb.y.shape[1]
    unsupported = NotSupportedError(
        "a controlled source or transformer depends on the derivative of a resistive quantity "
        f"({', '.join(involved) or 'check the controlled sources'}); not supported",
        netlist.elements[0].loc,
    )
    if n_y > ALGEBRAIC_DERIVATIVE_LIMIT or len(rows) == 0:
        raise unsupported
    # Judged on the equilibrated rows (every row and column peaking at 1), so that the rank and
    # residual decisions do not depend on the units of the unknowns.
    r_scale, c_scale = _equilibrate(sp.csr_array(yb.y.toarray()[rows]))
    g = r_scale[:, None] * yb.y.toarray()[rows] * c_scale[None, :]
    rhs = -r_scale[:, None] * np.hstack([yb.x.toarray()[rows], yb.u.toarray()[rows]])
    scaled_solution, *_ = np.linalg.lstsq(g, rhs, rcond=None)
    if np.linalg.norm(g @ scaled_solution - rhs) > 1e-9 * max(float(np.linalg.norm(rhs)), 1e-300):
        raise unsupported
    kernel = sla.null_space(g, rcond=1e-12) if g.shape[0] else np.eye(n_y)
    if kernel.size and np.max(np.abs(kernel[z])) > 1e-9:
        raise unsupported  # the derivative-free rows leave y_Z undetermined
    solution = c_scale[:, None] * scaled_solution
    nx_ = yb.x.shape[1]
    s_x = sp.csr_array(solution[z, :nx_])
    s_u = sp.csr_array(solution[z, nx_:])
    dy_z = sp.csr_array(dy[:, z])
    return Block(
        yb.x,
        yb.y,
        _clean(yb.dx + dy_z @ s_x),
        sp.csr_array(yb.dy.shape),
        yb.u,
        _clean(yb.du + dy_z @ s_u),
    )


def _equilibrate(matrix: sp.csr_array) -> tuple[np.ndarray, np.ndarray]:
    """Row and column scalings r, c making every row and column of diag(r)·M·diag(c) peak at 1.

    Element values span many decades (1 fF next to 1 kH): singularity is
    judged on the equilibrated matrix, as LAPACK's expert drivers do.
    """
    abs_m = abs(sp.csr_array(matrix))
    row_max = abs_m.max(axis=1).toarray().ravel()
    r = np.where(row_max > 0, 1.0 / np.where(row_max > 0, row_max, 1.0), 1.0)
    col_max = (sp.diags_array(r) @ abs_m).max(axis=0).toarray().ravel()
    c = np.where(col_max > 0, 1.0 / np.where(col_max > 0, col_max, 1.0), 1.0)
    return r, c


def _solve(matrix: sp.csr_array, rhs: sp.csr_array, what: str) -> sp.csr_array:
    """matrix⁻¹ rhs for a square sparse matrix, refusing (near-)singular ones.

    The matrix is equilibrated first (rows, then columns, scaled to unit
    maximum); diagonal matrices are then inverted directly, small ones
    densely with LAPACK's reciprocal condition estimate, large ones with
    SuperLU.
    """
    n = matrix.shape[0]
    if n == 0 or rhs.shape[1] == 0:
        return sp.csr_array((n, rhs.shape[1]))
    r, c = _equilibrate(matrix)
    scaled = sp.csr_array(sp.diags_array(r) @ matrix @ sp.diags_array(c))
    rhs_scaled = sp.csr_array(sp.diags_array(r) @ rhs)
    return _clean(sp.diags_array(c) @ _solve_equilibrated(scaled, rhs_scaled, what))


def _solve_equilibrated(matrix: sp.csr_array, rhs: sp.csr_array, what: str) -> sp.csr_array:
    n = matrix.shape[0]
    coo = matrix.tocoo()
    if np.all(coo.row == coo.col) and coo.nnz == n:
        diag = matrix.diagonal()
        if np.min(np.abs(diag)) <= SINGULAR_RCOND * np.max(np.abs(diag)):
            raise SingularCircuitError(what)
        return _clean(sp.diags_array(1.0 / diag) @ rhs)
    if n <= 1500:
        dense = matrix.toarray()
        with warnings.catch_warnings():
            warnings.simplefilter("error", sla.LinAlgWarning)
            try:
                lu = sla.lu_factor(dense)
            except (sla.LinAlgError, sla.LinAlgWarning, ValueError):
                raise SingularCircuitError(what) from None
        rcond = _rcond(dense, lu)
        if rcond < SINGULAR_RCOND:
            raise SingularCircuitError(what)
        return _clean(sp.csr_array(sla.lu_solve(lu, rhs.toarray())))
    try:
        lu_sparse = spla.splu(sp.csc_matrix(matrix))
    except RuntimeError:
        raise SingularCircuitError(what) from None
    pivots = np.abs(lu_sparse.U.diagonal())
    if pivots.min() <= SINGULAR_RCOND * pivots.max():
        raise SingularCircuitError(what)
    rhs_csc = sp.csc_array(rhs)
    nonzero_cols = np.flatnonzero(np.diff(rhs_csc.indptr))
    result = sp.lil_array((n, rhs.shape[1]))
    for start in range(0, len(nonzero_cols), 256):
        cols = nonzero_cols[start : start + 256]
        result[:, cols] = lu_sparse.solve(rhs_csc[:, cols].toarray())
    return _clean(result)


def _rcond(dense: np.ndarray, lu: tuple[np.ndarray, np.ndarray]) -> float:
    anorm = np.linalg.norm(dense, 1)
    if anorm == 0:
        return 0.0
    (gecon,) = sla.get_lapack_funcs(("gecon",), (lu[0],))
    rcond, _ = gecon(lu[0], anorm, norm="1")
    return float(rcond)


def _check_finite(netlist: Netlist, matrices: dict[str, sp.csr_array]) -> None:
    """Refuse a model with overflowed (infinite or NaN) entries, naming the most extreme value.

    Element values near the ends of double precision (1e-308 Ω) make
    products such as 1/(R·C) overflow; a model holding ``inf`` would be
    a wrong number, not a model.
    """
    bad = [name for name, m in matrices.items() if m.nnz and not np.all(np.isfinite(m.data))]
    if not bad:
        return
    valued = [e for e in netlist.elements if e.value != 0 and np.isfinite(e.value)]
    worst = max(valued, key=lambda e: abs(np.log10(abs(e.value))), default=netlist.elements[0])
    raise NetlistError(
        f"{worst.label}: value {worst.value:g} overflows double precision in the model "
        f"({', '.join(bad)} would hold infinite entries); use values within about 1e-150…1e150",
        worst.loc,
    )


# --- exact rational arithmetic on the parsed doubles ------------------------------------------


class RationalMatrix:
    """A sparse matrix of exact rationals (``fractions.Fraction``): entries by position.

    Supports what :func:`netlistdyn.formulation.formulate.reduce` does with matrices:
    ``+``, ``-``, unary ``-``, ``@``, ``shape`` and ``m[:, a:b]`` slices.
    """

    __slots__ = ("entries", "shape")

    def __init__(self, entries: dict[tuple[int, int], Fraction], shape: tuple[int, int]) -> None:
        self.entries = {k: v for k, v in entries.items() if v}
        self.shape = shape

    def __add__(self, other: RationalMatrix) -> RationalMatrix:
        out = dict(self.entries)
        for k, v in other.entries.items():
            out[k] = out.get(k, 0) + v
        return RationalMatrix(out, self.shape)

    def __sub__(self, other: RationalMatrix) -> RationalMatrix:
        return self + (-other)

    def __neg__(self) -> RationalMatrix:
        return RationalMatrix({k: -v for k, v in self.entries.items()}, self.shape)

    def __matmul__(self, other: RationalMatrix) -> RationalMatrix:
        by_row: dict[int, list[tuple[int, Fraction]]] = {}
        for (r, c), v in other.entries.items():
            by_row.setdefault(r, []).append((c, v))
        out: dict[tuple[int, int], Fraction] = {}
        for (i, k), a in self.entries.items():
            for j, b in by_row.get(k, ()):
                out[(i, j)] = out.get((i, j), 0) + a * b
        return RationalMatrix(out, (self.shape[0], other.shape[1]))

    def __getitem__(self, key: tuple[slice, slice]) -> RationalMatrix:
        rows, cols = (range(n)[s] for s, n in zip(key, self.shape, strict=True))
        return self.pick(rows, cols)

    def pick(self, rows: Index, cols: Index) -> RationalMatrix:
        """The submatrix of the given rows and columns, in that order."""
        row_at = {int(r): k for k, r in enumerate(rows)}
        col_at = {int(c): k for k, c in enumerate(cols)}
        out = {(row_at[r], col_at[c]): v for (r, c), v in self.entries.items() if r in row_at and c in col_at}
        return RationalMatrix(out, (len(row_at), len(col_at)))

    def to_float(self) -> sp.csr_array:
        """The correctly rounded doubles (``float(Fraction)`` rounds to nearest)."""
        if not self.entries:
            return sp.csr_array(self.shape)
        rows = [r for r, _ in self.entries]
        cols = [c for _, c in self.entries]
        vals = [float(v) for v in self.entries.values()]
        return sp.csr_array((vals, (rows, cols)), shape=self.shape)


@dataclass(frozen=True)
class ExactRationals:
    """The exact :class:`Algebra` over the rationals: the doubles of the netlist, taken exactly.

    Every operation is exact (``fractions.Fraction``), so the reduction's result,
    rounded once at the end (:meth:`RationalMatrix.to_float`), is the correctly
    rounded model of the parsed values: no entry suffers the cancellation that
    floating-point elimination meets where element values span decades. The
    questions the numeric algebra answers to rounding (which tree, higher
    index) have been decided by the numeric compile on the same tree; a
    product that must vanish is checked to vanish exactly. Derivatives of
    resistive unknowns are left to the numeric algebra (NotSupportedError).
    The cost grows fast with the circuit: see :data:`EXACT_BRANCH_LIMIT`.
    """

    def triplets(self, entries: Sequence[tuple[int, int, Any]], shape: tuple[int, int]) -> RationalMatrix:
        out: dict[tuple[int, int], Fraction] = {}
        for row, col, coeff in entries:
            out[(row, col)] = out.get((row, col), 0) + Fraction(coeff)
        return RationalMatrix(out, shape)

    def topology(self, matrix: sp.csr_array) -> RationalMatrix:
        coo = matrix.tocoo()
        entries = [
            (int(r), int(c), round(float(v))) for r, c, v in zip(coo.row, coo.col, coo.data, strict=True)
        ]
        return self.triplets(entries, coo.shape)

    def zeros(self, rows: int, cols: int) -> RationalMatrix:
        return RationalMatrix({}, (rows, cols))

    def rows(self, matrix: RationalMatrix, index: Index) -> RationalMatrix:
        return matrix.pick(index, range(matrix.shape[1]))

    def cols(self, matrix: RationalMatrix, index: Index) -> RationalMatrix:
        return matrix.pick(range(matrix.shape[0]), index)

    def hstack(self, blocks: Sequence[RationalMatrix]) -> RationalMatrix:
        out: dict[tuple[int, int], Fraction] = {}
        offset = 0
        for block in blocks:
            out.update({(r, c + offset): v for (r, c), v in block.entries.items()})
            offset += block.shape[1]
        return RationalMatrix(out, (blocks[0].shape[0] if blocks else 0, offset))

    def vstack(self, blocks: Sequence[RationalMatrix]) -> RationalMatrix:
        out: dict[tuple[int, int], Fraction] = {}
        offset = 0
        for block in blocks:
            out.update({(r + offset, c): v for (r, c), v in block.entries.items()})
            offset += block.shape[0]
        return RationalMatrix(out, (offset, blocks[0].shape[1] if blocks else 0))

    def diag(self, values: Sequence[Any], inverse: bool = False) -> RationalMatrix:
        exact = [Fraction(v) for v in values]
        return RationalMatrix(
            {(k, k): 1 / v if inverse else v for k, v in enumerate(exact)}, (len(exact),) * 2
        )

    def clean(self, matrix: RationalMatrix) -> RationalMatrix:
        return matrix

    def nonzero(self, matrix: RationalMatrix) -> bool:
        return bool(matrix.entries)

    def cancelled(self, base: RationalMatrix, left: RationalMatrix, right: RationalMatrix) -> RationalMatrix:
        return base - left @ right

    def negligible(self, left: RationalMatrix, right: RationalMatrix) -> bool:
        return not (left @ right).entries

    def solve(self, matrix: RationalMatrix, rhs: RationalMatrix, what: str) -> RationalMatrix:
        """matrix⁻¹ rhs by Gaussian elimination on sparse rows (exact: any nonzero pivot)."""
        n = matrix.shape[0]
        rows: list[dict[int, Fraction]] = [{} for _ in range(n)]
        right: list[dict[int, Fraction]] = [{} for _ in range(n)]
        for (r, c), v in matrix.entries.items():
            rows[r][c] = v
        for (r, c), v in rhs.entries.items():
            right[r][c] = v
        order: list[int] = []  # pivot row of each column
        used: set[int] = set()
        for col in range(n):
            pivot = next((r for r in range(n) if r not in used and rows[r].get(col)), None)
            if pivot is None:
                raise SingularCircuitError(what)
            order.append(pivot)
            used.add(pivot)
            prow, pright, p = rows[pivot], right[pivot], rows[pivot][col]
            for r in range(n):
                factor = rows[r].get(col) if r != pivot else None
                if not factor:
                    continue
                factor = factor / p
                for target, source in ((rows[r], prow), (right[r], pright)):
                    for c, v in source.items():
                        value = target.get(c, 0) - factor * v
                        if value:
                            target[c] = value
                        else:
                            target.pop(c, None)
        out: dict[tuple[int, int], Fraction] = {}
        for col, r in enumerate(order):
            p = rows[r][col]
            out.update({(col, c): v / p for c, v in right[r].items()})
        return RationalMatrix(out, (n, rhs.shape[1]))

    def algebraic_derivatives(self, block: Block, involved: Sequence[str], netlist: Netlist) -> Block:
        raise NotSupportedError("exact reduction: derivatives of resistive unknowns", netlist.elements[0].loc)

    def check_finite(self, netlist: Netlist, matrices: dict[str, Any]) -> None:
        return None  # rationals do not overflow; the rounding at the end is checked instead


#: The exact algebra (stateless).
EXACT = ExactRationals()
