"""Control analysis of a compiled model: controllability, observability, minimal
realisation and transfer functions.

Controllability and observability use the PBH test: eigenvalue λ is
uncontrollable when [A − λI, B] loses rank, unobservable when [A − λI; C]
does. Rank is judged by the smallest singular value relative to the largest,
with :data:`RANK_RTOL`. The Krylov ranks (of [B AB … Aⁿ⁻¹B] and its dual,
columns normalised) are computed too and shown only when they disagree with
PBH, which is the more reliable of the two for stiff models.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.signal as sig

from .model import CompileInfo, StateSpaceModel

#: Relative singular-value threshold for numerical rank.
RANK_RTOL = 1e-9


@dataclass(frozen=True)
class Structure:
    """Controllability and observability of a model.

    Attributes
    ----------
    uncontrollable, unobservable : tuple of complex
        Eigenvalues that fail the PBH test (1/s).
    controllable, observable : bool
    krylov_ranks : tuple of int
        Ranks of the controllability and observability matrices.
    tolerance : float
        The relative singular-value threshold used.
    """

    uncontrollable: tuple[complex, ...]
    unobservable: tuple[complex, ...]
    krylov_ranks: tuple[int, int]
    nstates: int
    tolerance: float = RANK_RTOL

    @property
    def controllable(self) -> bool:
        """True when every mode passes the PBH controllability test."""
        return not self.uncontrollable

    @property
    def observable(self) -> bool:
        """True when every mode passes the PBH observability test."""
        return not self.unobservable

    @property
    def krylov_agrees(self) -> bool:
        """True when the Krylov ranks tell the same story as PBH."""
        n = self.nstates
        return (self.krylov_ranks[0] == n) == self.controllable and (
            self.krylov_ranks[1] == n
        ) == self.observable


def _rank_deficient(matrix: np.ndarray, tol: float) -> bool:
    values = sla.svdvals(matrix)
    return values.size == 0 or values[-1] <= tol * max(values[0], 1e-300)


def _krylov(A: np.ndarray, B: np.ndarray, normalise: bool = True) -> np.ndarray:
    """[B AB … Aⁿ⁻¹B], by default with unit columns (zero columns dropped)."""
    n = A.shape[0]
    blocks, block = [], B
    for _ in range(n):
        blocks.append(block)
        block = A @ block
    K = np.hstack(blocks) if blocks else np.zeros((n, 0))
    if not normalise:
        return K
    norms = np.linalg.norm(K, axis=0)
    return K[:, norms > 0] / norms[norms > 0]


def _krylov_rank(A: np.ndarray, B: np.ndarray, tol: float) -> int:
    K = _krylov(A, B)
    if K.size == 0:
        return 0
    values = sla.svdvals(K)
    return int(np.sum(values > tol * values[0]))


def _distinct(values: np.ndarray) -> list[complex]:
    out: list[complex] = []
    for v in values:
        if all(abs(v - w) > 1e-9 * max(1.0, abs(v)) for w in out):
            out.append(complex(v))
    return out


def structure(model: StateSpaceModel, tol: float = RANK_RTOL) -> Structure:
    """PBH controllability and observability of ``model``."""
    A, B, C = model.A, model.B, model.C
    n = model.nstates
    eye = np.eye(n)
    unc, uno = [], []
    for lam in _distinct(np.linalg.eigvals(A)) if n else []:
        if _rank_deficient(np.hstack([A - lam * eye, B]), tol):
            unc.append(lam)
        if _rank_deficient(np.vstack([A - lam * eye, C]), tol):
            uno.append(lam)
    ranks = (_krylov_rank(A, B, tol), _krylov_rank(A.T, C.T, tol))
    return Structure(tuple(unc), tuple(uno), ranks, n, tol)


def minimal(model: StateSpaceModel, tol: float = RANK_RTOL) -> tuple[StateSpaceModel, int]:
    """Minimal realisation: keep the controllable part, then its observable part.

    Orthonormal bases of the reachable and observable subspaces come from
    SVDs of the column-normalised Krylov matrices. The states of the result
    are combinations of the original ones and are named ``z1``, ``z2``...

    Returns
    -------
    model : StateSpaceModel
        The reduced model (the original when it is already minimal).
    dropped : int
        Number of states removed.
    """
    A, B, C = model.A, model.B, model.C
    basis = _range_basis(A, B, tol)
    A1, B1, C1 = basis.T @ A @ basis, basis.T @ B, C @ basis
    obs = _range_basis(A1.T, C1.T, tol)
    A2, B2, C2 = obs.T @ A1 @ obs, obs.T @ B1, C1 @ obs
    dropped = model.nstates - A2.shape[0]
    if dropped == 0:
        return model, 0
    import scipy.sparse as sp

    names = tuple(f"z{k + 1}" for k in range(A2.shape[0]))
    info = CompileInfo(order=A2.shape[0], warnings=model.info.warnings)
    reduced = StateSpaceModel(
        sp.csr_array(A2),
        sp.csr_array(B2),
        sp.csr_array(C2),
        model.D_sparse,
        model.D1_sparse,
        names,
        model.inputs,
        model.outputs,
        model.title,
        info,
    )
    return reduced, dropped


def _range_basis(A: np.ndarray, B: np.ndarray, tol: float) -> np.ndarray:
    K = _krylov(A, B)
    if K.size == 0:
        return np.zeros((A.shape[0], 0))
    U, values, _ = sla.svd(K, full_matrices=False)
    rank = int(np.sum(values > tol * values[0]))
    return U[:, :rank]


@dataclass(frozen=True)
class TransferFunction:
    """One input–output transfer function G(s) = num(s)/den(s) (coefficients, highest power first)."""

    output: str
    input: str
    num: tuple[float, ...]
    den: tuple[float, ...]
    poles: tuple[complex, ...]
    zeros: tuple[complex, ...]
    dc_gain: float

    def text(self, digits: int = 6) -> str:
        """``(a s^2 + b s + c) / (s^3 + ...)``."""

        def poly(coeffs: tuple[float, ...]) -> str:
            deg = len(coeffs) - 1
            terms = []
            for k, c in enumerate(coeffs):
                if abs(c) <= 1e-12 * max(abs(x) for x in coeffs):
                    continue
                power = deg - k
                mono = "" if power == 0 else ("s" if power == 1 else f"s^{power}")
                terms.append(f"{c:+.{digits}g}{'·' + mono if mono else ''}")
            return " ".join(terms) if terms else "0"

        return f"{self.output}/{self.input} = ({poly(self.num)}) / ({poly(self.den)})"


def transfer_functions(model: StateSpaceModel) -> list[TransferFunction]:
    """G(s) for every input–output pair, normalised to a monic denominator.

    Uses scipy's ``ss2tf`` (characteristic polynomial of A and the numerators
    from it). The coefficients are not reduced; the poles and zeros are the
    roots after cancelling common ones (within 1e-6 relative), i.e. those of
    the reduced transfer function.
    """
    out = []
    for j, name_in in enumerate(model.inputs):
        num, den = (
            sig.ss2tf(model.A, model.B, model.C, model.D, input=j)
            if model.nstates
            else (model.D[:, [j]], np.array([1.0]))
        )
        den = np.atleast_1d(den)
        lead = den[0]
        for i, name_out in enumerate(model.outputs):
            n = np.atleast_2d(num)[i] / lead
            big = np.max(np.abs(n)) if n.size else 0.0
            first = np.flatnonzero(np.abs(n) > 1e-12 * big)  # leading rounding residue is not a term
            n = n[first[0] :] if first.size else np.zeros(0)
            d = den / lead
            if n.size == 0:
                n = np.array([0.0])
            zeros = list(np.roots(n)) if n.size > 1 else []
            poles = list(np.roots(d)) if d.size > 1 else []
            for z in list(zeros):  # cancel common roots (modes the pair does not see)
                match = next((p for p in poles if abs(p - z) <= 1e-6 * max(1.0, abs(z))), None)
                if match is not None:
                    zeros.remove(z)
                    poles.remove(match)
            dc = float(n[-1] / d[-1]) if d[-1] != 0 else float("inf")
            out.append(
                TransferFunction(
                    name_out,
                    name_in,
                    tuple(float(x) for x in n),
                    tuple(float(x) for x in d),
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
    from .errors import UsageError

    n = model.nstates
    if n == 0 or n > CANONICAL_STATE_LIMIT:
        raise UsageError(
            f"canonical forms are for models of 1 to {CANONICAL_STATE_LIMIT} states; this has {n}"
        )


def _controller_transform(A: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """T = [q; qA; …; qAⁿ⁻¹] with q the last row of [b Ab … Aⁿ⁻¹b]⁻¹; None if (A, b) is uncontrollable."""
    if _krylov_rank(A, b[:, None], RANK_RTOL) < A.shape[0]:
        return None
    rows = [np.linalg.inv(_krylov(A, b[:, None], normalise=False))[-1]]
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
    from .errors import UsageError

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
    from .errors import UsageError

    _check_canonical_size(model)
    for i in [output] if output is not None else range(model.noutputs):
        T_c = _controller_transform(model.A.T, model.C[i])
        if T_c is not None:
            return _companion("observer", model.outputs[i], np.linalg.inv(T_c.T), model, transpose=True)
    raise UsageError("observer form: no output observes every state (see --control)")


def _companion(
    kind: str, signal: str, T: np.ndarray, model: StateSpaceModel, transpose: bool
) -> CanonicalForm:
    n = model.nstates
    T_inv = np.linalg.inv(T)
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
