"""What a state-space model looks like: the text, HTML and LaTeX that its ``repr()``, ``_repr_html_`` and
``_repr_latex_`` return (Jupyter shows the HTML)."""

from __future__ import annotations

import html
from collections.abc import Sequence
from typing import Any

import numpy as np

from netlistdyn.base.formatting import (
    VIEW_MATRIX_LIMIT,
    format_matrix,
    latex_label,
    matrix_cell,
    plural,
    signal_list,
)


def model_text(model: Any) -> str:
    """``repr(model)``: sizes, labels and (for small models) the labelled matrices."""
    head = (
        f"<StateSpaceModel {model.title!r}: {plural(model.nstates, 'state')}, "
        f"{plural(model.ninputs, 'input')}, {plural(model.noutputs, 'output')}>"
    )
    lines = [
        head,
        f"states:  {signal_list(model.states)}",
        f"inputs:  {signal_list(model.inputs)}",
        f"outputs: {signal_list(model.outputs)}",
    ]
    if max(model.nstates, model.ninputs, model.noutputs) > VIEW_MATRIX_LIMIT:
        for name in ("A", "B", "C", "D"):
            matrix = getattr(model, f"{name}_sparse")
            lines.append(f"{name}: {matrix.shape[0]}x{matrix.shape[1]}, {matrix.nnz} non-zeros")
    else:
        for name, rows, cols in _blocks(model):
            lines += format_matrix(name, getattr(model, name), rows, cols)
    return "\n".join(lines)


def _blocks(model: Any) -> list[tuple[str, Sequence[str], Sequence[str]]]:
    blocks: list[tuple[str, Sequence[str], Sequence[str]]] = [
        ("A", model.states, model.states),
        ("B", model.states, model.inputs),
        ("C", model.outputs, model.states),
        ("D", model.outputs, model.inputs),
    ]
    if model.has_input_derivative:
        blocks.append(("D1", model.outputs, model.inputs))
    return blocks


def model_html(model: Any) -> str:
    """``_repr_html_``: the block matrix [[A, B], [C, D]] as a labelled table."""
    esc = html.escape
    title = (
        f"<p><b>StateSpaceModel</b> {esc(model.title)}: {plural(model.nstates, 'state')}, "
        f"{plural(model.ninputs, 'input')}, {plural(model.noutputs, 'output')}</p>"
    )
    if max(model.nstates, model.ninputs, model.noutputs) > VIEW_MATRIX_LIMIT:
        sizes = "".join(
            f"<li>{name}: {m.shape[0]}×{m.shape[1]}, {m.nnz} non-zeros</li>"
            for name in ("A", "B", "C", "D")
            for m in [getattr(model, f"{name}_sparse")]
        )
        return title + f"<ul>{sizes}</ul>"
    cols = [*model.states, *model.inputs]
    head = "<tr><th></th>" + "".join(f"<th>{esc(c)}</th>" for c in cols) + "</tr>"
    rows = []
    top = np.hstack([model.A, model.B])
    bottom = np.hstack([model.C, model.D])
    for label, row, kind in [
        *((s, r, "x'") for s, r in zip(model.states, top, strict=True)),
        *((o, r, "y") for o, r in zip(model.outputs, bottom, strict=True)),
    ]:
        cells = "".join(
            f'<td style="text-align:right{";border-left:1px solid" if k == model.nstates else ""}">'
            f"{matrix_cell(v)}</td>"
            for k, v in enumerate(row)
        )
        rows.append(f"<tr><th>{kind} {esc(label)}</th>{cells}</tr>")
    note = "<p>y also gets D1·du/dt (see <code>.D1</code>)</p>" if model.has_input_derivative else ""
    return title + f"<table>{head}{''.join(rows)}</table>" + note


def model_latex(model: Any) -> str | None:
    """``_repr_latex_``: ẋ = Ax + Bu, y = Cx + Du as one block matrix (small models only)."""
    if max(model.nstates, model.ninputs, model.noutputs) > VIEW_MATRIX_LIMIT or not model.nstates:
        return None
    n, m = model.nstates, model.ninputs
    top = np.hstack([model.A, model.B])
    bottom = np.hstack([model.C, model.D])

    def rows(block: np.ndarray) -> str:
        return r" \\ ".join(" & ".join(matrix_cell(v) for v in row) for row in block)

    spec = "c" * n + ("|" + "c" * m if m else "")
    matrix = rf"\left[\begin{{array}}{{{spec}}} {rows(top)} \\ \hline {rows(bottom)} \end{{array}}\right]"
    x = r" \\ ".join(latex_label(s) for s in model.states)
    u = r" \\ ".join(latex_label(s) for s in model.inputs)
    y = r" \\ ".join(latex_label(s) for s in model.outputs)
    lhs = r"\begin{bmatrix} \dot{x} \\ y \end{bmatrix}"
    legend = rf",\quad x = \begin{{bmatrix}} {x} \end{{bmatrix}}"
    legend += rf",\ u = \begin{{bmatrix}} {u} \end{{bmatrix}}" if m else ""
    legend += rf",\ y = \begin{{bmatrix}} {y} \end{{bmatrix}}" if model.noutputs else ""
    rhs = r"\begin{bmatrix} x \\ u \end{bmatrix}" if m else "x"
    return f"$${lhs} = {matrix} {rhs}{legend}$$"
