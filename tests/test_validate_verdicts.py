"""validate's verdicts (issue #27): the original-file check of nonlinear netlists, a behavioural
constant ngspice cannot alter, outputs at ngspice's own tolerance, and "inconclusive" when
ngspice itself fails."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from netlistdyn.cli import main
from netlistdyn.io.report import validation_text
from netlistdyn.spice.ngspice import SpiceRun, SpiceSettings
from netlistdyn.spice.validate import error_scale

needs_ngspice = pytest.mark.skipif(shutil.which("ngspice") is None, reason="ngspice is not installed")
pytest.importorskip("PySpice")

#: A SIN without DC value into a diode: the operating point is the waveform's value at t = 0.
SIN_OFFSET = (
    "sin offset\n.param off=0.5\nVin 1 0 SIN({off} 0.5 120)\nR1 1 2 300\nR2 2 3 300\nD1 3 0 dmod\n"
    "C1 2 0 1u\n.model dmod D(IS=1e-14 CJO=1p)\n.tran 0.1m 20m\n.end\n"
)


def validate_json(path: Path, *args: str) -> tuple[int, dict]:
    result = CliRunner().invoke(main, ["validate", "--format", "json", "--no-pz", str(path), *args])
    return result.exit_code, json.loads(result.stdout) if result.stdout.strip() else {}


@needs_ngspice
def test_nonlinear_netlist_gets_the_original_op_and_ac_check(tmp_path: Path) -> None:
    """The op and .ac of the original file are compared for a nonlinear netlist too, and the check
    fails when the model reads the source's offset differently from ngspice (here through
    --model-param, which changes the model only)."""
    path = tmp_path / "sin.cir"
    path.write_text(SIN_OFFSET)
    code, doc = validate_json(path)
    assert code == 0, doc
    original = doc["original_file"]
    assert original["ran"] and original["passed"], original
    assert original["worst_rel_difference"] <= 1e-6
    code, doc = validate_json(path, "--model-param", "off=0.45")
    assert code == 3
    assert doc["original_file"]["ran"] and not doc["original_file"]["passed"], doc["original_file"]


@needs_ngspice
def test_original_check_of_a_diode_in_breakdown(tmp_path: Path) -> None:
    """ngspice at its default reltol matches the breakdown knee to IBV only to 1e-3 and converges its
    Newton to it: the check runs ngspice at reltol 1e-9 (was 3.4e-5: DISAGREES), each analysis in
    its own session (ngspice 39 applies a diode's m= again at each further analysis)."""
    path = tmp_path / "zener.cir"
    path.write_text(
        "m\n.model dd D(IS=1e-12 CJO=5p BV=8 IBV=1u)\nV1 in 0 SIN(-12 1 1k)\nR1 in a 1k\nD1 a 0 dd m=3\n"
        ".tran 1u 3m\n.end\n"
    )
    code, doc = validate_json(path)
    assert code == 0, doc
    original = doc["original_file"]
    assert original["ran"] and original["worst_rel_difference"] <= 1e-9, original


@needs_ngspice
def test_behavioural_constant_is_not_called_misread(tmp_path: Path) -> None:
    """``B1 b 0 v = {10 * 10}``: ngspice cannot alter its constant; the check keeps it (was "misreads")."""
    path = tmp_path / "b.cir"
    path.write_text(
        "b\nV1 in 0 1\nR1 in a 1k\nC1 a 0 1u\nB1 b 0 v = {10 * 10}\nR2 b a 1k\n.tran 1u 5m\n.end\n"
    )
    code, doc = validate_json(path)
    assert code == 0, doc
    original = doc["original_file"]
    assert original["ran"] and original["worst_rel_difference"] <= 1e-6, original


def test_small_output_is_judged_against_ngspice_vntol() -> None:
    """An output peaking at 4e-12 V that differs by 4e-13 V (below ngspice's vntol 1e-12 V) is
    judged against vntol; 4e-12 V off (above vntol) still fails against its peak."""
    settings = SpiceSettings(1e-6, 1e-3, vntol=1e-12, abstol=1e-15)
    scale, note = error_scale("v(out)", "v", 4e-12, 4e-12, 4e-13, settings, 1e-3)
    assert 4e-13 / scale <= 1e-3 and "vntol" in note
    scale, note = error_scale("v(out)", "v", 4e-12, 4e-12, 4e-12, settings, 1e-3)
    assert 4e-12 / scale > 1e-3 and note == ""
    scale, note = error_scale("i(V1)", "i", 1e-14, 1e-14, 5e-16, settings, 1e-3)
    assert 5e-16 / scale <= 1e-3 and "abstol" in note


def test_ngspice_failure_is_inconclusive_not_fail() -> None:
    settings = SpiceSettings(1e-6, 1e-3)
    run = SpiceRun(np.zeros(0), {}, 0.0, settings, ok=False, message="timestep too small", status="failed")

    class Report:
        netlist = "x.cir"
        horizon = type("H", (), {"tstop": 1e-3, "tstep": 1e-6, "source": ".tran"})()
        spice = run
        comparisons = ()
        poles = None
        notes = ("ngspice failed: timestep too small",)
        passed = False
        rtol = 1e-3
        model_seconds = 0.0

    text = validation_text(Report(), "x")
    assert "INCONCLUSIVE: ngspice failed on this file" in text
    assert "FAIL:" not in text
