"""ngspice cross-checks (issue 3). Skipped, with the reason, only where ngspice is absent.

ACCEPT_RTOL 1e-4 of peak is the issue's acceptance bar. Measured errors are
1e-9..4e-6 with the settings validate picks; the bar leaves room for the
spread between ngspice builds while staying 10x below ngspice's own default
accuracy (1e-3), so a modelling error of 0.1 % or more cannot pass.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from netlistdyn.cli import main
from netlistdyn.spice.ngspice import ngspice_missing

from .conftest import NETLISTS

ACCEPT_RTOL = 1e-4

needs_ngspice = pytest.mark.skipif(ngspice_missing() is not None, reason=str(ngspice_missing()))

CASES = [
    ("circuit1.cir", []),
    ("circuit1.cir", ["--param", "R1=100", "--param", "R2=100"]),
    ("circuit2.cir", []),
    ("circuit2.cir", ["--param", "R1=100", "--param", "R2=100"]),
    ("cap_loop.cir", ["--output", "v(a)", "--output", "i(C3)", "--output", "i(Vin)"]),
    ("parallel_caps.cir", []),
    ("series_inductors.cir", []),
    ("inductor_isource.cir", ["--output", "v(a)", "--output", "i(L1)"]),
    ("bridge.cir", ["--output", "v(b)", "--output", "i(R5)", "--output", "i(L2)"]),
    (
        "controlled.cir",
        [
            "--output",
            "v(b)",
            "--output",
            "v(d)",
            "--output",
            "v(g)",
            "--output",
            "v(h)",
            "--output",
            "i(E1)",
            "--output",
            "i(G1)",
            "--output",
            "i(F1)",
            "--output",
            "i(H1)",
        ],
    ),
    ("waveforms.cir", [f"--output=v(o{k})" for k in range(1, 6)] + ["--output", "i(C2)"]),
    ("two_blocks.cir", ["--output", "v(b1)", "--output", "x(b2)", "--output", "i(k2)"]),
    ("blocks_pendulum.cir", ["--output", "x(bob)", "--output", "angle(rod)"]),
    ("blocks_pendulum.cir", ["--param", "inv=1", "--tstop", "2"]),
    ("double_pendulum.cir", ["--output", "angle(r1)", "--output", "angle(r2)"]),
    ("dipc.cir", ["--output", "x(cart)", "--output", "angle(r1)", "--output", "angle(r2)"]),
    ("two_pendula_cart.cir", []),
    ("servo_shaft.cir", ["--output", "x(load)", "--output", "v(motor)", "--output", "i(L1)"]),
    ("servo_shaft.cir", ["--param", "K=50", "--output", "v(shaft)", "--output", "v(load)"]),
    ("gear_train.cir", ["--output", "v(load)", "--output", "i(L1)", "--output", "i(b)"]),
    ("balanced.cir", ["--output", "v(a)", "--output", "v(b,c)", "--output", "i(R2)"]),
    ("pendulum.cir", ["--output", "v(bob)", "--tstop", "1"]),
    ("oblique_blocks.cir", ["--output", "v(b1)", "--output", "v(b2)", "--tstop", "0.3"]),
    ("blocks_pendulum_geometry.cir", ["--output", "x(bob)", "--tstop", "2"]),
    ("double_pendulum_geometry.cir", ["--output", "v(b2)", "--tstop", "1"]),
    ("rectifier.cir", ["--output", "v(out)"]),
    ("clipper.cir", ["--output", "v(out)"]),
    ("nonlinear_rc.cir", ["--output", "v(a)", "--output", "v(c)"]),
    ("diode_ladder.cir", ["--output", "v(n4)"]),
]


def run_json(args: list[str]) -> tuple[int, dict]:
    result = CliRunner().invoke(main, ["validate", "--format", "json", *args])
    doc = json.loads(result.stdout) if result.stdout.strip() else {}
    return result.exit_code, doc


def test_every_netlist_is_covered() -> None:
    covered = {name for name, _ in CASES}
    assert covered == {p.name for p in NETLISTS.glob("*.cir")}


@needs_ngspice
@pytest.mark.parametrize(("name", "args"), CASES, ids=[f"{n}{' '.join(a)[:30]}" for n, a in CASES])
def test_netlist_validates(name: str, args: list[str]) -> None:
    code, doc = run_json([str(NETLISTS / name), *args])
    assert code == 0, doc
    assert doc["passed"] and doc["ngspice"]["ok"]
    assert "reltol" in doc["ngspice"]["settings"]  # the report says which settings were used
    for output in doc["comparisons"]:
        assert output["max_rel_error"] < ACCEPT_RTOL, output


@needs_ngspice
def test_stiff_circuit1_eigenvalues_and_poles() -> None:
    """Circuit 1 case 1 (eigenvalues -2000 and -0.0005): ngspice's .pz agrees to 1e-9."""
    code, doc = run_json([str(NETLISTS / "circuit1.cir")])
    assert code == 0
    assert doc["poles"]["max_rel_difference"] < 1e-9
    assert "method=gear" in doc["ngspice"]["settings"]


@needs_ngspice
@pytest.mark.parametrize("perturbation", ["R1=1.01m", "C1=0.99"])
def test_perturbed_model_is_a_mismatch(perturbation: str) -> None:
    """One element 1 % off in the model only: validate must fail with exit 3."""
    result = CliRunner().invoke(
        main, ["validate", str(NETLISTS / "circuit1.cir"), "--model-param", perturbation, "--no-pz"]
    )
    assert result.exit_code == 3, result.stdout
    assert "MISMATCH" in result.stdout and "FAIL" in result.stdout


@needs_ngspice
def test_plot_is_written(tmp_path: Path) -> None:
    target = tmp_path / "v.png"
    result = CliRunner().invoke(
        main, ["validate", str(NETLISTS / "parallel_caps.cir"), "--plot", str(target), "--no-pz"]
    )
    assert result.exit_code == 0
    assert target.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@needs_ngspice
def test_horizon_from_eigenvalues_when_no_tran(tmp_path: Path) -> None:
    path = tmp_path / "rc.cir"
    path.write_text("rc\nV1 a 0 1\nR1 a b 1k\nC1 b 0 1u\n")
    code, doc = run_json([str(path), "--no-pz"])
    assert code == 0
    # Slowest time constant 1 ms: five of them.
    assert doc["horizon"]["tstop"] == pytest.approx(5e-3, rel=1e-9)
    assert "eigenvalues" in doc["horizon"]["source"]


def test_missing_ngspice_says_how_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    import netlistdyn.spice.ngspice as spice

    monkeypatch.setattr(spice, "ngspice_missing", lambda: spice.INSTALL_HINT)
    result = CliRunner().invoke(main, ["validate", str(NETLISTS / "circuit1.cir")])
    assert result.exit_code == 4
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "apt-get install -y ngspice libngspice0-dev" in lines[0]


def test_analyze_works_without_pyspice() -> None:
    """analyze never imports PySpice: block the import and run it."""
    code = (
        "import sys; sys.modules['PySpice'] = None\n"
        "from netlistdyn.cli import main\n"
        f"main(['analyze', {str(NETLISTS / 'circuit1.cir')!r}, '--format', 'json'])\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["states"] == ["q(C1)", "i(L1)"]


@needs_ngspice
def test_ngspice_failure_is_reported_not_raised() -> None:
    """A stimulus ngspice cannot follow at these settings is a failed run with a message."""
    from netlistdyn.circuit.probes import default_probes
    from netlistdyn.frontend.parser import parse_file
    from netlistdyn.spice.ngspice import SpiceSettings, run_transient

    net = parse_file(NETLISTS / "circuit1.cir")
    run = run_transient(net, default_probes(net), SpiceSettings(1e-3, 10.0, 1e-3), timeout=1e-9)
    assert not run.ok and "did not finish" in run.message
    assert np.asarray(run.time).size == 0
