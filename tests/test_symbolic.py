"""Symbolic matrices (--symbolic): the seeds' formulas, and agreement with the numeric compiler.

Tolerances:
* seed formulas: exact — ``sympy.simplify(ours − seed)`` must be the zero matrix;
* symbolic evaluated at the netlist's values vs the numeric compiler: 1e-10
  of each matrix's largest entry — the symbolic side is exact (evaluated at
  30 digits), the numeric side accumulates a few roundings per entry through
  one or two LU solves of well-conditioned systems; 1e-10 leaves room for
  that and still catches any wrong sign, term or factor.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import sympy
from click.testing import CliRunner

from netlistdyn.base.errors import UsageError
from netlistdyn.cli import main
from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.formulation.symbolic import SYMBOLIC_STATE_LIMIT, symbolic_model
from netlistdyn.frontend.parser import parse_file, parse_text

from .conftest import NETLISTS, compile_file

NUMERIC_RTOL = 1e-10


def _symbols(model, *names):
    return [model.symbols[n][0] for n in names]


def _assert_equal(ours: sympy.MatrixBase, seed: sympy.MatrixBase) -> None:
    difference = sympy.simplify(sympy.Matrix(ours) - seed)
    assert difference.is_zero_matrix, f"differs from the seed by {difference}"


def test_circuit1_matches_seed_formula() -> None:
    model = symbolic_model(parse_file(NETLISTS / "circuit1.cir"))
    R1, R2, L1, C1 = _symbols(model, "R1", "R2", "L1", "C1")
    assert model.states == ("q(C1)", "i(L1)")
    _assert_equal(model.A, sympy.Matrix([[-1 / (R1 * C1) - 1 / (R2 * C1), -1], [1 / (L1 * C1), 0]]))
    _assert_equal(model.B, sympy.Matrix([[1 / R1], [0]]))


def test_circuit2_matches_seed_formula() -> None:
    model = symbolic_model(parse_file(NETLISTS / "circuit2.cir"))
    R1, R2, L1, L2, L3, C1 = _symbols(model, "R1", "R2", "L1", "L2", "L3", "C1")
    assert model.states == ("q(C1)", "i(L1)", "i(L2)", "i(L3)")
    seed_A = sympy.Matrix(
        [
            [0, -1, -1, 1],
            [1 / (L1 * C1), 0, 0, 0],
            [1 / (L2 * C1), 0, -R2 / L2, 0],
            [-1 / (L3 * C1), 0, 0, -R1 / L3],
        ]
    )
    _assert_equal(model.A, seed_A)
    _assert_equal(model.B, sympy.Matrix([[0], [0], [0], [1 / L3]]))


def test_two_blocks_in_mechanical_names() -> None:
    """Springs enter as stiffness k, dampers as d, masses as m (not their analog L = 1/k, R = 1/d)."""
    model = symbolic_model(parse_file(NETLISTS / "two_blocks.cir"))
    m1, m2, k1, k2, d1, d2 = _symbols(model, "m1", "m2", "k1", "k2", "d1", "d2")
    seed_A = sympy.Matrix(
        [
            [-(d1 + d2) / m1, d2 / m2, -1, 1],
            [d2 / m1, -d2 / m2, 0, -1],
            [k1 / m1, 0, 0, 0],
            [-k2 / m1, k2 / m2, 0, 0],
        ]
    )
    assert model.states == ("p(m1)", "p(m2)", "f(k1)", "f(k2)")
    _assert_equal(model.A, seed_A)


NETLIST_FILES = sorted(p.name for p in NETLISTS.glob("*.cir")) + [
    f"stress/{p.name}" for p in sorted((NETLISTS / "stress").glob("*.cir"))
]


@pytest.mark.parametrize("name", NETLIST_FILES)
def test_symbolic_evaluates_to_the_numeric_model(name: str) -> None:
    numeric = compile_file(name)
    if numeric.nstates > SYMBOLIC_STATE_LIMIT:
        with pytest.raises(UsageError, match="small circuits"):
            symbolic_model(parse_file(NETLISTS / name))
        return
    model = symbolic_model(parse_file(NETLISTS / name))
    assert (model.states, model.inputs, model.outputs) == (numeric.states, numeric.inputs, numeric.outputs)
    values = model.numeric()
    for key in ("A", "B", "C", "D", "D1"):
        expected = getattr(numeric, key)
        scale = max(float(np.abs(expected).max(initial=0.0)), 1e-300)
        np.testing.assert_allclose(values[key], expected, rtol=0, atol=NUMERIC_RTOL * scale, err_msg=key)


def test_symbolic_with_displacement_outputs_and_coupling() -> None:
    text = """coupled inductors with a displacement-like integrator output
V1 in 0 DC 1
R1 in a 10
L1 a 0 1m
L2 b 0 2m
K1 L1 L2 0.5
R2 b 0 5
C1 a 0 1u
.end
"""
    netlist = parse_text(text)
    outputs = ["v(a)", "i(L2)", "x(a)"]
    numeric = compile_netlist(netlist, outputs)
    model = symbolic_model(netlist, outputs)
    values = model.numeric()
    for key in ("A", "B", "C", "D"):
        expected = getattr(numeric, key)
        scale = max(float(np.abs(expected).max(initial=0.0)), 1e-300)
        np.testing.assert_allclose(values[key], expected, rtol=0, atol=NUMERIC_RTOL * scale, err_msg=key)


def test_keep_substitutes_the_other_values() -> None:
    """keep=R1: every other element takes its netlist value, as an exact rational."""
    model = symbolic_model(parse_file(NETLISTS / "circuit1.cir", {"R2": 100}), keep=["r1"])
    (R1,) = _symbols(model, "R1")
    assert set(model.symbols) == {"R1"}
    _assert_equal(model.A, sympy.Matrix([[-1 / R1 - sympy.Rational(1, 100), -1], [1, 0]]))


def test_numeric_overrides_reproduce_the_param_case() -> None:
    model = symbolic_model(parse_file(NETLISTS / "circuit1.cir"))
    case2 = compile_file("circuit1.cir", {"R1": 100, "R2": 100})
    np.testing.assert_allclose(model.numeric({"R1": 100, "R2": 100})["A"], case2.A, rtol=1e-14)
    with pytest.raises(UsageError, match="no symbol"):
        model.numeric({"R9": 1})


def test_unknown_keep_name_is_refused() -> None:
    with pytest.raises(UsageError, match="no element r9"):
        symbolic_model(parse_file(NETLISTS / "circuit1.cir"), keep=["R9"])


def test_cli_symbolic_text_and_json(tmp_path) -> None:
    runner = CliRunner()
    result = runner.invoke(main, ["analyze", str(NETLISTS / "circuit1.cir"), "--symbolic"])
    assert result.exit_code == 0, result.output
    assert "-(R1 + R2)/(C1*R1*R2)" in result.output
    result = runner.invoke(
        main, ["analyze", str(NETLISTS / "circuit1.cir"), "--symbols", "R1,C1", "--format", "json"]
    )
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert data["symbolic"]["symbols"] == {"R1": 0.001, "C1": 1.0}
    A = sympy.Matrix([[sympy.sympify(e) for e in row] for row in data["symbolic"]["A"]])
    R1, C1 = sympy.symbols("R1 C1")
    assert sympy.simplify(A - sympy.Matrix([[-1 / (R1 * C1) - 1000 / C1, -1], [1 / C1, 0]])).is_zero_matrix
    bad = runner.invoke(main, ["analyze", str(NETLISTS / "circuit1.cir"), "--symbols", "Q7"])
    assert bad.exit_code != 0 and "no element q7" in bad.output


@pytest.mark.parametrize("inverted", [False, True])
def test_blocks_pendulum_has_the_seeds_characteristic_polynomial(inverted: bool) -> None:
    """Seed 000 linearises the blocks + pendulum in (x1, x2, θ, ẋ1, ẋ2, θ̇) with the mass matrix
    M(θ) and the Jacobian ∂F/∂z; at θ = 0 (hanging) or θ = π (upright, cos θ = −1) the
    −M⁻¹(∂M/∂θ)M⁻¹F term vanishes. Our model uses momenta, spring forces and the rod as a
    spring ±m3·g/l: a different state basis, so the characteristic polynomials must be equal —
    exactly, as rational functions of the nine symbols."""
    params = {"inv": 1.0} if inverted else {}
    model = symbolic_model(parse_file(NETLISTS / "blocks_pendulum.cir", params))
    m1, m2, m3, k1, k2, d1, d2, ell, g = _symbols(
        model, "m1", "m2", "m3", "k1", "k2", "d1", "d2", "l_rod", "g"
    )
    c = -1 if inverted else 1  # cos θ at the equilibrium
    M = sympy.Matrix([[m1, 0, 0], [0, m2 + m3, m3 * ell * c], [0, m3 * ell * c, m3 * ell**2]])
    dF = sympy.Matrix(
        [
            [-k1 - k2, k2, 0, -d1 - d2, d2, 0],
            [k2, -k2, 0, d2, -d2, 0],
            [0, 0, -m3 * g * ell * c, 0, 0, 0],
        ]
    )
    seed_A = sympy.Matrix.vstack(sympy.Matrix.hstack(sympy.zeros(3, 3), sympy.eye(3)), M.inv() * dF)
    s = sympy.Symbol("s")
    ours = sympy.Poly(sympy.Matrix(model.A).charpoly(s).as_expr(), s)
    seed = sympy.Poly(seed_A.charpoly(s).as_expr(), s)
    assert ours.degree() == seed.degree() == 6
    for a, b in zip(ours.all_coeffs(), seed.all_coeffs(), strict=True):
        assert sympy.cancel(a - b) == 0, (a, b)


# --- units: from the element's kind and mechanical keyword, never from its name -------------------

#: Element names whose first letters suggest the wrong unit (R, C, L, i, r): a capacitor and a resistor
#: inside a subcircuit (X1.C1, X1.R1), a mass R2, a spring C3, a damper i1, and a force L2 that reads its
#: node's velocity (linearised: a VCCS named L2 whose gain is a damping in N·s/m).
MISLEADING = """Misleading names: a filter cell beside a damped mass
.subckt cell a b
R1 a m 1k
C1 m b 1u
.ends
V1 in 0 DC 1
X1 in out cell
Rload out 0 10k
MASS R2 b1 2
SPRING C3 b1 0 50
DAMPER i1 b1 0 0.5
FORCE L2 b1 0 {-3*v(b1)}
FORCE F1 b1 0 DC 0
.end
"""

#: A 2 kg bob on a 0.5 m rod about a fixed pivot, with a torque named r1 (a pendulum rod's usual name)
#: that is gravity's -m·g·l·sin(theta), and a bearing friction named R2 that reads the angular velocity.
TORQUE_R1 = """Pendulum whose gravity torque is named r1
.param m=2 l=0.5 g=9.81
INERTIA bob bob {m*l*l}
TORQUE r1 bob 0 {-m*g*l*sin(x(bob))}
TORQUE R2 bob 0 {-0.05*v(bob)}
.end
"""


def _symbolic_text(tmp_path, text: str, name: str, *extra: str) -> str:
    path = tmp_path / name
    path.write_text(text)
    result = CliRunner().invoke(main, ["analyze", str(path), "--symbolic", "--eig", "none", *extra])
    assert result.exit_code == 0, result.output
    return result.stdout


def test_symbol_units_come_from_the_kind_not_the_first_letter(tmp_path) -> None:
    out = _symbolic_text(tmp_path, MISLEADING, "misleading.cir")
    for shown in (
        "X1.R1 = 1 kΩ",
        "X1.C1 = 1 µF",
        "Rload = 10 kΩ",
        "R2 = 2 kg",
        "C3 = 50 N/m",
        "i1 = 500 mN·s/m",
        "L2 = -3 N·s/m",
    ):
        assert shown in out, (shown, out)
    assert "q(X1.C1) [C], p(R2) [kg·m/s], f(C3) [N]" in out
    doc = json.loads(
        CliRunner()
        .invoke(main, ["analyze", str(tmp_path / "misleading.cir"), "--symbolic", "--format", "json"])
        .stdout
    )
    assert doc["symbolic"]["symbol_units"] == {
        "X1_R1_": "Ω",
        "X1_C1_": "F",
        "Rload": "Ω",
        "R2": "kg",
        "C3": "N/m",
        "i1": "N·s/m",
        "L2": "N·s/m",
    }


def test_linearised_torque_named_r1_is_a_stiffness_in_newton_metres_per_radian(tmp_path) -> None:
    out = _symbolic_text(tmp_path, TORQUE_R1, "torque_r1.cir")
    # d(-m g l sin x)/dx at x = 0 is -m g l = -9.81 N·m/rad; the bob's inertia m l² = 0.5 kg·m²
    assert "r1 = -9.81 N·m/rad" in out and "R2 = -50 mN·m·s/rad" in out and "bob = 0.5 kg·m²" in out
    assert "p(bob) [kg·m²/s], x(bob) [rad]" in out


def test_controlled_source_gains_and_torsional_springs_in_their_units(tmp_path) -> None:
    out = _symbolic_text(tmp_path, (NETLISTS / "controlled.cir").read_text(), "controlled.cir")
    for shown in ("E1 = 2 V/V", "G1 = 1 mA/V", "F1 = 2 A/A", "H1 = 100 V/A", "K1 = 500m,", "L1 = 10 mH"):
        assert shown in out, (shown, out)
    out = _symbolic_text(tmp_path, (NETLISTS / "servo_shaft.cir").read_text(), "servo.cir")
    for shown in ("K = 500 N·m/rad", "Jm = 0.0008 kg·m²", "motor = 50 mN·m/A", "gear = 12,", "f(K) [N·m]"):
        assert shown in out, (shown, out)


def test_symbolic_model_renders_its_equations_in_latex() -> None:
    """Jupyter shows a SymbolicModel as its two state equations: each matrix as sympy writes it, beside
    the labels of x, u and y (Circuit 1: A's first entry is −(R1 + R2)/(C1 R1 R2), as in the notes)."""
    import sympy

    import netlistdyn

    model = netlistdyn.symbolic(NETLISTS / "circuit1.cir")
    latex = model._repr_latex_()
    assert latex.startswith("$$") and latex.endswith("$$")
    for matrix in (model.A, model.B, model.C, model.D):
        assert sympy.latex(matrix, mat_delim="[", mat_str="matrix") in latex
    assert r"\text{q(C1)}" in latex and r"\text{Vin}" in latex and r"\text{v(a)}" in latex
    R1, R2, C1 = (model.symbols[n][0] for n in ("R1", "R2", "C1"))
    assert sympy.simplify(model.A[0, 0] + (R1 + R2) / (C1 * R1 * R2)) == 0
    assert r"\frac{d}{dt}" in latex.split("&=")[0]
