"""How a simulation looks to people: the text and HTML of
:class:`~netlistdyn.workflows.pipelines.Simulation` (Jupyter shows the HTML).

The model's and the eigenvalue analysis' own views live beside them
(:mod:`netlistdyn.statespace.views`, :mod:`netlistdyn.analysis.views`); JSON output
never goes through a view: it keeps full-precision numbers.
"""

from __future__ import annotations

import html
from typing import Any

from netlistdyn.base.formatting import eng

# --- simulations -----------------------------------------------------------------------


def simulation_rows(sim: Any) -> list[tuple[str, str, str, str]]:
    """Per output: name, final value, minimum and maximum (engineering notation)."""
    rows = []
    for j, (name, unit) in enumerate(zip(sim.outputs, sim.units, strict=True)):
        column = sim.values[:, j]
        rows.append((name, eng(column[-1], unit, 6), eng(column.min(), unit, 6), eng(column.max(), unit, 6)))
    return rows


def simulation_text(sim: Any) -> str:
    """``repr(simulation)``: what was simulated and each output's final value and range."""
    rows = simulation_rows(sim)
    width = max(6, *(len(r[0]) for r in rows)) if rows else 6
    lines = [
        f"<Simulation {sim.title!r}: 0..{eng(sim.horizon.tstop, 's')}, {sim.time.size} points, "
        f"{sim.method} ({sim.setting}), {sim.status}>",
        f"  {'output':<{width}} {'final':>12} {'min':>12} {'max':>12}",
    ]
    lines += [f"  {n:<{width}} {f:>12} {lo:>12} {hi:>12}" for n, f, lo, hi in rows]
    lines.append("(samples: .time and .values, or sim['name'])")
    return "\n".join(lines)


def simulation_html(sim: Any) -> str:
    """``_repr_html_`` of a simulation: the summary table."""
    esc = html.escape
    head = "<tr><th>output</th><th>final</th><th>min</th><th>max</th></tr>"
    body = "".join(
        "<tr>" + "".join(f'<td style="text-align:right">{esc(c)}</td>' for c in row) + "</tr>"
        for row in simulation_rows(sim)
    )
    return (
        f"<p><b>Simulation</b> {esc(sim.title)}: 0..{esc(eng(sim.horizon.tstop, 's'))}, "
        f"{sim.time.size} points, {esc(sim.method)} ({esc(sim.setting)}), {esc(sim.status)}</p>"
        f"<table>{head}{body}</table>"
    )
