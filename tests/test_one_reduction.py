"""The one reduction over its two algebras: exact rational functions against sparse floats.

:func:`netlistdyn.formulation.formulate.reduce` is run on the same normal tree with the
numeric algebra and with the exact one (:mod:`netlistdyn.symbolic`); the
exact matrices, evaluated at the netlist's values, must equal the numeric
ones to the numeric path's rounding.

Tolerance, derived from that rounding: the numeric path solves two systems
(the resistive part, n_y unknowns, and the capacitance/inductance matrix,
n_x states), each equilibrated and factorised by LU. LU's first-order
forward error is ‖Δx‖ ≤ γ_n·κ·‖x‖ with γ_n = n·eps (Higham, Accuracy and
Stability of Numerical Algorithms, §9.2, with the norm condition number κ
of the equilibrated matrix); the two solves' errors add to first order. The
right-hand sides and the outputs are sums and products of a few terms, each
rounded once: a factor of 16 covers them. The bound is on each matrix's
largest entry (the errors of the small entries are relative to the large
ones they were computed beside). A wrong sign, term or factor in either
algebra is an O(1) difference and fails it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest

from netlistdyn.formulation.algebra import SparseFloats, _equilibrate
from netlistdyn.formulation.compile import formulate
from netlistdyn.formulation.formulate import NUMERIC_VALUES, reduce
from netlistdyn.formulation.symbolic import symbolic_model
from netlistdyn.frontend.parser import parse_file, parse_text

from .conftest import NETLISTS
from .random_networks import random_network

EPS = float(np.finfo(float).eps)
#: Rounding of the right-hand sides and output products beside the two LU solves (see docstring).
SAFETY = 16.0


@dataclass(frozen=True)
class _Recording(SparseFloats):
    """The numeric algebra, noting n·κ of every (equilibrated) matrix it solves with."""

    solves: list[float] = field(default_factory=list)

    def solve(self, matrix: Any, rhs: Any, what: str) -> Any:
        r, c = _equilibrate(matrix)
        dense = r[:, None] * matrix.toarray() * c[None, :]
        self.solves.append(dense.shape[0] * float(np.linalg.cond(dense, 1)))
        return super().solve(matrix, rhs, what)


NETLIST_CASES = [
    "circuit1.cir",
    "circuit2.cir",
    "two_blocks.cir",
    "bridge.cir",
    "cap_loop.cir",
    "controlled.cir",
    "gear_train.cir",
    "inductor_isource.cir",
    "parallel_caps.cir",
    "series_inductors.cir",
    "stress/lc_tank.cir",
]
RANDOM_SEEDS = list(range(8))


def _compare(netlist, outputs=None) -> None:
    form = formulate(netlist, outputs)
    algebra = _Recording()
    numeric = reduce(algebra, NUMERIC_VALUES, form.netlist, form.circuit, form.tree, form.probes)
    exact = symbolic_model(netlist, outputs).numeric()
    tolerance = SAFETY * EPS * max(sum(algebra.solves), 1.0)
    for key in ("A", "B", "C", "D", "D1"):
        ours = getattr(numeric, key).toarray()
        assert ours.shape == exact[key].shape, key
        scale = float(np.abs(exact[key]).max(initial=0.0))
        error = float(np.abs(ours - exact[key]).max(initial=0.0))
        assert error <= tolerance * scale, f"{key}: {error:.3g} > {tolerance:.3g} × {scale:.3g}"


@pytest.mark.parametrize("name", NETLIST_CASES)
def test_exact_and_numeric_reductions_agree_on_the_netlists(name: str) -> None:
    _compare(parse_file(NETLISTS / name))


COUPLED = """coupled springs-like inductors: x(a), x(b) are sums of fluxes, through a coupling
V1 in 0 DC 1
R1 in a 47
C1 a 0 220n
L1 a b 4.7m
L2 b 0 10m
L3 c 0 3.3m
K1 L2 L3 0.3
R2 c 0 12
.end
"""
FREE_CHAIN = """a chain of springs tied to nothing: x(a) integrated, x(b) and x(c) from it and the fluxes
I1 0 a 1
C1 a 0 2
L1 a b 0.5
C2 b 0 3
L2 b c 0.25
C3 c 0 1
R1 c 0 7
.end
"""
DISPLACEMENT_CASES = [
    (parse_file, NETLISTS / "two_blocks.cir", ["x(b1)", "x(b2)", "x(b2,b1)", "v(b1)", "i(k1)"]),
    (parse_text, COUPLED, ["v(a)", "i(L3)", "x(a)", "x(b)", "x(c)"]),
    (parse_text, FREE_CHAIN, ["x(a)", "x(b)", "x(c)", "x(c,a)", "v(b)"]),
]


@pytest.mark.parametrize("case", range(len(DISPLACEMENT_CASES)))
def test_exact_and_numeric_reductions_agree_with_held_and_integrated_displacements(case: int) -> None:
    """Outputs built inside the reduction: spring fluxes (held, coupled, based) and integrators."""
    read, source, outputs = DISPLACEMENT_CASES[case]
    _compare(read(source), outputs)


@pytest.mark.parametrize("seed", RANDOM_SEEDS)
def test_exact_and_numeric_reductions_agree_on_random_networks(seed: int) -> None:
    """Random networks at realistic values (mΩ…GΩ, pF…mF, pH…H; VCCS and couplings)."""
    _compare(parse_text(random_network(np.random.default_rng(1000 + seed), spread=False)))
