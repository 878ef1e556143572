"""Symbolic state-space matrices (sympy) in terms of the element names.

The numeric compiler picks the normal tree and checks the circuit; this
module then writes the same branch laws (:func:`~netlistdyn.formulate.branch_laws`)
with sympy symbols for the element values and eliminates everything but the
states exactly, over the field of rational functions in those symbols
(``sympy.polys.matrices.DomainMatrix``). The result for the seeds' Circuit 1
is the notes' A = [[−1/(R1·C1) − 1/(R2·C1), −1], [1/(L1·C1), 0]].

Symbols are named after the elements (``R1``, ``C1``, ``m1``, ``k1``): a
spring contributes 1/k1, a damper 1/d1, a mass m1, a gear or motor its ratio.
A pendulum rod of length l carrying masses m… is the spring of stiffness
±g·(m…)/l, written with the symbols ``l_<rod>`` and ``g`` and the masses' symbols.
Elements left out of ``keep`` take their netlist values as exact rationals,
which is how ``.param`` values are substituted.
"""

from __future__ import annotations

import keyword
import re
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .display import element_unit
from .errors import NetlistError, UsageError

try:
    import sympy
    from sympy.polys.matrices import DomainMatrix
except ImportError:  # sympy is the optional "symbolic" extra
    raise UsageError(
        "--symbolic needs sympy, which is not installed: "
        "pip install 'netlistdyn[symbolic]' (or pip install sympy)"
    ) from None
from .formulate import (
    Formulation,
    _potential_rows,
    branch_laws,
    classify,
    formulate,
    held_displacements,
    primary_maps,
)
from .mechanics import DISPLACEMENT_KEYWORD, carried_masses
from .netlist import Element, Kind, Netlist

#: Largest model (states) for which symbolic matrices are computed.
SYMBOLIC_STATE_LIMIT = 12

_VALUED = (
    Kind.RESISTOR,
    Kind.CAPACITOR,
    Kind.INDUCTOR,
    Kind.COUPLING,
    Kind.VCVS,
    Kind.VCCS,
    Kind.CCCS,
    Kind.CCVS,
    Kind.TRANSFORMER,
)


@dataclass(frozen=True)
class SymbolicModel:
    """x' = A x + B u, y = C x + D u (+ D1 u') with sympy entries.

    Attributes
    ----------
    A, B, C, D, D1 : sympy.ImmutableMatrix
        Same shapes, states, inputs and outputs as the numeric model.
    states, inputs, outputs : tuple of str
        Labels.
    symbols : dict
        ``name -> (sympy.Symbol, numeric value)``: each symbol, with the
        value the netlist gives it, in the element's own unit (a spring's
        stiffness k in N/m, not its analog inductance 1/k).
    title : str
    units : dict
        ``name -> unit`` of each symbol's value (``"N/m"``, ``"Ω"``, ``"A/V"``;
        ``""`` when dimensionless), from the element's kind and mechanical
        keyword (:func:`~netlistdyn.display.element_unit`), never from its name.
    """

    A: sympy.ImmutableMatrix
    B: sympy.ImmutableMatrix
    C: sympy.ImmutableMatrix
    D: sympy.ImmutableMatrix
    D1: sympy.ImmutableMatrix
    states: tuple[str, ...]
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    symbols: Mapping[str, tuple[sympy.Symbol, float]]
    title: str
    units: Mapping[str, str] = field(default_factory=dict)

    def numeric(self, values: Mapping[str, float] | None = None) -> dict[str, np.ndarray]:
        """The matrices as float arrays, with the netlist's values unless overridden.

        Parameters
        ----------
        values : Mapping[str, float], optional
            ``symbol name -> value`` overrides (element units).

        Returns
        -------
        dict
            ``{"A": ..., "B": ..., "C": ..., "D": ..., "D1": ...}``.
        """
        chosen = {name: value for name, (_, value) in self.symbols.items()}
        for name, value in (values or {}).items():
            if name not in chosen:
                raise UsageError(f"no symbol {name!r}; the model has {', '.join(chosen) or 'none'}")
            chosen[name] = value
        subs = {self.symbols[name][0]: sympy.Float(value, 30) for name, value in chosen.items()}
        return {
            key: np.array(getattr(self, key).subs(subs).evalf(), dtype=float).reshape(
                getattr(self, key).shape
            )
            for key in ("A", "B", "C", "D", "D1")
        }


def symbolic_model(
    netlist: Netlist,
    outputs: Sequence[str] | None = None,
    keep: Collection[str] | None = None,
) -> SymbolicModel:
    """Compile a netlist with element values as symbols.

    Parameters
    ----------
    netlist : Netlist
    outputs : sequence of str, optional
        As for :func:`~netlistdyn.formulate.compile_netlist`.
    keep : collection of str, optional
        Element names to keep symbolic (case-insensitive); the others take
        their netlist values. Default: all.

    Returns
    -------
    SymbolicModel

    Raises
    ------
    UsageError
        For an unknown name in ``keep`` or a model above
        :data:`SYMBOLIC_STATE_LIMIT` states.
    NetlistError
        For circuits the numeric compiler refuses.
    """
    if netlist.is_nonlinear:  # the symbols of its linearisation at the operating point
        from .nonlinear import linearised

        netlist, outputs = linearised(netlist, outputs)
    form = formulate(netlist, outputs)
    if form.model.nstates > SYMBOLIC_STATE_LIMIT:
        raise UsageError(
            f"--symbolic is for small circuits: this one has {form.model.nstates} states "
            f"(limit {SYMBOLIC_STATE_LIMIT})"
        )
    valued = {e.key: e for e in netlist.elements if e.kind in _VALUED}
    # a linearised mechanism's displacement integrators (1 F, 1 S) are not parameters of the system
    default = {k for k, e in valued.items() if e.keyword != DISPLACEMENT_KEYWORD}
    wanted = {name.lower() for name in keep} if keep is not None else default
    unknown = sorted(wanted - set(valued))
    if unknown:
        raise UsageError(
            f"--symbols: no element {', '.join(unknown)} with a value "
            f"(elements: {', '.join(e.name for e in valued.values())})"
        )
    symbols = {
        e.name: (_symbol(e), _element_unit_value(e))
        for key, e in valued.items()
        if key in wanted and e.rod is None
    }
    units = {e.name: element_unit(netlist, e) for e in valued.values() if e.name in symbols}
    by_name = {name: sym for name, (sym, _) in symbols.items()}
    rod_terms = _rod_symbols(
        [e for k, e in valued.items() if k in wanted and e.rod is not None], symbols, units
    )
    carried = carried_masses(netlist.elements)

    def rod_length(rod: Element) -> sympy.Expr:
        assert rod.rod is not None
        return rod_terms[rod.key][0] if rod.key in rod_terms else _exact(rod.rod.length)

    def value(element: Element) -> sympy.Expr:
        if element.rod is not None:  # L = ±l / (g · carried mass)
            g = rod_terms[element.key][1] if element.key in rod_terms else _exact(element.rod.g)
            sign = -1 if element.rod.inverted else 1
            return sign * rod_length(element) / (g * sympy.Add(*(value(m) for m in carried[element.key])))
        if element.name in by_name:
            sym = by_name[element.name]
            return 1 / sym if element.keyword in ("SPRING", "DAMPER") else sym
        return _exact(element.value)

    def mutual(coupling: Element, la: Element, lb: Element) -> sympy.Expr:
        # As ngspice: M = k·sqrt(|La·Lb|), positive whatever the signs of the inductances.
        sign = 1 if la.value * lb.value > 0 else -1
        return value(coupling) * sympy.sqrt(sign * value(la) * value(lb))

    A, B, C, D, D1 = _reduce(form, value, mutual, rod_length)
    model = form.model
    return SymbolicModel(
        A, B, C, D, D1, model.states, model.inputs, model.outputs, symbols, netlist.title, units
    )


def _rod_symbols(
    rods: Sequence[Element], symbols: dict[str, tuple[sympy.Symbol, float]], units: dict[str, str]
) -> dict[str, tuple[sympy.Symbol, sympy.Symbol]]:
    """Length ``l_<rod>`` and gravity ``g`` symbols of the kept rods (added to ``symbols``, in m and m/s²).

    One ``g`` serves every rod when they share its value and no element is
    called g; otherwise each rod has its own ``g_<rod>``.
    """
    shared = len({r.rod.g for r in rods if r.rod is not None}) == 1 and "g" not in symbols
    out = {}
    for rod in rods:
        assert rod.rod is not None
        l_name, g_name = f"l_{rod.name}", "g" if shared else f"g_{rod.name}"
        for name, number, unit in ((l_name, rod.rod.length, "m"), (g_name, rod.rod.g, "m/s²")):
            if name not in symbols:
                symbols[name] = (sympy.Symbol(name, positive=True), number)
                units[name] = unit
        out[rod.key] = (symbols[l_name][0], symbols[g_name][0])
    return out


def _symbol(element: Element) -> sympy.Symbol:
    passive = element.kind in (Kind.RESISTOR, Kind.CAPACITOR, Kind.INDUCTOR, Kind.COUPLING)
    if passive and element.value > 0:
        return sympy.Symbol(element.name, positive=True)
    return sympy.Symbol(element.name, real=True)


def _element_unit_value(element: Element) -> float:
    """The value in the element's own unit: k and d for springs and dampers."""
    return 1.0 / element.value if element.keyword in ("SPRING", "DAMPER") else element.value


def _exact(value: float) -> sympy.Rational:
    """The shortest decimal that reads back as ``value``, as an exact rational."""
    return sympy.Rational(repr(value))


# --- exact linear algebra over rational functions ---------------------------------------------


def _matrix(entries: Sequence[tuple[int, int, Any]], shape: tuple[int, int]) -> sympy.Matrix:
    out = sympy.zeros(*shape)
    for row, col, coeff in entries:
        out[row, col] += coeff
    return out


def _from_sparse(matrix: Any) -> sympy.Matrix:
    """A scipy sparse matrix of small integers (topology) as a sympy matrix."""
    coo = matrix.tocoo()
    return _matrix(
        [
            (int(r), int(c), sympy.Integer(round(float(v))))
            for r, c, v in zip(coo.row, coo.col, coo.data, strict=True)
        ],
        coo.shape,
    )


def _solve(matrix: sympy.Matrix, rhs: sympy.Matrix) -> sympy.Matrix:
    """matrix⁻¹ rhs exactly; the numeric compiler has already checked solvability."""
    if matrix.rows == 0 or rhs.cols == 0:
        return sympy.zeros(matrix.cols, rhs.cols)
    a, b = DomainMatrix.from_Matrix(matrix), DomainMatrix.from_Matrix(rhs)
    a, b = a.unify(b)
    a, b = a.to_field(), b.to_field()
    try:
        x = a.lu_solve(b)
    except (ZeroDivisionError, ValueError, sympy.polys.matrices.exceptions.DMNonInvertibleMatrixError):
        raise NetlistError("the circuit equations are singular for symbolic element values") from None
    return x.to_Matrix().applyfunc(sympy.cancel)


def _cols(m: sympy.Matrix, index: Sequence[int]) -> sympy.Matrix:
    return m.extract(list(range(m.rows)), [int(k) for k in index])


def _rows(m: sympy.Matrix, index: Sequence[int]) -> sympy.Matrix:
    return m.extract([int(k) for k in index], list(range(m.cols)))


@dataclass(frozen=True)
class _Block:
    x: sympy.Matrix
    y: sympy.Matrix
    dx: sympy.Matrix
    dy: sympy.Matrix
    u: sympy.Matrix
    du: sympy.Matrix


def _reduce(
    form: Formulation,
    value: Callable[[Element], sympy.Expr],
    mutual: Callable[[Element, Element, Element], sympy.Expr],
    rod_length: Callable[[Element], sympy.Expr],
) -> tuple[sympy.ImmutableMatrix, ...]:
    """The algebra of :func:`~netlistdyn.formulate.reduce_to_state_space`, exactly."""
    netlist, circuit, tree = form.netlist, form.circuit, form.tree
    n, m = circuit.nbranches, len(netlist.sources)
    vmap_s, imap_s = primary_maps(tree)
    vmap, imap = _from_sparse(vmap_s), _from_sparse(imap_s)
    laws = branch_laws(netlist, circuit, value, mutual)
    G = _matrix(laws.v, (n, n)) * vmap + _matrix(laws.i, (n, n)) * imap
    if laws.control:
        ctrl = _from_sparse(_potential_rows(tree, [pair for _, pair, _ in laws.control], n))
        place = _matrix(
            [(row, j, gain) for j, (row, _, gain) in enumerate(laws.control)], (n, len(laws.control))
        )
        G += place * ctrl
    E = _matrix(laws.dv, (n, n)) * vmap + _matrix(laws.di, (n, n)) * imap
    F = _matrix(laws.u, (n, m))
    classes = classify(circuit, tree, netlist)
    unit = _matrix([(r, int(j), 1) for r, j in enumerate(classes.source_input)], (len(classes.s), m))
    e_d = _rows(E, classes.d)

    def eliminate(g: sympy.Matrix, e: sympy.Matrix, f: sympy.Matrix) -> _Block:
        """Inputs for source primaries, −E_d w' for excess primaries."""
        u = f + _cols(g, classes.s) * unit
        du = _cols(e, classes.s) * unit
        dx, dy = _cols(e, classes.x), _cols(e, classes.y)
        if len(classes.d):
            g_d = _cols(g, classes.d)
            dx -= g_d * _cols(e_d, classes.x)
            dy -= g_d * _cols(e_d, classes.y)
            du -= g_d * _cols(e_d, classes.s) * unit
        return _Block(_cols(g, classes.x), _cols(g, classes.y), dx, dy, u, du)

    nx_ = len(classes.x)
    yb = eliminate(_rows(G, classes.y), _rows(E, classes.y), _rows(F, classes.y))
    if not yb.dy.is_zero_matrix:
        yb = _algebraic_derivatives(yb)
    solved = -_solve(yb.y, sympy.Matrix.hstack(yb.x, yb.dx, yb.u, yb.du))
    P, R = solved[:, :nx_], solved[:, nx_ : 2 * nx_]
    Q, S = solved[:, 2 * nx_ : 2 * nx_ + m], solved[:, 2 * nx_ + m :]
    xb = eliminate(_rows(G, classes.x), _rows(E, classes.x), _rows(F, classes.x))
    mass = xb.dx + xb.dy * P + xb.y * R
    rhs = sympy.Matrix.hstack(xb.x + xb.y * P, xb.u + xb.y * Q, xb.du + xb.dy * Q + xb.y * S)
    solved_x = -_solve(mass, rhs)
    A, B, K = solved_x[:, :nx_], solved_x[:, nx_ : nx_ + m], solved_x[:, nx_ + m :]

    # Outputs, as in formulate._outputs; displacements that springs hold as sums of fluxes
    # (formulate.held_displacements decides which, for both paths).
    held = held_displacements(form.netlist, form.probes)
    branch_of = {b.element.key: b for b in circuit.branches}
    by_key = {e.key: e for e in form.netlist.elements}
    rows = []
    for j, probe in enumerate(form.probes):
        if j in held:
            row = sympy.zeros(1, n)
            for key, sign in held[j][1]:
                row += sign * value(by_key[key]) * imap.extract([branch_of[key].index], list(range(n)))
                for coupling in form.netlist.elements:
                    if coupling.kind is Kind.COUPLING and coupling.coupled and key in coupling.coupled:
                        a, b = coupling.coupled
                        other = b if a == key else a
                        m_ab = mutual(coupling, by_key[a], by_key[b])
                        row += sign * m_ab * imap.extract([branch_of[other].index], list(range(n)))
            rows.append(row)
        elif probe.kind in ("v", "x"):
            rows.append(_from_sparse(_potential_rows(tree, [probe.nodes], n)))
        else:
            branch = next(b for b in circuit.branches if b.element.key == probe.element)
            row = imap.extract([branch.index], list(range(n)))
            if probe.kind == "angle":
                row = row * (-value(branch.element) / rod_length(branch.element))
            rows.append(row)
    k = len(rows)
    c_w = sympy.Matrix.vstack(*rows) if rows else sympy.zeros(0, n)
    ob = eliminate(c_w, sympy.zeros(k, n), sympy.zeros(k, m))
    c_x = ob.x + ob.y * P
    c_dx = ob.dx + ob.y * R + ob.dy * P  # y' = P x' + Q u' (+ R x'', S u'' = 0: checked numerically)
    c_u = ob.u + ob.y * Q
    c_du = ob.du + ob.y * S + ob.dy * Q
    C = c_x + c_dx * A
    D = c_u + c_dx * B
    D1 = c_du + c_dx * K

    # Shift z = x − K u, then capacitor voltages → charges (q = C v).
    B = B + A * K
    D = D + C * K
    scale = [
        value(circuit.branches[int(j)].element)
        if circuit.branches[int(j)].element.kind is Kind.CAPACITOR
        else sympy.Integer(1)
        for j in classes.x
    ]
    if nx_:
        T, T_inv = sympy.diag(*scale), sympy.diag(*[1 / s for s in scale])
        A, B, C = T * A * T_inv, T * B, C * T_inv

    # Displacement outputs x(n): integrators appended after the circuit's states.
    picks = [j for j, p in enumerate(form.probes) if p.kind == "x" and j not in held]
    if picks:
        A = sympy.Matrix.vstack(
            sympy.Matrix.hstack(A, sympy.zeros(nx_, len(picks))),
            sympy.Matrix.hstack(_rows(C, picks), sympy.zeros(len(picks), len(picks))),
        )
        B = sympy.Matrix.vstack(B, _rows(D, picks))
        select = _matrix([(j, col, 1) for col, j in enumerate(picks)], (k, len(picks)))
        keep = sympy.diag(*[0 if j in picks else 1 for j in range(k)])
        C = sympy.Matrix.hstack(keep * C, select)
        D = keep * D + select * _rows(D1, picks)
        D1 = keep * D1
    for j, (base, _) in held.items():  # a position in a free chain: another's plus fluxes
        if base is not None:
            C[j, :] = C[j, :] + C[base, :]
            D[j, :] = D[j, :] + D[base, :]
            D1[j, :] = D1[j, :] + D1[base, :]
    return tuple(sympy.ImmutableMatrix(M.applyfunc(_tidy)) for M in (A, B, C, D, D1))


def _algebraic_derivatives(yb: _Block) -> _Block:
    """Exact counterpart of formulate._substitute_algebraic_derivatives.

    The rows without derivatives, brought to reduced row echelon form, give
    the resistive unknowns whose derivatives appear as combinations of
    states and inputs; their derivatives then follow from x' and u'.
    """
    n_y, n_x = yb.y.cols, yb.x.cols
    dynamic = [any(not M.row(r).is_zero_matrix for M in (yb.dx, yb.dy, yb.du)) for r in range(yb.y.rows)]
    static = [r for r, dyn in enumerate(dynamic) if not dyn]
    z = [c for c in range(n_y) if not yb.dy.col(c).is_zero_matrix]
    augmented = sympy.Matrix.hstack(_rows(yb.y, static), -_rows(yb.x, static), -_rows(yb.u, static))
    rref, pivots = augmented.rref(simplify=sympy.cancel)
    where = {col: r for r, col in enumerate(pivots)}
    s_x, s_u = sympy.zeros(len(z), n_x), sympy.zeros(len(z), yb.u.cols)
    for i, col in enumerate(z):
        r = where.get(col)
        if r is None or any(rref[r, c] != 0 for c in range(n_y) if c != col):
            raise NetlistError("a resistive quantity's derivative is not determined by the states")
        s_x[i, :] = rref[r, n_y : n_y + n_x]
        s_u[i, :] = rref[r, n_y + n_x :]
    dy_z = _cols(yb.dy, z)
    return _Block(yb.x, yb.y, yb.dx + dy_z * s_x, sympy.zeros(*yb.dy.shape), yb.u, yb.du + dy_z * s_u)


def _tidy(expr: sympy.Expr) -> sympy.Expr:
    """Cancel, then split the numerator over the denominator's factors as the notes write it."""
    expr = sympy.cancel(sympy.together(expr))
    if expr.is_number:
        return sympy.nsimplify(expr) if expr.is_Rational else expr
    return sympy.factor(expr)


def _reads_back(name: str) -> bool:
    """True when ``sympy.sympify(name)`` is the plain symbol of that name (not E, I, pi, beta, …)."""
    if not name.isidentifier() or keyword.iskeyword(name):
        return False
    try:
        value = sympy.sympify(name)
    except (sympy.SympifyError, SyntaxError, TypeError, AttributeError):
        return False
    return isinstance(value, sympy.Symbol) and value.name == name


def json_names(names: Collection[str]) -> dict[str, str]:
    """An identifier for each symbol name that ``sympy.sympify`` reads back as that symbol.

    Names that already do (R1, C1, l_r1) keep themselves; the others (E, I,
    pi, S, beta, X1.R1) get their non-word characters replaced by ``_`` and
    one or more trailing ``_`` until the identifier reads back and is unique.
    """
    out: dict[str, str] = {}
    taken = {n for n in names if _reads_back(n)}
    for name in names:
        if name in taken and name not in out.values():
            out[name] = name
            continue
        base = re.sub(r"\W", "_", name)
        if not base or base[0].isdigit():
            base = "s_" + base
        candidate = base + "_"
        while candidate in taken or not _reads_back(candidate):
            candidate += "_"
        taken.add(candidate)
        out[name] = candidate
    return out


def entry_strings(matrix: sympy.MatrixBase, names: Mapping[str, str] | None = None) -> list[list[str]]:
    """Entries as strings (``sympy.sstr``) for reports and JSON.

    ``names`` renames symbols (see :func:`json_names`) so that
    ``sympy.sympify`` reads every string back with the same free symbols.
    """
    if names:
        swap = {
            sym: sympy.Symbol(names[sym.name], **sym.assumptions0)
            for sym in matrix.free_symbols
            if isinstance(sym, sympy.Symbol) and names.get(sym.name, sym.name) != sym.name
        }
        matrix = matrix.xreplace(swap)
    return [[sympy.sstr(matrix[i, j]) for j in range(matrix.cols)] for i in range(matrix.rows)]
