"""Sparse descriptor form E x' = A x + B u and its transient (issue 13).

Three independent references: the explicit tree/cotree model simulated exactly
(matrix exponential with first-order hold), a nodal DC solve written here
with its own elimination of shorts and supplies, and batch ngspice.
"""

from __future__ import annotations

import importlib.util
import json
import shutil
import subprocess

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from click.testing import CliRunner

from netlistdyn.analysis.eigen import analyze_eigenvalues
from netlistdyn.circuit.netlist import GROUND, Kind
from netlistdyn.circuit.sources import source_waveform
from netlistdyn.cli import main
from netlistdyn.formulation import descriptor
from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.frontend.parser import parse_file, parse_text
from netlistdyn.simulation import integrators, transient
from netlistdyn.simulation.foh import choose_horizon, input_signals
from netlistdyn.workflows import large

from .conftest import NETLISTS, ROOT

# Netlists with DC/PULSE/PWL sources and only elements the descriptor form assembles.
PIECEWISE_LINEAR = [
    "balanced.cir",
    "bridge.cir",
    "circuit1.cir",
    "circuit2.cir",
    "controlled.cir",
    "parallel_caps.cir",
    "series_inductors.cir",
    "stress/extremes.cir",
    "stress/ladder12.cir",
    "stress/unstable.cir",
]


@pytest.mark.parametrize("name", PIECEWISE_LINEAR)
def test_descriptor_transient_matches_exact_model(name: str) -> None:
    """From zero state (UIC), the descriptor transient reproduces the exact explicit model.

    Both are exact for piecewise-linear inputs up to the Padé step (order 23,
    every step after a breakpoint checked at rtol 1e-10 of the largest
    voltage); 1e-9 of the largest output leaves room for 200 steps of
    rounding. The t = 0 sample is left out: under UIC it is taken 1e-9 of a
    step after the start (see transient._consistent).
    """
    netlist = parse_file(NETLISTS / name)
    model = compile_netlist(netlist)
    horizon = choose_horizon(netlist, analyze_eigenvalues(model.A_sparse, "auto"), None, None)
    times = np.linspace(0.0, horizon.tstop, 201)
    signals = input_signals(netlist, horizon.tstep, horizon.tstop)
    system = descriptor.assemble(netlist)
    assert system.outputs == model.outputs
    run = transient.run_transient(system, signals.waveforms, times, uic=True)
    assert run.status == "ok", run.message
    exact = integrators.run(model, signals, times, "exact", 1e-12, None, None, False, None)
    scale = np.abs(exact.outputs).max()
    error = np.abs(run.outputs[1:] - exact.outputs[1:]).max() / scale
    assert error < 1e-9, f"{name}: {error:.3g} of the largest output"


def test_unreachable_tolerance_is_raised() -> None:
    """rtol 1e-16 would ask two approximants to agree below rounding: it is raised to MIN_RTOL and
    the run completes, as accurate as at that tolerance (1e-9 of the peak against the exact model)."""
    netlist = parse_file(NETLISTS / "circuit2.cir")
    model = compile_netlist(netlist)
    times = np.linspace(0.0, 20.0, 41)
    signals = input_signals(netlist, 0.5, 20.0)
    run = transient.run_transient(
        descriptor.assemble(netlist), signals.waveforms, times, uic=True, rtol=1e-16
    )
    assert run.status == "ok", run.message
    exact = integrators.run(model, signals, times, "exact", 1e-12, None, None, False, None)
    assert np.abs(run.outputs[1:] - exact.outputs[1:]).max() < 1e-9 * np.abs(exact.outputs).max()


def _grid_text(rng: np.random.Generator, size: int) -> str:
    """Two stacked resistive layers joined by 0 V vias, grounded supplies behind R (and L), loads."""
    lines = ["two-layer grid"]
    for layer in (1, 2):
        for i in range(size):
            for j in range(size):
                here = f"m{layer}_{i}_{j}"
                if j + 1 < size:
                    lines.append(f"R{layer}h{i}_{j} {here} m{layer}_{i}_{j + 1} {rng.uniform(0.01, 2.0):.6g}")
                if i + 1 < size:
                    lines.append(f"R{layer}v{i}_{j} {here} m{layer}_{i + 1}_{j} {rng.uniform(0.01, 2.0):.6g}")
                lines.append(f"C{layer}_{i}_{j} {here} 0 {rng.uniform(1e-15, 1e-12):.6g}")
    for i in range(0, size, 2):
        for j in range(0, size, 2):
            lines.append(f"Vvia{i}_{j} m1_{i}_{j} m2_{i}_{j} 0")
    lines.append(f"Vdd sup 0 {rng.uniform(0.8, 3.3):.6g}")
    lines.append(f"Lpkg sup pkg {rng.uniform(1e-10, 1e-8):.6g}")
    lines.append(f"Rpkg pkg m2_0_0 {rng.uniform(0.01, 1.0):.6g}")
    lines.append(f"Vdd2 m2_{size - 1}_{size - 1} 0 {rng.uniform(0.8, 3.3):.6g}")
    for k in range(4):
        i, j = rng.integers(0, size, 2)
        lines.append(f"Iload{k} m1_{i}_{j} 0 PULSE({rng.uniform(1e-4, 1e-2):.6g} 0.05 1n 0.1n 0.1n 1n 3n)")
    lines.append(".tran 10p 2n")
    return "\n".join(lines) + "\n"


def _nodal_dc(netlist) -> dict[str, float]:
    """DC node voltages by nodal analysis: inductors and 0 V sources merge nodes, grounded
    sources fix them, capacitors are open; the rest is a conductance Laplacian (spsolve)."""
    parent: dict[str, str] = {}

    def find(n: str) -> str:
        while parent.get(n, n) != n:
            n = parent[n]
        return n

    fixed: dict[str, float] = {GROUND: 0.0}
    for e in netlist.elements:
        if e.kind is Kind.INDUCTOR or (e.kind is Kind.VSOURCE and e.value == 0):
            a, b = find(e.nodes[0]), find(e.nodes[1])
            if a != b:
                if b == GROUND:
                    a, b = b, a
                parent[b] = a
    for e in netlist.elements:
        if e.kind is Kind.VSOURCE and e.value != 0:
            plus, minus = find(e.nodes[0]), find(e.nodes[1])
            assert minus == GROUND, "the test grids put supplies against ground"
            fixed[plus] = e.value
    free = sorted({find(n) for n in netlist.nodes} - set(fixed))
    index = {n: k for k, n in enumerate(free)}
    rows, cols, vals = [], [], []
    rhs = np.zeros(len(free))
    for e in netlist.elements:
        a, b = find(e.nodes[0]), find(e.nodes[1])
        if e.kind is Kind.RESISTOR and a != b:
            g = 1.0 / e.value
            for p, q in ((a, b), (b, a)):
                if p in index:
                    rows.append(index[p])
                    cols.append(index[p])
                    vals.append(g)
                    if q in index:
                        rows.append(index[p])
                        cols.append(index[q])
                        vals.append(-g)
                    else:
                        rhs[index[p]] += g * fixed[q]
        elif e.kind is Kind.ISOURCE:
            value = float(source_waveform(e).resolved(1e-11, 1e-9)(np.array([0.0]))[0])
            if a in index:
                rhs[index[a]] -= value
            if b in index:
                rhs[index[b]] += value
    G = sp.csc_matrix((vals, (rows, cols)), shape=(len(free), len(free)))
    v = spla.spsolve(G, rhs)
    return {n: (fixed[find(n)] if find(n) in fixed else v[index[find(n)]]) for n in netlist.nodes}


@pytest.mark.parametrize("system_number", [1, 2, 3])
@pytest.mark.parametrize("reduce", [False, True])
def test_dc_operating_point_matches_nodal_solve(system_number: int, reduce: bool) -> None:
    """The MNA operating point equals an independent nodal solve to 1e-10 (relative), with and
    without the elimination of 0 V sources and grounded supplies."""
    rng = np.random.default_rng(1000 + system_number)
    netlist = parse_text(_grid_text(rng, 5 + system_number))
    outputs = [f"v({n})" for n in netlist.nodes]
    system = descriptor.assemble(netlist, outputs, reduce=reduce)
    assert (system.size < len(netlist.nodes)) == reduce  # the vias and supplies are gone
    waves = [source_waveform(e).resolved(1e-11, 2e-9) for e in netlist.sources]
    u0 = transient.SourceValues(waves)(0.0)
    x = transient.dc_operating_point(system, u0, "grid")
    got = dict(zip(netlist.nodes, system.C @ x + system.D @ u0, strict=True))
    reference = _nodal_dc(netlist)
    scale = max(abs(v) for v in reference.values())
    worst = max(abs(got[n] - reference[n]) for n in netlist.nodes) / scale
    assert worst < 1e-10


def test_reduction_keeps_the_response() -> None:
    """Merging 0 V vias and fixing supply nodes changes the unknowns, not the answer: the same
    equations, summed and factorised differently, agree to rounding (~1e-13 of the values, here
    up to 1/80 of them is swing: 1e-10 of the swing); a via whose current is asked for stays."""
    rng = np.random.default_rng(7)
    netlist = parse_text(_grid_text(rng, 6))
    outputs = ["v(m1_1_1)", "v(m2_3_4)", "v(pkg)", "i(Vvia0_0)", "i(Lpkg)"]
    waves = [source_waveform(e).resolved(1e-11, 2e-9) for e in netlist.sources]
    times = np.linspace(0.0, 2e-9, 201)
    full = descriptor.assemble(netlist, outputs, reduce=False)
    reduced = descriptor.assemble(netlist, outputs, reduce=True)
    assert "i(Vvia0_0)" in reduced.variables and "i(Vvia0_2)" not in reduced.variables
    a = transient.run_transient(full, waves, times).outputs
    b = transient.run_transient(reduced, waves, times).outputs
    swing = np.ptp(a, axis=0)
    assert swing.min() > 0
    assert (np.abs(a - b).max(axis=0) / swing).max() < 1e-10


def test_power_grid_directives_are_accepted() -> None:
    """`.opti`, `.width` and `.print tran` (as in the IBM benchmarks) parse with warnings only."""
    text = "pg\nV1 a 0 1.8\nR1 a b 0.25\nC1 b 0 1p\n.tran 1e-11 1e-9\n.opti nopage acct\n"
    text += ".width out=512\n.print tran v(b)\n.end\n"
    netlist = parse_text(text)
    assert len(netlist.elements) == 3
    assert {w.message.split()[0] for w in netlist.warnings} >= {".opti", ".width", ".print"}


def test_dc_start_is_steady() -> None:
    """From the DC operating point a circuit with constant sources stays put."""
    netlist = parse_text("rc\nV1 a 0 1.5\nR1 a b 100\nC1 b 0 1u\nR2 b 0 300\n.tran 10u 1m\n.end\n")
    system = descriptor.assemble(netlist)
    waves = [source_waveform(e) for e in netlist.sources]
    run = transient.run_transient(system, waves, np.linspace(0, 1e-3, 11))
    assert np.abs(run.outputs - run.outputs[0]).max() < 1e-12
    assert abs(run.outputs[0, 1] - 1.5 * 300 / 400) < 1e-12


def test_singular_dc_is_one_line(tmp_path) -> None:
    """A node reached only through capacitors has no DC operating point: one line, exit 1."""
    path = tmp_path / "float.cir"
    path.write_text("float\nV1 a 0 1\nR1 a b 1k\nC1 b c 1n\nC2 c 0 1n\n.tran 1u 1m\n.end\n")
    result = CliRunner().invoke(main, ["simulate", str(path), "--method", "descriptor"])
    assert result.exit_code == 1
    assert "no DC operating point" in result.output
    assert "Traceback" not in result.output and len(result.output.strip().splitlines()) == 1


def _load_powergrid():
    spec = importlib.util.spec_from_file_location("powergrid", ROOT / "benchmarks" / "powergrid.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.skipif(shutil.which("ngspice") is None, reason="ngspice is not installed")
@pytest.mark.parametrize(("kind", "tmax", "tolerance"), [("rc", 1e-12, 1e-6), ("rlc", 1e-13, 1e-4)])
def test_small_grid_matches_batch_ngspice(tmp_path, kind: str, tmax: float, tolerance: float) -> None:
    """A 6x6 grid from benchmarks/powergrid.py against `ngspice -b` at tight settings.

    ngspice (reltol 1e-9) is itself the looser side: on the RC grid it agrees
    to ~1e-8 of the swing; on the RLC grid its step control leaves ~1e-3
    unless the maximum step is forced down (TMAX 0.1 ps: ~1.5e-5), hence
    the tolerances, each ~10x ngspice's own measured error.
    """
    grid = _load_powergrid()
    text = grid.grid_netlist(6, kind, pitch=4, seed=3)
    probes = ["n2_3", "n3_5", "n1_1"]
    (tmp_path / "grid.cir").write_text(text)
    body = text.replace(".end\n", "").replace(".tran 1e-11 1e-08", f".tran 1e-11 1e-8 0 {tmax:g}")
    body += ".options reltol=1e-9 abstol=1e-15 vntol=1e-12 chgtol=1e-20 interp\n.control\n"
    body += "set wr_singlescale\nset wr_vecnames\noption numdgt=16\nrun\n"
    body += f"wrdata {tmp_path / 'ng.out'} " + " ".join(f"v({p})" for p in probes) + "\n.endc\n.end\n"
    (tmp_path / "ng.cir").write_text(body)
    subprocess.run(["ngspice", "-b", str(tmp_path / "ng.cir")], capture_output=True, timeout=300, check=False)
    ng = np.loadtxt(tmp_path / "ng.out", skiprows=1)
    netlist = parse_file(tmp_path / "grid.cir")
    system = descriptor.assemble(netlist, [f"v({p})" for p in probes])
    times = np.linspace(0.0, 1e-8, 1001)
    assert np.abs(ng[:, 0] - times).max() < 1e-20
    waves = [source_waveform(e).resolved(1e-11, 1e-8) for e in netlist.sources]
    run = transient.run_transient(system, waves, times)
    swing = np.ptp(run.outputs, axis=0)
    assert swing.min() > 1e-4  # the loads do move the probed nodes
    error = (np.abs(ng[:, 1:] - run.outputs).max(axis=0) / swing).max()
    assert error < tolerance


def test_cli_uses_descriptor_form_for_large_circuits(tmp_path, monkeypatch) -> None:
    """Above the size threshold `simulate` and `analyze` take the descriptor path; the states
    reported are those of the explicit model (same count, same names)."""
    grid = _load_powergrid()
    path = tmp_path / "grid.cir"
    path.write_text(grid.grid_netlist(5, "rlc", pitch=3, seed=2))
    monkeypatch.setattr(large, "DESCRIPTOR_UNKNOWNS", 10)
    result = CliRunner().invoke(main, ["analyze", str(path), "--format", "json"])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    model = compile_netlist(parse_file(path))
    assert doc["form"] == "descriptor"
    assert doc["nstates"] == model.nstates
    assert sorted(doc["states"]) == sorted(model.states)
    slow = analyze_eigenvalues(model.A_sparse, "all").modes
    slowest = min(abs(m.value) for m in slow)
    # the slowest mode of the explicit model is among the descriptor pencil's slowest (1e-8: ARPACK tol)
    assert any(abs(abs(complex(*v)) - slowest) <= 1e-8 * slowest for v in doc["slowest_eigenvalues"])
    result = CliRunner().invoke(main, ["analyze", str(path), "--control"])
    assert result.exit_code != 0 and "explicit model" in result.output
    result = CliRunner().invoke(
        main, ["simulate", str(path), "--output", "v(n2_2)", "--tstop", "1e-9", "--format", "json"]
    )
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["method"] == "descriptor"
    assert len(doc["time"]) == 1001
    assert abs(doc["values"]["v(n2_2)"][0] - 1.8) < 1e-9  # the DC operating point: no load at t = 0


def test_source_values_evaluate_pwl_tables_as_each_waveform_does() -> None:
    """The side-by-side PWL evaluation equals each waveform's own (jumps, holds before the first
    and after the last corner, corners exactly hit), to the last bit."""
    from netlistdyn.circuit.waveforms import Dc, Pwl

    rng = np.random.default_rng(3)
    waves = []
    for k in range(40):
        count = int(rng.integers(1, 8))
        times = np.sort(rng.uniform(0.0, 1e-9, count))
        if count > 2 and k % 3 == 0:
            times[2] = times[1]  # a time written twice: a jump
        waves.append(Pwl(tuple(map(float, times)), tuple(map(float, rng.uniform(-1e-2, 1e-2, count)))))
    waves.append(Dc(1.8))
    values = transient.SourceValues(waves)
    probes = [*rng.uniform(-1e-10, 1.1e-9, 500), *(t for w in waves[:-1] for t in w.times)]
    for t in probes:
        own = np.array([float(w(np.array([t]))[0]) for w in waves])
        assert np.array_equal(values(float(t)), own)


@pytest.mark.parametrize("uic", [True, False])
def test_descriptor_path_honours_tran_uic(uic: bool) -> None:
    """``.tran ... UIC`` starts the descriptor transient from zero (an RC charging as
    1 − e^{−t/RC}); without it, from the DC operating point (v(b) = 1 V throughout)."""
    tran = ".tran 0.1m 5m uic" if uic else ".tran 0.1m 5m"
    net = parse_text(f"rc\nV1 a 0 1\nR1 a b 1k\nC1 b 0 1u\n{tran}\n.end\n")
    run = large.simulate_large(net, ["v(b)"], None, None, [])
    assert run.status == "ok"
    t = np.asarray(run.time)
    expected = 1.0 - np.exp(-t / 1e-3) if uic else np.ones_like(t)
    # Closed form; the t = 0 output of a UIC start is taken 1e-9 of a step in (1e-10 V here).
    assert np.max(np.abs(np.asarray(run.values)[1:, 0] - expected[1:])) <= 1e-9


CURRENTS = """currents of the elements whose current is not an unknown
V1 in 0 1
I1 0 a 2m
R1 in a 1k
C1 a 0 1u
G1 0 b a 0 1m
R2 b 0 2k
Vs b c 0
L1 c 0 1m
F1 0 d Vs 2
R3 d 0 500
.end
"""


def test_current_outputs_match_the_tree_model() -> None:
    """i(R), i(I), i(G), i(F) (each device's own output row) and i(L), i(V) (unknowns): the
    descriptor form's C (sE − A)⁻¹ B + D equals the tree/cotree model's transfer function at
    1 kHz, to 1e-9 of its largest entry (two dense solves of a 6-unknown system)."""
    netlist = parse_text(CURRENTS)
    outputs = ["i(R1)", "i(I1)", "i(G1)", "i(F1)", "i(L1)", "i(V1)", "i(R3)"]
    system = descriptor.assemble(netlist, outputs, reduce=False)
    model = compile_netlist(netlist, outputs)
    s = 2j * np.pi * 1e3
    E, A, B, C, D = (m.toarray() for m in (system.E, system.A, system.B, system.C, system.D))
    mna = C @ np.linalg.solve(s * E - A, B) + D
    tree = model.transfer_function(s)
    assert np.abs(mna - tree).max() < 1e-9 * np.abs(tree).max(), (mna, tree)
