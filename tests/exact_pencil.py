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
import numpy as np
import sympy

from tests.mna import build_mna

#: Working precision of the root finder (decimal digits).
DIGITS = 70


def _rational_matrix(a: np.ndarray) -> sympy.Matrix:
    return sympy.Matrix(a.shape[0], a.shape[1], [sympy.Rational(Fraction(float(v))) for v in a.ravel()])


def exact_natural_frequencies(netlist) -> list[complex]:
    """Roots of det(G + sC) (1/s) for the parsed netlist, as complex doubles.

    Zero roots are exact (the power of s that divides the determinant).
    Raises ValueError when the pencil is singular (det ≡ 0).
    """
    mna = build_mna(netlist)
    s = sympy.Symbol("s")
    pencil = _rational_matrix(mna.G) + s * _rational_matrix(mna.C)
    det = sympy.Poly(pencil.det(method="berkowitz"), s)
    if det.is_zero:
        raise ValueError("singular pencil")
    coeffs = [sympy.Rational(c) for c in det.all_coeffs()]
    zeros = 0
    while coeffs and coeffs[-1] == 0:
        coeffs.pop()
        zeros += 1
    roots: list[complex] = [0j] * zeros
    if len(coeffs) > 1:
        with mp.workdps(DIGITS):
            mp_coeffs = [mp.mpf(c.p) / mp.mpf(c.q) for c in coeffs]
            found = mp.polyroots(mp_coeffs, maxsteps=500, extraprec=4 * DIGITS)
            roots.extend(complex(r) for r in found)
    return roots
