"""The ``rational`` stepper ends (issue 28): no halving without end, a one-line stop instead.

An RLC ladder's far nodes are still ≈ 0 when the step from rest begins: the approximant's relative
error on them is O(1) at every step length (they are made of powers of hA beyond its order), so a
check against each output's running peak halved the step without end (the 100-section ladder at
the default rtol ran for minutes; 1000 sections stopped after 200 s of CPU and 830 MB). The runs
here are bounded by a count of Padé steps (a wrapper that raises past it), not by a timer: the old
code fails them instead of hanging.
"""

from __future__ import annotations

import numpy as np
import pytest

from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.frontend.parser import parse_text
from netlistdyn.simulation import integrators
from netlistdyn.simulation.foh import input_signals

#: Padé step applications (main and check) a run may use here: the 100-section ladder needs
#: about 1,500 (1,000 steps, 413 checks); the old code had used 40,000 within 20 s and went on.
STEP_CALLS = 20_000


class _TooManySteps(Exception):
    """The run used up its step count."""


def _ladder(sections: int) -> str:
    """RLC ladder (1 Ω + 1 mH series, 1 µF shunt) driven by a unit step, as benchmarks/ladder.py."""
    lines = ["ladder", "Vin in 0 DC 1"]
    prev = "in"
    for k in range(1, sections + 1):
        lines += [f"R{k} {prev} m{k} 1", f"L{k} m{k} n{k} 1m", f"C{k} n{k} 0 1u"]
        prev = f"n{k}"
    horizon = 2.0 * sections * (1e-3 * 1e-6) ** 0.5
    return "\n".join([*lines, f".tran {horizon / 1000!r} {horizon!r} uic", ".end"]) + "\n"


@pytest.fixture
def step_count(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Counts Padé step applications and raises past STEP_CALLS."""
    calls = [0]
    original = integrators._PadeStep.__call__

    def counted(self, x, u, s):  # type: ignore[no-untyped-def]
        calls[0] += 1
        if calls[0] > STEP_CALLS:
            raise _TooManySteps
        return original(self, x, u, s)

    monkeypatch.setattr(integrators._PadeStep, "__call__", counted)
    return calls


def _ladder_run(sections: int, rtol: float) -> tuple[integrators.SimResult, np.ndarray]:
    net = parse_text(_ladder(sections))
    model = compile_netlist(net, None)
    tran = net.tran
    assert tran is not None
    times = np.linspace(0.0, tran.tstop, round(tran.tstop / tran.tstep) + 1)
    signals = input_signals(net, tran.tstep, tran.tstop)
    result = integrators.run(model, signals, times, "rational", rtol=rtol)
    reference = integrators.run(model, signals, times, "exact", rtol=1e-12)
    return result, reference.outputs


@pytest.mark.parametrize("rtol", [1e-10, 1e-9])
def test_ladder_far_nodes_still_at_zero_do_not_halve_the_step_without_end(
    step_count: list[int], rtol: float
) -> None:
    """100 sections (200 states), the default rtol and 1e-9: ends, ok, and within rtol of the dense
    exact method (its own estimate ~1e-13 on this model: 200 states, every eigenvalue resolved)."""
    result, reference = _ladder_run(100, rtol)
    assert result.ok, result.message
    peak = np.max(np.abs(reference), axis=0)
    assert np.max(np.abs(result.outputs - reference) / peak) <= rtol
    assert step_count[0] <= STEP_CALLS


def test_halving_has_a_limit_and_says_where(monkeypatch: pytest.MonkeyPatch, step_count: list[int]) -> None:
    """An injected fault (the diagonal check approximant off by 1 %) makes every check fail: the
    run stops where both approximants are exact to rounding (the difference is then far above
    rounding), failed, with one line naming the time."""
    good = integrators.pade_factors

    def broken(diagonal: bool = False) -> tuple[tuple[complex, complex, float], ...]:
        factors = good(diagonal)
        return tuple((p, a * 1.01, c) for p, a, c in factors) if diagonal else factors

    monkeypatch.setattr(integrators, "pade_factors", broken)
    result, _ = _ladder_run(5, 1e-9)
    assert result.status == "failed"
    assert "\n" not in result.message
    assert "stopped at t = 0 s" in result.message and "times the rounding level" in result.message
