"""Conversions, symbolic JSON names, the symbolic API and the multi-output observer form.

Issue 11 items 7-9 and the multi-output observer canonical form of issue 15.
Tolerances: the notes print Ĉ to one decimal (240.6, −29.4), so entries are
compared to half a unit of that digit; the form computed from the notes' own
Lagrangian matrices (other state coordinates: Ĉ does not depend on them) must
agree to 1e-9 relative (cond(T) ~ 2e5 times eps).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import sympy
from click.testing import CliRunner

import netlistdyn
from netlistdyn.analysis import control
from netlistdyn.base.errors import UsageError
from netlistdyn.cli import main

from .conftest import NETLISTS, ROOT, compile_file

NAMES_NETLIST = """Names sympy reads as constants, and a subcircuit's dotted names
.subckt rc a b
R1 a m 1k
C1 m b 1u
.ends
MASS I b1 2
SPRING E b1 0 100
DAMPER pi b1 0 3
FORCE F b1 0 DC 1
V1 in 0 DC 1
X1 in 0 rc
E1 out 0 in 0 2
Rload out 0 1k
.end
"""


def test_conversions_refuse_an_input_derivative() -> None:
    """Item 7: y = … + D1 u' has no place in scipy's or python-control's StateSpace."""
    model = compile_file("cap_loop.cir", outputs=["i(C2)", "v(a)"])
    assert model.has_input_derivative
    with pytest.raises(UsageError, match=r"i\(C2\) has .*d\(Vin\)/dt"):
        model.to_scipy()
    with pytest.raises(UsageError, match="input's derivative"):
        model.to_control()
    plain = compile_file("cap_loop.cir", outputs=["v(a)"])  # no D1: converted exactly
    ss = plain.to_scipy()
    for name in ("A", "B", "C", "D"):
        np.testing.assert_array_equal(getattr(ss, name), getattr(plain, name))


def test_symbolic_json_reads_back_with_sympify(tmp_path: Path) -> None:
    """Item 8: E, I, pi, E1 and X1.R1 come back as symbols, and the entries evaluate to A."""
    path = tmp_path / "names.cir"
    path.write_text(NAMES_NETLIST)
    result = CliRunner().invoke(
        main, ["analyze", str(path), "--symbolic", "--format", "json", "--eig", "none"]
    )
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    sym = doc["symbolic"]
    assert sym["symbol_elements"]["X1_R1_"] == "X1.R1" and sym["symbol_elements"]["E_"] == "E"
    values = {sympy.Symbol(name): value for name, value in sym["symbols"].items()}
    for key in ("A", "B", "C", "D"):
        exact = np.array(doc[key], dtype=float)
        for i, row in enumerate(sym[key]):
            for j, text in enumerate(row):
                expr = sympy.sympify(text)
                assert expr.free_symbols <= set(values), text  # no E, I, pi constants, no parse error
                assert float(expr.subs(values)) == pytest.approx(exact[i, j], rel=1e-12, abs=1e-300)


def test_symbolic_api_can_be_called_again() -> None:
    """Item 9: importing the symbolic stage must not replace the function netlistdyn.symbolic."""
    first = netlistdyn.symbolic(NETLISTS / "circuit1.cir")
    from netlistdyn.formulation.symbolic import symbolic_model  # the stage stays importable

    second = netlistdyn.symbolic(NETLISTS / "circuit1.cir")
    assert callable(netlistdyn.symbolic) and callable(symbolic_model)
    assert sympy.simplify(first.A - second.A).is_zero_matrix
    code = (
        "import netlistdyn, netlistdyn.formulation.symbolic\n"  # a fresh interpreter, stage imported first
        "netlistdyn.symbolic('netlists/circuit1.cir'); netlistdyn.symbolic('netlists/circuit1.cir')\n"
    )
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr


def _notes_cart() -> tuple[np.ndarray, np.ndarray]:
    """A and C of the notes' cart in their coordinates (x, θ1, θ2, ẋ, θ̇1, θ̇2), from the Lagrangian."""
    M, m1, m2, l1, l2, g = 1.5, 0.5, 0.75, 0.5, 0.75, 9.81
    mass = np.array(
        [
            [M + m1 + m2, (m1 + m2) * l1, m2 * l2],
            [(m1 + m2) * l1, (m1 + m2) * l1**2, m2 * l1 * l2],
            [m2 * l2, m2 * l1 * l2, m2 * l2**2],
        ]
    )
    stiffness = np.diag([0.0, (m1 * l1 + m2 * l1) * g, m2 * l2 * g])
    A = np.block([[np.zeros((3, 3)), np.eye(3)], [np.linalg.solve(mass, stiffness), np.zeros((3, 3))]])
    return A, np.hstack([np.eye(3), np.zeros((3, 3))])


def test_multi_output_observer_form_matches_the_notes() -> None:
    """Issue 15: L = [c1, A'c1, c2, A'c2, c3, A'c3]; Ĉ as printed in the notes."""
    model = compile_file("dipc.cir", outputs=["x(cart)", "angle(r1)", "angle(r2)"])
    form = control.observer_form_multi(model)
    notes_c = [[0, 0, 0, 0, 0, 240.6], [0, 0, 0, -29.4, 0, -2887.1], [0, 1, 0, 32.7, 0, 2031.7]]
    np.testing.assert_allclose(form.C, notes_c, rtol=0, atol=0.05)
    np.testing.assert_allclose(form.A[:, -1], [0, 0, -1176.2, 0, 98.1, 0], rtol=0, atol=0.05)
    np.testing.assert_allclose(form.A[:, -1], -np.poly(model.A)[1:][::-1], rtol=1e-8, atol=1e-8)
    scale = np.abs(model.A).max() * np.abs(form.T).max()
    np.testing.assert_allclose(form.T @ model.A, form.A @ form.T, atol=1e-9 * scale)
    np.testing.assert_allclose(form.C @ form.T, model.C, atol=1e-9 * np.abs(model.C).max())
    # Independently: the notes' recipe on the notes' own matrices (other state coordinates).
    A, C = _notes_cart()
    L = np.column_stack([C[0], A.T @ C[0], C[1], A.T @ C[1], C[2], A.T @ C[2]])
    q = np.linalg.inv(L)[-1]
    T_o = np.array([q @ np.linalg.matrix_power(A.T, k) for k in range(6)])
    np.testing.assert_allclose(form.C, C @ T_o.T, rtol=1e-9, atol=1e-9 * 2887.1)
    assert "x(cart): 2" in form.signal and "angle(r2): 2" in form.signal


def test_multi_output_observer_form_in_the_report_and_refusal() -> None:
    args = ["analyze", str(NETLISTS / "dipc.cir"), "--canonical", "--format", "json", "--eig", "none"]
    args += ["--output", "x(cart)", "--output", "angle(r1)", "--output", "angle(r2)"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    form = json.loads(result.stdout)["canonical"]["observer_all_outputs"]
    assert form["C"][0][-1] == pytest.approx(240.6, abs=0.05)
    unobservable = compile_file("balanced.cir", outputs=["v(a)"])  # the difference mode is not seen
    with pytest.raises(UsageError, match="do not observe every state"):
        control.observer_form_multi(unobservable)
