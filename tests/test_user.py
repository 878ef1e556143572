"""The everyday edges of issue #16: ``python -m``, the Python API, reprs, options, schemas."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from .conftest import NETLISTS, ROOT


def _python_m(*args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run(
        [sys.executable, "-m", *args], capture_output=True, text=True, env=env, timeout=120, check=False
    )


def test_python_m_netlistdyn_runs_the_cli() -> None:
    done = _python_m("netlistdyn", "analyze", str(NETLISTS / "circuit1.cir"), "--eig", "none")
    assert done.returncode == 0, done.stderr
    assert "q(C1)" in done.stdout


def test_python_m_cli_knows_every_command(tmp_path: Path) -> None:
    done = _python_m("netlistdyn.cli", "connect", "--help")
    assert done.returncode == 0, done.stderr
    assert "series" in done.stdout


# --- the Python API -----------------------------------------------------------------------

import io  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from click.testing import CliRunner  # noqa: E402

import netlistdyn  # noqa: E402
from netlistdyn.base.formatting import eng  # noqa: E402
from netlistdyn.cli import main  # noqa: E402
from netlistdyn.devices.units import signal_units  # noqa: E402

CIRCUIT1 = NETLISTS / "circuit1.cir"
#: Two compiles of the same netlist run the same operations: they agree to rounding.
SAME_RTOL = 1e-14


def test_compile_accepts_path_text_and_file_objects() -> None:
    text = CIRCUIT1.read_text()
    by_path = netlistdyn.compile(CIRCUIT1)
    for source in (str(CIRCUIT1), text, io.StringIO(text)):
        model = netlistdyn.compile(source)
        assert model.states == by_path.states
        np.testing.assert_allclose(model.A, by_path.A, rtol=SAME_RTOL, atol=0)


def test_params_accept_spice_numbers_with_the_users_spelling() -> None:
    as_text = netlistdyn.compile(CIRCUIT1, params={"R1": "10u", "r2": "2.2k"})
    as_float = netlistdyn.compile(CIRCUIT1, params={"R1": 1e-5, "r2": 2200.0})
    np.testing.assert_allclose(as_text.A, as_float.A, rtol=SAME_RTOL, atol=0)
    # A[q, q] = -(1/R1 + 1/R2)/C1 with C1 = 1 F: the override reached the model.
    assert as_text.A[0, 0] == pytest.approx(-(1 / 1e-5 + 1 / 2200.0), rel=1e-12)


@pytest.mark.parametrize(
    ("kwargs", "expected"),
    [
        ({"params": {"R9": 1}}, "params['R9']"),
        ({"params": {"R1": "ten"}}, "params['R1']: 'ten' is not a number"),
        ({"params": {"R1": [1]}}, "params['R1']: expected a number"),
        ({"outputs": ["v(zz)"]}, "outputs v(zz): no node 'zz'"),
    ],
)
def test_api_errors_name_arguments_not_flags(kwargs: dict, expected: str) -> None:
    with pytest.raises(netlistdyn.UsageError) as info:
        netlistdyn.compile(CIRCUIT1, **kwargs)
    assert expected in str(info.value)
    assert "--" not in str(info.value)


def test_api_simulate_returns_a_typed_result_equal_to_the_cli(tmp_path: Path) -> None:
    sim = netlistdyn.simulate(CIRCUIT1, params={"R1": "100", "R2": "100"}, tstop="20m", tstep="1m")
    assert isinstance(sim, netlistdyn.Simulation) and sim.ok
    assert sim.outputs == ("v(in)", "v(a)") and sim.units == ("V", "V")
    assert sim.values.shape == (21, 2) and sim.time[-1] == pytest.approx(0.02, rel=1e-15)
    with pytest.raises(AttributeError):
        sim.method = "x"  # type: ignore[misc]  # frozen
    result = CliRunner().invoke(
        main,
        [
            *("simulate", str(CIRCUIT1), "--param", "R1=100", "--param", "R2=100"),
            *("--tstop", "20m", "--tstep", "1m", "--format", "json"),
        ],
    )
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    # The same pipeline: identical samples, not merely close ones.
    np.testing.assert_array_equal(np.array(doc["values"]["v(a)"]), sim["v(a)"])
    # Circuit 1, R1 = R2 = 100, C1 = L1 = 1: v(a) = Vin·(1/R1)·s/(s² + (2/R)s + 1) — check the
    # step response in closed form: v(a)(t) = (1/(R1·ωd))·e^{-t/R}·sin(ωd t), ωd = sqrt(1 - 1/R²).
    wd = math.sqrt(1 - 1e-4)
    exact = np.exp(-sim.time / 100) * np.sin(wd * sim.time) / (100 * wd)
    np.testing.assert_allclose(sim["v(a)"], exact, rtol=0, atol=1e-12)


def test_api_simulate_raises_on_a_refused_method() -> None:
    with pytest.raises(netlistdyn.SimulationError, match="RK45 refused"):
        netlistdyn.simulate(CIRCUIT1, params={"R1": "1n", "R2": "1n"}, method="RK45", tstop="10")


def test_api_sweep_keeps_spelling_and_tracks_modes() -> None:
    result = netlistdyn.sweep(CIRCUIT1, {"R1": "log:10:1k:9", "R2": [1e6] * 9})
    assert [tuple(c.params) for c in result.cases] == [("R1", "R2")] * 9
    tracks = np.array([c.eigenvalues for c in result.cases])
    # Tracked: each column moves continuously (no jump to the other mode between cases).
    steps = np.abs(np.diff(tracks, axis=0))
    spread = np.abs(tracks[:, 0] - tracks[:, 1])
    assert np.all(steps <= spread[1:, None] + spread[:-1, None])
    assert "R1" in repr(result)


def test_track_follows_crossing_modes() -> None:
    from netlistdyn.workflows.sweep import track

    first = track(None, [[-1.0, 0.0], [-5.0, 0.0]])
    assert first == [[-1.0, 0.0], [-5.0, 0.0]]
    # The modes pass each other: sorting would swap the columns, tracking must not.
    assert track(first, [[-4.5, 0.0], [-1.5, 0.0]]) == [[-1.5, 0.0], [-4.5, 0.0]]


# --- reprs ----------------------------------------------------------------------------------


def test_model_repr_is_labelled_and_has_no_sparse_dump() -> None:
    model = netlistdyn.compile(CIRCUIT1)
    text = repr(model)
    assert "sparse" not in text.lower() and "csr" not in text.lower()
    assert "2 states, 1 input, 2 outputs" in text and "q(C1)" in text and "A =" in text
    html = model._repr_html_()
    assert html.startswith("<p><b>StateSpaceModel</b>") and "<table>" in html and "q(C1)" in html
    latex = model._repr_latex_()
    assert latex.startswith("$$") and r"\dot{x}" in latex and r"\text{q(C1)}" in latex


def test_large_model_repr_gives_sizes_not_entries(tmp_path: Path) -> None:
    lines = ["ladder", "V1 n0 0 1"]
    for k in range(20):
        lines += [f"R{k} n{k} m{k} 1", f"L{k} m{k} n{k + 1} 1m", f"C{k} n{k + 1} 0 1u"]
    model = netlistdyn.compile("\n".join(lines) + "\n")
    assert "40x40" in repr(model) and "non-zeros" in model._repr_html_()
    assert model._repr_latex_() is None  # Jupyter falls back to the HTML


def test_eigen_and_simulation_reprs() -> None:
    model = netlistdyn.compile(CIRCUIT1, params={"R1": 100, "R2": 100})
    analysis = netlistdyn.eigenvalues(model)
    text = repr(analysis)
    assert "asymptotically stable" in text and "rad/s" in text and "Hz" in text
    # ωn = 1 rad/s for C1 = L1 = 1: fn = 1/(2π) Hz = 159.2 mHz.
    assert "159.2 mHz" in text
    assert "<table>" in analysis._repr_html_() and r"\lambda(A)" in analysis._repr_latex_()
    sim = netlistdyn.simulate(CIRCUIT1, tstop="20m")
    assert "0..20 ms" in repr(sim) and "v(a)" in sim._repr_html_()


# --- engineering notation -------------------------------------------------------------


@pytest.mark.parametrize(
    ("value", "unit", "text"),
    [
        (1e-5, "H", "10 µH"),
        (0.00025, "s", "250 µs"),
        (2200.0, "", "2.2k"),
        (999.96, "V", "1 kV"),
        (0.0, "s", "0 s"),
        (-4.7e-12, "F", "-4.7 pF"),
        (1e20, "Hz", "1e+20 Hz"),
    ],
)
def test_engineering_notation(value: float, unit: str, text: str) -> None:
    assert eng(value, unit) == text


def test_signal_units_tell_circuits_from_mechanics() -> None:
    from netlistdyn.frontend.parser import parse_file

    circuit = parse_file(CIRCUIT1)
    assert signal_units(circuit, ["v(a)", "i(L1)", "v(in,a)"]) == ("V", "A", "V")
    blocks = parse_file(NETLISTS / "two_blocks.cir")
    node = next(e.nodes[0] for e in blocks.elements if e.keyword == "MASS")
    assert signal_units(blocks, [f"v({node})", f"x({node})"]) == ("m/s", "m")


# --- numeric options ----------------------------------------------------------------------


def test_every_numeric_option_takes_spice_numbers() -> None:
    runner = CliRunner()
    plain = runner.invoke(
        main,
        [
            "simulate",
            str(CIRCUIT1),
            "--tstop",
            "0.02",
            "--tstep",
            "1e-3",
            "--rtol",
            "1e-9",
            "--format",
            "json",
        ],
    )
    spice = runner.invoke(
        main,
        ["simulate", str(CIRCUIT1), "--tstop", "20m", "--tstep", "1m", "--rtol", "1n", "--format", "json"],
    )
    assert plain.exit_code == 0 and spice.exit_code == 0, spice.output
    assert json.loads(plain.stdout)["values"] == json.loads(spice.stdout)["values"]
    swept = runner.invoke(
        main, ["sweep", str(CIRCUIT1), "--param", "R1=1,2", "--jobs", "1", "--format", "json"]
    )
    assert swept.exit_code == 0, swept.output


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["--tstop", "twenty"], "'twenty' is not a number"),
        (["--tstop", "-1m"], "must be positive"),
        (["--tstop", "1m", "--tstep", "2m"], "longer than the horizon"),
        (["--tstep", "1k"], "longer than the horizon"),
    ],
)
def test_bad_numbers_and_tstep_beyond_tstop_are_refused(args: list[str], fragment: str) -> None:
    result = CliRunner().invoke(main, ["simulate", str(CIRCUIT1), *args])
    assert result.exit_code == 2
    assert fragment in result.output
    assert "Traceback" not in result.output


# --- optional dependencies ----------------------------------------------------------------


def test_symbolic_without_sympy_says_how_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "sympy", None)
    monkeypatch.delitem(sys.modules, "netlistdyn.formulation.symbolic", raising=False)
    result = CliRunner().invoke(main, ["analyze", str(CIRCUIT1), "--symbolic"])
    assert result.exit_code == 2, result.output
    assert "pip install 'netlistdyn[symbolic]'" in result.output and "Traceback" not in result.output
    # Everything else works without sympy.
    assert CliRunner().invoke(main, ["analyze", str(CIRCUIT1)]).exit_code == 0


def test_to_control_without_python_control_says_how_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "control", None)
    with pytest.raises(ImportError, match="pip install"):
        netlistdyn.compile(CIRCUIT1).to_control()


# --- JSON schemas -------------------------------------------------------------------------

SCHEMAS = ROOT / "netlistdyn" / "schemas"


def _check(document: object, schema_name: str) -> None:
    jsonschema = pytest.importorskip("jsonschema")
    schema = json.loads((SCHEMAS / f"{schema_name}.json").read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    jsonschema.Draft202012Validator(schema).validate(document)


def _json_of(args: list[str]) -> dict:
    result = CliRunner().invoke(main, [*args, "--format", "json"])
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


@pytest.mark.parametrize(
    ("schema", "args"),
    [
        ("analyze", ["analyze", str(CIRCUIT1), "--control", "--canonical", "--symbolic"]),
        ("analyze", ["analyze", str(NETLISTS / "cap_loop.cir"), "--eig", "none"]),
        ("simulate", ["simulate", str(CIRCUIT1), "--tstop", "1m"]),
        ("sweep", ["sweep", str(CIRCUIT1), "--param", "R1=0,1,100"]),
        ("bench", ["bench", str(CIRCUIT1), "--no-ngspice", "--method", "exact", "--repeats", "1"]),
        (
            "connect",
            ["connect", "series", str(CIRCUIT1), str(CIRCUIT1), "--output1", "v(a)"],
        ),
    ],
)
def test_json_output_matches_its_schema(schema: str, args: list[str]) -> None:
    _check(_json_of(args), schema)


def test_validate_json_matches_its_schema() -> None:
    from netlistdyn.spice.ngspice import ngspice_missing

    if ngspice_missing():
        pytest.skip("ngspice is not installed")
    doc = _json_of(["validate", str(CIRCUIT1), "--tstop", "1", "--no-pz"])
    _check(doc, "validate")
    assert doc["outputs"] == [c["name"] for c in doc["comparisons"]]


def test_outputs_are_names_in_every_command() -> None:
    """analyze, simulate and validate (checked above) agree: ``outputs`` lists names, as the API does."""
    analyzed = _json_of(["analyze", str(CIRCUIT1), "--eig", "none"])
    simulated = _json_of(["simulate", str(CIRCUIT1), "--tstop", "1m"])
    model = netlistdyn.compile(CIRCUIT1)
    assert analyzed["outputs"] == simulated["outputs"] == list(model.outputs)
    assert list(simulated["values"]) == simulated["outputs"]


def test_every_command_has_a_schema() -> None:
    commands = set(main.commands)
    assert {p.stem for p in SCHEMAS.glob("*.json")} >= commands


def test_jsonl_lines_match_the_case_schema(tmp_path: Path) -> None:
    target = tmp_path / "cases.jsonl"
    result = CliRunner().invoke(
        main, ["sweep", str(CIRCUIT1), "--param", "R1=0,1,100", "--format", "jsonl", "-o", str(target)]
    )
    assert result.exit_code == 0, result.output
    lines = target.read_text().splitlines()
    assert len(lines) == 3
    for k, line in enumerate(lines):
        record = json.loads(line)
        _check(record, "sweep-case")
        assert record["index"] == k
    assert "error" in json.loads(lines[0])  # R1 = 0 is refused, the others still run


def test_stopped_jsonl_sweep_keeps_finished_cases(tmp_path: Path) -> None:
    """SIGTERM half way: every line written so far is a complete case."""
    import signal
    import time

    target = tmp_path / "cases.jsonl"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    # 40 states: each case costs tens of milliseconds, the sweep about ten seconds.
    lines = ["ladder", "V1 n0 0 PULSE(0 1 0 1u 1u 1 2)", ".param r=1"]
    for k in range(20):
        lines += [f"R{k} n{k} m{k} {{r}}", f"L{k} m{k} n{k + 1} 1m", f"C{k} n{k + 1} 0 1u"]
    netlist = tmp_path / "ladder.cir"
    netlist.write_text("\n".join(lines) + "\n")
    process = subprocess.Popen(
        [
            *(sys.executable, "-m", "netlistdyn", "sweep", str(netlist), "--param", "r=lin:1:100:2000"),
            *("--eig", "all", "--format", "jsonl", "-o", str(target)),
        ],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    deadline = time.monotonic() + 240  # generous: a loaded CI machine starts Python slowly
    while time.monotonic() < deadline:
        if target.exists() and target.read_text().count("\n") >= 3:
            break
        time.sleep(0.05)
    process.send_signal(signal.SIGTERM)
    process.wait(timeout=30)
    assert process.returncode != 0, "the sweep finished before it could be stopped"
    text = target.read_text()
    assert text.endswith("\n")
    records = [json.loads(line) for line in text.splitlines()]
    assert 3 <= len(records) < 2000
    assert [r["index"] for r in records] == list(range(len(records)))
    assert all(len(r["eigenvalues"]) == 40 for r in records)


def test_progress_is_silent_when_not_a_terminal(tmp_path: Path) -> None:
    done = _python_m("netlistdyn", "simulate", str(CIRCUIT1), "--tstop", "1m")
    assert done.returncode == 0 and done.stderr == ""
    done = _python_m("netlistdyn", "sweep", str(CIRCUIT1), "--param", "R1=1,2")
    assert done.returncode == 0 and done.stderr == ""


def test_progress_on_a_terminal_ends_its_line(monkeypatch: pytest.MonkeyPatch) -> None:
    from netlistdyn.base import progress

    stream = io.StringIO()
    monkeypatch.setattr(sys, "stderr", stream)
    monkeypatch.setattr(stream, "isatty", lambda: True, raising=False)
    with progress.bar("simulate", 100, unit="%") as handle:
        progress.fraction_callback(handle)(1.0)
    assert "simulate" in stream.getvalue() and stream.getvalue().endswith("\n")
    stream2 = io.StringIO()
    monkeypatch.setattr(sys, "stderr", stream2)
    monkeypatch.setattr(stream2, "isatty", lambda: True, raising=False)
    with progress.bar("simulate", 100, quiet=True) as handle:
        handle.update(100)
    assert stream2.getvalue() == ""


def test_zero_state_model_with_an_exp_source_is_not_stepped(tmp_path: Path) -> None:
    """A resistor on an EXP source has no state: its output is the source itself, exactly,
    without stepping through the 1e-9 linear pieces of the EXP (which took 18 s)."""
    netlist = tmp_path / "rexp.cir"
    netlist.write_text("one resistor\nV1 a 0 EXP(0 1 1m 1m 5m 2m)\nR1 a 0 1k\n.tran 1u 10m\n")
    sim = netlistdyn.simulate(netlist)
    t = sim.time
    rise = 1 - np.exp(-np.clip(t - 1e-3, 0, None) / 1e-3)
    fall = 1 - np.exp(-np.clip(t - 5e-3, 0, None) / 2e-3)
    np.testing.assert_allclose(sim["v(a)"], rise - fall, rtol=0, atol=1e-15)


def test_plots_use_the_extensions_format_and_the_ac_range(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    netlist = tmp_path / "rc.cir"
    netlist.write_text("rc\nV1 in 0 AC 1\nR1 in a 1k\nC1 a 0 1u\n.ac dec 10 10 100k\n")
    from netlistdyn.frontend.parser import parse_file
    from netlistdyn.io.plots import ac_range

    assert ac_range(parse_file(netlist)) == (10.0, 100e3)
    for suffix, magic in ((".png", b"\x89PNG"), (".svg", b"<?xml"), (".pdf", b"%PDF")):
        target = tmp_path / f"bode{suffix}"
        result = CliRunner().invoke(main, ["analyze", str(netlist), "--bode", str(target)])
        assert result.exit_code == 0, result.output
        assert target.read_bytes().startswith(magic)
    bad = CliRunner().invoke(main, ["analyze", str(netlist), "--bode", str(tmp_path / "bode.xyz")])
    assert bad.exit_code == 2 and "cannot write a .xyz figure" in bad.output
    assert not (tmp_path / "bode.xyz").exists()


def test_electrical_plots_are_not_labelled_with_mechanical_units(monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("matplotlib")
    from netlistdyn.io import plots

    figures = []
    monkeypatch.setattr(plots, "save_figure", lambda fig, path: figures.append(fig))
    plots.simulation_plot(netlistdyn.simulate(CIRCUIT1, tstop="1m"), "unused.png")
    plots.simulation_plot(netlistdyn.simulate(NETLISTS / "two_blocks.cir", tstop="1"), "unused.png")
    (electrical,), (mechanical,) = (fig.axes for fig in figures)
    for ax in (electrical, mechanical):
        ax.figure.canvas.draw()
    ticks = [[t.get_text() for t in ax.get_yticklabels()] for ax in (electrical, mechanical)]
    assert any(t.endswith(" V") for t in ticks[0]) and not any("m/s" in t for t in ticks[0])
    assert any(t.endswith("m/s") for t in ticks[1])
    assert [t.get_text() for t in electrical.get_xticklabels()][-1].endswith("s")


def test_top_level_functions_survive_imports_of_the_stages() -> None:
    """Importing a stage binds only its sub-package on ``netlistdyn``: no stage shadows an API function."""
    import importlib

    for stage in ("simulation.foh", "workflows.sweep", "spice.validate", "formulation.symbolic"):
        importlib.import_module(f"netlistdyn.{stage}")
    for name in ("compile", "simulate", "sweep", "validate", "symbolic", "eigenvalues"):
        assert callable(getattr(netlistdyn, name)), name


# --- validate's reference settings ------------------------------------------------------------


def test_reference_settings_and_their_accuracy_bound() -> None:
    from netlistdyn.spice.ngspice import SpiceSettings
    from netlistdyn.workflows.pipelines import reference_accuracy, reference_settings

    base = SpiceSettings(tstep=1e-6, tstop=1.0, tmax=1e-4, reltol=1e-9)
    chosen = reference_settings(base, {"reltol": 1e-6, "maxstep": 1e-7})
    assert (chosen.reltol, chosen.tmax, chosen.tstep) == (1e-6, 1e-7, 1e-7)
    # Circuit 1 with R = 100: λ = -0.01 ± 0.99995j, |λ| = 1 rad/s, lasting 5/0.01 = 500 s > 1 s.
    analysis = netlistdyn.eigenvalues(netlistdyn.compile(CIRCUIT1, params={"R1": 100, "R2": 100}))
    bound = reference_accuracy(base, analysis, 1.0)
    assert bound == pytest.approx((1e-4) ** 2 * 1.0 / 12, rel=1e-6)
    # Halving the step quarters the bound (second order).
    assert reference_accuracy(reference_settings(base, {"maxstep": 5e-5}), analysis, 1.0) == pytest.approx(
        bound / 4, rel=1e-9
    )
    real_only = netlistdyn.eigenvalues(netlistdyn.compile(CIRCUIT1))
    assert reference_accuracy(base, real_only, 1.0) == 0.0


def test_validate_takes_the_users_reference_settings() -> None:
    from netlistdyn.spice.ngspice import ngspice_missing

    if ngspice_missing():
        pytest.skip("ngspice is not installed")
    doc = _json_of(
        [
            *("validate", str(CIRCUIT1), "--param", "R1=100", "--param", "R2=100", "--tstop", "2"),
            *("--no-pz", "--ngspice-reltol", "1u", "--ngspice-maxstep", "1m"),
        ]
    )
    assert "reltol=1e-06" in doc["ngspice"]["settings"] and " 0 0.001 uic" in doc["ngspice"]["settings"]
    assert doc["ngspice"]["phase_error_bound"] == pytest.approx((1e-3) ** 2 * 2.0 / 12, rel=1e-3)
    assert any("reference accuracy" in note for note in doc["notes"])


def test_state_units_come_from_the_netlist() -> None:
    """A velocity-like state v(...) is in V on a circuit and in m/s on a mechanical node."""
    electrical = CliRunner().invoke(
        main, ["analyze", str(CIRCUIT1), "--coordinates", "v(a),i(L1)", "--eig", "none"]
    )
    assert electrical.exit_code == 0, electrical.output
    assert "v(a) [V], i(L1) [A]" in electrical.stdout
    mechanical = CliRunner().invoke(
        main, ["analyze", str(NETLISTS / "two_blocks.cir"), "--coordinates", "x(b1),x(b2),v(b1),v(b2)"]
    )
    assert mechanical.exit_code == 0, mechanical.output
    assert "v(b1) [m/s]" in mechanical.stdout and "x(b1) [m]" in mechanical.stdout


# --- API edges a user meets first ---------------------------------------------------------------


def test_one_output_given_as_a_string_is_one_output() -> None:
    """``outputs="v(a,b)"`` is one differential voltage, not five one-character outputs."""
    as_string = netlistdyn.compile(CIRCUIT1, outputs="v(a)")
    as_list = netlistdyn.compile(CIRCUIT1, outputs=["v(a)"])
    assert as_string.outputs == as_list.outputs == ("v(a)",)
    np.testing.assert_array_equal(as_string.C, as_list.C)
    sim = netlistdyn.simulate(CIRCUIT1, tstop="1m", outputs="i(L1)")
    assert sim.outputs == ("i(L1)",)


def test_transfer_function_over_an_array_of_frequencies() -> None:
    """Circuit 1 (R1, C1 into L1): an array of s gives python-control's (noutputs, ninputs, k) shape,
    and each entry equals the scalar evaluation and the closed form of the notes' G(s)."""
    from netlistdyn.workflows.pipelines import read_netlist

    model = netlistdyn.compile(CIRCUIT1, outputs=["i(L1)"])
    s = np.array([0.5j, 10.0 + 3.0j, 2e3j])
    values = model.transfer_function(s)
    assert values.shape == (1, 1, 3)
    for k, z in enumerate(s):
        np.testing.assert_allclose(values[:, :, k], model.transfer_function(z), rtol=SAME_RTOL)
    # KCL at a: (Vin − Va)/R1 = (Cs + 1/R2 + 1/(Ls)) Va and I = Va/(Ls), so
    # I(s)/Vin(s) = 1 / (L C R1 s² + L (1 + R1/R2) s + R1)
    elements = {e.name: e.value for e in read_netlist(CIRCUIT1).elements}
    R1, R2, C, L = elements["R1"], elements["R2"], elements["C1"], elements["L1"]
    closed = 1 / (L * C * R1 * s**2 + L * (1 + R1 / R2) * s + R1)
    # conditioning of the 2x2 solve: |s|·max(A) / |det| stays below 1e6, so 1e-9 covers rounding
    np.testing.assert_allclose(values[0, 0], closed, rtol=1e-9)
    response = model.frequency_response([1.0, 100.0])
    assert response.response.shape == (1, 1, 2)
    np.testing.assert_allclose(
        response("i(L1)", "Vin"), model.transfer_function(1j * np.array([1.0, 100.0]))[0, 0]
    )
    np.testing.assert_allclose(response.frequency_hz, np.array([1.0, 100.0]) / (2 * np.pi))
    with pytest.raises(ValueError, match="1-D"):
        model.transfer_function(np.ones((2, 2)))


def test_csv_on_stdout_is_the_csv_alone() -> None:
    """``--csv -`` feeds a pipe: stdout parses as CSV alone (the summary goes to stderr)."""
    import csv as csv_module
    import subprocess
    import sys

    done = subprocess.run(
        [sys.executable, "-m", "netlistdyn", "simulate", str(CIRCUIT1), "--tstop", "1m", "--csv", "-", "-q"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    rows = list(csv_module.reader(io.StringIO(done.stdout)))
    assert rows[0][0].startswith("time")
    assert len(rows) > 2 and all(len(row) == len(rows[0]) for row in rows)
    [float(cell) for row in rows[1:] for cell in row]  # every line after the header is numbers
    assert "simulated" in done.stderr
    json_too = CliRunner().invoke(main, ["simulate", str(CIRCUIT1), "--csv", "-", "--format", "json"])
    assert json_too.exit_code != 0 and "standard output" in json_too.output


@pytest.mark.parametrize("typo", ["1x", "1kk", "20mX", "1e-3e"])
def test_command_line_numbers_refuse_trailing_garbage(typo: str) -> None:
    """A command-line number is a number, a scale factor and at most a unit: ``--tstop 1x`` is a typo,
    refused in one line (a netlist field would ignore the letters, as ngspice does)."""
    result = CliRunner().invoke(main, ["simulate", str(CIRCUIT1), "--tstop", typo])
    assert result.exit_code != 0
    assert "is not a number" in result.output and "Traceback" not in result.output


@pytest.mark.parametrize(
    ("spelling", "seconds"), [("20m", 20e-3), ("10ms", 10e-3), ("1meg", 1e6), ("5us", 5e-6)]
)
def test_command_line_numbers_with_scale_and_unit(spelling: str, seconds: float) -> None:
    result = CliRunner().invoke(
        main, ["simulate", str(CIRCUIT1), "--tstop", spelling, "--format", "json", "-q"]
    )
    assert result.exit_code == 0, result.output
    assert json.loads(result.output)["time"][-1] == pytest.approx(seconds, rel=1e-12)


def test_op_prints_si_units_and_takes_quiet(tmp_path: Path) -> None:
    """``op`` writes values with SI prefixes and units, as ``analyze`` does, and accepts ``-q`` like every
    command; the text agrees with the JSON's full-precision numbers to its 12 digits."""
    path = tmp_path / "divider.cir"
    path.write_text(
        "divider\nV1 in 0 DC 1\nR1 in out 1.5k\nR2 out 0 470\nD1 out 0 dmod\n.model dmod D(IS=1e-14)\n.end\n"
    )
    text = CliRunner().invoke(main, ["op", str(path), "-q"])
    assert text.exit_code == 0, text.output
    doc = json.loads(CliRunner().invoke(main, ["op", str(path), "--format", "json", "-q"]).output)
    point = doc["operating_point"]
    vout = point["voltages"]["v(out)"]
    assert f"v(out) = {eng(vout, 'V', 12)}" in text.output
    assert " mV" in text.output or " V" in text.output
    assert "i(R1) = " in text.output and text.output.split("i(R1) = ")[1].split("\n")[0].endswith("A")
    # KCL at out closes to rounding: the current through R1 is R2's plus the diode's
    kcl = point["currents"]["i(R2)"] + point["currents"]["i(D1)"]
    assert (1 - vout) / 1.5e3 == pytest.approx(kcl, rel=1e-12)


def test_connect_takes_quiet(tmp_path: Path) -> None:
    out = tmp_path / "series.json"
    result = CliRunner().invoke(
        main, ["connect", "series", str(CIRCUIT1), str(CIRCUIT1), "--output1", "v(a)", "-q", "-o", str(out)]
    )
    assert result.exit_code == 0, result.output
    assert out.exists()


def test_bode_data_as_csv_and_json(tmp_path: Path) -> None:
    """``--bode b.csv`` writes the plotted data; the JSON carries it too. Circuit 1's i(L1)/Vin is
    1 / (L C R1 s² + L (1 + R1/R2) s + R1) (KCL at a): each row agrees with it at s = jω."""
    import csv as csv_module

    from netlistdyn.workflows.pipelines import read_netlist

    target = tmp_path / "b.csv"
    args = ["analyze", str(CIRCUIT1), "--output", "i(L1)", "--bode", str(target), "--format", "json"]
    result = CliRunner().invoke(main, [*args, "--param", "R1=100", "--param", "R2=100"])
    assert result.exit_code == 0, result.output
    rows = list(csv_module.reader(target.read_text().splitlines()))
    assert rows[0] == [
        "frequency_hz",
        "omega_rad_s",
        "re(i(L1)/Vin)",
        "im(i(L1)/Vin)",
        "db(i(L1)/Vin)",
        "phase_deg(i(L1)/Vin)",
    ]
    table = np.array(rows[1:], dtype=float)
    elements = {e.name: e.value for e in read_netlist(CIRCUIT1, {"R1": 100, "R2": 100}).elements}
    R1, R2, C, L = elements["R1"], elements["R2"], elements["C1"], elements["L1"]
    s = 1j * table[:, 1]
    closed = 1 / (L * C * R1 * s**2 + L * (1 + R1 / R2) * s + R1)
    np.testing.assert_allclose(table[:, 1], 2 * np.pi * table[:, 0], rtol=1e-15)
    # a 2-state solve per frequency: rounding of order κ·eps with κ < 1e4 on this grid
    np.testing.assert_allclose(table[:, 2] + 1j * table[:, 3], closed, rtol=1e-10)
    np.testing.assert_allclose(table[:, 4], 20 * np.log10(np.abs(closed)), rtol=0, atol=1e-8)
    doc = json.loads(result.output)["frequency_response"]
    assert [(p["output"], p["input"]) for p in doc["pairs"]] == [("i(L1)", "Vin")]
    # the CSV writes repr(float), which reads back to the same double: the two are one computation
    np.testing.assert_allclose(doc["frequency_hz"], table[:, 0], rtol=0)
    np.testing.assert_allclose(doc["pairs"][0]["re"], table[:, 2], rtol=0)
