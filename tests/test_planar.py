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
  sensitivity to a 1e-10 error stays below 100: 10 s for the pendula from 0.5 rad, 3 s for
  the two upright pendula on the cart, 1.2 s for the unstable DIPC; the oblique blocks at
  rtol 1e-11, see the case);
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
def derivation(system: str, **params: float) -> dict[str, Any]:
    """The system by hand in sympy: Lagrange's equations, lambdified, and its linearisation.

    Positions are written in the notes' coordinates; forces not derived from a potential (the
    dampers, the notes' linear track springs, the loads) are given as generalised forces on the
    points; gravity and the oblique spring enter the Lagrangian as potentials.
    """
    import sympy as sm
    import sympy.physics.mechanics as me

    N = me.ReferenceFrame("N")
    O = me.Point("O")  # noqa: E741 (sympy.physics.mechanics' own name for the origin)
    O.set_vel(N, 0)
    R = sm.Rational
    hor, up = N.x, N.y

    def placed(base: Any, name: str, offset: Any) -> Any:
        point = base.locatenew(name, offset)
        point.set_vel(N, point.pos_from(O).dt(N))
        return point

    def swing(length: Any, theta: Any, upright: bool) -> Any:  # the notes' x + l sin, ±l cos
        return length * (sm.sin(theta) * hor + (1 if upright else -1) * sm.cos(theta) * up)

    potential = sm.Integer(0)
    rigid: list[Any] = []
    loads: list[tuple[Any, Any]] = []
    if system == "dipc":  # the notes' Lagrangian: cart x, theta from the upward vertical
        x, t1, t2 = me.dynamicsymbols("x theta1 theta2")
        F = me.dynamicsymbols("F")
        g = R(981, 100)
        cart = placed(O, "C", x * hor)
        b1 = placed(cart, "B1", swing(R(1, 2), t1, True))
        b2 = placed(b1, "B2", swing(R(3, 4), t2, True))
        particles = [(cart, R(3, 2)), (b1, R(1, 2)), (b2, R(3, 4))]
        q, inputs = [x, t1, t2], [F]
        loads = [(cart, F * hor)]
        path = PLANAR / "dipc.cir"
    elif system == "double_pendulum":  # theta from the downward vertical
        t1, t2 = me.dynamicsymbols("theta1 theta2")
        F = me.dynamicsymbols("F")
        g = 10
        b1 = placed(O, "B1", swing(1, t1, False))
        b2 = placed(b1, "B2", swing(1, t2, False))
        particles = [(b1, 1), (b2, 1)]
        q, inputs = [t1, t2], [F]
        loads = [(b2, F * hor)]
        path = PLANAR / "double_pendulum.cir"
    elif system == "two_pendula_cart":  # the notes' equation 7: both upright on the cart
        x, t1, t2 = me.dynamicsymbols("x theta1 theta2")
        F = me.dynamicsymbols("F")
        g = R(981, 100)
        cart = placed(O, "C", x * hor)
        b1 = placed(cart, "B1", swing(1, t1, True))
        b2 = placed(cart, "B2", swing(2, t2, True))
        particles = [(cart, 1), (b1, 1), (b2, 1)]
        q, inputs = [x, t1, t2], [F]
        loads = [(cart, F * hor)]
        path = PLANAR / "two_pendula_cart.cir"
    elif system == "block_pendulum":  # the kinematics notes: M x'' = F1 + Fp sin θ − k x − d x'
        x, th = me.dynamicsymbols("x theta")
        F = me.dynamicsymbols("F1")
        g = 10
        block = placed(O, "Bk", x * hor)
        bob = placed(block, "Bp", swing(1, th, False))
        particles = [(block, 1), (bob, 1)]
        q, inputs = [x, th], [F]
        loads = [(block, (F - x - x.diff()) * hor)]
        path = PLANAR / "block_pendulum.cir"
    elif system == "blocks_pendulum":  # the notes' F vector: linear track springs and dampers
        x1, x2, th = me.dynamicsymbols("x1 x2 theta")
        F1, F2 = me.dynamicsymbols("F1 F2")
        g, length = 10, R(params.get("l", 1))
        upright = bool(params.get("inv", 0))
        b1 = placed(O, "B1", x1 * hor)
        b2 = placed(O, "B2", (1 + x2) * hor)
        bob = placed(b2, "Bp", swing(length, th, upright))
        particles = [(b1, 1), (b2, 1), (bob, 1)]
        q, inputs = [x1, x2, th], [F1, F2]
        spring2 = (x2 - x1) + (x2.diff() - x1.diff())  # k2 (x2 − x1) + d2 (x2' − x1'), k2 = d2 = 1
        loads = [(b1, (F1 - x1 - x1.diff() + spring2) * hor), (b2, (F2 - spring2) * hor)]
        path = PLANAR / "blocks_pendulum.cir"
    elif system == "oblique_blocks":  # the notes' geometry: length g(x1, x2) of the oblique spring
        x1, x2 = me.dynamicsymbols("x1 x2")
        F1, F2 = me.dynamicsymbols("F1 F2")
        g, xi, k1, k2 = 10, 1, 100, 200
        b1 = placed(O, "B1", x1 * hor)
        b2 = placed(O, "B2", (xi + x2 / sm.sqrt(2)) * hor + x2 / sm.sqrt(2) * up)
        particles = [(b1, 1), (b2, 1)]
        q, inputs = [x1, x2], [F1, F2]
        glen = sm.sqrt((xi - x1 + x2 / sm.sqrt(2)) ** 2 + x2**2 / 2)
        potential = R(k1, 2) * x1**2 + R(k2, 2) * (glen - xi) ** 2
        loads = [(b1, (F1 - x1.diff()) * hor), (b2, F2 * (hor + up) / sm.sqrt(2))]
        path = PLANAR / "oblique_blocks.cir"
    elif system == "bead_on_rod":  # a rigid body turning with the rod, a bead sliding along it
        th, s = me.dynamicsymbols("theta s")
        tau = me.dynamicsymbols("tau")
        g = R(981, 100)
        along = sm.sin(th) * hor - sm.cos(th) * up
        p = placed(O, "P", along)
        bead = placed(p, "Bd", (R(1, 2) + s) * along)
        particles = [(bead, R(1, 2))]
        frame = N.orientnew("A", "Axis", [th, N.z])
        frame.set_ang_vel(N, th.diff() * N.z)
        body = me.RigidBody("Rod", p, frame, 2, (me.inertia(frame, 0, 0, R(3, 10)), p))
        body.potential_energy = 2 * g * p.pos_from(O).dot(up)
        rigid = [body]
        q, inputs = [th, s], [tau]
        potential = 10 * s**2  # k/2 (length − l0)², k = 20, length − l0 = s
        loads = [(frame, tau * N.z)]
        path = PLANAR / "bead_on_rod.cir"
    else:
        raise AssertionError(system)
    bodies = list(rigid) if system == "bead_on_rod" else []
    for k, (point, mass) in enumerate(particles):
        particle = me.Particle(f"P{k}", point, mass)
        particle.potential_energy = mass * g * point.pos_from(O).dot(up)
        bodies.append(particle)
    L = me.Lagrangian(N, *bodies) - potential
    method = me.LagrangesMethod(L, q, forcelist=loads, frame=N)
    method.form_lagranges_equations()
    qd = [s.diff() for s in q]
    n = len(q)
    plain = sm.symbols(f"q0:{n}"), sm.symbols(f"u0:{n}"), sm.symbols(f"f0:{len(inputs)}")
    swap = (
        dict(zip(qd, plain[1], strict=True))
        | dict(zip(q, plain[0], strict=True))
        | dict(zip(inputs, plain[2], strict=True))
    )
    args = [*plain[0], *plain[1], *plain[2]]
    mass = sm.lambdify(args, method.mass_matrix.subs(swap), "numpy")
    forcing = sm.lambdify(args, method.forcing.subs(swap), "numpy")
    energy = sm.lambdify(
        args,
        (sum(b.kinetic_energy(N) + b.potential_energy for b in bodies) + potential).subs(swap),
        "numpy",
    )
    nu = len(inputs)
    return {
        "method": method,
        "q": q,
        "qd": qd,
        "inputs": inputs,
        "mass": lambda x, u: np.array(mass(*x, *np.broadcast_to(u, nu)), dtype=float),
        "forcing": lambda x, u: np.array(forcing(*x, *np.broadcast_to(u, nu)), dtype=float).ravel(),
        "energy": lambda x: float(energy(*x, *np.zeros(nu))),
        "path": path,
        "n": n,
        "params": params,
    }


def sympy_rhs(d: dict[str, Any], x: np.ndarray, u: Any = 0.0) -> np.ndarray:
    n = d["n"]
    return np.concatenate([x[n:], np.linalg.solve(d["mass"](x, u), d["forcing"](x, u))])


def sympy_equilibrium(d: dict[str, Any], u: np.ndarray, q0: np.ndarray) -> np.ndarray:
    """Newton on sympy's forcing at rest (central differences: only the root is used)."""
    n = d["n"]
    q = np.array(q0, dtype=float)
    for _ in range(50):
        x = np.r_[q, np.zeros(n)]
        Q = d["forcing"](x, u)
        J = np.empty((n, n))
        for j in range(n):
            e = np.zeros(2 * n)
            e[j] = 1e-6
            J[:, j] = (d["forcing"](x + e, u) - d["forcing"](x - e, u)) / 2e-6
        step = np.linalg.lstsq(J, -Q, rcond=None)[0]  # a free cart: minimum-norm step
        q = q + step
        if np.max(np.abs(step)) < 1e-15:
            break
    return q


def sympy_linear(d: dict[str, Any], q0: list[Any], u: list[float]) -> tuple[np.ndarray, np.ndarray]:
    """The Linearizer's A, B at (q0, q' = 0, u), B's columns in the netlist's input order."""
    import sympy as sm

    op = dict(zip(d["q"], q0, strict=True)) | dict.fromkeys(d["qd"], 0)
    op |= dict(zip(d["inputs"], u, strict=True))
    op |= {s.diff(): 0 for s in d["qd"]}
    A, B, r = d["method"].linearize(q_ind=d["q"], qd_ind=d["qd"], A_and_B=True, op_point=op)
    order = [list(r).index(v) for v in d["inputs"]]
    A = np.array(sm.N(A.subs(op), 30), dtype=float)
    B = np.array(sm.N(B.subs(op), 30), dtype=float)[:, order]
    return A, B


def relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


#: (system, its netlist's --param values)
CASES = [
    ("dipc", {}),
    ("double_pendulum", {}),
    ("two_pendula_cart", {}),
    ("block_pendulum", {}),
    ("blocks_pendulum", {"l": 1, "inv": 0}),
    ("blocks_pendulum", {"l": 100, "inv": 0}),
    ("blocks_pendulum", {"l": 1, "inv": 1}),
    ("blocks_pendulum", {"l": 100, "inv": 1}),
    ("oblique_blocks", {}),
    ("bead_on_rod", {}),
]
IDS = [f"{s}{''.join(f'-{k}{v}' for k, v in p.items())}" for s, p in CASES]


def ours(d: dict[str, Any]) -> Any:
    return parse_file(str(d["path"]), {k: float(v) for k, v in d["params"].items()})


@pytest.mark.parametrize(("system", "params"), CASES, ids=IDS)
def test_mass_matrix_and_forcing_at_random_states(system: str, params: dict[str, float]) -> None:
    d = derivation(system, **params)
    model = PlanarSystem(ours(d)).model
    rng = np.random.default_rng(26)
    n = d["n"]
    worst = 0.0
    for _ in range(25):
        x = np.concatenate([rng.uniform(-np.pi, np.pi, n), rng.uniform(-3, 3, n)])
        # displacements within ±0.39 m: the track springs (1 m long at rest) stay longer than
        # 0.2 m, where a spring along the line between its ends is the notes' linear k x
        x[:n] = np.where([c.startswith("x(") for c in model.mechanism.coordinates], x[:n] / 8, x[:n])
        u = rng.uniform(-2, 2, model.ninputs)
        M, Q = model.mass_forcing(x[:n], x[n:], u)
        Ms, Qs = d["mass"](x, u), d["forcing"](x, u)
        worst = max(worst, relative(M, Ms), relative(Q, Qs))
    print(f"{system} {params}: mass matrix and forcing within {worst:.2e} of the largest entry")
    assert worst <= MATRIX_RTOL


@pytest.mark.parametrize(("system", "params"), CASES, ids=IDS)
def test_linearisation_equals_sympy_linearizer(system: str, params: dict[str, float]) -> None:
    d = derivation(system, **params)
    netlist = ours(d)
    point = planar_point(netlist)
    assert not point.drift  # an equilibrium
    q_sym = sympy_equilibrium(d, point.u, np.zeros(d["n"]))
    assert np.max(np.abs(point.q - q_sym)) <= 1e-12 * max(1.0, float(np.max(np.abs(q_sym))))
    model = planar_linear_model(netlist, point=point)
    A, B = sympy_linear(d, list(q_sym), list(point.u))
    errors = relative(model.A, A), relative(model.B, B)
    print(f"{system} {params} at q = {point.q}: A within {errors[0]:.1e}, B within {errors[1]:.1e}")
    assert max(errors) <= LINEAR_RTOL


@pytest.mark.parametrize(
    ("at", "q0"),
    [
        ({"angle(r1)": np.pi, "angle(r2)": np.pi}, ["pi", "pi"]),
        ({"angle(r1)": 0.0, "angle(r2)": np.pi}, [0, "pi"]),
    ],
)
def test_double_pendulum_other_equilibria(at: dict[str, float], q0: list[Any]) -> None:
    import sympy as sm

    d = derivation("double_pendulum")
    netlist = ours(d)
    assert not planar_point(netlist, at).drift
    model = planar_linear_model(netlist, at=at)
    A, B = sympy_linear(d, [sm.pi if v == "pi" else v for v in q0], [0.0])
    errors = relative(model.A, A), relative(model.B, B)
    print(f"double pendulum at {at}: A within {errors[0]:.1e}, B within {errors[1]:.1e}")
    assert max(errors) <= LINEAR_RTOL


def test_double_pendulum_eigenvalues_are_the_corrected_ones() -> None:
    model = planar_linear_model(parse_file(str(PLANAR / "double_pendulum.cir")))
    eig = np.sort(np.linalg.eigvals(model.A).imag)
    expected = np.array([-5.84312721, -2.42030254, 2.42030254, 5.84312721])
    exact = np.sqrt(10 * (2 + np.array([np.sqrt(2), -np.sqrt(2)])))  # (g/l)(2 ± √2)
    assert np.allclose(np.sort(np.r_[-exact, exact]), eig, rtol=1e-13, atol=0)
    assert np.allclose(eig, expected, rtol=0, atol=5e-9)


def test_dipc_matrices_are_the_notes() -> None:
    """The notes' printed A and B (seed 002), to their printed digits."""
    model = planar_linear_model(parse_file(str(PLANAR / "dipc.cir")))
    A = np.zeros((6, 6))
    A[:3, 3:] = np.eye(3)
    A[3:, :3] = [[0, -8.175, 0], [0, 65.4, -29.43], [0, -32.7, 32.7]]
    assert np.max(np.abs(model.A - A)) <= 1e-12
    assert np.allclose(model.B.ravel(), [0, 0, 0, 2 / 3, -4 / 3, 0], rtol=0, atol=1e-12)


#: (planar netlist, linear netlist, --param of both)
LINEAR_TWINS = [
    ("dipc.cir", "dipc.cir", {}),
    ("double_pendulum.cir", "double_pendulum.cir", {}),
    ("two_pendula_cart.cir", "two_pendula_cart.cir", {}),
    ("blocks_pendulum.cir", "blocks_pendulum.cir", {"l": 1.0, "inv": 0.0}),
    ("blocks_pendulum.cir", "blocks_pendulum.cir", {"l": 100.0, "inv": 0.0}),
    ("blocks_pendulum.cir", "blocks_pendulum.cir", {"l": 1.0, "inv": 1.0}),
    ("blocks_pendulum.cir", "blocks_pendulum.cir", {"l": 100.0, "inv": 1.0}),
    ("oblique_blocks.cir", "oblique_blocks.cir", {}),
]


@pytest.mark.parametrize(("planar", "linear", "params"), LINEAR_TWINS)
def test_linearisation_equals_the_linear_netlist(planar: str, linear: str, params: dict[str, float]) -> None:
    """Where a ROD/MASS netlist (or the notes' formula) models the same system, A (and B) agree."""
    model = planar_linear_model(parse_file(str(PLANAR / planar), params))
    rods = parse_file(str(ROOT / "netlists" / linear), params)
    change = prepare(rods, None, ",".join(model.states)).change
    assert change is not None and list(change.model.states) == list(model.states)
    err = relative(model.A, change.model.A)
    shared = [j for j, name in enumerate(change.model.inputs) if name in model.inputs]
    ours_b = model.B[:, [model.inputs.index(change.model.inputs[j]) for j in shared]]
    err_b = relative(ours_b, change.model.B[:, shared]) if shared else 0.0
    print(f"{planar} {params}: A within {err:.1e}, B within {err_b:.1e} of {linear}'s")
    assert err <= LINEAR_RTOL and err_b <= LINEAR_RTOL


@pytest.mark.parametrize(
    ("system", "params", "x0", "tstop"),
    [
        ("double_pendulum", {}, [0.5, 0.0, 0.0, 0.0], 10.0),
        ("double_pendulum", {}, [0.5, -0.5, 0.0, 1.0], 10.0),
        ("block_pendulum", {}, [0.0, 0.5, 0.0, 0.0], 10.0),
        ("blocks_pendulum", {"l": 1, "inv": 0}, [0.0, 0.0, 0.5, 0.0, 0.0, 0.0], 10.0),
        ("two_pendula_cart", {}, [0.0, 0.5, 0.0, 0.0, 0.0, 0.0], 3.0),
        ("dipc", {}, [0.0, 0.3, -0.2, 0.0, 0.0, 0.0], 1.2),
        # the one case run at rtol 1e-11: at 1e-10 DOP853's global error is 4.4e-8 of the peak
        # (measured: 14 periods of the 17.8 rad/s mode), at 1e-11 3.0e-9
        ("oblique_blocks", {}, [0.0, 0.0, 0.0, 0.0], 5.0),
        ("bead_on_rod", {}, [0.8, 0.1, 0.0, 0.0], 5.0),
    ],
)
def test_trajectory_matches_sympy(
    system: str, params: dict[str, float], x0: list[float], tstop: float
) -> None:
    d = derivation(system, **params)
    netlist = ours(d)
    system_ = PlanarSystem(netlist)
    u = system_.inputs(0.0)
    times = np.linspace(0.0, tstop, 501)
    names = list(system_.state_names)
    rtol = 1e-11 if system == "oblique_blocks" else 1e-10
    run, _ = simulate_planar(netlist, names, times, "DOP853", rtol, np.array(x0))
    assert run.status == "ok", run.message
    ref = solve_ivp(
        lambda t, x: sympy_rhs(d, x, u),
        (0.0, tstop),
        x0,
        method="DOP853",
        rtol=1e-12,
        atol=1e-14,
        t_eval=times,
    )
    peak = np.max(np.abs(ref.y.T), axis=0)
    err = np.max(np.abs(run.outputs - ref.y.T), axis=0) / peak
    print(f"{system} {params} from {x0}: {err.max():.1e} of the peak over {tstop} s")
    assert err.max() <= TRAJECTORY_RTOL


def test_oblique_blocks_stay_bounded() -> None:
    netlist = parse_file(str(PLANAR / "oblique_blocks.cir"))
    times = np.linspace(0.0, 5.0, 2001)
    run, _ = simulate_planar(netlist, ["x(b2)"], times, "DOP853", 1e-10)
    assert run.status == "ok"
    assert 1.8 < np.max(np.abs(run.outputs)) <= 1.84


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
    scale = np.maximum(np.abs(ref[:last]), 1e-300)
    err = np.max(np.abs(run.outputs[:last] - ref[:last]) / scale, where=ref[:last] != 0, initial=0.0)
    print(f"Euler: {last} steps before |theta| > 1 rad, largest relative difference {err:.1e}")
    assert err <= EULER_RTOL
    # the notes' run falls and spins; Euler's error pumps energy in
    assert np.max(np.abs(run.outputs[:, 1])) > 10
    print(f"Euler energy: {run.stats['energy_start']:.4g} J -> largest {run.stats['energy_max']:.4g} J")
    assert run.stats["energy_max"] > 4 * run.stats["energy_start"]


def test_exact_run_keeps_the_energy() -> None:
    netlist = parse_file(str(PLANAR / "dipc.cir"))
    times = np.linspace(0.0, 10.0, 1001)
    x0 = np.array([0, -0.01, -0.02, 0, 0, 0])
    run, _ = simulate_planar(netlist, ["x(cart)"], times, "DOP853", 1e-10, x0)
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


@pytest.mark.parametrize("name", sorted(p.name for p in PLANAR.glob("*.cir") if p.name != "bead_on_rod.cir"))
def test_chain_sums_equal_the_point_recursion(name: str) -> None:
    """ChainSums, the generated rhs and the point-by-point recursion give the same M, Q and x'."""
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
        p1, p2 = model.sums.positions(x[:n]), model.kinematics(x[:n], x[n:])[0]
        assert np.max(np.abs(p1 - p2)) <= 1e-14 * max(1.0, float(np.max(np.abs(p2))))
        # the generated straight-line rhs (planarcode), real and through the complex step
        assert model.code is not None
        tree = np.r_[x[n:], np.linalg.solve(M2, Q2)]
        assert relative(model.rhs(x, u), tree) <= MATRIX_RTOL
        assert relative(model.rhs(x.astype(complex), u).real, tree) <= MATRIX_RTOL


def test_animation_draws_the_bobs_where_the_run_puts_them(tmp_path: Path) -> None:
    """A frame's pixel at a bob's simulated position is the bob's colour; the gif has every frame."""
    from netlistdyn.io.animate import Options
    from netlistdyn.io.planar_animate import PlanarAnimation, position_variables

    netlist = parse_file(str(PLANAR / "double_pendulum.cir"))
    names = position_variables(netlist)
    times = np.linspace(0.0, 1.0, 101)
    run, _ = simulate_planar(netlist, names, times, "DOP853", 1e-10, np.array([1.0, -0.5, 0.0, 0.0]))
    movie = PlanarAnimation(netlist, times, run.outputs, names, np.zeros((101, 1)), Options(fps=10))
    for frame in (0, 5, 10):
        image = movie.render(frame)
        k = int(movie.frames()[frame])
        for bob in ("b1", "b2"):
            x, y = run.outputs[k, names.index(f"px({bob})")], run.outputs[k, names.index(f"py({bob})")]
            _fig, ax, _ = movie._figure()
            col, row = ax.transData.transform((x, y))
            r, g, b = image[int(image.shape[0] - row), int(col)]
            assert r > 150 and g < 100 and b < 100, (frame, bob, (r, g, b))
    assert movie.save(str(tmp_path / "dp.gif")) == 11


@pytest.mark.parametrize("command", [["validate"], ["sweep", "--param", "l1=0.5,1"]])
def test_commands_without_a_planar_path_refuse_in_one_line(command: list[str]) -> None:
    code, out = _cli(*command, str(PLANAR / "double_pendulum.cir"))
    assert code != 0 and len(out.strip().splitlines()) == 1, out
    assert (
        "double_pendulum.cir:10: GRAVITY: a planar mechanism is compiled by op, analyze and simulate" in out
    )


def test_a_slider_on_a_turning_frame_takes_the_point_recursion() -> None:
    """bead_on_rod's slider rides on the rod: no ChainSums, no generated code (its sympy tests
    above then check the recursion of PlanarModel.kinematics and the BODY's J)."""
    model = PlanarSystem(parse_file(str(PLANAR / "bead_on_rod.cir"))).model
    assert model.sums is None and model.code is None


def test_held_point_reports_the_accelerations_of_its_release() -> None:
    d = derivation("double_pendulum")
    point = planar_point(ours(d), {"angle(r1)": 1.0})
    assert abs(point.q[1]) <= 1e-14  # the lower rod hangs straight down
    expected = sympy_rhs(d, np.array([1.0, point.q[1], 0.0, 0.0]))[2:]
    got = np.array([point.drift["omega(r1)"], point.drift["omega(r2)"]])
    assert relative(got, expected) <= MATRIX_RTOL
