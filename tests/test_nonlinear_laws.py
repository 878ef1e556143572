"""The nonlinear residual and the linear compiler state each element's law once.

:mod:`netlistdyn.nonlinear` builds its modified nodal equations from
:func:`netlistdyn.formulation.formulate.element_laws`, the laws the tree/cotree compiler
reduces. For a *linear* netlist both must then give the same model: the
Jacobian of the nonlinear transient's ``f`` (``state`` mode, implicit
differentiation) is A, its response to each input is B's column, and ``op``
(``dc`` mode, Newton) is the DC solution −C A⁻¹ B u + D u.

Tolerance (an error estimate, per case): the Jacobian J = S G⁻¹ P comes from
one LU solve, whose componentwise rounding bound is 3n·eps·|S||G⁻¹||L||U||G⁻¹P|
(Higham, *Accuracy and Stability*, Thm 9.4); the compiled A comes from a
sparse elimination of the same equations, whose forward error is that of a
backward-stable solve, n·eps·κ₁(G)·max|A| normwise. A law written differently
in the two places changes entries at the level of the element values, far
above both (the last test checks that such a change is caught).
"""

from __future__ import annotations

import functools
import json
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp

import netlistdyn.formulation.nonlinear as nonlinear
from netlistdyn.base.errors import NetlistError
from netlistdyn.circuit.netlist import Kind, Netlist
from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.formulation.nlsystem import NonlinearSystem
from netlistdyn.frontend.parser import parse_file, parse_text
from tests.random_networks import random_network

ROOT = Path(__file__).resolve().parent.parent
EPS = np.finfo(float).eps


def _linear_cases() -> list[str]:
    files = sorted(str(p.relative_to(ROOT)) for p in (ROOT / "netlists").glob("*.cir"))
    manifest = json.loads((ROOT / "tests/corpus/manifest.json").read_text())
    files += [f"tests/corpus/{f['file']}" for f in manifest["files"] if f["expect"] == "agree"]
    return files


@functools.cache
def _parse(path: str) -> Netlist | None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        netlist = parse_file(ROOT / path)
    return None if netlist.is_nonlinear else netlist


def _scaled_condition(matrix: np.ndarray) -> float:
    """κ₁ of the matrix with rows, then columns, scaled by powers of 2 to unit largest entries.

    LU with partial pivoting makes the same rounding errors on such a scaling (it is exact), so
    its forward error follows this condition number, not that of the unscaled matrix, whose
    rows mix amperes and volts.
    """
    scaled = matrix / 2.0 ** np.round(np.log2(np.abs(matrix).max(axis=1, keepdims=True)))
    scaled = scaled / 2.0 ** np.round(np.log2(np.abs(scaled).max(axis=0, keepdims=True)))
    return float(np.linalg.cond(scaled, 1))


def _compare(netlist: Netlist) -> dict[str, float] | None:
    """Largest |difference| / tolerance of A, B and the DC point; None when not comparable.

    Not comparable: the compiler refuses the netlist, or its states are not the
    nonlinear transient's (excess capacitors or inductors, which the transient
    refuses, or no state at all).
    """
    try:
        model = compile_netlist(netlist)
    except NetlistError:
        return None
    # the waveforms play no part in A, B or the DC point; the inputs are set below
    netlist = replace(netlist, elements=tuple(replace(e, waveform=None) for e in netlist.elements))
    system = NonlinearSystem(netlist)
    circuit = system.circuit
    names = circuit.state_names
    if model.info.excess or not names or sorted(names) != sorted(model.states):
        return None
    order = [names.index(s) for s in model.states]
    n = circuit.size
    u = np.zeros(len(circuit.sources))
    system.inputs = lambda t: u
    x0 = np.zeros(len(names))
    jac = system.jacobian(0.0, x0)
    J = (jac.toarray() if sp.issparse(jac) else np.asarray(jac))[np.ix_(order, order)]
    A = model.A_sparse.toarray()
    G = circuit.linear_matrix("state").toarray()
    rows, cols, vals = system._P_fixed
    P = sp.csc_array((vals, (rows, cols)), shape=(n, len(names))).toarray()
    Ginv = np.linalg.inv(G)
    perm, lower, upper = sla.lu(G)
    lu_bound = (
        np.abs(system.S.toarray()) @ np.abs(Ginv) @ (perm @ np.abs(lower) @ np.abs(upper)) @ np.abs(Ginv @ P)
    )
    level = n * EPS * _scaled_condition(G)
    tol_a = 3 * n * EPS * lu_bound[np.ix_(order, order)] + level * np.abs(A).max() + 1e-300
    out = {"A": float(np.max(np.abs(J - A) / tol_a))}

    # B: f is linear in u, so f(0, e_j) − f(0, 0) is B's column j
    B = model.B_sparse.toarray()
    inputs = [circuit.source_index[name.lower()] for name in model.inputs]
    f0 = system.f(0.0, x0)
    columns = []
    for j in inputs:
        u[:] = 0.0
        u[j] = 1.0
        columns.append(system.f(0.0, x0)[order] - f0[order])
    u[:] = 0.0
    if not model.info.shifts:  # a shifted state's B holds M⁻¹K₀ terms
        scale = (np.abs(system.S.toarray()) @ np.abs(Ginv)).max() if B.size else 0.0
        tol_b = 3 * n * EPS * scale + level * np.abs(B).max() + 1e-300
        out["B"] = float(np.max(np.abs(np.column_stack(columns) - B)) / tol_b) if B.size else 0.0

    # op: the DC solution of the compiled model, where A is invertible
    kappa_a = np.linalg.cond(A, 1)
    if kappa_a * EPS < 1e-3:
        u_dc = np.array([circuit.dc_value(circuit.sources[j]) for j in inputs])
        x_dc = -np.linalg.solve(A, B @ u_dc)
        C, D = model.C_sparse.toarray(), model.D_sparse.toarray()
        y = C @ x_dc + D @ u_dc
        point = circuit.operating_point()
        got = np.array([point.voltages[o[2:-1]] for o in model.outputs])
        terms = np.abs(C) @ np.abs(x_dc) + np.abs(D) @ np.abs(u_dc)
        g_dc = circuit.linear_matrix("dc").toarray()
        tol_op = n * EPS * (_scaled_condition(g_dc) + kappa_a) * max(terms.max(), np.abs(got).max()) + 1e-300
        out["op"] = float(np.max(np.abs(got - y)) / tol_op) if y.size else 0.0
    return out


@functools.cache
def _compared(path: str) -> dict[str, float] | None:
    netlist = _parse(path)
    return None if netlist is None else _compare(netlist)


@pytest.mark.parametrize("path", _linear_cases())
def test_linear_netlist_same_model(path: str) -> None:
    ratios = _compared(path)
    if ratios is None:
        return
    assert all(0.0 <= r <= 1.0 for r in ratios.values()), ratios


def test_compared_cases_cover_every_linear_kind() -> None:
    """The comparison above runs on netlists with every linear element kind (it would catch each law)."""
    kinds: set[Kind] = set()
    compared = 0
    for path in _linear_cases():
        netlist = _parse(path)
        if netlist is not None and _compared(path) is not None:
            compared += 1
            kinds |= {e.kind for e in netlist.elements}
    assert compared >= 40
    assert kinds >= nonlinear.LINEAR_KINDS, nonlinear.LINEAR_KINDS - kinds


def test_random_networks_same_model() -> None:
    """Random R, L, C, VCCS and K networks at realistic values (E12, mΩ..GΩ, pF..mF, pH..H)."""
    rng = np.random.default_rng(20261123)
    compared = 0
    worst: dict[str, float] = {}
    for _ in range(120):
        ratios = _compare(parse_text(random_network(rng, spread=False)))
        if ratios is None:
            continue
        compared += 1
        for key, value in ratios.items():
            worst[key] = max(worst.get(key, 0.0), value)
    assert compared >= 40
    assert all(0.0 <= r <= 1.0 for r in worst.values()), worst


def test_a_law_stated_differently_is_caught(monkeypatch: pytest.MonkeyPatch) -> None:
    """A VCCS gain 1 % off in the nonlinear equations only: the comparison fails by far."""
    netlist = _parse("netlists/controlled.cir")
    assert netlist is not None and any(e.kind is Kind.VCCS for e in netlist.elements)
    shared = nonlinear.element_laws

    def skewed(element, value, mutual):  # type: ignore[no-untyped-def]
        if element.kind is Kind.VCCS:
            return shared(element, lambda e: 1.01 * value(e), mutual)
        return shared(element, value, mutual)

    monkeypatch.setattr(nonlinear, "element_laws", skewed)
    ratios = _compare(netlist)
    assert ratios is not None and max(ratios.values()) > 1e3, ratios
