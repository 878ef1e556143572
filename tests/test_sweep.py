"""Sweeps: compiled once, re-evaluated per case on the same normal tree, locally or on Dask.

Re-evaluation runs exactly the operations a fresh compile runs on the same
tree, so the matrices must agree to rounding (rtol 1e-13: a few ulps).
"""

from __future__ import annotations

import sys

import numpy as np
import pytest

import netlistdyn.formulation.formulate as formulate_module
from netlistdyn.base.errors import UsageError
from netlistdyn.formulation.compile import compile_netlist, formulate, recompile
from netlistdyn.frontend.parser import parse_file
from netlistdyn.workflows.sweep import run_sweep

from .conftest import NETLISTS

SAME_RTOL = 1e-13


@pytest.mark.parametrize(
    ("name", "cases"),
    [
        ("circuit1.cir", [{"r1": 1e-3, "r2": 1e-3}, {"r1": 100.0, "r2": 100.0}, {"r1": -5.0, "r2": 1.0}]),
        ("blocks_pendulum.cir", [{"l": 1.0, "inv": 0.0}, {"l": 0.25, "inv": 1.0}, {"l": 4.0, "inv": 1.0}]),
        ("gear_train.cir", [{}, {}]),
    ],
)
def test_recompile_equals_a_fresh_compile(name: str, cases: list[dict[str, float]]) -> None:
    first = formulate(parse_file(NETLISTS / name, cases[0]))
    for params in cases:
        netlist = parse_file(NETLISTS / name, params)
        again, fresh = recompile(first, netlist), compile_netlist(netlist)
        assert again.states == fresh.states
        for key in ("A", "B", "C", "D", "D1"):
            np.testing.assert_allclose(getattr(again, key), getattr(fresh, key), rtol=SAME_RTOL, atol=0)


def test_sweep_searches_for_a_tree_once(monkeypatch: pytest.MonkeyPatch) -> None:
    calls = []
    original = formulate_module.normal_tree
    monkeypatch.setattr(formulate_module, "normal_tree", lambda c: calls.append(1) or original(c))
    cases = [{"r1": r, "r2": r} for r in np.logspace(-3, 2, 6)]
    result = run_sweep(str(NETLISTS / "circuit1.cir"), cases, None, jobs=1)
    assert len(calls) == 1
    assert all(case["stability"] == "asymptotically stable" for case in result)


def test_a_failing_first_case_does_not_stop_the_sweep() -> None:
    """R1 = 0 is refused by the parser; the sweep compiles from the next case and reports the error."""
    cases = [{"r1": 0.0, "r2": 1.0}, {"r1": 100.0, "r2": 100.0}]
    first, second = run_sweep(str(NETLISTS / "circuit1.cir"), cases, None, jobs=1)
    assert "zero" in first["error"]
    assert len(second["eigenvalues"]) == 2


def test_dask_scheduler_gives_the_process_pool_result() -> None:
    pytest.importorskip("dask.distributed")
    cases = [{"r1": r, "r2": r} for r in (1e-3, 1.0, 100.0)]
    path = str(NETLISTS / "circuit1.cir")
    local = run_sweep(path, cases, None, jobs=2)
    on_dask = run_sweep(path, cases, None, jobs=2, scheduler="dask")
    assert on_dask == local


def test_dask_missing_says_how_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "dask.distributed", None)
    with pytest.raises(UsageError, match=r"pip install 'dask\[distributed\]'"):
        run_sweep(str(NETLISTS / "circuit1.cir"), [{"r1": 1.0}], None, jobs=1, scheduler="dask")


def test_unreachable_dask_scheduler_is_a_usage_error() -> None:
    pytest.importorskip("dask.distributed")
    with pytest.raises(UsageError, match="cannot reach"):
        run_sweep(str(NETLISTS / "circuit1.cir"), [{"r1": 1.0}], None, jobs=1, scheduler="tcp://127.0.0.1:9")


def test_sweep_plot_is_written(tmp_path) -> None:
    from click.testing import CliRunner

    from netlistdyn.cli import main

    target = tmp_path / "locus.png"
    result = CliRunner().invoke(
        main, ["sweep", str(NETLISTS / "circuit1.cir"), "--param", "R1=log:1e-3:1e2:5", "--plot", str(target)]
    )
    assert result.exit_code == 0, result.output
    assert target.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert result.output.count("asymptotically stable") == 5


def test_sweep_reads_standard_input_as_analyze_does() -> None:
    """``sweep -`` takes the netlist from stdin: the same cases as from the file, eigenvalue for
    eigenvalue (the same compile on the same text; 1e-12 relative leaves room for rounding)."""
    import json

    from click.testing import CliRunner

    from netlistdyn.cli import main

    path = NETLISTS / "circuit1.cir"
    args = ["--param", "R1=1m,10", "--param", "R2=1m,10", "--format", "json", "-q"]
    runner = CliRunner()
    from_file = runner.invoke(main, ["sweep", str(path), *args])
    from_stdin = runner.invoke(main, ["sweep", "-", *args], input=path.read_text())
    assert from_file.exit_code == 0 and from_stdin.exit_code == 0, from_stdin.output
    cases_file = json.loads(from_file.stdout)["cases"]
    cases_stdin = json.loads(from_stdin.stdout)["cases"]
    assert len(cases_stdin) == len(cases_file) == 2
    for a, b in zip(cases_file, cases_stdin, strict=True):
        assert a["stability"] == b["stability"]
        np.testing.assert_allclose(b["eigenvalues"], a["eigenvalues"], rtol=1e-12, atol=0)


def test_sweep_as_arrays_records_and_a_data_frame() -> None:
    """Circuit 1 with R1 = R2 = 100 (the notes' case 2): L C R1 s² + L (1 + R1/R2) s + R1 = 0 is
    s² + 0.02 s + 1 = 0, so λ = −0.01 ± j·sqrt(1 − 10⁻⁴), ωn = 1 rad/s, ζ = 0.01, τ = 100 s, in every
    export of the sweep; a failed case (R1 = 0: a voltage source across a capacitor) stays a row with
    its error."""
    import pandas

    import netlistdyn

    result = netlistdyn.sweep(NETLISTS / "circuit1.cir", {"R1": [100, 0], "R2": [100, 100]})
    table = result.eigenvalues
    assert table.shape == (2, 2)
    exact = [complex(-0.01, -np.sqrt(1 - 1e-4)), complex(-0.01, np.sqrt(1 - 1e-4))]
    # the reported bounds of this well-separated pair are ~1e-15; 1e-12 leaves room for the BLAS
    np.testing.assert_allclose(np.sort_complex(table[0]), exact, rtol=1e-12)
    assert np.isnan(table[1]).all() and result.cases[1].error is not None
    frame = result.to_frame()
    assert isinstance(frame, pandas.DataFrame)
    ok = frame[frame["case"] == 1]
    np.testing.assert_allclose(ok["natural_frequency"], 1.0, rtol=1e-12)
    np.testing.assert_allclose(ok["natural_frequency_hz"], 1 / (2 * np.pi), rtol=1e-12)
    np.testing.assert_allclose(ok["damping"], 0.01, rtol=1e-10)
    np.testing.assert_allclose(ok["time_constant"], 100.0, rtol=1e-10)
    failed = frame[frame["case"] == 2]
    assert len(failed) == 1 and isinstance(failed["error"].iloc[0], str)
    assert list(frame.columns[:3]) == ["R1", "R2", "case"]


def test_sweep_table_shows_natural_frequency_and_damping() -> None:
    """Beside each λk the table gives fnk = |λk|/2π and ζk = −Re λk/|λk| (case 2 of the notes:
    |λ| = 1 rad/s, so fn = 159.2 mHz and ζ = 0.01)."""
    from click.testing import CliRunner

    from netlistdyn.cli import main

    args = ["sweep", str(NETLISTS / "circuit1.cir"), "--param", "R1=100", "--param", "R2=100"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    head, row = result.output.splitlines()[:2]
    assert head.split()[-6:] == ["λ1", "[1/s]", "fn1", "ζ1", "λ2", "[1/s]", "fn2", "ζ2"][-6:]
    assert row.count("159.2 mHz") == 2 and row.split()[-1] == "0.01"


def test_log_sweep_locus_has_a_logarithmic_colour_bar(tmp_path, monkeypatch) -> None:
    """A sweep of R1 over one decade evenly spaced in log gets a logarithmic colour bar (before, only
    spreads above 100 did), and the same range evenly spaced in value keeps a linear one."""
    from matplotlib.colors import LogNorm, Normalize

    from netlistdyn.io import plots

    seen = []
    real = plots.save_figure

    def spy(fig, path):
        bars = [ax._colorbar for ax in fig.axes if hasattr(ax, "_colorbar")]
        seen.append(type(bars[0].norm))
        real(fig, path)

    monkeypatch.setattr(plots, "save_figure", spy)
    for values in (np.logspace(0, 1, 20), np.linspace(1, 10, 20)):
        cases = run_sweep(str(NETLISTS / "circuit1.cir"), [{"r1": float(v)} for v in values], None, jobs=1)
        plots.sweep_plot(cases, str(tmp_path / "locus.png"))
    assert seen == [LogNorm, Normalize]
