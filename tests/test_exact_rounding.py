"""Small circuits' matrices are the correctly rounded values of the exact model.

The floating-point reduction is accurate normwise, but an entry much smaller
than the others in its column can lose digits to cancellation (E12 values
decades apart: an entry of A 1.9e-4 off). ``formulate`` therefore takes the
matrices of circuits up to ``EXACT_BRANCH_LIMIT`` branches from the same
reduction in exact rationals, rounded once.

Reference: ``--symbolic``'s sympy model with every element kept as a symbol,
then each symbol replaced by the exact binary value of the parsed double
(``sympy.Rational(float)``) — sympy's own arithmetic, no floating point.
Correct rounding puts every entry within half an ulp, 2⁻⁵³ relative
(:data:`ROUNDING`), of the exact value.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.frontend.parser import parse_text

from .random_networks import random_network

sympy = pytest.importorskip("sympy")
from netlistdyn.formulation.symbolic import symbolic_model  # noqa: E402

#: |float(x) − x| ≤ 2⁻⁵³·|x| for a correctly rounded x.
ROUNDING = 2.0**-53

#: Draws of ``random_network(default_rng(1), spread=False)`` whose floating-point A printed a wrong
#: 6th significant digit (122, 167, 170; benchmarks/entrywise_accuracy.py), and the first ones without a K.
DRAWS = [0, 1, 2, 3, 5, 6, 7, 9, 122, 167, 170]


def _draw(k: int) -> str:
    rng = np.random.default_rng(1)
    for _ in range(k):
        random_network(rng, spread=False)
    return random_network(rng, spread=False)


@pytest.mark.parametrize("k", DRAWS)
def test_every_entry_is_correctly_rounded(k: int) -> None:
    text = _draw(k)
    assert "K1" not in text  # the draws have no coupling: M = k·sqrt(La·Lb) has no exact rational value
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        netlist = parse_text(text)
        model = compile_netlist(netlist)
    symbolic = symbolic_model(netlist)
    exact_values = {sym: sympy.Rational(value) for sym, value in symbolic.symbols.values()}
    for name in ("A", "B", "C", "D"):
        reference = getattr(symbolic, name).subs(exact_values)
        ours = getattr(model, name)
        for (i, j), value in np.ndenumerate(ours):
            exact = reference[i, j]
            if exact == 0:  # the correct rounding of an exact zero is 0.0 itself: no tolerance applies
                assert value == 0, (name, i, j, value)
            else:
                error = abs(sympy.Rational(float(value)) - exact) / abs(exact)
                assert error <= ROUNDING, (name, i, j, value, float(exact), float(error))
