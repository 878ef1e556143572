"""Series and feedback interconnection of compiled models (seed 003).

``series(m1, m2)`` feeds m1's outputs into m2's inputs:

    A = [[A1, 0], [B2 C1, A2]],  B = [[B1], [B2 D1]],  C = [D2 C1, C2],  D = D2 D1.

``feedback(m1, m2, sign=-1)`` closes u1 = r + sign·y2 with u2 = y1; for
D1 = D2 = 0 and negative feedback this is the seed's
[[A1, −B1 C2], [B2 C1, A2]]. With feedthrough the algebraic loop
(I − sign·D1 D2) is solved and must be invertible.

States, inputs and outputs are prefixed with their model's name
(``m1.q(C1)``, ``m1.V1``, ``m2.v(out)``); models with
input-derivative terms (D1 ≠ 0) are refused, since the derivative of an
interconnected signal is not in the state.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from netlistdyn.base.errors import ControlDimension, UsageError
from netlistdyn.statespace.model import CompileInfo, StateSpaceModel


def _check_plain(model: StateSpaceModel, name: str) -> None:
    if model.has_input_derivative:
        raise UsageError(f"{name} has input-derivative terms (D1 ≠ 0): it cannot be interconnected")


def _build(
    A: np.ndarray,
    B: np.ndarray,
    C: np.ndarray,
    D: np.ndarray,
    states: tuple[str, ...],
    inputs: tuple[str, ...],
    outputs: tuple[str, ...],
    title: str,
) -> StateSpaceModel:
    zero = sp.csr_array(D.shape)
    return StateSpaceModel(
        sp.csr_array(A),
        sp.csr_array(B),
        sp.csr_array(C),
        sp.csr_array(D),
        zero,
        states,
        inputs,
        outputs,
        title,
        CompileInfo(order=A.shape[0]),
    )


def series(
    m1: StateSpaceModel, m2: StateSpaceModel, names: tuple[str, str] = ("m1", "m2")
) -> StateSpaceModel:
    """Cascade: every output of ``m1`` drives the input of ``m2`` in the same position.

    Raises
    ------
    ControlDimension
        When m1's outputs and m2's inputs differ in number.
    """
    if m1.noutputs != m2.ninputs:
        raise ControlDimension(
            f"series: {names[0]} has {m1.noutputs} outputs, {names[1]} expects {m2.ninputs} inputs"
        )
    _check_plain(m1, names[0])
    _check_plain(m2, names[1])
    n1, n2 = m1.nstates, m2.nstates
    A = np.block([[m1.A, np.zeros((n1, n2))], [m2.B @ m1.C, m2.A]])
    B = np.vstack([m1.B, m2.B @ m1.D])
    C = np.hstack([m2.D @ m1.C, m2.C])
    D = m2.D @ m1.D
    states = tuple(f"{names[0]}.{s}" for s in m1.states) + tuple(f"{names[1]}.{s}" for s in m2.states)
    inputs = tuple(f"{names[0]}.{u}" for u in m1.inputs)
    outputs = tuple(f"{names[1]}.{y}" for y in m2.outputs)
    return _build(A, B, C, D, states, inputs, outputs, f"series({m1.title}, {m2.title})")


def feedback(
    m1: StateSpaceModel, m2: StateSpaceModel, sign: float = -1.0, names: tuple[str, str] = ("m1", "m2")
) -> StateSpaceModel:
    """Closed loop u1 = r + sign·y2, u2 = y1; outputs y1, input r.

    Raises
    ------
    ControlDimension
        When the two models' signals do not match in number.
    UsageError
        When the algebraic loop through the feedthroughs has no unique solution.
    """
    if m1.noutputs != m2.ninputs or m2.noutputs != m1.ninputs:
        raise ControlDimension(
            f"feedback: {names[0]} is {m1.ninputs}-in/{m1.noutputs}-out, so {names[1]} must be "
            f"{m1.noutputs}-in/{m1.ninputs}-out; it is {m2.ninputs}-in/{m2.noutputs}-out"
        )
    _check_plain(m1, names[0])
    _check_plain(m2, names[1])
    A1, B1, C1, D1 = m1.A, m1.B, m1.C, m1.D
    A2, B2, C2, D2 = m2.A, m2.B, m2.C, m2.D
    # u1 = r + s y2, y2 = C2 x2 + D2 y1, y1 = C1 x1 + D1 u1  ⇒  (I − s D1 D2) y1 = C1 x1 + s D1 C2 x2 + D1 r
    loop = np.eye(m1.noutputs) - sign * D1 @ D2
    if np.linalg.cond(loop) > 1e12:
        raise UsageError("feedback: the algebraic loop I − sign·D1·D2 is singular")
    L = np.linalg.inv(loop)
    Cy = L @ np.hstack([C1, sign * D1 @ C2])  # y1 = Cy x + Dy r
    Dy = L @ D1
    y2_x = D2 @ Cy + np.hstack([np.zeros((m2.noutputs, m1.nstates)), C2])
    y2_r = D2 @ Dy
    u1_x = sign * y2_x
    u1_r = np.eye(m1.ninputs) + sign * y2_r
    A = np.block([[A1, np.zeros((m1.nstates, m2.nstates))], [np.zeros((m2.nstates, m1.nstates)), A2]])
    A = A + np.vstack([B1 @ u1_x, B2 @ Cy])
    B = np.vstack([B1 @ u1_r, B2 @ Dy])
    states = tuple(f"{names[0]}.{s}" for s in m1.states) + tuple(f"{names[1]}.{s}" for s in m2.states)
    inputs = tuple(f"{names[0]}.{u}" for u in m1.inputs)
    outputs = tuple(f"{names[0]}.{y}" for y in m1.outputs)
    return _build(A, B, Cy, Dy, states, inputs, outputs, f"feedback({m1.title}, {m2.title})")


def connection_names(
    m1: StateSpaceModel, m2: StateSpaceModel, how: str, names: tuple[str, str], sign: float = -1.0
) -> list[str]:
    """The signal links of :func:`series` or :func:`feedback`, e.g. ``plant.v(a) -> sensor.V1``."""
    forward = [f"{names[0]}.{y} -> {names[1]}.{u}" for y, u in zip(m1.outputs, m2.inputs, strict=True)]
    if how == "series":
        return forward
    back = "+" if sign > 0 else "-"
    return forward + [
        f"{names[1]}.{y} -> {names[0]}.{u} (sign {back}; the closed loop's input {names[0]}.{u} is added)"
        for y, u in zip(m2.outputs, m1.inputs, strict=True)
    ]
