"""Physical coordinates: a model in the variables the user names, and initial states in them.

The compiler's states are momenta, spring forces, charges and currents. The
lecture notes write mechanical models in positions, angles and velocities.
Both are related by a linear map of the state: every physical variable the
model can output (``x(node)``, ``angle(rod)``, ``v(node)``, ``i(element)``)
is a row ``c`` of ``C`` with ``y = c x`` when its ``D`` and ``D1`` rows are
zero, and ``omega(rod)``, the angular velocity of a rod, is the derivative
of its angle, the row ``c A`` (when ``c B = 0``).

:func:`change_coordinates` stacks those rows into ``T`` (``z = T x``) and
returns ``T A T⁻¹``, ``T B``, ``C T⁻¹``, ``D`` with ``cond(T)``; it refuses,
naming what is missing or dependent, when ``T`` is not invertible.
:func:`initial_state` solves ``--ic`` conditions given in such variables,
mixed with state names, for the initial state.

Some states can be tied by a *conserved relation* ``r x = 0`` that holds for
every input (``r A = 0`` and ``r B = 0``): a displacement integrator added
for ``x(b1)`` and the spring force ``f(k1) = k1 x(b1)`` that measures the same
position. Such a relation is zero from the zero state; both functions impose
the relations that tie two or more states (a relation on one state alone, a
free momentum nothing acts on, is left free).
"""

from __future__ import annotations

import contextlib
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.linalg import matrix_balance, qr

from netlistdyn.base.errors import UsageError
from netlistdyn.base.formatting import format_matrix
from netlistdyn.base.values import parse_number
from netlistdyn.circuit.netlist import GROUND, Kind, Netlist
from netlistdyn.circuit.probes import default_probes, parse_probe, parse_probes
from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.statespace.model import StateSpaceModel

#: Relative size below which an entry of a row counts as zero (rows come from
#: direct solves of small, well-scaled systems; their noise is ~1e-16).
ROW_TOL = 1e-11
#: Relative singular-value threshold for rank decisions on scaled rows.
RANK_TOL = 1e-9
#: Residual (of a unit row projected on the others) below which a row is dependent: true
#: dependence leaves rounding (~1e-15 · cond); the rows are over balanced states.
DEPENDENT_TOL = 1e-8
#: Largest model whose conserved relations are looked for (a dense SVD), and the largest
#: model ``--coordinates`` transforms (dense T A T⁻¹).
RELATIONS_LIMIT = 400

_OMEGA = re.compile(r"^\s*omega\s*\(\s*([^,()\s]+)\s*\)\s*$", re.IGNORECASE)


@dataclass(frozen=True)
class Variable:
    """One physical variable as the user wrote it, and the output it comes from.

    Attributes
    ----------
    text : str
        As written (``omega(r1)``).
    name : str
        Canonical label (``omega(r1)``, ``angle(r1)``, ``x(cart)``).
    output : str
        The model output it is computed from (``angle(r1)`` for ``omega(r1)``).
    derivative : bool
        True for ``omega(rod)``: the time derivative of ``output``.
    """

    text: str
    name: str
    output: str
    derivative: bool = False


def split_list(text: str) -> list[str]:
    """Split ``x(a),v(a,b),angle(r1)`` at the commas outside parentheses."""
    parts, depth, start = [], 0, 0
    for k, ch in enumerate(text):
        depth += (ch == "(") - (ch == ")")
        if ch == "," and depth == 0:
            parts.append(text[start:k])
            start = k + 1
    parts.append(text[start:])
    return [p.strip() for p in parts if p.strip()]


def parse_variable(text: str, netlist: Netlist) -> Variable:
    """Parse ``x(n)``, ``v(n)``, ``v(a,b)``, ``i(e)``, ``angle(rod)`` or ``omega(rod)``.

    Raises
    ------
    UsageError
        For malformed text and unknown nodes or elements.
    """
    match = _OMEGA.match(text)
    if match:
        probe = parse_probe(f"angle({match.group(1)})", netlist)
        return Variable(text, "omega" + probe.name[len("angle") :], probe.name, True)
    probe = parse_probe(text, netlist)
    return Variable(text, probe.name, probe.name)


def compile_with(
    netlist: Netlist, outputs: Sequence[str] | None, variables: Sequence[Variable]
) -> tuple[StateSpaceModel, tuple[str, ...]]:
    """Compile with the outputs shown to the user plus every listed variable as an output.

    Parameters
    ----------
    netlist : Netlist
    outputs : sequence of str, optional
        The user's ``--output`` values (default: every node voltage/velocity).
    variables : sequence of Variable
        Extra physical variables (coordinates, ``--ic`` conditions, angles);
        ``omega(rod)`` becomes an output row ``c A``.

    Returns
    -------
    model : StateSpaceModel
        With every needed output (the shown ones first).
    shown : tuple of str
        Labels of the outputs to show.
    """
    probes = parse_probes(outputs, netlist) if outputs else default_probes(netlist)
    shown = tuple(dict.fromkeys(p.name for p in probes))
    wanted = list(shown)
    for v in variables:
        if v.output not in wanted:
            wanted.append(v.output)
    model = compile_netlist(netlist, wanted)
    derived = [v for v in dict.fromkeys(variables) if v.derivative and v.name not in model.outputs]
    if derived:
        rows = np.array([variable_row(model, v, "variable") for v in derived])
        zeros = sp.csr_array((len(derived), model.ninputs))
        model = replace(
            model,
            C_sparse=sp.csr_array(sp.vstack([model.C_sparse, sp.csr_array(rows)])),
            D_sparse=sp.csr_array(sp.vstack([model.D_sparse, zeros])),
            D1_sparse=sp.csr_array(sp.vstack([model.D1_sparse, zeros])),
            outputs=(*model.outputs, *(v.name for v in derived)),
        )
    return model, shown


def select_outputs(model: StateSpaceModel, names: Sequence[str]) -> StateSpaceModel:
    """The model with only the named outputs, in that order."""
    index = {n: k for k, n in enumerate(model.outputs)}
    rows = [index[n] for n in names]
    return replace(
        model,
        C_sparse=sp.csr_array(model.C_sparse[rows]),
        D_sparse=sp.csr_array(model.D_sparse[rows]),
        D1_sparse=sp.csr_array(model.D1_sparse[rows]),
        outputs=tuple(names),
    )


def variable_row(model: StateSpaceModel, variable: Variable, what: str) -> NDArray[np.float64]:
    """The row ``c`` with ``variable = c x`` (the model must output ``variable.output``).

    Raises
    ------
    UsageError
        When the variable depends on an input directly, not on the state alone.
    """
    k = model.outputs.index(variable.output)
    c = np.asarray(model.C_sparse[[k]].toarray()[0], dtype=float)
    d = model.D_sparse[[k]].toarray()[0]
    d1 = model.D1_sparse[[k]].toarray()[0]
    direct = [u for j, u in enumerate(model.inputs) if d[j] != 0 or d1[j] != 0]
    if direct:
        raise UsageError(
            f"{what} {variable.text}: depends on the input {', '.join(direct)} directly, "
            "not on the state alone"
        )
    if variable.derivative:
        B = model.B_sparse.toarray()
        through = [u for j, u in enumerate(model.inputs) if abs(c @ B[:, j]) > ROW_TOL * _scale(c, B[:, j])]
        if through:
            raise UsageError(
                f"{what} {variable.text}: its rate depends on the input {', '.join(through)} directly"
            )
        c = np.asarray(model.A_sparse.T @ c, dtype=float)
    return c


def _scale(c: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    return float(np.abs(c) @ np.abs(b)) or 1.0


def state_scale(model: StateSpaceModel) -> NDArray[np.float64]:
    """Diagonal scaling s of the states (x = diag(s) y) that balances A (LAPACK gebal).

    Rank and dependence decisions are made on ``y``: states of different units
    (a momentum beside a spring force of a 1e5 N/m spring) otherwise make a
    relation's small entries look like rounding.
    """
    n = model.nstates
    if n == 0 or n > RELATIONS_LIMIT:
        return np.ones(n)

    _, (scale, _) = matrix_balance(model.A, permute=False, separate=True)
    return np.asarray(scale, dtype=float)


def _relations_y(model: StateSpaceModel, scale: NDArray[np.float64]) -> NDArray[np.float64]:
    """Conserved relations as rows over the balanced states y (x = diag(scale) y)."""
    n = model.nstates
    if n == 0 or n > RELATIONS_LIMIT:
        return np.zeros((0, n))
    stacked = np.hstack([model.A * scale[None, :] / scale[:, None], model.B / scale[:, None]])
    norms = np.linalg.norm(stacked, axis=1)
    norms[norms == 0] = 1.0
    _, sv, vt = np.linalg.svd((stacked / norms[:, None]).T)
    rank = int(np.sum(sv > RANK_TOL * (sv[0] if sv.size else 1.0)))
    null = vt[rank:] / norms[None, :]  # r = c N⁻¹ for the row-normalised solution c
    if null.shape[0] == 0:
        return np.zeros((0, n))
    rows = _echelon(null)
    a_y, b_y = stacked[:, :n], stacked[:, n:]
    keep = []
    for r in rows:
        if np.sum(np.abs(r) > ROW_TOL * np.abs(r).max()) < 2:
            continue
        # Only a relation that holds to rounding, entry by entry, is imposed.
        size = np.concatenate([np.abs(r) @ np.abs(a_y), np.abs(r) @ np.abs(b_y)])
        residual = np.abs(np.concatenate([r @ a_y, r @ b_y]))
        if np.all(residual <= 1e-10 * np.maximum(size, np.finfo(float).tiny)):
            keep.append(r)
    return np.array(keep).reshape(len(keep), n)


def _to_x(rows_y: NDArray[np.float64], scale: NDArray[np.float64]) -> NDArray[np.float64]:
    """Relations over y as rows over x (r_x = r_y diag(1/scale)), largest entry 1."""
    rows = rows_y / scale[None, :]
    if rows.size:
        rows = rows / np.abs(rows).max(axis=1, keepdims=True)
    return rows


def _echelon(rows: NDArray[np.float64]) -> list[NDArray[np.float64]]:
    """Reduced row echelon form with partial pivoting, tiny entries set to zero."""
    m = rows.copy()
    out_rows, col = 0, 0
    k, n = m.shape
    while out_rows < k and col < n:
        pivot = out_rows + int(np.argmax(np.abs(m[out_rows:, col])))
        if abs(m[pivot, col]) <= RANK_TOL * np.abs(m).max():
            col += 1
            continue
        m[[out_rows, pivot]] = m[[pivot, out_rows]]
        m[out_rows] /= m[out_rows, col]
        for r in range(k):
            if r != out_rows:
                m[r] -= m[r, col] * m[out_rows]
        out_rows += 1
        col += 1
    result = []
    for r in m[:out_rows]:
        r = r / np.abs(r).max()
        r[np.abs(r) < ROW_TOL] = 0.0
        result.append(r)
    return result


def _combination(row: NDArray[np.float64], names: Sequence[str], limit: int = 4) -> str:
    """``f(k1), p(m2)``: the names with the largest weights in a row."""
    order = np.argsort(-np.abs(row))
    picked = [names[j] for j in order[:limit] if abs(row[j]) > 1e-6 * np.abs(row).max()]
    return ", ".join(picked)


def _dependent(
    rows: NDArray[np.float64], base: NDArray[np.float64] | None = None
) -> list[tuple[int, NDArray[np.float64]]]:
    """Rows that are combinations of the rows before them (and of ``base``).

    Returns (index, coefficients on the rows before it) for each.
    """
    base = np.zeros((0, rows.shape[1])) if base is None else base
    out = []
    everything = np.vstack([base, rows])
    scale = np.linalg.norm(everything, axis=1)
    scale[scale == 0] = 1.0
    unit = everything / scale[:, None]
    nb = base.shape[0]
    for k in range(rows.shape[0]):
        if not np.any(rows[k]):
            out.append((k, np.zeros(0)))
            continue
        before = unit[: nb + k]
        if before.shape[0] == 0:
            continue
        coef, *_ = np.linalg.lstsq(before.T, unit[nb + k], rcond=None)
        if np.linalg.norm(before.T @ coef - unit[nb + k]) < DEPENDENT_TOL:
            out.append((k, coef[nb:] * scale[nb + k] / scale[nb : nb + k]))
    return out


@dataclass(frozen=True)
class CoordinateChange:
    """A model presented in physical coordinates.

    Attributes
    ----------
    model : StateSpaceModel
        ``T A T⁻¹, T B, C T⁻¹, D`` with the coordinates as state names.
    original : StateSpaceModel
        The model in the compiler's states.
    T : numpy.ndarray
        ``(k, n)``: z = T x over the compiler's states.
    condition : float
        2-norm condition number of the square map used (T, or T restricted to
        the subspace of the conserved relations).
    relations : numpy.ndarray
        Conserved relations imposed (rows over the compiler's states).
    """

    model: StateSpaceModel
    original: StateSpaceModel
    T: NDArray[np.float64]
    condition: float
    relations: NDArray[np.float64]

    @property
    def coordinates(self) -> tuple[str, ...]:
        """The coordinate names, in order."""
        return self.model.states


def _row_max(matrix: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each row's largest entry, as a column."""
    return matrix.max(axis=1, keepdims=True) if matrix.size else np.zeros((matrix.shape[0], 1))


def _clean(matrix: NDArray[np.float64], bound: NDArray[np.float64]) -> NDArray[np.float64]:
    """Set to 0 the entries no larger than their rounding-error ``bound`` (same shape or a column)."""
    out = matrix.copy()
    out[np.abs(out) <= bound] = 0.0
    return out


def change_coordinates(
    model: StateSpaceModel,
    variables: Sequence[Variable],
    keep_outputs: Sequence[str] | None = None,
    candidates: Sequence[Variable] = (),
) -> CoordinateChange:
    """Present ``model`` in the listed variables.

    Parameters
    ----------
    model : StateSpaceModel
        Compiled with every ``variable.output`` among its outputs
        (:func:`compile_with`).
    variables : sequence of Variable
        The coordinates, in order.
    keep_outputs : sequence of str, optional
        Outputs of the result (default: all of ``model``'s).
    candidates : sequence of Variable
        Variables (among the model's outputs) to suggest when some are missing.

    Raises
    ------
    UsageError
        When the variables are not an invertible map of the state: naming
        the dependent ones, or what is missing.
    """
    if model.nstates > RELATIONS_LIMIT:
        raise UsageError(
            f"--coordinates is for models of up to {RELATIONS_LIMIT} states ({model.nstates} here)"
        )
    names = [v.name for v in variables]
    if len(set(names)) != len(names):
        twice = sorted({n for n in names if names.count(n) > 1})
        raise UsageError(f"--coordinates: {', '.join(twice)} listed twice")
    rows = np.array([variable_row(model, v, "--coordinates") for v in variables]).reshape(
        len(variables), model.nstates
    )
    scale = state_scale(model)
    rows_y = rows * scale[None, :]
    relations = _relations_y(model, scale)
    for k, coef in _dependent(rows_y, relations):
        terms = [names[j] for j in range(coef.size) if abs(coef[j]) > 1e-9] if coef.size else []
        why = f"a combination of {', '.join(terms)}" if terms else "zero for every state"
        raise UsageError(f"--coordinates: {names[k]} is {why}: the coordinates are dependent")
    n = model.nstates
    if len(variables) < n:
        basis = _echelon_null_space(relations) if relations.shape[0] else np.eye(n)
        square = rows_y @ basis
        if (
            square.shape[0] != square.shape[1]
            or np.linalg.matrix_rank(_unit_rows(square), tol=RANK_TOL) < square.shape[0]
        ):
            known = np.vstack([rows_y, relations])
            missing = _null_space(known) * scale[:, None]
            what = "; ".join(
                f"one involving {_combination(missing[:, j], model.states)}" for j in range(missing.shape[1])
            )
            rank = np.linalg.matrix_rank(_unit_rows(known), tol=RANK_TOL)
            helpful = []
            for cand in candidates:
                if cand.name in names or cand.output not in model.outputs:
                    continue
                try:
                    row = variable_row(model, cand, "--coordinates") * scale
                except UsageError:
                    continue
                if np.linalg.matrix_rank(_unit_rows(np.vstack([known, row])), tol=RANK_TOL) > rank:
                    helpful.append(cand.name)
            hint = f" (for instance {', '.join(helpful[:6])})" if helpful else ""
            raise UsageError(
                f"--coordinates: {len(variables)} variables for a model of {n - relations.shape[0]} "
                f"independent states; missing {missing.shape[1]} direction(s): {what}{hint}"
            )
    else:
        relations = np.zeros((0, n))
        basis = np.eye(n)
        square = rows_y
    # x = diag(scale) · basis · square⁻¹ · z on the relations' subspace.
    inverse = (basis * scale[:, None]) @ np.linalg.inv(square)
    # cond(T) over the model's own states (restricted to the subspace, orthonormal basis).
    orthonormal, _ = np.linalg.qr(basis * scale[:, None])
    cond = float(np.linalg.cond(rows @ orthonormal))
    # Entries within rounding of zero are printed as 0: below 64·n·eps times the largest
    # product |T_ik||A_kl||T⁻¹_lj| of their row (the size of the terms that cancelled).
    eps = 64 * max(n, 1) * np.finfo(float).eps
    A = _clean(rows @ model.A @ inverse, eps * _row_max(np.abs(rows) @ np.abs(model.A) @ np.abs(inverse)))
    B = _clean(rows @ model.B, eps * _row_max(np.abs(rows) @ np.abs(model.B)))
    _check_same_response(model, rows, A, B)
    outs = list(keep_outputs) if keep_outputs is not None else list(model.outputs)
    shown = select_outputs(model, outs)
    C = _clean(shown.C @ inverse, eps * _row_max(np.abs(shown.C) @ np.abs(inverse)))
    new = replace(
        shown,
        A_sparse=sp.csr_array(A),
        B_sparse=sp.csr_array(B),
        C_sparse=sp.csr_array(C),
        states=tuple(names),
        info=replace(model.info, integrators=()),
    )
    return CoordinateChange(new, model, rows, cond, _to_x(relations, scale))


#: Largest relative difference allowed between the responses of the presented model and the
#: compiled one (with the coordinates as outputs); beyond it the change is refused.
RESPONSE_RTOL = 1e-6


def _check_same_response(
    model: StateSpaceModel, rows: NDArray[np.float64], A: NDArray[np.float64], B: NDArray[np.float64]
) -> None:
    """Refuse a change of coordinates whose model does not respond as the compiled one.

    Compares rows (sI − A)⁻¹ B with (sI − T A T⁻¹)⁻¹ T B at three complex
    frequencies scaled to the model (an a-posteriori check: a rank decision
    gone wrong, such as a spurious relation, changes the response at O(1)).
    """
    n = model.nstates
    if n == 0 or model.ninputs == 0:
        return
    rho = max(float(np.abs(model.A).max()), float(np.abs(A).max()), 1e-300)
    for s in (rho * (0.1 + 0.3j), rho * (0.5 + 1.7j), 2.0 * rho + 0.9j * rho):
        old = rows @ np.linalg.solve(s * np.eye(n) - model.A, model.B)
        new = np.linalg.solve(s * np.eye(A.shape[0]) - A, B)
        scale = max(float(np.abs(old).max()), 1e-300)
        if float(np.abs(new - old).max()) > RESPONSE_RTOL * scale:
            raise UsageError(
                "--coordinates: the model in these variables does not reproduce the compiled model's "
                "response (the states are too badly scaled for this change of variables)"
            )


def _echelon_null_space(rows: NDArray[np.float64]) -> NDArray[np.float64]:
    """Basis (columns) of {y : rows y = 0}, one vector per free column.

    Pivot columns P are chosen by QR with column pivoting; each free column j
    gives e_j − (rows[:, P]⁻¹ rows[:, j]) on P. Free columns other than j stay
    exactly zero (an SVD basis would mix every column with rounding).
    """
    n = rows.shape[1]
    k = rows.shape[0]
    _, _, perm = qr(rows, pivoting=True, mode="economic")
    pivots = list(perm[:k])
    basis = []
    for j in range(n):
        if j in pivots:
            continue
        v = np.zeros(n)
        v[j] = 1.0
        v[pivots] = -np.linalg.solve(rows[:, pivots], rows[:, j])
        basis.append(v)
    return np.array(basis).T.reshape(n, len(basis))


def _unit_rows(rows: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each row divided by its 2-norm (zero rows stay zero)."""
    scale = np.linalg.norm(rows, axis=1)
    scale[scale == 0] = 1.0
    return rows / scale[:, None]


def _null_space(rows: NDArray[np.float64]) -> NDArray[np.float64]:
    """Orthonormal basis (columns) of {x : rows x = 0}, rows scaled first."""
    _, s, vt = np.linalg.svd(_unit_rows(rows))
    rank = int(np.sum(s > RANK_TOL * (s[0] if s.size else 1.0)))
    return vt[rank:].T


def change_text(change: CoordinateChange) -> str:
    """The report block: T, its condition number and the relations imposed."""
    lines = [f"coordinates: z = T x, cond(T) = {change.condition:.3g}"]
    lines += format_matrix("T", change.T, change.coordinates, change.original.states)
    for r in change.relations:
        terms = " ".join(
            f"{'+' if c > 0 else '-'} {abs(c):.6g}·{s}"
            for c, s in zip(r, change.original.states, strict=True)
            if c
        )
        lines.append(f"  conserved relation imposed (0 from the zero state): {terms.lstrip('+ ')} = 0")
    return "\n".join(lines) + "\n"


def change_dict(change: CoordinateChange) -> dict[str, object]:
    """The JSON block for ``coordinates``."""
    return {
        "names": list(change.coordinates),
        "model_states": list(change.original.states),
        "T": change.T.tolist(),
        "condition": change.condition,
        "relations": change.relations.tolist(),
    }


# --- initial conditions ------------------------------------------------------------


@dataclass(frozen=True)
class Condition:
    """One ``--ic NAME=VALUE``: a state name or a physical variable."""

    text: str
    name: str
    value: float
    variable: Variable | None


def parse_conditions(items: Sequence[str], netlist: Netlist, states: Sequence[str] = ()) -> list[Condition]:
    """Parse ``--ic`` values: a physical variable when the name reads as one, else a state name.

    ``x(b1)`` and ``i(L1)`` can be both (an integrator state, an inductor
    current): they are taken as variables, so that the relations between
    states (the conserved relations of the module notes) apply to them too.

    Raises
    ------
    UsageError
        For malformed items, unknown names and values that are not numbers.
    """
    known = {s.lower(): s for s in states}
    out = []
    for item in items:
        name, sep, text = item.partition("=")
        value = parse_number(text.strip()) if sep and len(text) <= 64 else None
        if value is None or not name.strip() or not math.isfinite(value):
            raise UsageError(
                f"--ic {item!r}: expected NAME=VALUE with a finite number, NAME a state or a variable "
                "such as angle(r1)"
            )
        key = name.strip()
        try:
            variable = parse_variable(key, netlist)
        except UsageError as exc:
            if key.lower() in known:
                out.append(Condition(item, known[key.lower()], value, None))
                continue
            hint = f"; states: {', '.join(states)}" if states else ""
            raise UsageError(f"--ic {item!r}: {str(exc).split(': ', 1)[-1]}{hint}") from None
        out.append(Condition(item, variable.name, value, variable))
    return out


def initial_state(model: StateSpaceModel, conditions: Sequence[Condition]) -> NDArray[np.float64] | None:
    """Solve the conditions for the initial state.

    A state that no condition involves is zero. The conditions (with the
    conserved relations that share a state with them) must fix the states
    they involve exactly: fewer independent conditions than those states is
    refused as under-determined, a condition that follows from the others as
    over-determined.

    Parameters
    ----------
    model : StateSpaceModel
        Compiled with every condition's variable among its outputs.
    conditions : sequence of Condition

    Returns
    -------
    numpy.ndarray or None
        The initial state; None without conditions.

    Raises
    ------
    UsageError
    """
    if not conditions:
        return None
    n = model.nstates
    index = {s: k for k, s in enumerate(model.states)}
    if all(c.variable is None for c in conditions):
        # State names only: each sets its own state; a state given twice is refused.
        x0 = np.zeros(n)
        seen: set[str] = set()
        for cond in conditions:
            if cond.name in seen:
                raise UsageError(f"--ic {cond.text}: over-determined: {cond.name} is given twice")
            seen.add(cond.name)
            x0[index[cond.name]] = cond.value
        return x0
    rows, values, labels = [], [], []
    for cond in conditions:
        if cond.variable is None:
            row = np.zeros(n)
            row[index[cond.name]] = 1.0
        else:
            row = variable_row(model, cond.variable, "--ic")
        rows.append(row)
        values.append(cond.value)
        labels.append(cond.text)
    scale = state_scale(model)
    R = np.array(rows) * scale[None, :]  # over the balanced states y, x = diag(scale) y
    for k, _ in _dependent(R):
        others = ", ".join(labels[:k])
        raise UsageError(
            f"--ic {labels[k]}: over-determined: the other conditions ({others}) already fix it"
            if others
            else f"--ic {labels[k]}: does not involve any state"
        )
    touched = _touched(R)
    relations = _relations_y(model, scale)
    used = np.zeros(relations.shape[0], dtype=bool)
    grew = True
    while grew:
        grew = False
        for j, r in enumerate(relations):
            if not used[j] and np.any(_touched(r[None, :]) & touched):
                used[j] = True
                touched |= _touched(r[None, :])
                grew = True
    system = np.vstack([R, relations[used]])
    rhs = np.concatenate([values, np.zeros(int(used.sum()))])
    cols = np.flatnonzero(touched)
    sub = system[:, cols]
    rank = np.linalg.matrix_rank(_unit_rows(sub), tol=RANK_TOL)
    if rank < cols.size:
        free = _null_space(sub) * scale[cols][:, None]
        states = [model.states[c] for c in cols]
        what = "; ".join(_combination(free[:, j], states) for j in range(free.shape[1]))
        raise UsageError(
            f"--ic: under-determined: the conditions involve {', '.join(states)} but fix only {rank} "
            f"combination(s) of them; add {cols.size - rank} condition(s) on {what}"
        )
    solution, *_ = np.linalg.lstsq(sub, rhs, rcond=None)
    if np.linalg.norm(sub @ solution - rhs) > RANK_TOL**0.5 * max(np.linalg.norm(rhs), 1e-300):
        raise UsageError(
            "--ic: over-determined: the conditions contradict a relation the model's states keep "
            "(a position and the spring force that measures it)"
        )
    x0 = np.zeros(n)
    x0[cols] = solution * scale[cols]
    return x0


def _touched(rows: NDArray[np.float64]) -> NDArray[np.bool_]:
    scale = np.abs(rows).max(axis=1, keepdims=True)
    scale[scale == 0] = 1.0
    return np.any(np.abs(rows) > ROW_TOL * scale, axis=0)


def _candidates(netlist: Netlist) -> list[Variable]:
    """Variables to suggest for missing coordinates: node voltages/velocities, inductor currents
    (spring forces), rod angles and rates.

    None of them adds a state (``x(node)`` would add an integrator).
    """
    out = [parse_variable(p.name, netlist) for p in default_probes(netlist)]
    for e in netlist.elements:
        if e.kind is Kind.INDUCTOR:
            out.append(parse_variable(f"i({e.name})", netlist))
        if e.rod is not None:
            out += [parse_variable(f"angle({e.name})", netlist), parse_variable(f"omega({e.name})", netlist)]
    return out


# --- one call for the command line and the API --------------------------------------


@dataclass(frozen=True)
class Prepared:
    """A model compiled for a run with physical coordinates and initial conditions.

    Attributes
    ----------
    full : StateSpaceModel
        In the compiler's states, with every output any part of the run needs
        (the shown ones first).
    shown : tuple of str
        The outputs to report (``--output``; without it, the coordinates
        when given, else every node voltage/velocity).
    change : CoordinateChange or None
        With ``--coordinates``: the model in those variables (its outputs
        the shown ones).
    x0 : numpy.ndarray or None
        Initial state over ``full.states`` from ``--ic``.
    """

    full: StateSpaceModel
    shown: tuple[str, ...]
    change: CoordinateChange | None
    x0: NDArray[np.float64] | None

    @property
    def model(self) -> StateSpaceModel:
        """The model to present: in the coordinates when given, else the compiled one (shown outputs)."""
        return self.change.model if self.change is not None else select_outputs(self.full, self.shown)


#: ``--coordinates voltage``: capacitor voltages and inductor currents, as SPICE users think of states.
VOLTAGE_KEYWORDS = frozenset({"voltage", "voltages"})


def voltage_coordinates(netlist: Netlist) -> list[str]:
    """The compiled states with every charge replaced by its capacitor's voltage.

    q(C) becomes ``v(a,b)`` (``v(a)`` when ``b`` is ground) and a mass's momentum p(m) its node's
    velocity ``v(n)``; inductor currents, spring forces and displacements stay. A charge and its
    voltage differ by the factor C, so A keeps its eigenvalues and loses the 1/C scaling that puts
    −1e12 beside −1e4 in a µH/nF circuit.

    Parameters
    ----------
    netlist : Netlist

    Returns
    -------
    list of str
        One variable per state, in state order.
    """
    by_name = {e.name.lower(): e for e in netlist.elements}
    variables = []
    for state in compile_netlist(netlist, []).states:
        prefix, _, rest = state.partition("(")
        element = by_name.get(rest[:-1].lower()) if prefix in ("q", "p") else None
        if element is None:
            variables.append(state)
            continue
        a, b = element.nodes[0], element.nodes[1]
        variables.append(f"v({a})" if b == GROUND else (f"v({b})" if a == GROUND else f"v({a},{b})"))
    return variables


def prepare(
    netlist: Netlist,
    outputs: Sequence[str] | None = None,
    coordinates: Sequence[str] | str | None = None,
    ics: Sequence[str] = (),
    extra: Sequence[str] = (),
) -> Prepared:
    """Compile ``netlist`` for ``--coordinates`` and ``--ic`` (and extra outputs a view needs).

    Parameters
    ----------
    netlist : Netlist
    outputs : sequence of str, optional
        ``--output`` values.
    coordinates : str or sequence of str, optional
        ``x(b1),x(b2),v(b1),v(b2)`` or a list of such names.
    ics : sequence of str
        ``--ic NAME=VALUE`` items: state names or physical variables.
    extra : sequence of str
        More variables to compute as (hidden) outputs, e.g. rod angles.

    Raises
    ------
    UsageError
    """
    if isinstance(coordinates, str) and coordinates.strip().lower() in VOLTAGE_KEYWORDS:
        coordinates = voltage_coordinates(netlist)
        outputs = outputs or [p.name for p in default_probes(netlist)]  # the usual outputs, not the states
    if isinstance(coordinates, str):
        coordinates = split_list(coordinates)
    coords = [parse_variable(c, netlist) for c in coordinates or ()]
    if coordinates is not None and not coords:
        raise UsageError("--coordinates: no variable given (e.g. x(b1),x(b2),v(b1),v(b2))")
    # State names are only known after compiling: compile once with every name that
    # reads as a variable, then sort the conditions out.
    probing = []
    for item in ics:
        name = item.partition("=")[0].strip()
        with contextlib.suppress(UsageError):
            probing.append(parse_variable(name, netlist))
    shown_given = list(outputs) if outputs else None
    hidden = [parse_variable(e, netlist) for e in extra]
    candidates = _candidates(netlist) if coords else []
    variables = [*coords, *probing, *hidden, *candidates]
    full, shown = compile_with(netlist, shown_given, variables)
    if coords and not shown_given:
        shown = tuple(v.name for v in coords)
    conditions = parse_conditions(ics, netlist, full.states)
    x0 = initial_state(full, conditions)
    change = change_coordinates(full, coords, shown, candidates) if coords else None
    return Prepared(full, shown, change, x0)
