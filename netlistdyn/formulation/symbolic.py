"""Symbolic state-space matrices (sympy) in terms of the element names.

The numeric compiler picks the normal tree and checks the circuit; this
module gives the element values as sympy symbols and runs the numeric
compiler's own reduction (:func:`~netlistdyn.formulation.formulate.reduce`, the same
branch laws and the same elimination) over :class:`RationalFunctions`, the
exact algebra of rational functions in those symbols
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
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from netlistdyn.base.errors import NetlistError, UsageError
from netlistdyn.base.formatting import latex_label
from netlistdyn.base.optional import missing
from netlistdyn.devices.units import element_unit

try:
    import sympy
    from sympy.polys.matrices import DomainMatrix
except ImportError:  # sympy is the optional "symbolic" extra
    raise missing("sympy", "--symbolic") from None
from netlistdyn.circuit.netlist import Element, Kind, Netlist
from netlistdyn.devices.mechanics import DISPLACEMENT_KEYWORD, carried_masses
from netlistdyn.formulation.algebra import Block, Index
from netlistdyn.formulation.compile import formulate
from netlistdyn.formulation.formulate import ElementValues, reduce
from netlistdyn.formulation.operating import linearised

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
        keyword (:func:`~netlistdyn.devices.units.element_unit`), never from its name.
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

    def _repr_latex_(self) -> str:
        """The state equations in LaTeX, as Jupyter renders them (``x' = A x + B u``, ``y = C x + D u``)."""
        x = r" \\ ".join(latex_label(s) for s in self.states)
        u = r" \\ ".join(latex_label(s) for s in self.inputs)
        y = r" \\ ".join(latex_label(s) for s in self.outputs)

        def block(matrix: sympy.ImmutableMatrix) -> str:
            return sympy.latex(matrix, mat_delim="[", mat_str="matrix")

        vector = r"\begin{{bmatrix}} {} \end{{bmatrix}}".format
        lines = [
            rf"\frac{{d}}{{dt}}{vector(x)} &= {block(self.A)} {vector(x)} + {block(self.B)} {vector(u)}",
            rf"{vector(y)} &= {block(self.C)} {vector(x)} + {block(self.D)} {vector(u)}",
        ]
        if any(entry != 0 for entry in self.D1):
            lines[-1] += rf" + {block(self.D1)} \frac{{d}}{{dt}}{vector(u)}"
        return r"$$\begin{aligned}" + r" \\ ".join(lines) + r"\end{aligned}$$"

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
        As for :func:`~netlistdyn.formulation.formulate.compile_netlist`.
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

    # The numeric compile has chosen the tree and decided every rounding-level question on it.
    exact = reduce(
        RationalFunctions(),
        ElementValues(value, mutual, rod_length),
        form.netlist,
        form.circuit,
        form.tree,
        form.probes,
    )
    A, B, C, D, D1 = (
        sympy.ImmutableMatrix(M.applyfunc(_tidy)) for M in (exact.A, exact.B, exact.C, exact.D, exact.D1)
    )
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


class RationalFunctions:
    """The exact :class:`~netlistdyn.formulation.algebra.Algebra`: sympy matrices over rational functions.

    Solves are exact LU over the fraction field (``DomainMatrix``) followed by
    ``cancel``; derivatives of resistive unknowns come from ``rref``. A
    difference is plain subtraction and a product is zero only when it is:
    there is no rounding, and the questions the numeric algebra answers to
    rounding (higher index, derivative outputs) were decided by the numeric
    compile on the same tree.
    """

    def triplets(self, entries: Sequence[tuple[int, int, Any]], shape: tuple[int, int]) -> sympy.Matrix:
        out = sympy.zeros(*shape)
        for row, col, coeff in entries:
            out[row, col] += coeff
        return out

    def topology(self, matrix: Any) -> sympy.Matrix:
        coo = matrix.tocoo()
        return self.triplets(
            [
                (int(r), int(c), sympy.Integer(round(float(v))))
                for r, c, v in zip(coo.row, coo.col, coo.data, strict=True)
            ],
            coo.shape,
        )

    def zeros(self, rows: int, cols: int) -> sympy.Matrix:
        return sympy.zeros(rows, cols)

    def rows(self, matrix: sympy.Matrix, index: Index) -> sympy.Matrix:
        return matrix.extract([int(k) for k in index], list(range(matrix.cols)))

    def cols(self, matrix: sympy.Matrix, index: Index) -> sympy.Matrix:
        return matrix.extract(list(range(matrix.rows)), [int(k) for k in index])

    def hstack(self, blocks: Sequence[sympy.Matrix]) -> sympy.Matrix:
        return sympy.Matrix.hstack(*blocks)

    def vstack(self, blocks: Sequence[sympy.Matrix]) -> sympy.Matrix:
        return sympy.Matrix.vstack(*blocks)

    def diag(self, values: Sequence[Any], inverse: bool = False) -> sympy.Matrix:
        entries = [sympy.sympify(v) for v in values]
        if not entries:
            return sympy.zeros(0, 0)
        return sympy.diag(*[1 / v for v in entries] if inverse else entries)

    def clean(self, matrix: sympy.Matrix) -> sympy.Matrix:
        return matrix

    def nonzero(self, matrix: sympy.Matrix) -> bool:
        return not matrix.is_zero_matrix

    def cancelled(self, base: sympy.Matrix, left: sympy.Matrix, right: sympy.Matrix) -> sympy.Matrix:
        return base - left @ right

    def negligible(self, left: sympy.Matrix, right: sympy.Matrix) -> bool:
        return True  # decided on the same tree by the numeric compile

    def solve(self, matrix: sympy.Matrix, rhs: sympy.Matrix, what: str) -> sympy.Matrix:
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

    def algebraic_derivatives(self, block: Block, involved: Sequence[str], netlist: Netlist) -> Block:
        """The rows without derivatives, in reduced row echelon form, give the resistive
        unknowns whose derivatives appear as combinations of states and inputs; their
        derivatives then follow from x' and u'."""
        n_y, n_x = block.y.cols, block.x.cols
        dynamic = [
            any(not M.row(r).is_zero_matrix for M in (block.dx, block.dy, block.du))
            for r in range(block.y.rows)
        ]
        static = [r for r, dyn in enumerate(dynamic) if not dyn]
        z = [c for c in range(n_y) if not block.dy.col(c).is_zero_matrix]
        augmented = sympy.Matrix.hstack(
            self.rows(block.y, static), -self.rows(block.x, static), -self.rows(block.u, static)
        )
        rref, pivots = augmented.rref(simplify=sympy.cancel)
        where = {col: r for r, col in enumerate(pivots)}
        s_x, s_u = sympy.zeros(len(z), n_x), sympy.zeros(len(z), block.u.cols)
        for i, col in enumerate(z):
            r = where.get(col)
            if r is None or any(rref[r, c] != 0 for c in range(n_y) if c != col):
                raise NetlistError("a resistive quantity's derivative is not determined by the states")
            s_x[i, :] = rref[r, n_y : n_y + n_x]
            s_u[i, :] = rref[r, n_y + n_x :]
        dy_z = self.cols(block.dy, z)
        return Block(
            block.x,
            block.y,
            block.dx + dy_z @ s_x,
            sympy.zeros(*block.dy.shape),
            block.u,
            block.du + dy_z @ s_u,
        )

    def check_finite(self, netlist: Netlist, matrices: dict[str, Any]) -> None:
        pass  # exact entries do not overflow


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
