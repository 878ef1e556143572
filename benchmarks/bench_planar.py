"""The notes' DIPC, exact, 60 s: netlistdyn's planar cards beside the sympy.physics.mechanics workflow.

The workflow a Python user would pick instead: derive the equations with
``sympy.physics.mechanics.LagrangesMethod``, lambdify the mass matrix and forcing, integrate with
``scipy.integrate.solve_ivp`` (DOP853). Both sides integrate the same start, θ = (−0.01, −0.02) rad
upright, at the same rtol (default 1e-10, atol rtol·1e-3) for 60 s, and report

- CPU seconds of the integration (process time; sympy's derivation and lambdify separately);
- the energy drift over the 60 s: max |E(t) − E(0)| / |E(0)| on a 6001-sample grid;
- the trajectory error against DOP853 at rtol 1e-13 on sympy's equations, over the first
  ``--window`` seconds (default 2 s: the motion is chaotic once the pendula fall, so after that
  any two integrations part, whatever their accuracy), relative to each state's peak.

Run::

    python benchmarks/bench_planar.py [--rtol 1e-10] [--tstop 60] [--window 2]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np
from scipy.integrate import solve_ivp

from netlistdyn.formulation.planar import PlanarSystem
from netlistdyn.frontend.parser import parse_file
from netlistdyn.simulation.planartransient import simulate_planar

DIPC = Path(__file__).resolve().parent.parent / "netlists" / "planar" / "dipc.cir"
X0 = [0.0, -0.01, -0.02, 0.0, 0.0, 0.0]


def sympy_dipc() -> tuple[Any, Any, float]:
    """(rhs, energy, CPU s of derivation + lambdify): the notes' Lagrangian in sympy."""
    start = time.process_time()
    import sympy as sm
    import sympy.physics.mechanics as me

    x, t1, t2 = me.dynamicsymbols("x theta1 theta2")
    N = me.ReferenceFrame("N")
    origin = me.Point("O")
    origin.set_vel(N, 0)
    M, m1, m2, l1, l2, g = 1.5, 0.5, 0.75, 0.5, 0.75, 9.81
    cart = origin.locatenew("C", x * N.x)
    b1 = cart.locatenew("B1", l1 * (sm.sin(t1) * N.x + sm.cos(t1) * N.y))
    b2 = b1.locatenew("B2", l2 * (sm.sin(t2) * N.x + sm.cos(t2) * N.y))
    bodies = []
    for k, (point, mass) in enumerate(((cart, M), (b1, m1), (b2, m2))):
        point.set_vel(N, point.pos_from(origin).dt(N))
        particle = me.Particle(f"P{k}", point, mass)
        particle.potential_energy = mass * g * point.pos_from(origin).dot(N.y)
        bodies.append(particle)
    method = me.LagrangesMethod(me.Lagrangian(N, *bodies), [x, t1, t2], frame=N)
    method.form_lagranges_equations()
    q = [x, t1, t2]
    qd = [s.diff() for s in q]
    plain = sm.symbols("q0:3"), sm.symbols("u0:3")
    swap = dict(zip(qd, plain[1], strict=True)) | dict(zip(q, plain[0], strict=True))
    args = [*plain[0], *plain[1]]
    mass_matrix = sm.lambdify(args, method.mass_matrix.subs(swap), "numpy")
    forcing = sm.lambdify(args, method.forcing.subs(swap), "numpy")
    energy = sm.lambdify(args, sum(b.kinetic_energy(N) + b.potential_energy for b in bodies).subs(swap))

    def rhs(t: float, s: np.ndarray) -> np.ndarray:
        return np.concatenate([s[3:], np.linalg.solve(mass_matrix(*s), np.ravel(forcing(*s)))])

    return rhs, energy, time.process_time() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rtol", type=float, default=1e-10)
    parser.add_argument("--tstop", type=float, default=60.0)
    parser.add_argument("--window", type=float, default=2.0)
    args = parser.parse_args()
    times = np.linspace(0.0, args.tstop, round(args.tstop * 100) + 1)
    netlist = parse_file(str(DIPC))
    names = list(PlanarSystem(netlist).state_names)
    rhs, energy, derive_cpu = sympy_dipc()

    start = time.process_time()
    ours, _ = simulate_planar(netlist, names, times, "DOP853", args.rtol, np.array(X0))
    ours_cpu = time.process_time() - start
    start = time.process_time()
    sym = solve_ivp(
        rhs, (0, args.tstop), X0, method="DOP853", rtol=args.rtol, atol=args.rtol * 1e-3, t_eval=times
    )
    sym_cpu = time.process_time() - start

    window = times <= args.window
    ref = solve_ivp(
        rhs, (0, args.window), X0, method="DOP853", rtol=1e-13, atol=1e-16, t_eval=times[window]
    ).y.T
    peak = np.max(np.abs(ref), axis=0)

    def error(states: np.ndarray) -> float:
        return float(np.max(np.abs(states[window] - ref) / peak))

    def drift(states: np.ndarray) -> float:
        e = np.array([energy(*s) for s in states])
        return float(np.max(np.abs(e - e[0])) / abs(e[0]))

    print(f"DIPC exact, {args.tstop:g} s from theta = (-0.01, -0.02) rad, DOP853 at rtol {args.rtol:g}")
    head = f"| workflow | CPU s | energy drift, {args.tstop:g} s | error over {args.window:g} s (of peak) |"
    print(head)
    print("|---|---|---|---|")
    integration = ours.stats["integration_cpu"]
    ours_row = f"{integration:.2f} ({ours_cpu:.2f} with outputs and energy check) | {drift(ours.outputs):.2e}"
    print(f"| netlistdyn (planar cards) | {ours_row} | {error(ours.outputs):.2e} |")
    print(f"| sympy.physics.mechanics + lambdify + solve_ivp | {sym_cpu:.2f} (+{derive_cpu:.2f} to derive) "
          f"| {drift(sym.y.T):.2e} | {error(sym.y.T):.2e} |")  # fmt: skip


if __name__ == "__main__":
    main()
