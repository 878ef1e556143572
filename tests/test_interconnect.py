"""Series and feedback interconnection (issue 6) against seed 003's block formulas
and against transfer-function algebra (G2·G1 and G1(I − s·G2 G1)⁻¹), rtol 1e-10."""

from __future__ import annotations

import numpy as np
import pytest

from netlistdyn.base.errors import ControlDimension
from netlistdyn.statespace.interconnect import feedback, series

from .conftest import compile_file, compile_string

PLANT = "plant\nV1 in 0 1\nR1 in a 10\nC1 a 0 1m\nL1 a 0 1\n"
SENSOR = "sensor\nV1 in 0 1\nR1 in a 1k\nC1 a 0 10u\nR2 a 0 1k\n"


def models():
    return compile_string(PLANT, ["v(a)"]), compile_string(SENSOR, ["v(a)"])


def test_series_block_formula_and_transfer_function() -> None:
    m1, m2 = models()
    s = series(m1, m2)
    expected = np.block([[m1.A, np.zeros((2, 1))], [m2.B @ m1.C, m2.A]])
    np.testing.assert_allclose(s.A, expected, rtol=1e-14)
    assert s.states == ("m1.q(C1)", "m1.i(L1)", "m2.q(C1)")
    for z in (3j, 50.0 + 20j):
        np.testing.assert_allclose(
            s.transfer_function(z), m2.transfer_function(z) @ m1.transfer_function(z), rtol=1e-10
        )


def test_feedback_block_formula_and_transfer_function() -> None:
    m1, m2 = models()
    f = feedback(m1, m2)
    expected = np.block([[m1.A, -m1.B @ m2.C], [m2.B @ m1.C, m2.A]])  # seed 003, D1 = D2 = 0
    np.testing.assert_allclose(f.A, expected, rtol=1e-14)
    for z in (3j, 50.0 + 20j):
        g1, g2 = m1.transfer_function(z), m2.transfer_function(z)
        closed = g1 @ np.linalg.inv(np.eye(1) + g2 @ g1)
        np.testing.assert_allclose(f.transfer_function(z), closed, rtol=1e-10)


def test_feedback_with_feedthrough() -> None:
    m1 = compile_string("d\nV1 in 0 1\nR1 in a 1\nR2 a 0 1\nC1 a 0 1\n", ["v(a)", "v(in)"])
    m2 = compile_string("k\nV1 in 0 1\nV2 in2 0 1\nR1 in a 1\nR2 in2 a 1\nC1 a 0 1\n", ["v(in)"])
    f = feedback(m1, m2, sign=-1.0)
    for z in (1j, 2.0):
        g1, g2 = m1.transfer_function(z), m2.transfer_function(z)
        np.testing.assert_allclose(
            f.transfer_function(z), g1 @ np.linalg.inv(np.eye(1) + g2 @ g1), rtol=1e-10
        )


def test_dimension_mismatch_says_expected_and_actual() -> None:
    m1 = compile_file("circuit2.cir")  # 4 outputs
    m2 = compile_string(SENSOR, ["v(a)"])  # 1 input
    with pytest.raises(ControlDimension, match=r"4 outputs.*expects 1 inputs"):
        series(m1, m2)
    assert issubclass(ControlDimension, ValueError)


def _write(tmp_path, name: str, text: str):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def test_connect_cli_series_and_feedback_match_the_api(tmp_path) -> None:
    """The CLI builds the same matrices as the API (rtol 1e-14: identical arithmetic), names the
    signals, and reads saved models as well as netlists."""
    import json

    from click.testing import CliRunner

    from netlistdyn.cli import main
    from netlistdyn.io.exports import save_model

    plant = _write(tmp_path, "plant.cir", PLANT)
    sensor = _write(tmp_path, "sensor.cir", SENSOR)
    m1, m2 = models()
    saved = str(tmp_path / "sensor.npz")
    save_model(m2, saved)
    runner = CliRunner()
    args = ["--output1", "v(a)", "--format", "json"]
    for how, expected in (("series", series(m1, m2, ("plant", "sensor"))), ("feedback", feedback(m1, m2))):
        result = runner.invoke(main, ["connect", how, plant, saved, *args])
        assert result.exit_code == 0, result.output
        doc = json.loads(result.stdout)
        np.testing.assert_allclose(np.array(doc["A"]), expected.A, rtol=1e-14)
        assert doc["states"] == ["plant.q(C1)", "plant.i(L1)", "sensor.q(C1)"]
        assert doc["connections"][0] == "plant.v(a) -> sensor.V1"
    assert doc["inputs"] == ["plant.V1"] and doc["outputs"] == ["plant.v(a)"]
    assert doc["connections"][1].startswith("sensor.v(a) -> plant.V1 (sign -")

    mismatch = runner.invoke(main, ["connect", "series", plant, sensor])  # plant has 2 outputs
    assert mismatch.exit_code == 2
    assert (
        mismatch.output.strip() == "netlistdyn: error: series: plant has 2 outputs, sensor expects 1 inputs"
    )
    misuse = runner.invoke(main, ["connect", "series", plant, saved, "--output2", "v(a)"])
    assert misuse.exit_code == 2 and "saved model" in misuse.output
