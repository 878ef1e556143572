"""Forward Euler at a fixed step (issue #15): the method the lecture notes animate the DIPC with.

The notes' figure carries a lesson: at dt = 0.03 s Euler's θ2 is already ~10 % off at 0.3 s. The
method must be Euler exactly (an independent loop in this file reproduces it to 1e-12 of the peak)
and must say how far it is from the exact solution (checked against scipy's ``lsim``).
"""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner
from scipy import signal

import netlistdyn
from netlistdyn.cli import main

from .conftest import NETLISTS

DIPC = NETLISTS / "dipc.cir"
ANGLES = ["angle(r1)", "angle(r2)"]
H = 0.03
TSTOP = 1.5


def _force(t: np.ndarray) -> np.ndarray:
    """The DIPC's push, PULSE(0 1 0 10m 10m 80m 100), written out by hand: 0→1 in 10 ms, 80 ms at 1, 1→0."""
    t = np.asarray(t, dtype=float)
    return np.interp(t, [0.0, 0.01, 0.09, 0.10, 100.0], [0.0, 1.0, 1.0, 0.0, 0.0])


def _model_and_start() -> tuple:
    """A, B, C, D with the two rod angles as outputs, and the state at θ1 = −0.01, θ2 = −0.02 rad.

    The start is solved here from C alone: momenta zero (the cart and bobs at rest), the two rod
    forces from the two angles (the angles depend on nothing else).
    """
    model = netlistdyn.compile(DIPC, outputs=ANGLES)
    forces = [k for k, s in enumerate(model.states) if s.startswith("f(")]
    assert len(forces) == 2 and model.nstates == 5
    x0 = np.zeros(model.nstates)
    x0[forces] = np.linalg.solve(model.C[:, forces], [-0.01, -0.02])
    others = [k for k in range(model.nstates) if k not in forces]
    assert np.all(model.C[:, others] == 0)  # the angles do not involve the momenta
    return model, x0


def test_euler_reproduces_an_independent_loop_and_reports_its_error() -> None:
    model, x0 = _model_and_start()
    A, B, C, D = (np.asarray(m, dtype=float) for m in (model.A, model.B, model.C, model.D))
    steps = round(TSTOP / H)
    t = np.arange(steps + 1) * H
    x = x0.copy()
    loop = np.empty((steps + 1, 2))
    for k in range(steps + 1):
        u = np.array([_force(t[k])])
        loop[k] = C @ x + D @ u
        x = x + H * (A @ x + B @ u)
    sim = netlistdyn.simulate(
        DIPC, outputs=ANGLES, method="euler", step=H, tstop=TSTOP, x0={"angle(r1)": -0.01, "angle(r2)": -0.02}
    )
    np.testing.assert_allclose(sim.time, t, rtol=0, atol=1e-15)
    peak = np.max(np.abs(loop), axis=0)
    assert np.all(np.abs(sim.values - loop) <= 1e-12 * peak)
    assert sim.values[0] == pytest.approx([-0.01, -0.02], abs=1e-15)
    # The exact solution from an independent method: scipy's lsim, first-order hold on a 1 ms grid
    # that contains every corner of the push (exact for a piecewise-linear input).
    fine = np.arange(round(TSTOP / 1e-3) + 1) * 1e-3
    _, exact, _ = signal.lsim(signal.StateSpace(A, B, C, D), _force(fine), fine, X0=x0, interp=True)
    exact = exact[:: round(H / 1e-3)]
    expected = np.max(np.abs(loop - exact), axis=0) / np.max(np.abs(exact), axis=0)
    for name, value in zip(ANGLES, expected, strict=True):
        # lsim's own accuracy (~1e-10 of the peak over this unstable run) bounds the agreement.
        assert sim.stats[f"error_vs_exact {name}"] == pytest.approx(value, rel=1e-6)
    assert sim.stats["error_vs_exact"] == pytest.approx(max(expected), rel=1e-6)
    assert "forward Euler, h = 0.03 s" in sim.message and "angle(r2)" in sim.message
    assert sim.stats["error_vs_exact"] > 0.05  # the notes' lesson: at this step Euler is visibly off


def test_euler_on_the_command_line_states_its_error() -> None:
    args = ["simulate", str(DIPC), "--method", "euler", "--step", "30m", "--tstop", "0.3"]
    args += ["--ic", "angle(r1)=-0.01", "--ic", "angle(r2)=-0.02", "--output", "angle(r2)"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    assert "11 points every 30 ms" in result.output
    assert "max |error| / peak against exact at the same times: angle(r2)" in result.output


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--method", "euler"], "--method euler needs a fixed step: --step H"),
        (["--step", "1m"], "--step is the fixed step of --method euler"),
        (["--method", "euler", "--step", "1m", "--tstep", "2m"], "--tstep must be --step"),
    ],
)
def test_euler_options_are_checked(extra: list[str], message: str) -> None:
    result = CliRunner().invoke(main, ["simulate", str(DIPC), *extra])
    assert result.exit_code == 2
    assert message in result.output


def test_api_x0_takes_physical_variables_like_ic() -> None:
    """`simulate(x0={"angle(r1)": ...})` starts where `--ic angle(r1)=...` does; outputs as asked."""
    model, x0 = _model_and_start()
    by_angle = netlistdyn.simulate(
        DIPC, outputs=["x(cart)"], tstop=0.5, x0={"angle(r1)": -0.01, "angle(r2)": "-20m"}
    )
    by_state = netlistdyn.simulate(
        DIPC, outputs=["x(cart)"], tstop=0.5, x0=dict(zip(model.states, x0, strict=True))
    )
    assert by_angle.outputs == ("x(cart)",)
    peak = np.max(np.abs(by_state.values))
    assert np.max(np.abs(by_angle.values - by_state.values)) <= 1e-12 * peak
