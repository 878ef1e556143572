"""PNG figures (matplotlib, Agg backend), written atomically."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import numpy as np

from .atomic import write_bytes


def _figure() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Any, path: str) -> None:
    """Save as PNG through a temporary file and a rename, then close the figure."""
    buffer = io.BytesIO()
    try:
        fig.savefig(buffer, dpi=110, format="png")
        write_bytes(path, buffer.getvalue())
    finally:
        _figure().close(fig)


def _unit(name: str) -> str:
    """Electrical unit, or the mechanical quantity, of an output name."""
    head = name.split("(", 1)[0]
    return {"i": "A or N", "v": "V or m/s", "x": "m or rad", "angle": "rad"}.get(head, "")


def validation_plot(report: Any, path: str) -> None:
    """Model and ngspice responses overlaid, and their difference relative to the peak."""
    plt = _figure()
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True)
    t = report.time
    for j, comp in enumerate(report.comparisons):
        ref = report.spice.outputs[comp.name]
        (line,) = top.plot(t, report.ours[:, j], label=f"{comp.name} model", linewidth=1.4)
        top.plot(t, ref, "--", color=line.get_color(), label=f"{comp.name} ngspice", linewidth=1.0)
        scale = comp.peak if comp.peak > 0 else 1.0
        err = np.abs(report.ours[:, j] - ref) / scale
        bottom.semilogy(t, np.maximum(err, 1e-18), color=line.get_color(), label=comp.name, linewidth=1.0)
    units = sorted({_unit(c.name) for c in report.comparisons})
    top.set_ylabel(f"response [{', '.join(units)}]")
    top.set_title(f"validate: {Path(report.netlist).name}")
    top.legend(fontsize=8, ncol=2)
    top.grid(True, alpha=0.3)
    bottom.axhline(report.rtol, color="k", linestyle=":", label=f"rtol {report.rtol:g}")
    bottom.set_xlabel("time [s]")
    bottom.set_ylabel("|model − ngspice| / peak")
    bottom.legend(fontsize=8, ncol=2)
    bottom.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path)


def simulation_plot(result: Any, names: Any, title: str, path: str) -> None:
    """The simulated outputs against time, one labelled line each."""
    plt = _figure()
    fig, ax = plt.subplots(figsize=(9, 5))
    for j, name in enumerate(names):
        ax.plot(result.time, result.outputs[:, j], label=name, linewidth=1.2)
    units = sorted({_unit(n) for n in names})
    ax.set_xlabel("time [s]")
    ax.set_ylabel(f"output [{', '.join(units)}]")
    ax.set_title(f"{title}\n({result.method}, {result.setting})", fontsize=9)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)


def bench_plot(report: Any, path: str) -> None:
    """Error against run time, log-log, one series per method."""
    plt = _figure()
    fig, ax = plt.subplots(figsize=(8, 5.5))
    series: dict[str, list[tuple[float, float]]] = {}
    for row in report.rows:
        if row.status == "ok" and row.error > 0 and row.seconds > 0:
            series.setdefault(row.method, []).append((row.seconds, max(row.error, 1e-17)))
    for name, pts in series.items():
        pts.sort()
        style = "s--" if name.startswith("ngspice") else "o-"
        ax.loglog([p[0] for p in pts], [p[1] for p in pts], style, label=name)
    ax.set_xlabel("wall time [s]")
    ax.set_ylabel("max error / peak")
    ax.set_title(f"{report.title[:70]}\n{report.nstates} states", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)


def sweep_plot(cases: Any, path: str) -> None:
    """Eigenvalues in the complex plane, coloured by the swept parameter's value (a root locus)."""
    plt = _figure()
    from matplotlib.colors import LogNorm, Normalize

    fig, ax = plt.subplots(figsize=(7.5, 5.5))
    good = [c for c in cases if "eigenvalues" in c]
    name = next(iter(good[0]["params"]), None) if good else None
    values = np.array([c["params"][name] for c in good], dtype=float) if name else np.arange(len(good))
    positive = values.size and values.min() > 0
    spread = values.max() / values.min() if positive else 1.0
    norm = (
        LogNorm(values.min(), values.max())
        if positive and spread > 100
        else Normalize(values.min(), values.max())
    )
    for value, case in zip(values, good, strict=True):
        points = np.array(case["eigenvalues"])
        if points.size:
            ax.scatter(
                points[:, 0], points[:, 1], c=[value] * len(points), cmap="viridis", norm=norm, marker="x"
            )
    if good:
        mappable = plt.cm.ScalarMappable(norm=norm, cmap="viridis")
        others = [k for k in good[0]["params"] if k != name]
        label = name + (f" (with {', '.join(others)})" if others else "") if name else "case"
        fig.colorbar(mappable, ax=ax, label=label)
    ax.axvline(0, color="k", linewidth=0.5)
    ax.set_xlabel("Re λ [1/s]")
    ax.set_ylabel("Im λ [1/s]")
    ax.set_xscale("symlog", linthresh=1e-3)
    ax.set_title("eigenvalues per case", fontsize=9)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path)


def bode_plot(model: Any, path: str) -> None:
    """Magnitude (dB) and phase (degrees) of every input→output pair against ω (rad/s)."""
    from .control import frequency_grid, frequency_response

    if model.nstates > 400:
        from .errors import UsageError

        raise UsageError("--bode is for models of up to 400 states")
    omega = frequency_grid(model)
    response = frequency_response(model, omega)
    plt = _figure()
    fig, (mag, phase) = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True)
    for i, out in enumerate(model.outputs):
        for j, inp in enumerate(model.inputs):
            h = response[:, i, j]
            if not np.any(h):
                continue  # this input does not reach this output
            with np.errstate(divide="ignore"):
                mag.semilogx(omega, 20 * np.log10(np.abs(h)), label=f"{out}/{inp}", linewidth=1.2)
            phase.semilogx(omega, np.degrees(np.unwrap(np.angle(h))), linewidth=1.2)
    mag.set_ylabel("|H(jω)| [dB]")
    mag.set_title(f"frequency response: {model.title[:70]}", fontsize=9)
    mag.grid(True, which="both", alpha=0.3)
    mag.legend(fontsize=8, ncol=2)
    phase.set_ylabel("phase [deg]")
    phase.set_xlabel("ω [rad/s]")
    phase.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path)
