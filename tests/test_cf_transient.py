"""The CF stepping of the descriptor transient (netlistdyn/simulation/transient.py, method ``cf``) against
independent references: a dense exact discretisation of the grids of benchmarks/powergrid.py
(algebraic unknowns eliminated, matrix exponential of the Van Loan block with first-order hold)
and the closed form of an RC driven by a ramp (the nilpotent augmentation's r(0), r′(0))."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest
import scipy.linalg as sl

from netlistdyn.circuit.sources import source_waveform
from netlistdyn.formulation import descriptor
from netlistdyn.frontend.parser import parse_text
from netlistdyn.simulation import transient

from .conftest import ROOT


def _powergrid():
    spec = importlib.util.spec_from_file_location("powergrid", ROOT / "benchmarks" / "powergrid.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _exact(system: descriptor.DescriptorSystem, waves, times: np.ndarray) -> np.ndarray:
    """Outputs on ``times`` (uniform, every input corner on it) from the DC operating point:
    dense elimination of the algebraic unknowns, then x_{k+1} = Φ x_k + Γ0 u_k + Γ1 (u_{k+1} − u_k)
    from one expm of [[hA, hB, 0], [0, 0, I], [0, 0, 0]]."""
    E, A, B = (m.toarray() for m in (system.E, system.A, system.B))
    C, D = system.C.toarray(), system.D.toarray()
    dyn = np.flatnonzero(np.abs(E).sum(axis=0) + np.abs(E).sum(axis=1) > 0)
    alg = np.setdiff1d(np.arange(E.shape[0]), dyn)
    Ad, Bd, Cd, Dd = A[np.ix_(dyn, dyn)], B[dyn], C[:, dyn], D.copy()
    if alg.size:
        K = -np.linalg.solve(A[np.ix_(alg, alg)], np.hstack([A[np.ix_(alg, dyn)], B[alg]]))
        Kx, Ku = K[:, : dyn.size], K[:, dyn.size :]
        Ad, Bd = Ad + A[np.ix_(dyn, alg)] @ Kx, Bd + A[np.ix_(dyn, alg)] @ Ku
        Cd, Dd = Cd + C[:, alg] @ Kx, Dd + C[:, alg] @ Ku
    Einv = np.linalg.inv(E[np.ix_(dyn, dyn)])
    Ad, Bd = Einv @ Ad, Einv @ Bd
    n, m = Bd.shape
    h = times[1] - times[0]
    M = np.zeros((n + 2 * m, n + 2 * m))
    M[:n, :n], M[:n, n : n + m], M[n : n + m, n + m :] = Ad * h, Bd * h, np.eye(m)
    F = sl.expm(M)
    values = transient.SourceValues(waves)
    u = values(0.0)
    x = -np.linalg.solve(Ad, Bd @ u)
    out = [Cd @ x + Dd @ u]
    for t in times[1:]:
        u_new = values(float(t))
        x = F[:n, :n] @ x + F[:n, n : n + m] @ u + F[:n, n + m :] @ (u_new - u)
        u = u_new
        out.append(Cd @ x + Dd @ u)
    return np.array(out)


#: Step check tolerance of the grid comparison.
GRID_RTOL = 1e-10


@pytest.mark.parametrize("kind", ["rc", "rlc"])
@pytest.mark.parametrize("method", transient.METHODS)
def test_grid_matches_dense_exact_discretisation(kind: str, method: str) -> None:
    """An 8x8 grid (PWL loads, supplies behind pads, RLC: algebraic pad nodes) from its DC point.

    Every method keeps the error within rtol of the largest voltage (1.8 V: the check's
    yardstick), with a factor 3 for the accumulation over 1000 steps. CF on the RC grid does
    far better, 1e-9 of the swing: degree 14 is within 2.6e-14 of e^x on the whole real axis,
    and the dense reference itself is good to ~1e-11 (expm of a 1e4-stiff block).
    """
    text = _powergrid().grid_netlist(8, kind, pitch=4, seed=5)
    netlist = parse_text(text)
    probes = ["v(n2_3)", "v(n5_6)", "v(n7_0)"]
    system = descriptor.assemble(netlist, probes)
    times = np.linspace(0.0, 1e-8, 1001)
    waves = [source_waveform(e).resolved(1e-11, 1e-8) for e in netlist.sources]
    run = transient.run_transient(system, waves, times, rtol=GRID_RTOL, method=method)
    assert run.status == "ok", run.message
    ref = _exact(system, waves, times)
    swing = np.ptp(ref, axis=0)
    assert swing.min() > 1e-4  # the loads move the probes
    error = np.abs(run.outputs - ref).max()
    assert error < 3 * GRID_RTOL * 1.8, f"{method} {kind}: {error:.3g} V"
    if (method, kind) == ("cf", "rc"):
        assert (np.abs(run.outputs - ref).max(axis=0) / swing).max() < 1e-9


def test_rc_grid_takes_one_cf_step_per_output_interval() -> None:
    """On an RC grid (real spectrum) CF needs no halving at the tightest rtol: steps = intervals."""
    netlist = parse_text(_powergrid().grid_netlist(8, "rc", pitch=4, seed=5))
    system = descriptor.assemble(netlist, ["v(n2_3)"])
    times = np.linspace(0.0, 1e-8, 1001)
    waves = [source_waveform(e).resolved(1e-11, 1e-8) for e in netlist.sources]
    run = transient.run_transient(system, waves, times, rtol=transient.MIN_RTOL, method="cf")
    assert run.status == "ok"
    assert run.stats["rejected"] == 0
    assert run.stats["steps"] == times.size - 1


def test_tightest_rtol_passes_with_algebraic_nodes_at_supply_level() -> None:
    """RLC grid (pad nodes without capacitor sit at 1.8 V) at MIN_RTOL: the check compares
    degrees 12 and 14 on the deviation from the operating point, so rounding at the supply
    level does not fail it. The result is within 1e-11 V of the dense exact one: that reference
    is itself good to only ~2e-12 V per step on this stiff RLC block (after one step it differs
    by 2.2e-12 V from both CF and Padé, which agree to 3e-13 V)."""
    netlist = parse_text(_powergrid().grid_netlist(8, "rlc", pitch=4, seed=5))
    system = descriptor.assemble(netlist, ["v(n2_3)", "v(p0)"])
    times = np.linspace(0.0, 1e-8, 1001)
    waves = [source_waveform(e).resolved(1e-11, 1e-8) for e in netlist.sources]
    run = transient.run_transient(system, waves, times, rtol=transient.MIN_RTOL, method="cf")
    assert run.status == "ok", run.message
    assert np.abs(run.outputs - _exact(system, waves, times)).max() < 1e-11


@pytest.mark.parametrize("tau_over_h", [1e-4, 0.3, 30.0])
def test_ramp_through_rc_matches_closed_form(tau_over_h: float) -> None:
    """v(a) ramps at slope s from 0; C behind R follows v_C = s (t − τ (1 − e^{−t/τ})). Stiff
    (τ ≪ h), matched and slow (τ ≫ h) steps: the ramp enters only through the nilpotent
    augmentation, so this tests r and r′ near 0 and the divided differences of r at hλ.
    1e-10 of the final value: 200 steps of a step error of ~1e-13."""
    h = 1e-9
    tau = tau_over_h * h
    cap = 1e-12
    res = tau / cap
    stop = 200 * h
    slope = 1.0 / stop
    net = parse_text(
        f"ramp\nV1 a 0 PWL(0 0 {stop:.6g} 1)\nR1 a b {res:.17g}\nC1 b 0 {cap:g}\n.tran 1n 200n\n.end\n"
    )
    system = descriptor.assemble(net, ["v(b)"])
    times = np.linspace(0.0, stop, 201)
    waves = [source_waveform(e).resolved(h, stop) for e in net.sources]
    run = transient.run_transient(system, waves, times, rtol=1e-12, method="cf")
    assert run.status == "ok"
    expected = slope * (times - tau * -np.expm1(-times / tau))
    assert np.abs(run.outputs[:, 0] - expected).max() <= 1e-10


def test_auto_falls_back_to_pade_on_an_unresolved_oscillation() -> None:
    """A lightly damped LC (ω = 1e9 rad/s, ζ = 0.05) stepped at hω = 1: off the real axis CF
    fails its check and halves (more steps than output intervals); ``auto`` switches to Padé,
    which resolves it at that step, so it takes one step per output interval. Both within
    rtol (1e-10) of the largest voltage (~1.9 V), times 2 for the first, unchecked step."""
    h, stop, rtol = 1e-9, 300e-9, 1e-10
    net = parse_text("lc\nV1 a 0 PWL(0 0 1n 1)\nR1 a b 0.1\nL1 b c 1n\nC1 c 0 1n\n.tran 1n 300n\n.end\n")
    system = descriptor.assemble(net, ["v(c)"])
    times = np.linspace(0.0, stop, 301)
    waves = [source_waveform(e).resolved(h, stop) for e in net.sources]
    exact = _exact(system, waves, times)
    cf = transient.run_transient(system, waves, times, rtol=rtol, method="cf")
    auto = transient.run_transient(system, waves, times, rtol=rtol, method="auto")
    assert cf.status == auto.status == "ok"
    assert cf.stats["steps"] > times.size - 1
    assert auto.stats["steps"] == times.size - 1 and auto.stats["fallback_steps"] == 1
    largest = np.abs(exact).max()
    for run in (cf, auto):
        assert np.abs(run.outputs - exact).max() <= 2 * rtol * largest


def test_explicit_cf_fails_plainly_where_its_check_cannot_pass() -> None:
    """An RLC (1 kΩ, 470 nF, 22 mH, 680 Ω) hit by a 10 µs edge at 0.2 ms, at rtol 1e-12: CF's check
    fails at the edge's end at every step length down to 2^-48 of the interval (its partial
    fractions' rounding floor; the check's difference grows as the step shrinks). An explicitly
    chosen ``cf`` stops there with one line naming the time and the methods that do pass, instead
    of going on with Padé under CF's name; ``auto`` switches at the first failed check and stays
    within 2·rtol of the largest voltage of the dense exact discretisation (measured: 4.2e-14)."""
    net = parse_text(
        "edge\nV1 in 0 PULSE(0 1 0.2m 10u 10u 1 2)\nR1 in a 1k\nC1 a 0 470n\nL1 a c 22m\nR3 c 0 680\n"
        ".tran 10u 4m\n.end\n"
    )
    system = descriptor.assemble(net, ["v(a)", "v(c)"])
    times = np.linspace(0.0, 4e-3, 401)
    waves = [source_waveform(e).resolved(1e-5, 4e-3) for e in net.sources]
    rtol = 1e-12
    cf = transient.run_transient(system, waves, times, rtol=rtol, method="cf")
    assert cf.status == "failed"
    assert "\n" not in cf.message and "t = 0.00020125 s" in cf.message
    assert "'auto'" in cf.message and "'pade'" in cf.message
    assert np.isfinite(cf.outputs[:21]).all() and np.isnan(cf.outputs[21:]).all()
    auto = transient.run_transient(system, waves, times, rtol=rtol, method="auto")
    assert auto.status == "ok" and auto.stats["fallback_steps"] == 1
    exact = _exact(system, waves, times)
    assert np.abs(auto.outputs - exact).max() <= 2 * rtol * np.abs(exact).max()
