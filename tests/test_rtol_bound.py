"""rtol bounds the error of a result that says ok (issue 13), over random linear circuits.

The circuits are :func:`tests.random_networks.random_network` at realistic values (E12
mantissas over mΩ…GΩ, pF…mF, pH…H), driven by a PWL source with four corners at random
times over a horizon drawn log-uniformly between the fastest and five times the slowest
time constant. The outputs are every node voltage but the driven one. Networks with a
growing mode (a VCCS can make one) are left out: the bound is for models without.

The reference is independent of netlistdyn's propagators and accurate whatever the stiffness:
the modal solution in mpmath (:func:`modal_reference`), the eigendecomposition of A at
:data:`REFERENCE_DIGITS` digits, each mode carried from breakpoint to breakpoint and output time to
output time by e^{λh}, h·φ1(λh) and h·φ2(λh) (exact for inputs linear between corners), evaluated
a second time at :data:`CHECK_DIGITS` digits. Their difference, relative to each output's peak, is
the reference's stated error (an ill-conditioned eigenvector basis loses digits in proportion to its
condition number, at each precision alike); a case where it exceeds :data:`REFERENCE_RTOL` is left
unjudged. (The earlier reference, scipy's ``expm`` of Van Loan's augmented matrix in double
precision, is off by up to 1e-9 of the peak when a mode makes ‖Ah‖ ~ 1e6: seed 683 below; and the
earlier judging rule trusted it where netlistdyn's ``exact`` agreed, which has the same weakness.)
Errors are measured, as the methods report them, relative to each output's own peak.
"""

from __future__ import annotations

import os
import signal

import mpmath
import numpy as np
import pytest
import scipy.linalg
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.frontend.parser import parse_text
from netlistdyn.simulation import integrators
from netlistdyn.simulation.foh import input_signals, refine_grid

from .random_networks import random_network

#: Largest difference, relative to each output's peak, between the reference at REFERENCE_DIGITS and
#: at CHECK_DIGITS for a case to be judged (measured over the campaign's cases: below one rounding of
#: a double, i.e. the two evaluations give the same floats).
REFERENCE_RTOL = 1e-13
#: Working precisions (decimal digits) of the reference and of its check.
REFERENCE_DIGITS, CHECK_DIGITS = 50, 40
#: CPU seconds one run may take in the property tests; a longer one is not judged (the bound is
#: about accuracy: ``rational`` takes minutes on a few very stiff real spectra, e.g. seed 0's modes
#: at −1.1e11, −1.3e9 and −3e4 1/s over 100 steps of 1.2 µs; the campaign counts them as stopped).
RUN_SECONDS = 3.0
#: Fixed examples (deterministic CI); the bound itself is what is tested, on each of them. A long
#: run: NETLISTDYN_RTOL_EXAMPLES=500 (or benchmarks/rtol_campaign.py, which counts and reports).
SETTINGS = settings(
    max_examples=int(os.environ.get("NETLISTDYN_RTOL_EXAMPLES", "8")),
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)


def driven_case(seed: int):
    """(model, times, signals) of a random realistic network on a PWL source, or None."""
    rng = np.random.default_rng(seed)
    text = random_network(rng, spread=False)
    model = compile_netlist(parse_text(text), [])
    if model.nstates == 0:
        return None
    eigenvalues = np.linalg.eigvals(model.A)
    if np.max(eigenvalues.real) > 0:  # a growing mode: rtol bounds nothing over its growth
        return None
    rates = np.abs(eigenvalues)
    rates = rates[rates > 0]
    if rates.size == 0:
        return None
    horizon = 10 ** rng.uniform(np.log10(1 / rates.max()), np.log10(5 / rates.min()))
    corners = np.sort(rng.uniform(0, horizon, 4))
    values = rng.uniform(-1, 1, 4)
    pwl = " ".join(f"{float(t)!r} {float(v)!r}" for t, v in zip(corners, values, strict=True))
    net = parse_text(text.replace("Vin n1 0 1", f"Vin n1 0 PWL(0 0 {pwl})"))
    nodes = sorted({n for e in net.elements for n in e.nodes} - {"0", "n1"})
    if not nodes:
        return None
    model = compile_netlist(net, [f"v({n})" for n in nodes])
    times = np.linspace(0.0, horizon, 101)
    return model, times, input_signals(net, horizon / 100, horizon)


def van_loan(model, signals, times: np.ndarray) -> np.ndarray:
    """The earlier reference: scipy's double-precision ``expm`` of Van Loan's augmented matrix
    [[hA, hB, 0], [0, 0, I], [0, 0, 0]], breakpoint to breakpoint. Accurate while ‖Ah‖ is
    moderate, off by up to 1e-9 of the peak where a stiff mode makes it ~1e6 (seed 683); kept to
    cross-check :func:`modal_reference` where both are accurate, and to show that case."""
    n, m = model.nstates, model.ninputs
    events = refine_grid(times, signals)
    u, u_left = signals(events), signals.left(events)
    x = np.zeros(n)
    y = {0.0: model.D @ u[0]}
    for k in range(1, events.size):
        h = events[k] - events[k - 1]
        if h > 0:
            M = np.zeros((n + 2 * m, n + 2 * m))
            M[:n, :n] = model.A * h
            M[:n, n : n + m] = model.B * h
            M[n : n + m, n + m :] = np.eye(m)
            x = (scipy.linalg.expm(M) @ np.concatenate([x, u[k - 1], u_left[k] - u[k - 1]]))[:n]
        y[float(events[k])] = model.C @ x + model.D @ u[k]
    return np.array([y[float(t)] for t in times])


def _phi(w, tiny):
    """φ1(w) = (e^w − 1)/w and φ2(w) = (e^w − 1 − w)/w², to the working precision (series near 0)."""
    if abs(w) >= 0.5:
        em1 = mpmath.expm1(w)
        return em1 / w, (em1 - w) / (w * w)
    phi1 = phi2 = mpmath.mpf(0)
    term, k = mpmath.mpf(1), 0  # w^k / k!
    while True:
        phi1 += term / (k + 1)
        phi2 += term / ((k + 1) * (k + 2))
        if abs(term) < tiny:
            return phi1, phi2
        k += 1
        term = term * w / k


def modal_outputs(model, signals, times: np.ndarray, digits: int) -> np.ndarray | None:
    """Outputs at ``times`` from rest, by the modal solution at ``digits`` decimal digits.

    A = V Λ V⁻¹ (mpmath's eigendecomposition of the model's A, its floats taken exactly); a mode
    z = (V⁻¹x)ᵢ over an interval h on which the input goes linearly from u0 to u1 becomes
    e^{λh} z + h φ1(λh) (V⁻¹B u0)ᵢ + h φ2(λh) (V⁻¹B (u1 − u0))ᵢ, exactly; y = Re(C V z) + D u.
    None when mpmath finds no eigendecomposition.
    """
    n, m = model.nstates, model.ninputs
    events = refine_grid(times, signals)
    u, u_left = signals(events), signals.left(events)
    wanted = {float(t) for t in times}
    out = {}
    with mpmath.workdps(digits):
        tiny = mpmath.mpf(10) ** (-digits - 5)
        try:
            lam, V = mpmath.eig(mpmath.matrix(model.A.tolist()))
            drive = mpmath.inverse(V) * mpmath.matrix(model.B.tolist())
        except (ZeroDivisionError, ValueError):
            return None
        seen = mpmath.matrix(model.C.tolist()) * V
        z = [mpmath.mpc(0)] * n

        def outputs() -> list[float]:
            return [
                float(mpmath.re(mpmath.fsum(seen[j, i] * z[i] for i in range(n)))) for j in range(seen.rows)
            ]

        out[0.0] = outputs()
        for k in range(1, events.size):
            h = mpmath.mpf(float(events[k])) - mpmath.mpf(float(events[k - 1]))
            if h > 0:
                u0 = [mpmath.mpf(float(v)) for v in u[k - 1]]
                du = [
                    mpmath.mpf(float(a)) - mpmath.mpf(float(b))
                    for a, b in zip(u_left[k], u[k - 1], strict=True)
                ]
                for i in range(n):
                    w = lam[i] * h
                    phi1, phi2 = _phi(w, tiny)
                    base = mpmath.fsum(drive[i, j] * u0[j] for j in range(m))
                    ramp = mpmath.fsum(drive[i, j] * du[j] for j in range(m))
                    z[i] = mpmath.exp(w) * z[i] + h * (phi1 * base + phi2 * ramp)
            if float(events[k]) in wanted:
                out[float(events[k])] = outputs()
    return np.array([out[float(t)] for t in times]) + signals(times) @ model.D.T


def modal_reference(model, signals, times: np.ndarray) -> tuple[np.ndarray | None, float]:
    """(outputs at REFERENCE_DIGITS, their stated error): the peak-relative difference from the
    same solution at CHECK_DIGITS (inf when either has no eigendecomposition)."""
    reference = modal_outputs(model, signals, times, REFERENCE_DIGITS)
    check = modal_outputs(model, signals, times, CHECK_DIGITS)
    if reference is None or check is None:
        return None, float("inf")
    return reference, peak_error(check, reference)


def peak_error(y: np.ndarray, ref: np.ndarray) -> float:
    """Largest error relative to each output's own peak."""
    peak = np.maximum(np.max(np.abs(ref), axis=0), np.finfo(float).tiny)
    return float(np.max(np.abs(y - ref) / peak))


def judged_case(seed: int):
    """A case with a trustworthy reference, (model, times, signals, reference), or None."""
    case = driven_case(seed)
    if case is None:
        return None
    model, times, signals = case
    reference, error = modal_reference(model, signals, times)
    if reference is None or not error <= REFERENCE_RTOL:
        return None
    return model, times, signals, reference


class _OutOfTime(Exception):
    """A run used up its CPU seconds."""


def _stop(signum: int, frame: object) -> None:
    raise _OutOfTime


def limited_run(model, signals, times, method: str, rtol: float, seconds: float = RUN_SECONDS):
    """``integrators.run`` stopped after ``seconds`` of CPU time (None then)."""
    previous = signal.signal(signal.SIGVTALRM, _stop)
    signal.setitimer(signal.ITIMER_VIRTUAL, seconds)
    try:
        return integrators.run(model, signals, times, method, rtol=rtol)
    except _OutOfTime:
        return None
    finally:
        signal.setitimer(signal.ITIMER_VIRTUAL, 0)
        signal.signal(signal.SIGVTALRM, previous)


@SETTINGS
@given(seed=st.integers(0, 2**31 - 1), rtol=st.sampled_from([1e-5, 1e-8]))
def test_rational_error_within_rtol_when_ok(seed: int, rtol: float) -> None:
    case = judged_case(seed)
    assume(case is not None)
    model, times, signals, reference = case
    result = limited_run(model, signals, times, "rational", rtol)
    assume(result is not None)
    error = peak_error(result.outputs, reference)
    assert result.ok or result.status == "unverified", result.message
    if result.ok:
        assert error <= rtol, f"{error:.2g} > rtol {rtol:g} ({result.stats})"


@SETTINGS
@given(seed=st.integers(0, 2**31 - 1), rtol=st.sampled_from([1e-6, 1e-9]))
def test_exact_error_within_rtol_when_ok(seed: int, rtol: float) -> None:
    case = judged_case(seed)
    assume(case is not None)
    model, times, signals, reference = case
    result = limited_run(model, signals, times, "exact", rtol)
    assume(result is not None)
    if result.ok:
        assert peak_error(result.outputs, reference) <= rtol


@pytest.mark.parametrize("seed", [54])
def test_rational_judges_each_output_on_its_own_scale(seed: int) -> None:
    """Found by the campaign: a capacitor charge (1e-6 C, output 0.9 V) beside an inductor current
    (13 A) in a model with a diagonal A (balancing cannot equalise them). Judged against the
    largest state only, the step check passed steps whose error was 1.2e-7 of v(n2)'s peak at
    every rtol."""
    case = judged_case(seed)
    assert case is not None
    model, times, signals, reference = case
    result = integrators.run(model, signals, times, "rational", rtol=1e-9)
    assert result.ok, result.message
    assert peak_error(result.outputs, reference) <= 1e-9


@pytest.mark.parametrize("seed", [442])
def test_exact_counts_the_recurrence_rounding_of_slow_modes(seed: int) -> None:
    """Found by the long run (benchmarks/rtol_campaign.py): v(n2) = 22 mΩ · i(L1) peaks at
    2.5e-13 V beside a stiff pair (-4.5e11 1/s) and an inductor loop. The 40-digit modal path
    counted 8 eps of each mode's largest |z| for its evaluation, but each of its ~2000 grid steps
    multiplies a mode by the same rounded e^{λh}: the error grew linearly to 3.8e-9 of the
    peak while the estimate said 6.3e-10, and the result said ok at rtol 1e-9."""
    case = judged_case(seed)
    assert case is not None
    model, times, signals, reference = case
    result = integrators.run(model, signals, times, "exact", rtol=1e-9)
    if result.ok:
        assert peak_error(result.outputs, reference) <= 1e-9
    assert result.ok or result.status == "unverified", result.message


@pytest.mark.parametrize("tau_over_h", [1e-7, 1.0, 1e3])
def test_modal_reference_matches_the_closed_form_of_a_ramp_through_rc(tau_over_h: float) -> None:
    """v(n2) behind 4.7 kΩ and a capacitor, driven by a ramp of slope s from 0: s(t − τ(1 − e^{−t/τ}))
    (mpmath, 30 digits). Stiff (|λh| = 1e7), matched and slow steps (|λh| = 1e-3: φ's series). The
    reference's stated accuracy is a double's rounding: 1e-14 of the peak leaves 10x for the
    closed form's own rounding."""
    h = 1e-6
    tau = tau_over_h * h
    res = 4.7e3
    cap = tau / res
    stop = 100 * h
    net = parse_text(f"rc\nVin n1 0 PWL(0 0 {stop!r} 1)\nR1 n1 n2 {res!r}\nC1 n2 0 {cap!r}\n.end\n")
    model = compile_netlist(net, ["v(n2)"])
    times = np.linspace(0.0, stop, 101)
    signals = input_signals(net, h, stop)
    reference, stated = modal_reference(model, signals, times)
    assert reference is not None and stated <= REFERENCE_RTOL
    with mpmath.workdps(30):
        tau_mp = mpmath.mpf(res) * mpmath.mpf(cap)
        expected = np.array(
            [float((t - tau_mp * -mpmath.expm1(-t / tau_mp)) / stop) for t in map(mpmath.mpf, times)]
        )
    assert peak_error(reference[:, 0:1], expected[:, None]) <= 1e-14


@pytest.mark.parametrize("seed", [1, 10, 12, 13])
def test_modal_reference_agrees_with_van_loan_where_both_are_accurate(seed: int) -> None:
    """Two independent algorithms (eigendecomposition at 50 digits; Padé scaling and squaring in
    double) on cases whose ‖Ah‖ stays below 15, where expm's error is ~1e-15·‖Ah‖: they agree to
    2.4e-14 of each output's peak (measured); 1e-13 is the bound."""
    case = driven_case(seed)
    assert case is not None
    model, times, signals = case
    assert np.abs(np.linalg.eigvals(model.A)).max() * (times[1] - times[0]) < 15
    reference, stated = modal_reference(model, signals, times)
    assert reference is not None and stated <= REFERENCE_RTOL
    assert peak_error(van_loan(model, signals, times), reference) <= 1e-13


def test_seed_683_is_judged_against_an_accurate_reference() -> None:
    """Found by the long run: a −1.4e13 1/s mode beside slow ones makes ‖Ah‖ ~1.4e6 on the output
    grid. The double-precision Van Loan reference is off there by 1.1e-9 of an output's peak, and
    judged ``exact`` at rtol 1e-9 to have broken its bound; the modal reference (stated error
    below a double's rounding) finds ``exact`` within 3.2e-12 of it, and the Van Loan result
    more than 100 times further away than ``exact``."""
    case = judged_case(683)
    assert case is not None
    model, times, signals, reference = case
    assert np.abs(np.linalg.eigvals(model.A)).max() * (times[1] - times[0]) > 1e6
    result = integrators.run(model, signals, times, "exact", rtol=1e-9)
    assert result.ok, result.message
    error = peak_error(result.outputs, reference)
    assert error <= 1e-9
    assert peak_error(van_loan(model, signals, times), reference) > 100 * error
    rational = integrators.run(model, signals, times, "rational", rtol=1e-8)
    assert not rational.ok or peak_error(rational.outputs, reference) <= 1e-8
    # At 1e-11 the modal estimate (3e-11) fails and the augmented-expm path is 1.07e-9 off: its
    # halving check alone said 3e-14 (ok); with expm's eps·‖Ah‖ counted it says 3e-10, unverified.
    tight = integrators.run(model, signals, times, "exact", rtol=1e-11)
    assert tight.ok or tight.status == "unverified", tight.message
    assert not tight.ok or peak_error(tight.outputs, reference) <= 1e-11


@pytest.mark.parametrize(
    ("seed", "rtol"), [(124, 1e-9), (187, 1e-9), (187, 1e-6), (205, 1e-6), (205, 1e-9), (215, 1e-9)]
)
def test_exact_forms_refined_outputs_from_the_refined_output_matrix(seed: int, rtol: float) -> None:
    """Found by the long run with the accurate reference: the 40-digit modal path formed its outputs
    as C·x from double states (and its estimate from C·V in double), while a mode's coordinate
    was huge and its output weight C·vᵢ a near-cancellation. Seed 187: modes ~0, −0.12 and
    −1.2e15 1/s over 6.2e8 s, a null-vector coordinate of 1.8e17 and v(n4) = 2200·(i(L0) −
    i(L2) − i(L3)), whose C·v is 5e-14 in double and ~1e-24 exactly: −2.48 V for −2.6e-5 V, an
    error 2.4e7 of the peak with an estimate of 2e-13, status ok. Seeds 124, 205 (a double zero
    eigenvalue, modal coordinates 8e13) and 215 alike, 1e-8 to 6e-3 of the peak. Now every
    result that says ok is within rtol (measured 3e-16, 3.5e-9, 1.3e-13, 3e-16) and seed 205 at
    1e-9, beyond what the modal path can vouch for, does not say ok."""
    case = judged_case(seed)
    assert case is not None
    model, times, signals, reference = case
    result = integrators.run(model, signals, times, "exact", rtol=rtol)
    assert result.ok or result.status == "unverified", result.message
    if seed != 205 or rtol >= 1e-6:
        assert result.ok, result.message
    if result.ok:
        assert peak_error(result.outputs, reference) <= rtol


#: Results that say ok beyond their rtol, found by ``benchmarks/rtol_campaign.py --count 200`` once
#: the reference was accurate (the old judging rule had left these cases out: it asked ``exact`` at
#: 1e-11 to agree with the double-precision Van Loan reference, and it did not). Each reference was
#: confirmed by mpmath's own expm (Taylor, scaling and squaring) of Van Loan's matrix at 50 digits,
#: which gives the same floats. (Seeds 124, 187, 205 and 215 of ``exact``'s 40-digit modal path are
#: fixed: test_exact_forms_refined_outputs_from_the_refined_output_matrix; seed 683 at rtol 1e-11,
#: its augmented-expm path: test_seed_683_is_judged_against_an_accurate_reference.)
OPEN_VIOLATIONS = [
    (
        95,
        "exact",
        1e-6,
        "8.7e-4 of v(n2)'s peak, estimate 9e-8: the double-precision modal path (modes -3.8e7, -9e6, "
        "-66, -1.2e-10 1/s; inductor currents of 8e9 A circulating against each other); at rtol 1e-9 "
        "the 40-digit path is taken and is within 5e-16",
    ),
    (
        51,
        "rational",
        1e-8,
        "7.6e-7 of the peak, estimate 7.7e-9 (modes 0, -1.8e-2, -4.4e3±1.1e3j, -5e7 1/s over 9.3 s); "
        "closed by issue 28: each state's rounding counts what the step couples into it (|x| and, "
        "weighted by min(1, h·Σ|aᵢⱼ|), its row's states), which sees that v(n3) (peak 1.6e-9 V beside "
        "3.7e-4 V) is summed from much larger states: estimate 2.1e-8, status unverified",
    ),
]
#: Closed violations: a plain test each (the result is no longer ok beyond its rtol).
CLOSED = (51,)


@pytest.mark.parametrize(
    ("seed", "method", "rtol"),
    [
        pytest.param(
            seed,
            method,
            rtol,
            # seed 95's error is rounding of 8e9 A modal terms in LAPACK's eigenvectors: its size
            # may differ with the BLAS, so a pass elsewhere is not an error there
            marks=() if seed in CLOSED else pytest.mark.xfail(reason=f"open: {why}", strict=seed != 95),
        )
        for seed, method, rtol, why in OPEN_VIOLATIONS
    ],
)
def test_open_violations_found_by_the_campaign(seed: int, method: str, rtol: float) -> None:
    case = judged_case(seed)
    assert case is not None
    model, times, signals, reference = case
    result = integrators.run(model, signals, times, method, rtol=rtol)
    assert not result.ok or peak_error(result.outputs, reference) <= rtol
