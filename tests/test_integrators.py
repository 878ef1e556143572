"""Simulation methods (issue 5): each method's accuracy against independent references.

Named tolerances and why:
* EXACT_RTOL 1e-11: the dense method is exact for piecewise-linear inputs up
  to rounding in expm (≈1e-14 here); the reference is an mpmath matrix
  exponential at 40 digits.
* RATIONAL_RTOL 1e-9: the Padé stepper at rtol=1e-10 controls its per-step
  error to 1e-10 of the peak state; accumulated over ≤ 2000 steps.
* KRYLOV_RTOL 1e-10: expm_multiply targets double precision per interval.
* IVP_RTOL 1e-5 at rtol=1e-9: solve_ivp controls local error only; the
  global error measured here is 1e-8..1e-7, the bound leaves a margin.
"""

from __future__ import annotations

import math
from pathlib import Path

import mpmath as mp
import numpy as np
import pytest

from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.frontend.parser import parse_file, parse_text
from netlistdyn.simulation import integrators
from netlistdyn.simulation.foh import input_signals
from netlistdyn.simulation.integrators import pade_factors, pade_factors_exact

from .conftest import NETLISTS, compile_file, compile_string

EXACT_RTOL = 1e-11
RATIONAL_RTOL = 1e-9
KRYLOV_RTOL = 1e-10
IVP_RTOL = 1e-5
DOP853_RTOL = 1e-4  # measured 3.8e-5: its error control is local and the case is mildly stiff


def mp_step_response(A: np.ndarray, B: np.ndarray, C: np.ndarray, D: np.ndarray, times, digits=40):
    """y(t) for a unit step on every input from zero state: C A⁻¹(e^{At} − I) B + D, in mpmath."""
    with mp.workdps(digits):
        a, b, c = mp.matrix(A.tolist()), mp.matrix(B.tolist()), mp.matrix(C.tolist())
        inv = a**-1
        out = []
        for t in times:
            x = inv * (mp.expm(a * t) - mp.eye(A.shape[0])) * b
            y = c * x
            out.append([float(y[i, 0]) + float(D[i, 0]) for i in range(C.shape[0])])
    return np.array(out)


def rel_err(y: np.ndarray, ref: np.ndarray) -> float:
    peak = np.max(np.abs(ref), axis=0)
    return float(np.max(np.abs(y - ref) / np.where(peak > 0, peak, 1.0)))


def test_stored_pade_factors_match_extended_precision() -> None:
    for diagonal in (False, True):
        stored = pade_factors(diagonal)
        exact = pade_factors_exact(diagonal=diagonal)
        assert len(stored) == len(exact) == 6
        for (p, a, c), (pe, ae, ce) in zip(stored, exact, strict=True):
            assert abs(p - pe) <= 1e-15 * abs(pe) and abs(a - ae) <= 1e-15 * abs(ae) and c == ce


@pytest.mark.parametrize("diagonal", [False, True])
def test_pade_approximates_the_exponential(diagonal: bool) -> None:
    factors = pade_factors(diagonal)

    def R(z: complex) -> complex:
        return complex(np.prod([c + a / (z - p) + np.conj(a) / (z - np.conj(p)) for p, a, c in factors]))

    for z in [0.5j, 2j, 4j, -1 + 3j, -3.5, -0.3 + 4.2j]:
        assert abs(R(z) - np.exp(z)) <= 1e-13, z
    if not diagonal:
        assert abs(R(-1e9)) < 1e-7  # L-stable: stiff modes are damped
    else:
        assert abs(abs(R(50j)) - 1) < 1e-12  # modulus one on the imaginary axis


@pytest.mark.parametrize("R", [1e-3, 100.0, 1e-9])
def test_exact_step_response_circuit1(R: float) -> None:
    net = parse_file(NETLISTS / "circuit1.cir", {"R1": R, "R2": R})
    model = compile_file("circuit1.cir", {"R1": R, "R2": R}, ["v(a)", "i(L1)"])
    times = np.array([0.0, 1e-4, 1e-3, 0.5, 3.0, 10.0])
    ref = mp_step_response(model.A, model.B, model.C, model.D, times)
    result = integrators.run(model, input_signals(net, 1e-3, 10.0), times, "exact")
    assert result.ok
    assert rel_err(result.outputs, ref) <= EXACT_RTOL


LADDER = "ladder\nVin in 0 DC 1\n" + "".join(
    f"R{k} {'in' if k == 1 else f'n{k - 1}'} m{k} 1\nL{k} m{k} n{k} 1m\nC{k} n{k} 0 1u\n"
    for k in range(1, 21)
)


@pytest.mark.parametrize("method", ["rational", "krylov"])
def test_large_model_methods_match_exact_on_a_ladder(method: str) -> None:
    net = parse_text(LADDER)
    model = compile_string(LADDER, ["v(n20)", "v(n10)", "i(L1)"])
    times = np.linspace(0, 2e-3, 401)
    signals = input_signals(net, 5e-6, 2e-3)
    exact = integrators.run(model, signals, times, "exact")
    other = integrators.run(model, signals, times, method, rtol=1e-10)
    assert other.ok, other.message
    assert rel_err(other.outputs, exact.outputs) <= (RATIONAL_RTOL if method == "rational" else KRYLOV_RTOL)


@pytest.mark.parametrize("method", ["Radau", "BDF", "LSODA", "DOP853"])
def test_solve_ivp_methods(method: str) -> None:
    net = parse_file(NETLISTS / "circuit2.cir", {"R1": 100, "R2": 100})
    model = compile_file("circuit2.cir", {"R1": 100, "R2": 100}, ["v(a)", "v(b)"])
    times = np.linspace(0, 20, 201)
    signals = input_signals(net, 0.1, 20)
    exact = integrators.run(model, signals, times, "exact")
    result = integrators.run(model, signals, times, method, rtol=1e-9, atol=1e-12)
    if method == "DOP853":  # 3.8e-5 of the peak: more than 1000 × rtol, so reported as unverified
        assert result.status == "unverified" and "solve_ivp's rtol bounds only" in result.message
    else:
        assert result.ok, result.message
    assert rel_err(result.outputs, exact.outputs) <= (DOP853_RTOL if method == "DOP853" else IVP_RTOL)


PIECEWISE = """corners
V1 p1 0 PULSE(0 1 0.1m 0.05m 0.05m 0.3m 1m)
R1 p1 o1 1k
C1 o1 0 100n
V3 p3 0 PWL(0 0 0.2m 1 0.5m 1 0.6m -0.5 1m 0)
R3 p3 o3 1k
C3 o3 0 100n
I5 0 o5 DC 1m
R5 o5 0 1k
C5 o5 0 100n
"""


def test_breakpoints_of_piecewise_linear_waveforms_are_respected() -> None:
    """PULSE and PWL corners are steps of both methods: they agree to the stepper's tolerance."""
    net = parse_text(PIECEWISE)
    model = compile_string(PIECEWISE, ["v(o1)", "v(o3)", "v(o5)"])
    times = np.linspace(0, 2e-3, 201)
    signals = input_signals(net, 1e-6, 2e-3)
    exact = integrators.run(model, signals, times, "exact")
    rational = integrators.run(model, signals, times, "rational", rtol=1e-11)
    assert rel_err(rational.outputs, exact.outputs) <= RATIONAL_RTOL


def test_explicit_method_on_stiff_model_is_refused() -> None:
    net = parse_file(NETLISTS / "stress" / "circuit1_stiff.cir", {"R": 1e-9})
    model = compile_file("stress/circuit1_stiff.cir", {"R": 1e-9}, ["v(a)"])
    times = np.linspace(0, 10, 11)
    result = integrators.run(model, input_signals(net, 1e-3, 10), times, "RK45")
    assert result.status == "refused"
    assert "stiff" in result.message and "Radau" in result.message


def test_exploding_solution_is_reported_not_returned() -> None:
    text = "boom\nI1 0 a DC 1\nC1 a 0 1\nR1 a 0 -1m\n"  # λ = +1000 1/s: e^(1000·10) overflows
    net = parse_text(text)
    model = compile_string(text, ["v(a)"])
    result = integrators.run(model, input_signals(net, 0.1, 10), np.linspace(0, 10, 101), "exact")
    assert result.status == "diverged"


def test_initial_condition_lc_tank() -> None:
    model = compile_string("lc\nC1 a 0 1\nL1 a 0 1\nR9 a 0 1e12\n", ["v(a)"])
    net = parse_text("lc\nC1 a 0 1\nL1 a 0 1\nR9 a 0 1e12\n")
    times = np.linspace(0, 2 * math.pi, 9)
    result = integrators.run(
        model, input_signals(net, 0.1, times[-1]), times, "exact", x0=np.array([1.0, 0.0])
    )
    np.testing.assert_allclose(result.outputs[:, 0], np.cos(times), atol=1e-9)


@pytest.mark.parametrize("R", [1e-3, 100.0, 1e-9])
def test_exact_at_many_times_matches_mpmath(R: float) -> None:
    """The exact method steps on its own grid of about MODAL_GRID_POINTS points and evaluates
    each requested time from the grid point before it (vectorised); with 10x more times than
    grid points it must stay exact (EXACT_RTOL against the 40-digit reference, at 25 of the
    20 001 times)."""
    from netlistdyn.simulation.foh import MODAL_GRID_POINTS

    net = parse_file(NETLISTS / "circuit1.cir", {"R1": R, "R2": R})
    model = compile_file("circuit1.cir", {"R1": R, "R2": R}, ["v(a)", "i(L1)"])
    times = np.linspace(0.0, 10.0, 20_001)
    assert times.size > MODAL_GRID_POINTS
    result = integrators.run(model, input_signals(net, 1e-3, 10.0), times, "exact")
    assert result.ok
    picks = np.unique(np.r_[0, np.random.default_rng(3).integers(0, times.size, 23), times.size - 1])
    ref = mp_step_response(model.A, model.B, model.C, model.D, times[picks])
    assert rel_err(result.outputs[picks], ref) <= EXACT_RTOL


CORPUS_CERT = Path(__file__).parent / "corpus" / "Xyce_Regression" / "Netlists" / "Certification_Tests"


@pytest.mark.parametrize(
    "name",
    [
        "dipc.cir",
        "servo_shaft.cir",
        "waveforms.cir",
        "cap_loop.cir",
        # Written by others, at realistic values: 60 Hz mains on 1 kΩ and 1 mH (L/R = 1 µs against a
        # 16.7 ms period) with five inductors coupled at 0.75 — a stiff SIN case (300 times over the
        # first 1.6 ms: each SIN substep is a Python step).
        CORPUS_CERT / "BUG_1957" / "mutindlin_odd_s3f5.cir",
    ],
    ids=lambda name: Path(name).name,
)
def test_vectorised_and_stepwise_exact_paths_agree(name: str | Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The vectorised modal path against stepping through every requested time with Van Loan's
    augmented exponential (PULSE, PWL, SIN and EXP sources, a D1 term). 2e-9 of the peak: both
    are exact for piecewise-linear inputs (they differ by rounding, ~1e-12 over 20 000 steps as
    measured by benchmarks/bench_foh.py); for SIN and EXP the vectorised path is exact and the
    stepwise one follows them by linear pieces within SMOOTH_INPUT_RTOL = 1e-9 (6e-10 measured),
    which its own check must see: it reports itself verified at 2e-9. 2000 random times over the
    first quarter of the horizon (a full SIN period, the EXP's rise; the SIN substeps cost a
    Python step each) keep the stepwise run at seconds, and put requested times between substeps
    of the SIN/EXP pieces (a requested time that rounding moved off the refined grid was once
    read one substep late: 7e-5 of the peak on waveforms.cir)."""
    from netlistdyn.simulation.foh import FohPropagator, propagate_foh

    net = parse_file(NETLISTS / name)
    model = compile_netlist(net, None)
    assert net.tran is not None
    signals = input_signals(net, net.tran.tstep, net.tran.tstop)
    corpus = isinstance(name, Path)
    span, count = (net.tran.tstop / 16, 300) if corpus else (net.tran.tstop / 4, 2_000)
    times = np.sort(np.r_[0.0, np.random.default_rng(5).uniform(0, span, count)])
    fast = propagate_foh(model, signals, times)
    # The stepwise path: through every requested time with Van Loan's augmented exponential.
    monkeypatch.setattr(FohPropagator, "modal", property(lambda self: False))
    slow = propagate_foh(model, signals, times, rtol=2e-9)
    assert slow.path == "augmented expm"
    if not corpus:
        assert slow.verified, slow.message
        assert rel_err(fast.outputs, slow.outputs) <= 2e-9
        return
    # The mains case: v(2) = L·di/dt is ~ωL/R = 4e-4 of the source, so linear pieces that follow
    # the SIN to 1e-9 of its amplitude leave ~1e-6 of v(2)'s peak (1.7e-6 measured). The stepped path
    # cannot reach 2e-9 here; what it must do is say so, with an estimate that covers its error.
    peaks = np.max(np.abs(fast.outputs), axis=0)
    actual = float(
        np.max(np.max(np.abs(fast.outputs - slow.outputs), axis=0) / np.where(peaks > 0, peaks, 1.0))
    )
    if slow.verified:
        assert actual <= 2e-9
    else:
        assert "cannot be vouched for" in slow.message
        assert actual <= slow.error, (actual, slow.error)


def test_phi_functions_against_mpmath() -> None:
    """φ1, φ2 to 4 ulps over |z| from 1e-20 to 1e2 in every direction. The reference carries
    40 + 2·log10(1/|z|) digits: φ2's cancellation costs twice the exponent."""
    from netlistdyn.simulation.foh import _phi12

    rng = np.random.default_rng(11)
    z = 10.0 ** rng.uniform(-20, 2, 400) * np.exp(1j * rng.uniform(0, 2 * np.pi, 400))
    z = np.r_[z, 0.0, 0.5, -0.5, 0.5j, 1e-300]
    phi1, phi2 = _phi12(z)
    for value, p1, p2 in zip(z, phi1, phi2, strict=True):
        digits = 40 + 2 * max(0, int(-np.log10(abs(value)))) if value else 40
        with mp.workdps(digits):
            mz = mp.mpc(value.real, value.imag)
            e1 = (mp.exp(mz) - 1) / mz if mz != 0 else mp.mpf(1)
            e2 = (mp.exp(mz) - 1 - mz) / mz**2 if mz != 0 else mp.mpf(0.5)
            assert abs(complex(e1) - p1) <= 4 * np.finfo(float).eps * abs(complex(e1)), value
            assert abs(complex(e2) - p2) <= 4 * np.finfo(float).eps * abs(complex(e2)), value


def mp_augmented_response(A_aug: np.ndarray, z0: np.ndarray, C_aug: np.ndarray, times) -> np.ndarray:
    """y(t) = C_aug e^{A_aug t} z0 in 40-digit arithmetic."""
    with mp.workdps(40):
        a, z, c = mp.matrix(A_aug.tolist()), mp.matrix(z0.tolist()), mp.matrix(C_aug.tolist())
        out = []
        for t in times:
            y = c * (mp.expm(a * t) * z)
            out.append([float(y[i, 0]) for i in range(c.rows)])
    return np.array(out)


@pytest.mark.parametrize(
    ("source", "generator"),
    [
        # u = 0.5 + 2 e^{-100 t} sin(2π·2000 t + 30°): states w1 = e^{-θt} sin(ωt+φ), w2 = e^{-θt} cos(ωt+φ)
        ("SIN(0.5 2 2k 0 100 30)", "sin"),
        # u = 1 + (−2 − 1)(1 − e^{−t/0.1m}) for t < TD2 = 1 s (beyond the horizon)
        ("EXP(1 -2 0 0.1m 1 0.2m)", "exp"),
    ],
)
def test_exact_sin_and_exp_inputs_against_an_augmented_system(source: str, generator: str) -> None:
    """SIN and EXP sources are propagated exactly (their exponential terms convolved in closed
    form), not by linear pieces: against the 40-digit exponential of the circuit augmented with
    the signal generator's own states, to EXACT_RTOL at 25 of 20 001 times."""
    text = f"rc\nV1 in 0 {source}\nR1 in a 1k\nC1 a 0 100n\nR2 a b 2k\nL1 b 0 10m\n.tran 1u 2m\n.end\n"
    net = parse_text(text)
    model = compile_string(text, ["v(a)", "i(L1)"])
    A, B, C, D = model.A, model.B, model.C, model.D
    n = model.nstates
    if generator == "sin":
        theta, omega, phi = 100.0, 2 * np.pi * 2000.0, np.radians(30.0)
        G = np.array([[0.0, 0.0, 0.0], [0.0, -theta, omega], [0.0, -omega, -theta]])  # [1, w1, w2]
        gain = np.array([[0.5, 2.0, 0.0]])
        g0 = np.array([1.0, np.sin(phi), np.cos(phi)])
    else:
        G = np.array([[0.0, 0.0], [0.0, -1.0 / 1e-4]])  # [1, e], u = −2 + 3 e
        gain = np.array([[-2.0, 3.0]])
        g0 = np.array([1.0, 1.0])
    k = G.shape[0]
    A_aug = np.block([[A, B @ gain], [np.zeros((k, n)), G]])
    C_aug = np.hstack([C, D @ gain])
    times = np.linspace(0.0, 2e-3, 20_001)
    result = integrators.run(model, input_signals(net, 1e-6, 2e-3), times, "exact")
    assert result.ok
    picks = np.unique(np.r_[0, np.random.default_rng(7).integers(0, times.size, 23), times.size - 1])
    ref = mp_augmented_response(A_aug, np.r_[np.zeros(n), g0], C_aug, times[picks])
    assert rel_err(result.outputs[picks], ref) <= EXACT_RTOL


def test_rational_stops_a_growing_fast_mode(monkeypatch: pytest.MonkeyPatch) -> None:
    """A 140 MHz mode growing at 1.3e5 1/s (a negative conductance, from a random network) made
    rational step for tens of minutes at 4 ns before the state could overflow; with a growing
    mode it now stops at its step budget with status "failed" and points to exact. The budget is
    lowered here so the test takes a second (the CLI's 100 000 steps took 32 s)."""
    text = """unstable: negative conductance
Vin n1 0 1
C0 n3 n2 3.9e-06
L1 n2 0 3.9e-11
L2 n2 n1 0.00022
L3 n2 n3 2.2e-11
R4 n1 0 0.0033
C5 n3 0 3.3e-08
L6 0 n3 8.2e-08
Rgn1 n1 0 180000
Rgn2 n2 0 8200
Rgn3 n3 0 820000
G1 n2 n1 n2 n1 -0.0086309984165507548
.end
"""
    monkeypatch.setattr(integrators, "RATIONAL_STEP_BUDGET", 2000)
    net = parse_text(text)
    model = compile_string(text, ["v(n3)"])
    times = np.linspace(0.0, 0.1, 101)
    result = integrators.run(model, input_signals(net, 1e-3, 0.1), times, "rational", rtol=1e-8)
    assert result.status == "failed"
    assert "growing mode" in result.message and "exact" in result.message
