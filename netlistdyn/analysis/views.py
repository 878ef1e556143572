"""What an eigenvalue analysis looks like: the text, HTML and LaTeX of its ``repr()``, ``_repr_html_`` and
``_repr_latex_``."""

from __future__ import annotations

import html
import math
from typing import Any

from netlistdyn.base.formatting import VIEW_MODE_LIMIT, eng, plural


def _mode_row(mode: Any) -> tuple[str, str, str, str, str]:
    value = complex(mode.value.real + 0.0, mode.value.imag + 0.0)  # no "-0"
    lam = f"{value.real:.8g}" + (
        f" {'-' if value.imag < 0 else '+'} {abs(value.imag):.8g}j" if value.imag else ""
    )
    zeta = f"{mode.damping:.4g}" if math.isfinite(mode.damping) else "-"
    tau = eng(mode.time_constant, "s") if math.isfinite(mode.time_constant) else "∞"
    return (
        lam,
        eng(mode.natural_frequency, "rad/s"),
        eng(mode.natural_frequency / (2 * math.pi), "Hz"),
        zeta,
        tau,
    )


def eigen_text(analysis: Any) -> str:
    """``repr(analysis)``: verdict, method and a table of the modes."""
    rows = [_mode_row(m) for m in analysis.modes[:VIEW_MODE_LIMIT]]
    widths = [
        max(len(h), *(len(r[k]) for r in rows)) if rows else len(h) for k, h in enumerate(EIGEN_HEADINGS)
    ]
    lines = [
        f"<EigenAnalysis: {plural(len(analysis.modes), 'eigenvalue')}"
        + ("" if analysis.complete else " (not all)")
        + f", {analysis.verdict}>",
        f"method: {analysis.method}",
        "  ".join(h.rjust(w) for h, w in zip(EIGEN_HEADINGS, widths, strict=True)),
    ]
    lines += ["  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
    if len(analysis.modes) > VIEW_MODE_LIMIT:
        lines.append(f"... {len(analysis.modes) - VIEW_MODE_LIMIT} more (see .modes)")
    if analysis.stiffness_ratio is not None:
        lines.append(f"stiffness ratio: {analysis.stiffness_ratio:.4g}")
    lines += [f"warning: {w}" for w in analysis.warnings]
    return "\n".join(lines)


def eigen_html(analysis: Any) -> str:
    """``_repr_html_`` of an eigen analysis: the same table."""
    esc = html.escape
    head = "<tr>" + "".join(f"<th>{esc(h)}</th>" for h in EIGEN_HEADINGS) + "</tr>"
    body = "".join(
        "<tr>" + "".join(f'<td style="text-align:right">{esc(c)}</td>' for c in _mode_row(m)) + "</tr>"
        for m in analysis.modes[:VIEW_MODE_LIMIT]
    )
    more = len(analysis.modes) - VIEW_MODE_LIMIT
    tail = f"<p>... {more} more (see <code>.modes</code>)</p>" if more > 0 else ""
    stiff = (
        f"; stiffness ratio {analysis.stiffness_ratio:.4g}" if analysis.stiffness_ratio is not None else ""
    )
    warn = "".join(f"<p>warning: {esc(w)}</p>" for w in analysis.warnings)
    return (
        f"<p><b>EigenAnalysis</b>: {plural(len(analysis.modes), 'eigenvalue')}, "
        f"{esc(analysis.verdict)}{stiff}<br><small>{esc(analysis.method)}</small></p>"
        f"<table>{head}{body}</table>{tail}{warn}"
    )


def eigen_latex(analysis: Any) -> str | None:
    """``_repr_latex_``: the eigenvalues as a column (up to :data:`VIEW_MODE_LIMIT`)."""
    if not analysis.modes or len(analysis.modes) > VIEW_MODE_LIMIT:
        return None

    def number(z: complex) -> str:
        re, im = z.real + 0.0, z.imag + 0.0
        text = f"{re:.8g}"
        if im:
            text += f" {'-' if im < 0 else '+'} {abs(im):.8g}\\,j"
        return text.replace("e", r"\mathrm{e}")

    body = r" \\ ".join(number(m.value) for m in analysis.modes)
    return rf"$$\lambda(A) = \begin{{bmatrix}} {body} \end{{bmatrix}}\ \text{{({analysis.verdict})}}$$"


EIGEN_HEADINGS = ("λ [1/s]", "ωn", "fn = ωn/2π", "ζ", "τ")
