"""Degenerate topologies and controlled sources against an independent MNA computation.

The MNA pencil (tests/mna.py) knows nothing of trees, states or excess
elements, so its finite generalized eigenvalues and its transfer function
are a reference that does not depend on any choice the compiler made.

Tolerances:
* EIG_RTOL 1e-8, relative to the spectral radius: QZ on the MNA pencil is
  backward stable, so its eigenvalues carry errors of about eps·cond of the
  pencil (the element values span 1e-8..1e3 here, cond ≈ 1e8 at most);
* TF_RTOL 1e-9: two direct solves of well-conditioned complex systems.
"""

from __future__ import annotations

import numpy as np
import pytest

from netlistdyn.analysis.eigen import analyze_eigenvalues
from netlistdyn.frontend.parser import parse_file

from .conftest import NETLISTS, compile_file, match_spectra
from .mna import build_mna

EIG_RTOL = 1e-8
TF_RTOL = 1e-9
TEST_FREQUENCIES = [1j * 10.0, 1j * 1e3 + 50.0, 1j * 3e4, 2e2 + 0j]

CASES = {
    # netlist: (expected order, outputs to compare)
    "cap_loop.cir": (1, ["v(a)", "v(in,a)", "i(C2)", "i(C3)", "i(C1)", "i(Vin)"]),
    "parallel_caps.cir": (1, ["v(a)", "i(C1)", "i(C2)", "i(R1)"]),
    "series_inductors.cir": (2, ["v(b)", "v(c)", "i(L1)", "i(L2)", "v(a,b)"]),
    "inductor_isource.cir": (1, ["v(a)", "v(b)", "i(L1)", "i(C1)", "i(I1)"]),
    "bridge.cir": (4, ["v(a)", "v(b)", "v(c)", "i(R5)", "i(C1)", "i(L2)"]),
    "controlled.cir": (
        5,
        [
            "v(a)",
            "v(b)",
            "v(d)",
            "v(e)",
            "v(g)",
            "v(h)",
            "i(Vsense)",
            "i(E1)",
            "i(H1)",
            "i(G1)",
            "i(F1)",
            "i(L2)",
        ],
    ),
    "circuit1.cir": (2, ["v(a)", "i(L1)", "i(C1)"]),
    "circuit2.cir": (4, ["v(a)", "v(b)", "v(c)", "i(C1)"]),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_order_and_eigenvalues_match_mna(name: str) -> None:
    order, outputs = CASES[name]
    model = compile_file(name, outputs=outputs)
    assert model.nstates == order
    mna = build_mna(parse_file(NETLISTS / name))
    reference = mna.finite_eigenvalues()
    assert len(reference) == order, "MNA pencil disagrees on the order of complexity"
    ours = [m.value for m in analyze_eigenvalues(model.A_sparse).modes]
    match_spectra(ours, reference, EIG_RTOL, scale=float(np.max(np.abs(reference))))


@pytest.mark.parametrize("name", sorted(CASES))
def test_transfer_function_matches_mna(name: str) -> None:
    _, outputs = CASES[name]
    model = compile_file(name, outputs=outputs)
    mna = build_mna(parse_file(NETLISTS / name))
    for s in TEST_FREQUENCIES:
        ours = model.transfer_function(s)
        ref = mna.transfer(outputs, s)
        scale = np.maximum(np.abs(ref), np.abs(ref).max(axis=1, keepdims=True) * 1e-6)
        err = np.abs(ours - ref) / scale
        assert err.max() <= TF_RTOL, f"{name} at s={s}: worst {err.max():.3g}\n{ours}\n{ref}"


def test_cap_loop_reports_excess_shift_and_d1() -> None:
    model = compile_file("cap_loop.cir", outputs=["i(C2)", "v(a)"])
    excess = {e.element: e for e in model.info.excess}
    assert set(excess) == {"C2", "C3"}
    assert set(excess["C3"].members) == {"Vin", "C1"}
    assert excess["C2"].members == ("Vin",)
    # KCL on C1's cutset carries C3·dVin/dt: q(C1) is shifted by C1·C3/(C1+C3)·Vin.
    (shift,) = model.info.shifts
    assert shift.state == "q(C1)"
    ((name, coeff),) = shift.coefficients
    assert name == "Vin"
    assert coeff == pytest.approx(1e-6 * 10e-9 / (1e-6 + 10e-9), rel=1e-12)
    # i(C2) = C2 dVin/dt exactly: only a D1 term.
    np.testing.assert_allclose(model.D1, [[100e-9], [0.0]], rtol=1e-12, atol=1e-30)
    np.testing.assert_allclose(model.C[0], [0.0], atol=1e-30)
    assert model.has_input_derivative


def test_no_d1_when_not_needed() -> None:
    model = compile_file("cap_loop.cir", outputs=["v(a)"])
    assert not model.has_input_derivative


def test_parallel_caps_single_state_time_constant() -> None:
    model = compile_file("parallel_caps.cir")
    (mode,) = analyze_eigenvalues(model.A_sparse).modes
    assert mode.value.real == pytest.approx(-1 / (1e3 * 3.2e-6), rel=1e-12)


def test_series_inductors_add() -> None:
    # Node b joins only L1 and L2: they carry one current, as one 32 mH inductor.
    model = compile_file("series_inductors.cir")
    assert [e.element for e in model.info.excess] == ["L2"]
    lam = analyze_eigenvalues(model.A_sparse).modes
    # Series R1-L(32m) driving C1 || R2: s² + (R1/L + 1/(R2 C))s + (1 + R1/R2)/(L C) = 0
    L, C, R1, R2 = 32e-3, 1e-6, 10.0, 100.0
    roots = np.roots([1, R1 / L + 1 / (R2 * C), (1 + R1 / R2) / (L * C)])
    match_spectra([m.value for m in lam], roots, 1e-10)


def test_inductor_in_series_with_current_source() -> None:
    model = compile_file("inductor_isource.cir", outputs=["i(L1)", "v(a)"])
    assert model.states == ("q(C1)",)
    # The inductor current is the source current; v(a) = v(b) + L dI/dt (D1 term).
    np.testing.assert_allclose(model.D, [[1.0], [0.0]], atol=1e-15)
    np.testing.assert_allclose(model.D1, [[0.0], [10e-3]], rtol=1e-12, atol=1e-18)
