"""x' = f(x, u) of a planar mechanism as straight-line Python, generated once per netlist.

:class:`netlistdyn.formulation.planar.ChainSums` gives M and Q in ~25 array operations; on the
notes' mechanisms (2 to 3 coordinates) numpy's per-call overhead is most of the cost. This module
writes the same formulas out as scalar statements — the joints' directions, M's entries (only
where the body-sum Mc or the inertia term is non-zero), Q's terms, the springs, dampers and
loads — and solves M q'' = Q by an unrolled Cholesky factorisation (M is symmetric positive
definite). The source is compiled twice, with :mod:`math` and with :mod:`cmath`, so the complex
step of the Jacobians runs through the same statements. Every constant is written with ``repr``
(the exact double), so the generated code computes what ChainSums computes, operation for
operation up to the order of additions.
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Callable
from typing import Any

import numpy as np

#: Most coordinates for which the code is generated (its size grows as n²; above, ChainSums).
MAX_GENERATED = 12


def _num(value: float) -> str:
    return repr(float(value))


def generate(sums: Any) -> str:
    """The source of ``rhs(x, u) -> tuple`` for the mechanism ``sums`` (a ChainSums)."""
    n = len(sums.link)
    link = [bool(v) for v in sums.link]
    lines = ["def rhs(x, u):"]
    add = lines.append
    for k in range(n):
        add(f"    q{k} = x[{k}]")
        add(f"    v{k} = x[{n + k}]")
    for k in range(n):
        ex, ey = (float(c) for c in sums.base[k])
        if link[k]:
            sign, a, bias, length = (
                float(sums.sign[k]),
                float(sums.t_link[k]),
                float(sums.bias[k]),
                sums.length[k],
            )
            add(f"    c{k} = cos(q{k})")
            add(f"    s{k} = {_num(sign)} * sin(q{k})")
            add(f"    ux{k} = {_num(ex)} * c{k} - {_num(ey)} * s{k}")
            add(f"    uy{k} = {_num(ex)} * s{k} + {_num(ey)} * c{k}")
            add(f"    tx{k} = {_num(-a)} * uy{k}")
            add(f"    ty{k} = {_num(a)} * ux{k}")
            add(f"    h{k} = {_num(bias)} * v{k} * v{k}")
            add(f"    ax{k} = h{k} * ux{k}")
            add(f"    ay{k} = h{k} * uy{k}")
            add(f"    wx{k} = {_num(length)} * ux{k}")
            add(f"    wy{k} = {_num(length)} * uy{k}")
        else:
            add(f"    tx{k} = {_num(ex)}")
            add(f"    ty{k} = {_num(ey)}")
            add(f"    wx{k} = ({_num(sums.length[k])} + q{k}) * {_num(ex)}")
            add(f"    wy{k} = ({_num(sums.length[k])} + q{k}) * {_num(ey)}")
    Mc, Mrot = sums.Mc, sums.Mrot
    gx, gy = (float(c) for c in sums.gravity)
    for i in range(n):
        for j in range(i + 1):
            terms = []
            if Mc[i, j]:
                terms.append(f"{_num(Mc[i, j])} * (tx{i} * tx{j} + ty{i} * ty{j})")
            if Mrot[i, j]:
                terms.append(_num(Mrot[i, j]))
            add(f"    m{i}_{j} = {' + '.join(terms) or '0.0'}")
    for i in range(n):
        terms = [f"{_num(sums.mk[i])} * ({_num(gx)} * tx{i} + {_num(gy)} * ty{i})"]
        terms += [
            f"- {_num(Mc[i, j])} * (tx{i} * ax{j} + ty{i} * ay{j})" for j in range(n) if link[j] and Mc[i, j]
        ]
        add(f"    Q{i} = {' '.join(terms)}")

    def along(D: Any, row: int, axis: str) -> str:
        parts = [f"{_num(D[row, k])} * w{axis}{k}" for k in range(n) if D[row, k]]
        return " + ".join(parts) or "0.0"

    for s in range(len(sums.spring_k)):
        D, R = sums.spring_D, sums.spring_R
        add(f"    rx = {_num(R[s, 0])} + {along(D, s, 'x')}")
        add(f"    ry = {_num(R[s, 1])} + {along(D, s, 'y')}")
        add("    length = sqrt(rx * rx + ry * ry)")
        add(f"    tension = {_num(sums.spring_k[s])} * (length - {_num(sums.spring_rest[s])}) / length")
        for i in range(n):
            if D[s, i]:
                add(f"    Q{i} = Q{i} - tension * {_num(D[s, i])} * (rx * tx{i} + ry * ty{i})")
    for s in range(len(sums.damper_d)):
        D, R = sums.damper_D, sums.damper_R
        add(f"    rx = {_num(R[s, 0])} + {along(D, s, 'x')}")
        add(f"    ry = {_num(R[s, 1])} + {along(D, s, 'y')}")
        add("    length2 = rx * rx + ry * ry")
        rate = " + ".join(f"{_num(D[s, k])} * (rx * tx{k} + ry * ty{k}) * v{k}" for k in range(n) if D[s, k])
        add(f"    pull = {_num(sums.damper_d[s])} * ({rate or '0.0'}) / length2")
        for i in range(n):
            if D[s, i]:
                add(f"    Q{i} = Q{i} - pull * {_num(D[s, i])} * (rx * tx{i} + ry * ty{i})")
    for f in range(len(sums.force_input)):
        fx, fy = (float(c) for c in sums.force_dir[f])
        j = int(sums.force_input[f])
        for i in range(n):
            if sums.force_D[f, i]:
                push = f"({_num(fx)} * tx{i} + {_num(fy)} * ty{i})"
                add(f"    Q{i} = Q{i} + u[{j}] * {_num(sums.force_D[f, i])} * {push}")
    for i in range(n):
        for j in range(sums.torque.shape[1]):
            if sums.torque[i, j]:
                add(f"    Q{i} = Q{i} + {_num(sums.torque[i, j])} * u[{j}]")
    # Cholesky M = L Lᵀ, then L y = Q, Lᵀ a = y
    for i in range(n):
        for j in range(i + 1):
            acc = " - ".join([f"m{i}_{j}"] + [f"L{i}_{k} * L{j}_{k}" for k in range(j)])
            if i == j:
                add(f"    L{i}_{i} = sqrt({acc})")
            else:
                add(f"    L{i}_{j} = ({acc}) / L{j}_{j}")
    for i in range(n):
        acc = " - ".join([f"Q{i}"] + [f"L{i}_{k} * y{k}" for k in range(i)])
        add(f"    y{i} = ({acc}) / L{i}_{i}")
    for i in reversed(range(n)):
        acc = " - ".join([f"y{i}"] + [f"L{k}_{i} * a{k}" for k in range(i + 1, n)])
        add(f"    a{i} = ({acc}) / L{i}_{i}")
    add(f"    return ({', '.join([*(f'v{k}' for k in range(n)), *(f'a{k}' for k in range(n))])},)")
    return "\n".join(lines) + "\n"


def compile_rhs(sums: Any) -> tuple[Callable[..., tuple[Any, ...]], Callable[..., tuple[Any, ...]]]:
    """(real, complex) versions of the generated ``rhs(x, u)``; x and u as Python sequences."""
    source = generate(sums)
    code = compile(source, "<planar rhs>", "exec")
    real: dict[str, Any] = {"cos": math.cos, "sin": math.sin, "sqrt": math.sqrt}
    cplx: dict[str, Any] = {"cos": cmath.cos, "sin": cmath.sin, "sqrt": cmath.sqrt}
    exec(code, real)  # our own generated straight-line arithmetic: no text from the netlist
    exec(code, cplx)
    return real["rhs"], cplx["rhs"]


def evaluate(fn: Callable[..., tuple[Any, ...]], x: Any, u: Any) -> Any:
    """``fn`` at numpy x, u as an array."""
    return np.array(fn(x.tolist(), u.tolist()))
