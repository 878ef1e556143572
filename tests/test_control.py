"""Control analysis, sweeps and exports (issue 6, first part).

TF_RTOL 1e-4 against seed 002's printed coefficients (printed to 4-6
digits); 1e-9 where compared with an independent evaluation of C(sI−A)⁻¹B.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from netlistdyn.analysis import control
from netlistdyn.base.errors import UsageError
from netlistdyn.cli import main
from netlistdyn.io.exports import load_model, save_model

from .conftest import NETLISTS, compile_file, compile_string, match_spectra


def test_cart_transfer_function_matches_seed_002() -> None:
    model = compile_file("dipc.cir", outputs=["x(cart)"])
    (tf,) = control.transfer_functions(model)
    np.testing.assert_allclose(tf.num, [0.6667, 0, -54.5, 0, 427.716], rtol=1e-4, atol=1e-9)
    np.testing.assert_allclose(tf.den, [1, 0, -98.1, 0, 1176.2, 0, 0], rtol=1e-4, atol=1e-9)
    for s in (0.5j, 2.0 + 1.0j):
        value = np.polyval(tf.num, s) / np.polyval(tf.den, s)
        assert value == pytest.approx(model.transfer_function(s)[0, 0], rel=1e-9)


def test_cart_with_positions_is_controllable_and_observable() -> None:
    model = compile_file("dipc.cir", outputs=["x(cart)", "angle(r1)", "angle(r2)"])
    structure = control.structure(model)
    assert structure.controllable and structure.observable
    assert structure.ranks == (6, 6) and structure.margin > 1e3


def test_balanced_branches_mode_is_named_and_removed() -> None:
    model = compile_file("balanced.cir", outputs=["v(a)"])
    structure = control.structure(model)
    assert len(structure.uncontrollable) == 1 and len(structure.unobservable) == 1
    mode = structure.unobservable[0]
    assert mode.real == pytest.approx(-1 / (2e3 * 470e-9), rel=1e-9)  # the difference mode: 1/(R2 C2)
    reduced, dropped = control.minimal(model)
    assert dropped == 1 and reduced.nstates == 2
    for s in (10j, 300.0, 2e3 + 5e3j):  # same input-output behaviour
        assert reduced.transfer_function(s)[0, 0] == pytest.approx(model.transfer_function(s)[0, 0], rel=1e-9)


def test_sweep_reproduces_the_seed_case_tables() -> None:
    result = CliRunner().invoke(
        main,
        [
            "sweep",
            str(NETLISTS / "circuit2.cir"),
            "--param",
            "R1=1e-3,100",
            "--param",
            "R2=1e-3,100",
            "--format",
            "json",
            "--jobs",
            "2",
        ],
    )
    assert result.exit_code == 0, result.output
    cases = json.loads(result.stdout)["cases"]
    assert [c["params"] for c in cases] == [{"R1": 1e-3, "R2": 1e-3}, {"R1": 100.0, "R2": 100.0}]
    match_spectra(
        [complex(*e) for e in cases[1]["eigenvalues"]],
        [-100.0, -99.979998, -0.0100010 + 1.00005j, -0.0100010 - 1.00005j],
        1e-6,
    )


def test_sweep_ranges() -> None:
    from netlistdyn.workflows.sweep import expand_cases

    cases = expand_cases(["R1=log:1e-6:1e3:10"])
    assert (
        len(cases) == 10 and cases[0]["R1"] == pytest.approx(1e-6) and cases[-1]["R1"] == pytest.approx(1e3)
    )
    assert len(expand_cases(["a=1,2", "b=3,4,5"])) == 6  # unequal lengths: every combination


@pytest.mark.parametrize("suffix", [".json", ".npz", ".mat"])
def test_exports_round_trip(suffix: str, tmp_path: Path) -> None:
    model = compile_file("cap_loop.cir", outputs=["i(C2)", "v(a)"])  # has a D1 term
    path = tmp_path / f"model{suffix}"
    save_model(model, path)
    back = load_model(path)
    assert back.states == model.states and back.inputs == model.inputs and back.outputs == model.outputs
    for name in ("A", "B", "C", "D", "D1"):
        np.testing.assert_array_equal(getattr(back, name), getattr(model, name))


def test_analyze_save_and_control_flags(tmp_path: Path) -> None:
    target = tmp_path / "servo.npz"
    result = CliRunner().invoke(
        main,
        [
            "analyze",
            str(NETLISTS / "servo_shaft.cir"),
            "--output",
            "x(load)",
            "--control",
            "--save",
            str(target),
            "--format",
            "json",
        ],
    )
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["control"]["controllable"] and doc["control"]["observable"]
    assert load_model(target).nstates == 5


def test_to_scipy_and_control() -> None:
    model = compile_file("circuit1.cir")
    ss = model.to_scipy()
    np.testing.assert_array_equal(ss.A, model.A)
    try:
        import control as ct  # noqa: F401
    except ImportError:
        with pytest.raises(ImportError, match="pip install control"):
            model.to_control()


def test_frequency_response_matches_circuit1_closed_form() -> None:
    """v(a)/Vin = Z/(R1 + Z) with Z = R2 ∥ sL1 ∥ 1/(sC1) (case 2: R = 100, L = C = 1).

    rtol 1e-12: both sides are a handful of complex operations at each frequency.
    """
    model = compile_file("circuit1.cir", {"R1": 100, "R2": 100})
    omega = control.frequency_grid(model, 50)
    assert omega[0] == pytest.approx(0.01) and omega[-1] == pytest.approx(100)  # |λ| = 1, two decades
    h = control.frequency_response(model, omega)[:, model.outputs.index("v(a)"), 0]
    s = 1j * omega
    Z = 1 / (1 / 100 + 1 / s + s)
    np.testing.assert_allclose(h, Z / (100 + Z), rtol=1e-12)


def test_bode_png_is_written(tmp_path: Path) -> None:
    target = tmp_path / "bode.png"
    result = CliRunner().invoke(
        main, ["analyze", str(NETLISTS / "circuit2.cir"), "--bode", str(target), "--eig", "none"]
    )
    assert result.exit_code == 0, result.output
    assert target.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_canonical_forms_of_the_cart_match_seed_002() -> None:
    """Seed 002: Ã's last row [0, 0, −1176.2, 0, 98.1, 0], B̃ = e6; Â is its transpose pattern.

    rtol 1e-4 against the seed's printed digits. Independently: Ã's last row must be minus the
    characteristic polynomial of A (numpy's poly, rtol 1e-8: the Krylov matrix has cond ~4e3,
    so T carries a few digits of rounding), and T must map the model onto the form
    (T A = Ã T to 1e-9 of ‖A‖).
    """
    model = compile_file("dipc.cir", outputs=["x(cart)", "angle(r1)", "angle(r2)"])
    ctrl, obs = control.controller_form(model), control.observer_form(model)
    np.testing.assert_allclose(ctrl.A[-1], [0, 0, -1176.2, 0, 98.1, 0], rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(ctrl.B[:, 0], np.eye(6)[-1], atol=1e-9)
    np.testing.assert_allclose(ctrl.A[-1], -np.poly(model.A)[1:][::-1], rtol=1e-8, atol=1e-8)
    np.testing.assert_allclose(obs.A[:, -1], ctrl.A[-1], rtol=1e-8, atol=1e-8)
    np.testing.assert_allclose(obs.C[0], np.eye(6)[-1], atol=1e-9)
    scale = np.abs(model.A).max()
    for form in (ctrl, obs):
        np.testing.assert_allclose(
            form.T @ model.A, form.A @ form.T, atol=1e-9 * scale * np.abs(form.T).max()
        )
    # The controller form's C̃ row for the cart carries the seed's transfer-function numerator.
    np.testing.assert_allclose(ctrl.C[0], [427.716, 0, -54.5, 0, 0.6667, 0], rtol=1e-4, atol=1e-6)


def test_canonical_form_refused_when_uncontrollable() -> None:
    # C2's charge is reached by no source: an uncontrollable mode.
    model = compile_string("uncontrollable\nV1 in 0 1\nR1 in a 1k\nC1 a 0 1u\nR2 b 0 1k\nC2 b 0 2.2u\n.end\n")
    with pytest.raises(UsageError, match="no input controls every state"):
        control.controller_form(model)
    result = CliRunner().invoke(
        main, ["analyze", str(NETLISTS / "circuit1.cir"), "--canonical", "--format", "json", "--eig", "none"]
    )
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)["canonical"]
    assert doc["controller"]["signal"] == "Vin"
    assert doc["observer"]["signal"] == "v(a)"  # v(in) = Vin sees no state; v(a) sees both


@pytest.mark.parametrize(("r2", "c2"), [("2k", "0.5u"), ("4k", "0.25u"), ("1k", "1u")])
def test_equal_time_constants_in_decoupled_parts_are_not_controllable_from_one_input(
    r2: str, c2: str
) -> None:
    """Two RCs fed by one source with R1C1 = R2C2 exactly (the halved/quartered values are exact in
    binary): A = −1000·I, a double eigenvalue with two eigenvectors, which one input cannot reach
    (rank [A − λI, B] = rank B = 1). The PBH test must say so, and the controller form must be
    refused with a reason rather than fail on the singular Krylov matrix (it raised LinAlgError)."""
    model = compile_string(f"twin RCs\nVin in 0 1\nR1 in a 1k\nC1 a 0 1u\nR2 in b {r2}\nC2 b 0 {c2}\n.end\n")
    found = control.structure(model)
    assert found.ranks[0] == 1  # the controllable subspace is one-dimensional
    assert len(found.uncontrollable) == 1
    assert abs(found.uncontrollable[0] + 1000.0) <= 1e-9 * 1000.0
    with pytest.raises(UsageError, match="no input controls every state"):
        control.controller_form(model)
    runner = CliRunner()
    with runner.isolated_filesystem():
        Path("twin.cir").write_text(
            f"twin RCs\nVin in 0 1\nR1 in a 1k\nC1 a 0 1u\nR2 in b {r2}\nC2 b 0 {c2}\n.end\n"
        )
        result = runner.invoke(main, ["analyze", "twin.cir", "--canonical", "--control", "--format", "json"])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert "no input controls every state" in doc["canonical"]["controller"]["unavailable"]


def test_cart_angle_transfer_functions_match_seed_002() -> None:
    """The siblings of the cart's transfer function: θ1/F = (−1.3333s⁴ + 43.6s²)/den and
    θ2/F = 43.6s²/den, den = s⁶ − 98.1s⁴ + 1176.2s² (printed to 4-5 digits: rtol 1e-4; the
    structurally zero coefficients must be below 1e-9 of the largest)."""
    model = compile_file("dipc.cir", outputs=["x(cart)", "angle(r1)", "angle(r2)"])
    tfs = {t.output: t for t in control.transfer_functions(model)}
    seed = {"angle(r1)": [-1.3333, 0, 43.6, 0, 0], "angle(r2)": [43.6, 0, 0]}
    for name, num in seed.items():
        tf = tfs[name]
        np.testing.assert_allclose(tf.num, num, rtol=1e-4, atol=1e-9 * max(abs(c) for c in num))
        np.testing.assert_allclose(tf.den, [1, 0, -98.1, 0, 1176.2, 0, 0], rtol=1e-4, atol=1e-9)


def test_minimal_transfer_function_cancels_the_modes_a_pair_does_not_see() -> None:
    """v(a)/Vin of an RC–RL branch beside an RC branch driven by the same source: the printed form
    keeps the notes' characteristic polynomial (third order); the minimal one is the closed form
    (L s + R3) / (R1 C L s² + (R1 C R3 + L) s + R1 + R3), normalised to a monic denominator.
    Tolerance 1e-9 relative: the coefficients come from eigenvalues and zeros known to ~1e-14."""
    r1, c, ind, r3 = 1e3, 1e-6, 1e-3, 10.0
    model = compile_string(
        f"RC beside RLC\nVin in 0 1\nR1 in a {r1}\nC1 a 0 {c}\nR2 in b 2k\nC2 b 0 1u\n"
        f"L1 a m {ind}\nR3 m 0 {r3}\n.end\n",
        outputs=["v(a)"],
    )
    (tf,) = control.transfer_functions(model)
    assert len(tf.den) == 4 and tf.cancelled == 1
    minimal = tf.minimal()
    k = r1 * c * ind
    np.testing.assert_allclose(minimal.num, [ind / k, r3 / k], rtol=1e-9)
    np.testing.assert_allclose(minimal.den, [1.0, (r1 * c * r3 + ind) / k, (r1 + r3) / k], rtol=1e-9)
    runner = CliRunner()
    with runner.isolated_filesystem():
        Path("rc.cir").write_text(
            "twin RCs\nVin in 0 1\nR1 in a 1k\nC1 a 0 1u\nR2 in b 1k\nC2 b 0 1u\n.end\n"
        )
        result = runner.invoke(main, ["analyze", "rc.cir", "--control", "--output", "v(a)"])
    assert result.exit_code == 0, result.output
    assert "= (+1000) / (+1·s +1000)  (1 common factor(s) cancelled" in result.output
