"""Linear superposition across independent sources (``simulate --superpose``, issue 13).

References: the direct run of the same netlist (a different computation: one job with every
source, one operating point, one set of breakpoints), the exact explicit model for the
descriptor jobs, and batch ngspice on the whole circuit.

Tolerances. A result that says ok is within rtol of each output's peak (``exact`` and
``rational``: tests/test_rtol_bound.py), and a superposed result that says ok has the sum of
its jobs' estimates within rtol too, so the two differ by at most 2·rtol of each output's
peak. The descriptor transient holds each step's check to rtol of the largest voltage; over
a few hundred steps tests/test_descriptor.py measures within 10·rtol of the largest output,
so there the two runs differ by at most twice that.
"""

from __future__ import annotations

import importlib.util
import json

import numpy as np
import pytest
from click.testing import CliRunner

from netlistdyn.circuit.waveforms import Pwl
from netlistdyn.cli import main
from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.frontend.parser import parse_text
from netlistdyn.simulation import integrators
from netlistdyn.simulation.foh import input_signals
from netlistdyn.workflows.large import simulate_large
from netlistdyn.workflows.superpose import Job, job_netlist, plan, simulate_superposed, source_groups

from .conftest import ROOT
from .ngspice_probe import needs_ngspice, ngspice_tran

#: An RLC network driven by two voltage sources (PWL, DC) and a current source (PULSE).
V_AND_I = """V and I sources, PULSE and PWL
V1 in 0 PWL(0 0 1m 1 3m 1 4m -0.5 10m -0.5)
R1 in a 1k
C1 a 0 1u
R2 a b 2k
C2 b 0 2u
I1 b 0 PULSE(0 1m 2m 0.5m 0.5m 2m 6m)
L1 b c 10m
R3 c 0 50
V2 d 0 1.5
R4 d a 10k
.tran 0.1m 20m
.end
"""
OUTPUTS = ["v(a)", "v(b)", "v(c)", "i(L1)"]


def _grid(size: int, kind: str, seed: int) -> str:
    spec = importlib.util.spec_from_file_location("powergrid", ROOT / "benchmarks" / "powergrid.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.grid_netlist(size, kind, pitch=3, seed=seed)


def _within(a: np.ndarray, b: np.ndarray, bound: float) -> float:
    """Largest difference relative to each output's peak (of ``b``), asserted within ``bound``."""
    peak = np.max(np.abs(b), axis=0)
    assert np.all(peak > 0)
    worst = float(np.max(np.abs(a - b) / peak))
    assert worst <= bound, f"{worst:.3g} of the peak > {bound:g}"
    return worst


def test_sources_sharing_breakpoints_go_together() -> None:
    """Two PWL loads with the same corners share a job; the others split so that no job has
    every breakpoint of the circuit."""
    text = (
        "t\nIa n1 0 PWL(0 0 1n 1m 2n 0)\nIb n2 0 PWL(0 0 1n 2m 2n 0)\nIc n1 0 PWL(0 0 3n 1m 4n 0)\n"
        "Id n2 0 PWL(0 0 5n 1m 6n 0 7n 1m)\nV1 v 0 1\nR1 v n1 1\nR2 n1 n2 1\nC1 n1 0 1p\nC2 n2 0 1p\n"
        ".tran 0.1n 10n\n.end\n"
    )
    netlist = parse_text(text)
    jobs = plan(netlist, 2, 1e-10, 1e-8)
    together = [job for job in jobs if "Ia" in job.sources]
    assert len(together) == 1 and "Ib" in together[0].sources
    assert len(jobs) == 2 and sum(len(j.sources) for j in jobs) == 5
    assert all(job.breakpoints < 7 for job in jobs)  # 7 distinct corners in the circuit
    assert max(job.breakpoints for job in jobs) == 4  # {1n, 2n} + {5n, 6n, 7n} vs {3n, 4n}
    # More groups than clusters: one per cluster, none empty.
    assert len(source_groups([frozenset({1.0}), frozenset({1.0}), frozenset()], 5)) == 2


def test_job_netlist_zeroes_the_other_sources_and_the_initial_conditions() -> None:
    netlist = parse_text(
        "t\nV1 a 0 PWL(0 0 1m 1)\nI1 a 0 2m\nR1 a b 1k\nC1 b 0 1u IC=2\n.ic v(b)=1\n.tran 1u 2m uic\n"
    )
    job = job_netlist(netlist, Job(0, ("I1",), 0))
    v1, i1 = job.sources
    assert v1.waveform is None and abs(v1.value) == 0
    assert i1.value == pytest.approx(2e-3, rel=1e-15)
    assert job.element("C1").ic is None and abs(job.initial_conditions[0].value) == 0
    kept = job_netlist(netlist, Job(1, (), 0, initial=True))
    assert kept.element("C1").ic == pytest.approx(2.0, rel=1e-15)
    assert all(s.waveform is None and abs(s.value) == 0 for s in kept.sources)


@pytest.mark.parametrize(("method", "rtol"), [("exact", 1e-9), ("rational", 1e-8)])
def test_superposed_equals_direct_on_v_and_i_sources(method: str, rtol: float) -> None:
    """Three jobs (V1's PWL, I1's PULSE, V2's DC), each from its own operating point."""
    netlist = parse_text(V_AND_I)
    direct = integrators_direct(netlist, method, rtol)
    result = simulate_superposed(netlist, 3, "processes", 1, outputs=OUTPUTS, method=method, rtol=rtol)
    assert result.ok, result.message
    assert len(result.stats["jobs"]) == 3
    assert result.stats["error_estimate"] <= rtol
    _within(result.values, direct, 2 * rtol)


def integrators_direct(netlist, method: str, rtol: float, x0=None) -> np.ndarray:
    """The direct run through simulate's own pipeline."""
    from netlistdyn.workflows.pipelines import simulation_pipeline

    model = compile_netlist(netlist, OUTPUTS)
    run = simulation_pipeline(netlist, model, method=method, rtol=rtol, x0=x0)
    assert run.ok, run.message
    return run.values


@pytest.mark.parametrize(
    ("lines", "initial_job"),
    [
        # UIC: IC= on C1 and L1, .ic on node b; the sources' jobs start from zero.
        (".ic v(b)=-0.7\n.tran 0.1m 20m uic", True),
        # .ic held during the operating point and released: held at 0 V in the sources' jobs.
        (".ic v(b)=0.4\n.tran 0.1m 20m", True),
        # Without UIC, IC= is ignored: no job of its own.
        (".tran 0.1m 20m", False),
    ],
)
def test_initial_state_goes_to_one_job(lines: str, initial_job: bool) -> None:
    text = V_AND_I.replace("C1 a 0 1u", "C1 a 0 1u IC=0.3").replace("L1 b c 10m", "L1 b c 10m IC=-2m")
    netlist = parse_text(text.replace(".tran 0.1m 20m", lines))
    jobs = plan(netlist, 2, 1e-4, 2e-2)
    assert any(job.initial for job in jobs) is initial_job
    direct = integrators_direct(netlist, "exact", 1e-9)
    result = simulate_superposed(netlist, 2, "processes", 1, outputs=OUTPUTS, method="exact", rtol=1e-9)
    assert result.ok, result.message
    _within(result.values, direct, 2e-9)


def test_given_state_goes_to_one_job() -> None:
    """--ic: the given state in one job with every source at 0, the sources' jobs from zero."""
    netlist = parse_text(V_AND_I)
    model = compile_netlist(netlist, OUTPUTS)
    x0 = np.array([1e-6 * 0.8, -2e-6 * 0.5, 3e-3])[: model.nstates]
    assert tuple(model.states) == ("q(C1)", "q(C2)", "i(L1)")
    direct = integrators_direct(netlist, "exact", 1e-9, x0=x0)
    result = simulate_superposed(
        netlist, 2, "processes", 1, outputs=OUTPUTS, method="exact", rtol=1e-9, x0=x0
    )
    assert result.ok and any(job["initial_state"] for job in result.stats["jobs"])
    _within(result.values, direct, 2e-9)


@pytest.mark.parametrize(("kind", "seed"), [("rc", 3), ("rlc", 2)])
def test_superposed_descriptor_grid_equals_direct_and_exact(kind: str, seed: int) -> None:
    """A 5x5 power grid (benchmarks/powergrid.py, 4 pads, 2 PWL loads) on the descriptor form,
    in 2 jobs, against the direct descriptor run and the exact explicit model (a third,
    independent computation: dense first-order hold on the tree/cotree model)."""
    netlist = parse_text(_grid(5, kind, seed))
    outputs = ["v(n1_1)", "v(n2_3)", "v(n4_4)"]
    rtol, tstop = 1e-10, 4e-9  # 400 output steps, 2-4 load corners each
    direct = simulate_large(netlist, outputs, tstop, 1e-11, (), rtol=rtol)
    result = simulate_superposed(
        netlist, 2, "processes", 1, outputs=outputs, method="descriptor", rtol=rtol, tstop=tstop, tstep=1e-11
    )
    assert direct.ok and result.ok, result.message
    assert len(result.stats["jobs"]) == 2
    scale = np.max(np.abs(direct.values))
    assert np.max(np.abs(result.values - direct.values)) <= 2 * 10 * rtol * scale
    model = compile_netlist(netlist, outputs)
    signals = input_signals(netlist, 1e-11, tstop)
    u0 = signals(np.array([0.0]))[0]
    x0 = np.linalg.solve(model.A, -(model.B @ u0))  # the operating point, solved here
    exact = integrators.run(model, signals, direct.time, "exact", 1e-12, None, x0, False, None)
    assert np.max(np.abs(result.values - exact.outputs)) <= 10 * rtol * scale


@needs_ngspice
def test_superposed_as_batch_ngspice() -> None:
    """The superposed run of V_AND_I against ``ngspice -b`` at reltol 1e-9 and a 0.25 µs maximum
    step, interpolated linearly onto our 0.1 ms grid. ngspice's trapezoidal error dominates and
    goes as h²: measured 1.2e-7, 4.8e-7 and 1.8e-6 of v(b)'s peak at 0.25, 0.5 and 1 µs; 2e-6
    as in tests/test_initial.py."""
    deck = V_AND_I.replace(
        ".tran 0.1m 20m", ".options reltol=1e-9 abstol=1e-15 vntol=1e-12\n.tran 0.1m 20m 0 0.25u"
    )
    theirs = ngspice_tran(deck, OUTPUTS[:3])
    result = simulate_superposed(
        parse_text(V_AND_I), 2, "processes", 1, outputs=OUTPUTS, method="exact", rtol=1e-9
    )
    assert result.ok, result.message
    for j in range(3):
        ref = np.interp(result.time, theirs[:, 0], theirs[:, j + 1])
        peak = np.max(np.abs(ref))
        assert peak > 0.05  # each output moves: 0.07 V (v(c)) to 1.2 V
        assert np.max(np.abs(result.values[:, j] - ref)) < 2e-6 * peak, OUTPUTS[j]


def test_dask_scheduler_gives_the_process_pool_result() -> None:
    pytest.importorskip("dask.distributed", reason="dask[distributed] is not installed (extra: test)")
    netlist = parse_text(V_AND_I)
    local = simulate_superposed(netlist, 2, "processes", 1, outputs=OUTPUTS, method="exact", rtol=1e-9)
    # One Dask worker (a cluster of two takes twice as long to start): the jobs still travel to it.
    on_dask = simulate_superposed(netlist, 2, "dask", 1, outputs=OUTPUTS, method="exact", rtol=1e-9)
    assert on_dask.ok and local.ok
    # The same jobs summed in the same order: only the worker process differs.
    _within(on_dask.values, local.values, 1e-14)


def test_cli_superpose_json_and_refusals(tmp_path) -> None:
    path = tmp_path / "vi.cir"
    path.write_text(V_AND_I)
    runner = CliRunner()
    done = runner.invoke(main, ["simulate", str(path), "--superpose", "--format", "json", "-q"])
    assert done.exit_code == 0, done.output
    doc = json.loads(done.stdout)
    assert "superposed" in doc["setting"] and len(doc["stats"]["jobs"]) == 2
    alone = runner.invoke(main, ["simulate", str(path), "--jobs", "2"])
    assert alone.exit_code == 2 and "--jobs applies to --superpose only" in alone.stderr
    bad = runner.invoke(main, ["simulate", str(path), "--superpose", "--scheduler", "nowhere"])
    assert bad.exit_code == 2 and "--scheduler" in bad.stderr
    diode = tmp_path / "diode.cir"
    diode.write_text(
        "t\nV1 a 0 PULSE(0 1 0 1u 1u 1m 2m)\nR1 a b 1k\nD1 b 0 dmod\n.model dmod D\n.tran 1u 1m\n"
    )
    refused = runner.invoke(main, ["simulate", str(diode), "--superpose"])
    assert refused.exit_code == 1
    lines = refused.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"{diode}:4:") and "linear" in lines[0]


def test_pwl_corners_are_the_breakpoints_grouped() -> None:
    """The grouping reads each source's resolved waveform: a PWL's corners inside the horizon."""
    netlist = parse_text("t\nI1 a 0 PWL(0 0 1m 1 2m 0 5m 1)\nR1 a 0 1\nC1 a 0 1u\n.tran 1u 3m\n")
    (job,) = plan(netlist, 4, 1e-6, 3e-3)
    assert isinstance(netlist.sources[0].waveform, Pwl)
    assert job.breakpoints == 2  # 1 ms and 2 ms; 5 ms lies beyond the horizon
