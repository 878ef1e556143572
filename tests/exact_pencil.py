"""Exact reference: natural frequencies from the MNA pencil in rational arithmetic.

The MNA matrices of :mod:`tests.mna` are built from the parsed element values
(doubles, hence exact rationals). ``det(G + s C)`` is expanded exactly over
the rationals (sympy, fraction-free), and its roots are found with mpmath at
:data:`DIGITS` digits. Nothing here shares code with the tree/cotree
formulation, so it is an independent check of every eigenvalue netlistdyn
reports, at any spread of element values.
"""

from __future__ import annotations

from fractions import Fraction

import mpmath as mp
import sympy

from netlistdyn.circuit.netlist import GROUND, Kind

#: Working precision of the root finder (decimal digits).
DIGITS = 70
ONE = sympy.Integer(1)


def _exact_mna(netlist) -> tuple[sympy.Matrix, sympy.Matrix]:
    """MNA matrices (G, C) with exact entries: every stamp summed in rational arithmetic.

    (The floating-point MNA of :mod:`tests.mna` rounds when two stamps land on
    one entry, e.g. 1e-5 + 1e-3 on a node's diagonal; that rounding is the
    size of the errors under test here.) Mutual inductances are k·sqrt(La·Lb),
    kept as exact algebraic numbers.
    """
    nodes = [n for n in netlist.nodes if n != GROUND]
    index = {n: i for i, n in enumerate(nodes)}
    extra = [e.key for e in netlist.elements if e.kind in (Kind.VSOURCE, Kind.INDUCTOR, Kind.VCVS, Kind.CCVS)]
    branch = {k: len(nodes) + i for i, k in enumerate(extra)}
    ports = {}
    size = len(nodes) + len(extra)
    for e in netlist.elements:
        if e.kind is Kind.TRANSFORMER:
            ports[e.key] = (size, size + 1)
            size += 2
    G = [[sympy.Integer(0)] * size for _ in range(size)]
    C = [[sympy.Integer(0)] * size for _ in range(size)]

    def q(x: float) -> sympy.Rational:
        return sympy.Rational(Fraction(float(x)))

    def at(node: str) -> int | None:
        return None if node == GROUND else index[node]

    def add(mat, r, c, v) -> None:
        if r is not None and c is not None:
            mat[r][c] += v

    def admittance(mat, a, b, y) -> None:
        add(mat, at(a), at(a), y)
        add(mat, at(b), at(b), y)
        add(mat, at(a), at(b), -y)
        add(mat, at(b), at(a), -y)

    def branch_current(a, b, col, gain=ONE) -> None:
        add(G, at(a), col, gain)
        add(G, at(b), col, -gain)

    def branch_voltage(row, a, b, gain=ONE) -> None:
        add(G, row, at(a), gain)
        add(G, row, at(b), -gain)

    inductance = {e.key: q(e.value) for e in netlist.elements if e.kind is Kind.INDUCTOR}
    for e in netlist.elements:
        k = e.kind
        if k is Kind.RESISTOR:
            admittance(G, *e.nodes, 1 / q(e.value))
        elif k is Kind.CAPACITOR:
            admittance(C, *e.nodes, q(e.value))
        elif k in (Kind.INDUCTOR, Kind.VSOURCE, Kind.VCVS, Kind.CCVS):
            r = branch[e.key]
            branch_current(*e.nodes, r)
            branch_voltage(r, *e.nodes)
            if k is Kind.INDUCTOR:
                C[r][r] -= q(e.value)
            elif k is Kind.VCVS:
                branch_voltage(r, *e.control_nodes, -q(e.value))
            elif k is Kind.CCVS:
                G[r][branch[e.control_source]] -= q(e.value)
        elif k is Kind.VCCS:
            a, b = e.nodes
            c, d = e.control_nodes
            for node, sign in ((a, 1), (b, -1)):
                add(G, at(node), at(c), sign * q(e.value))
                add(G, at(node), at(d), -sign * q(e.value))
        elif k is Kind.CCCS:
            branch_current(*e.nodes, branch[e.control_source], q(e.value))
        elif k is Kind.COUPLING:
            a, b = e.coupled
            mutual = q(e.value) * sympy.sqrt(inductance[a] * inductance[b])
            C[branch[a]][branch[b]] -= mutual
            C[branch[b]][branch[a]] -= mutual
        elif k is Kind.TRANSFORMER:
            r1, r2 = ports[e.key]
            p1, n1, p2, n2 = e.nodes
            branch_current(p1, n1, r1)
            branch_current(p2, n2, r2)
            branch_voltage(r1, p1, n1)
            branch_voltage(r1, p2, n2, -q(e.value))
            G[r2][r2] += 1
            G[r2][r1] += q(e.value)
    return sympy.Matrix(G), sympy.Matrix(C)


def natural_frequency_count(netlist) -> int:
    """The number of finite natural frequencies: the degree of det(G + sC), exact.

    Raises ValueError when the pencil is singular (det ≡ 0).
    """
    from sympy.polys.matrices import DomainMatrix

    G, C = _exact_mna(netlist)
    s = sympy.Symbol("s")
    pencil = G + s * C
    try:  # fraction-free over QQ[s]: fast; coupled inductors bring square roots (M = k·√(L1·L2))
        expr = DomainMatrix.from_Matrix(pencil).convert_to(sympy.QQ[s]).det().as_expr()
    except (ValueError, sympy.polys.polyerrors.CoercionFailed):
        expr = sympy.expand(pencil.det(method="berkowitz"))
    det = sympy.Poly(expr, s)
    if det.is_zero:
        raise ValueError("singular pencil")
    return int(det.degree())


def exact_natural_frequencies(netlist) -> list[complex]:
    """Roots of det(G + sC) (1/s) for the parsed netlist, as complex doubles.

    Zero roots are exact (the power of s that divides the determinant).
    Raises ValueError when the pencil is singular (det ≡ 0).
    """
    G, C = _exact_mna(netlist)
    s = sympy.Symbol("s")
    det = sympy.Poly(sympy.expand((G + s * C).det(method="berkowitz")), s)
    if det.is_zero:
        raise ValueError("singular pencil")
    coeffs = list(det.all_coeffs())
    zeros = 0
    while coeffs and coeffs[-1] == 0:
        coeffs.pop()
        zeros += 1
    roots: list[complex] = [0j] * zeros
    if len(coeffs) > 1:
        with mp.workdps(DIGITS):
            mp_coeffs = [mp.mpf(sympy.N(c, DIGITS + 10)) for c in coeffs]
            found = mp.polyroots(mp_coeffs, maxsteps=2000, extraprec=4 * DIGITS)
            roots.extend(complex(r) for r in found)
    return roots


#: An exact root this close to the axis (relative to its modulus) lies on it (70-digit roots).
AXIS = 1e-40


def bar_violations(modes, exact: list[complex]) -> list[str]:
    """Each reported mode against the nearest unused exact root: the parts beyond their bars.

    Returns one line per violation (an empty list: every eigenvalue is within
    its own reported error bounds, and the counts agree).
    """
    exact = list(exact)
    if len(modes) != len(exact):
        return [f"{len(modes)} states, exact order {len(exact)}"]
    out = []
    for mode in sorted(modes, key=lambda m: m.abs_error):
        j = min(range(len(exact)), key=lambda i: abs(mode.value - exact[i]))
        truth = exact.pop(j)
        if abs(mode.value.real - truth.real) > mode.real_error or abs(mode.value.imag - truth.imag) > (
            mode.imag_error
        ):
            out.append(f"{mode.value} ± ({mode.real_error:.3g}, {mode.imag_error:.3g}); exact {truth}")
    return out


def expected_verdict(exact: list[complex]) -> str | None:
    """The verdict the exact roots imply, or None when it needs a multiplicity argument."""
    if any(e.real > AXIS * abs(e) for e in exact):
        return "unstable"
    axis = [e for e in exact if abs(e.real) <= AXIS * abs(e)]
    if not axis:
        return "asymptotically stable"
    distinct = all(
        abs(a - b) > 1e-30 * max(abs(a), abs(b), 1.0) for i, a in enumerate(axis) for b in axis[i + 1 :]
    )
    return "marginally stable" if distinct else None
