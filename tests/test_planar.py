"""Planar mechanisms (issue 26) against an independent derivation with sympy.physics.mechanics.

Each system is described here by hand, as the lecture notes write it — the points' positions in
the notes' coordinates, the particles' masses, gravity, the applied force — and sympy's
``LagrangesMethod`` derives its equations; its ``linearize`` (the Linearizer) gives A and B. None
of this reads netlistdyn's kinematics: the netlists in ``netlists/planar/`` describe the same
systems with LINK/SLIDER/BODY cards and netlistdyn walks its own tree.

Tolerances, and why:
- mass matrix and forcing at random states: 1e-12 of the largest entry (both are sums of a few
  products of cosines; rounding is ~1e-15);
- A, B at the equilibria: 1e-12 of the largest entry (ours by the complex step, exact to rounding;
  sympy's evaluated from exact rationals);
- trajectories: ours at rtol 1e-10 against DOP853 at rtol 1e-12 on sympy's lambdified
  equations, within 1e-8 of each output's peak (the horizon is kept where the motion's
  sensitivity to a 1e-10 error stays below 100: 10 s for the double pendulum from 0.5 rad,
  1.2 s for the unstable DIPC);
- forward Euler: the same map on both sides (x + h f(x)); 1e-9 relative while |θ| < 1 rad
  (different rounding of f, ~1e-15 per step, amplified by the unstable modes, e^(9.17·t));
- energy of an exact run: 1e-8 relative (DOP853 at rtol 1e-10 over the run).
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.integrate import solve_ivp

from netlistdyn.analysis.coordinates import prepare
from netlistdyn.base.errors import NetlistError
from netlistdyn.cli import main
from netlistdyn.formulation.planar import PlanarSystem
from netlistdyn.frontend.parser import parse_file, parse_text
from netlistdyn.simulation.planartransient import simulate_planar
from netlistdyn.workflows.planar import planar_linear_model, planar_point

ROOT = Path(__file__).resolve().parent.parent
PLANAR = ROOT / "netlists" / "planar"
#: Mass matrix and forcing agreement (relative to the largest entry).
MATRIX_RTOL = 1e-12
#: Linearisation agreement (relative to the largest entry of A, of B).
LINEAR_RTOL = 1e-12
#: Trajectory agreement (relative to each output's peak).
TRAJECTORY_RTOL = 1e-8
#: Forward-Euler agreement with an independent loop (relative, while |θ| < 1 rad).
EULER_RTOL = 1e-9
#: Energy drift of an exact run (relative).
ENERGY_RTOL = 1e-8


@functools.cache
def derivation(system: str) -> dict[str, Any]:
    """The system by hand in sympy: Lagrange's equations, lambdified, and its linearisation."""
    import sympy as sm
    import sympy.physics.mechanics as me

    N = me.ReferenceFrame("N")
    O = me.Point("O")  # noqa: E741 (sympy.physics.mechanics' own name for the origin)
    O.set_vel(N, 0)
    R = sm.Rational
    F = me.dynamicsymbols("F")

    def placed(base: Any, name: str, offset: Any) -> Any:
        point = base.locatenew(name, offset)
        point.set_vel(N, point.pos_from(O).dt(N))
        return point

    if system == "dipc":  # the notes' Lagrangian: cart x, theta from the upward vertical
        x, t1, t2 = me.dynamicsymbols("x theta1 theta2")
        values = {"M": R(3, 2), "m1": R(1, 2), "m2": R(3, 4), "l1": R(1, 2), "l2": R(3, 4), "g": R(981, 100)}
        v = values
        cart = placed(O, "C", x * N.x)
        b1 = placed(cart, "B1", v["l1"] * (sm.sin(t1) * N.x + sm.cos(t1) * N.y))
        b2 = placed(b1, "B2", v["l2"] * (sm.sin(t2) * N.x + sm.cos(t2) * N.y))
        particles = [(cart, v["M"]), (b1, v["m1"]), (b2, v["m2"])]
        q = [x, t1, t2]
        loads = [(cart, F * N.x)]
        path = PLANAR / "dipc.cir"
    elif system == "double_pendulum":  # theta from the downward vertical
        t1, t2 = me.dynamicsymbols("theta1 theta2")
        values = {"m1": 1, "m2": 1, "l1": 1, "l2": 1, "g": 10}
        b1 = placed(O, "B1", sm.sin(t1) * N.x - sm.cos(t1) * N.y)
        b2 = placed(b1, "B2", sm.sin(t2) * N.x - sm.cos(t2) * N.y)
        particles = [(b1, 1), (b2, 1)]
        q = [t1, t2]
        loads = [(b2, F * N.x)]
        path = PLANAR / "double_pendulum.cir"
    else:
        raise AssertionError(system)
    g = values["g"]
    bodies = []
    for k, (point, mass) in enumerate(particles):
        particle = me.Particle(f"P{k}", point, mass)
        particle.potential_energy = mass * g * point.pos_from(O).dot(N.y)
        bodies.append(particle)
    L = me.Lagrangian(N, *bodies)
    method = me.LagrangesMethod(L, q, forcelist=loads, frame=N)
    method.form_lagranges_equations()
    qd = [s.diff() for s in q]
    plain = sm.symbols(f"q0:{len(q)}"), sm.symbols(f"u0:{len(q)}"), sm.Symbol("F0")
    swap = dict(zip(qd, plain[1], strict=True)) | dict(zip(q, plain[0], strict=True)) | {F: plain[2]}
    args = [*plain[0], *plain[1], plain[2]]
    mass = sm.lambdify(args, method.mass_matrix.subs(swap), "numpy")
    forcing = sm.lambdify(args, method.forcing.subs(swap), "numpy")
    energy = sm.lambdify(
        args,
        sum(b.kinetic_energy(N) + b.potential_energy for b in bodies).subs(swap),
        "numpy",
    )
    return {
        "method": method,
        "q": q,
        "qd": qd,
        "F": F,
        "mass": lambda x, u: np.array(mass(*x, u), dtype=float),
        "forcing": lambda x, u: np.array(forcing(*x, u), dtype=float).ravel(),
        "energy": lambda x: float(energy(*x, 0.0)),
        "path": path,
        "n": len(q),
    }


def sympy_rhs(d: dict[str, Any], x: np.ndarray, u: float = 0.0) -> np.ndarray:
    n = d["n"]
    return np.concatenate([x[n:], np.linalg.solve(d["mass"](x, u), d["forcing"](x, u))])


def sympy_linear(d: dict[str, Any], q0: list[Any]) -> tuple[np.ndarray, np.ndarray]:
    import sympy as sm

    op = dict(zip(d["q"], q0, strict=True)) | dict.fromkeys(d["qd"], 0) | {d["F"]: 0}
    op |= {s.diff(): 0 for s in d["qd"]}
    A, B, _ = d["method"].linearize(q_ind=d["q"], qd_ind=d["qd"], A_and_B=True, op_point=op)
    A = A.subs(op)
    B = B.subs(op)
    return (
        np.array(sm.N(sm.simplify(A), 30), dtype=float),
        np.array(sm.N(sm.simplify(B), 30), dtype=float),
    )


def relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


SYSTEMS = ["dipc", "double_pendulum"]


@pytest.mark.parametrize("system", SYSTEMS)
def test_mass_matrix_and_forcing_at_random_states(system: str) -> None:
    d = derivation(system)
    ours = PlanarSystem(parse_file(str(d["path"]))).model
    rng = np.random.default_rng(26)
    n = d["n"]
    worst = 0.0
    for _ in range(25):
        x = np.concatenate([rng.uniform(-np.pi, np.pi, n), rng.uniform(-3, 3, n)])
        u = float(rng.uniform(-2, 2))
        M, Q = ours.mass_forcing(x[:n], x[n:], np.array([u]))
        Ms, Qs = d["mass"](x, u), d["forcing"](x, u)
        worst = max(worst, relative(M, Ms), relative(Q, Qs))
    print(f"{system}: mass matrix and forcing within {worst:.2e} of the largest entry")
    assert worst <= MATRIX_RTOL


@pytest.mark.parametrize(
    ("system", "at", "q0"),
    [
        ("dipc", {}, [0, 0, 0]),
        ("double_pendulum", {}, [0, 0]),
        ("double_pendulum", {"angle(r1)": np.pi, "angle(r2)": np.pi}, ["pi", "pi"]),
        ("double_pendulum", {"angle(r1)": 0.0, "angle(r2)": np.pi}, [0, "pi"]),
    ],
)
def test_linearisation_equals_sympy_linearizer(system: str, at: dict[str, float], q0: list[Any]) -> None:
    import sympy as sm

    d = derivation(system)
    netlist = parse_file(str(d["path"]))
    point = planar_point(netlist, at)
    assert not point.drift  # an equilibrium
    model = planar_linear_model(netlist, at=at)
    A, B = sympy_linear(d, [sm.pi if v == "pi" else v for v in q0])
    errors = relative(model.A, A), relative(model.B, B)
    print(f"{system} at {at or 'q = 0'}: A within {errors[0]:.1e}, B within {errors[1]:.1e}")
    assert max(errors) <= LINEAR_RTOL


def test_double_pendulum_eigenvalues_are_the_corrected_ones() -> None:
    model = planar_linear_model(parse_file(str(PLANAR / "double_pendulum.cir")))
    eig = np.sort(np.linalg.eigvals(model.A).imag)
    expected = np.array([-5.84312721, -2.42030254, 2.42030254, 5.84312721])
    exact = np.sqrt(10 * (2 + np.array([np.sqrt(2), -np.sqrt(2)])))  # (g/l)(2 ± √2)
    assert np.allclose(np.sort(np.r_[-exact, exact]), eig, rtol=1e-13, atol=0)
    assert np.allclose(eig, expected, rtol=0, atol=5e-9)


@pytest.mark.parametrize(
    ("planar", "linear", "params"),
    [("dipc.cir", "dipc.cir", {}), ("double_pendulum.cir", "double_pendulum.cir", {})],
)
def test_linearisation_equals_the_linear_rod_netlist(
    planar: str, linear: str, params: dict[str, float]
) -> None:
    ours = planar_linear_model(parse_file(str(PLANAR / planar)))
    names = [*ours.states]
    rods = parse_file(str(ROOT / "netlists" / linear), params)
    change = prepare(rods, None, ",".join(names)).change
    assert change is not None
    A = change.model.A
    assert list(change.model.states) == names
    err = relative(ours.A, A)
    print(f"{planar}: A within {err:.1e} of the linear netlist's")
    assert err <= LINEAR_RTOL
    if "F" in rods.params or planar == "dipc.cir":
        err_b = relative(ours.B, change.model.B)
        assert err_b <= LINEAR_RTOL


@pytest.mark.parametrize(
    ("system", "x0", "tstop"),
    [
        ("double_pendulum", [0.5, 0.0, 0.0, 0.0], 10.0),
        ("double_pendulum", [0.5, -0.5, 0.0, 1.0], 10.0),
        ("dipc", [0.0, 0.3, -0.2, 0.0, 0.0, 0.0], 1.2),
    ],
)
def test_trajectory_matches_sympy(system: str, x0: list[float], tstop: float) -> None:
    d = derivation(system)
    netlist = parse_file(str(d["path"]))
    times = np.linspace(0.0, tstop, 501)
    names = list(PlanarSystem(netlist).state_names)
    run, _ = simulate_planar(netlist, names, times, "DOP853", 1e-10, np.array(x0))
    assert run.status == "ok", run.message
    ref = solve_ivp(
        lambda t, x: sympy_rhs(d, x),
        (0.0, tstop),
        x0,
        method="DOP853",
        rtol=1e-12,
        atol=1e-14,
        t_eval=times,
    )
    peak = np.max(np.abs(ref.y.T), axis=0)
    err = np.max(np.abs(run.outputs - ref.y.T), axis=0) / peak
    print(f"{system} from {x0}: {err.max():.1e} of the peak over {tstop} s")
    assert err.max() <= TRAJECTORY_RTOL


def test_dipc_forward_euler_is_the_notes_loop() -> None:
    d = derivation("dipc")
    netlist = parse_file(str(PLANAR / "dipc.cir"))
    h, steps = 0.03, 2000
    times = np.arange(steps + 1) * h
    names = list(PlanarSystem(netlist).state_names)
    x0 = np.array([0.0, -0.01, -0.02, 0.0, 0.0, 0.0])
    run, _ = simulate_planar(netlist, names, times, "euler", x0=x0, step=h)
    assert run.status == "ok"
    ref = np.empty((steps + 1, 6))
    ref[0] = x0
    for k in range(steps):  # the notes' line 71: states(:,i) = dt*f(states(:,i-1), 0) + states(:,i-1)
        ref[k + 1] = h * sympy_rhs(d, ref[k]) + ref[k]
    small = np.max(np.abs(ref[:, 1:3]), axis=1) < 1.0
    last = int(np.argmin(small))  # the first step past 1 rad
    assert last > 10
    err = np.max(
        np.abs(run.outputs[:last] - ref[:last]) / np.maximum(np.abs(ref[:last]), 1e-300),
        where=ref[:last] != 0,
        initial=0.0,
    )
    print(f"Euler: {last} steps before |theta| > 1 rad, largest relative difference {err:.1e}")
    assert err <= EULER_RTOL
    # the notes' run falls and spins; Euler's error pumps energy in
    assert np.max(np.abs(run.outputs[:, 1])) > 10
    print(f"Euler energy: {run.stats['energy_start']:.4g} J -> largest {run.stats['energy_max']:.4g} J")
    assert run.stats["energy_max"] > 4 * run.stats["energy_start"]


def test_exact_run_keeps_the_energy() -> None:
    netlist = parse_file(str(PLANAR / "dipc.cir"))
    times = np.linspace(0.0, 10.0, 1001)
    run, _ = simulate_planar(
        netlist, ["x(cart)"], times, "DOP853", 1e-10, np.array([0, -0.01, -0.02, 0, 0, 0])
    )
    d = derivation("dipc")
    drift = run.stats["energy_drift"]
    print(f"DIPC 10 s exact: energy drift {drift:.2e}")
    assert drift <= ENERGY_RTOL
    # the energy is the sympy derivation's too
    system = PlanarSystem(netlist)
    x = np.array([0.1, 0.2, -0.3, 0.4, -0.5, 0.6])
    assert abs(sum(system.model.energy(x)) - d["energy"](x)) <= 1e-13 * abs(d["energy"](x))


def test_energy_drift_detects_a_wrong_gravity_term() -> None:
    """The drift figure can fail: forward Euler at a coarse step reports a large one."""
    netlist = parse_file(str(PLANAR / "double_pendulum.cir"))
    times = np.arange(201) * 0.05
    run, _ = simulate_planar(netlist, ["angle(r1)"], times, "euler", x0=np.array([0.5, 0, 0, 0]), step=0.05)
    assert run.stats["energy_drift"] > 1e-3


def _cli(*args: str) -> tuple[int, str]:
    result = CliRunner().invoke(main, list(args))
    return result.exit_code, result.output


def test_cli_op_analyze_simulate() -> None:
    path = str(PLANAR / "dipc.cir")
    code, out = _cli("op", path)
    assert code == 0 and "angle(r1) = 0" in out
    code, out = _cli("analyze", path, "--output", "x(cart)", "--output", "angle(r2)", "--format", "json")
    assert code == 0, out
    code, out = _cli(
        "simulate", path, "--method", "euler", "--step", "30m", "--tstop", "3",
        "--ic", "angle(r1)=-0.01", "--ic", "angle(r2)=-0.02", "-q",
    )  # fmt: skip
    assert code == 0, out
    assert "energy drift" in out and "on the nonlinear equations" in out


BAD = {
    "zero length": ("LINK r1 0 b1 0\nBODY m b1 1\n", 2, "length must be positive"),
    "no mass": ("LINK r1 0 b1 1\nBODY m b1 1\nLINK r2 b1 b2 1\n", 4, "moves no mass"),
    "unknown body point": ("LINK r1 0 b1 1\nBODY m b9 1\n", 3, "unknown point b9"),
    "unknown link": ("LINK r1 0 b1 1\nBODY m b1 1\nPTORQUE t r9 DC 0\n", 4, "unknown link r9"),
    "closed loop": (
        "LINK r1 0 b1 1\nBODY m b1 1\nLINK r2 b1 b2 1\nBODY m2 b2 1\nLINK r3 0 b2 1\n",
        6,
        "closes a kinematic loop (r3 -> r1 -> r2",
    ),
    "connected to nothing": ("FIXED w 1 0\nLINK r1 0 b1 1\nBODY m b1 1\n", 2, "connected to nothing"),
    "mixed": ("LINK r1 0 b1 1\nBODY m b1 1\nMASS m2 n2 1\n", 4, "cannot be mixed"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_input_is_one_line_at_the_card(case: str, tmp_path: Path) -> None:
    body, line, words = BAD[case]
    path = tmp_path / "bad.cir"
    path.write_text("bad planar netlist\n" + body + "GRAVITY 10\n.end\n")
    with pytest.raises(NetlistError) as info:
        PlanarSystem(parse_text(path.read_text(), str(path)))
    message = str(info.value)
    assert message.startswith(f"{path}:{line}:"), message
    assert words in message and "\n" not in message
    code, out = _cli("op", str(path))
    assert code != 0 and len(out.strip().splitlines()) == 1 and words in out


def test_ic_violating_a_rod_length_names_the_rod(tmp_path: Path) -> None:
    code, out = _cli(
        "simulate", str(PLANAR / "double_pendulum.cir"), "--ic", "x(b1)=1.5", "--tstop", "1", "-q"
    )
    assert code != 0 and len(out.strip().splitlines()) == 1
    assert "double_pendulum.cir:11:" in out and "LINK r1" in out and "farther than the rod's length" in out
    code, out = _cli(
        "simulate", str(PLANAR / "double_pendulum.cir"), "--ic", "x(b1)=0.5", "--tstop", "1", "-q"
    )
    assert code == 0, out


@pytest.mark.parametrize("name", ["dipc.cir", "double_pendulum.cir"])
def test_chain_sums_equal_the_point_recursion(name: str) -> None:
    """The array form (ChainSums) and the point-by-point recursion give the same M and Q."""
    model = PlanarSystem(parse_file(str(PLANAR / name))).model
    assert model.sums is not None
    rng = np.random.default_rng(7)
    n = model.n
    for _ in range(20):
        x = rng.uniform(-4, 4, 2 * n)
        u = rng.uniform(-2, 2, model.ninputs)
        M1, Q1 = model.sums.mass_forcing(x[:n], x[n:], u)
        M2, Q2 = model.tree_mass_forcing(x[:n], x[n:], u)
        assert relative(M1, M2) <= MATRIX_RTOL and relative(Q1, Q2) <= MATRIX_RTOL
