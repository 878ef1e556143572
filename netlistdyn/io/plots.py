"""Figures (matplotlib, Agg backend), written atomically in the format of the file's extension.

``plot.png`` is a PNG, ``plot.svg`` an SVG, ``plot.pdf`` a PDF (any format
matplotlib writes); a file without an extension gets a PNG. Axes carry SI
prefixes (``250 µs``, ``1.6 kHz``).
"""

from __future__ import annotations

import io
import math
import textwrap
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from netlistdyn.base.atomic import write_bytes
from netlistdyn.base.errors import UsageError
from netlistdyn.base.formatting import eng_formatter
from netlistdyn.base.optional import require
from netlistdyn.base.values import parse_number
from netlistdyn.frontend.lines import read_lines
from netlistdyn.io.bode import Bode


def _figure() -> Any:
    matplotlib = require("matplotlib", "a figure (--plot, --bode)")
    matplotlib.use("Agg")
    return require("matplotlib.pyplot", "a figure (--plot, --bode)")


def geometric(values: NDArray[np.float64]) -> bool:
    """Whether distinct positive ``values`` are evenly spaced in log (a ``log:a:b:n`` sweep).

    Three or more distinct values whose log steps agree to 1e-6 relative (SPICE numbers and
    ``logspace`` round each value once, far below that); two values are taken as linear.
    """
    distinct = np.unique(values)
    if distinct.size < 3 or distinct.min() <= 0:
        return False
    steps = np.diff(np.log(distinct))
    return bool(np.all(np.abs(steps - steps.mean()) <= 1e-6 * steps.mean()))


def figure_format(path: str) -> str:
    """The matplotlib format for ``path``'s extension (``png`` without one).

    Raises
    ------
    UsageError
        For an extension matplotlib cannot write.
    """
    suffix = Path(path).suffix.lower().lstrip(".")
    if not suffix:
        return "png"
    plt = _figure()
    supported = plt.figure().canvas.get_supported_filetypes()
    plt.close("all")
    if suffix not in supported:
        raise UsageError(
            f"{path}: cannot write a .{suffix} figure; use one of .{', .'.join(sorted(supported))}"
        )
    return suffix


def save_figure(fig: Any, path: str) -> None:
    """Save in the format of ``path``'s extension through a temporary file and a rename, then close."""
    buffer = io.BytesIO()
    try:
        fig.savefig(buffer, dpi=110, format=figure_format(path))
        write_bytes(path, buffer.getvalue())
    finally:
        _figure().close(fig)


def _eng_axis(axis: Any, unit: str) -> None:
    axis.set_major_formatter(eng_formatter(unit))


def _title(text: str, width: int = 90) -> str:
    """Wrap a long title on word boundaries instead of cutting it."""
    return "\n".join(textwrap.wrap(text, width)) if text else ""


def _units_label(units: Any) -> str:
    distinct = sorted({u for u in units if u})
    return f" [{', '.join(distinct)}]" if distinct else ""


def validation_plot(report: Any, path: str, units: Any = (), title: str = "") -> None:
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
    top.set_ylabel("response" + _units_label(units))
    heading = f"validate: {Path(report.netlist).name}" + (f"\n{_title(title)}" if title else "")
    top.set_title(heading, fontsize=9)
    top.legend(fontsize=8, ncol=2, loc="upper right", framealpha=0.8)
    top.grid(True, alpha=0.3)
    bottom.axhline(report.rtol, color="k", linestyle=":", label=f"rtol {report.rtol:g}")
    bottom.set_xlabel("time")
    _eng_axis(bottom.xaxis, "s")
    bottom.set_ylabel("|model − ngspice| / peak")
    bottom.legend(fontsize=8, ncol=2, loc="lower right", framealpha=0.8)
    bottom.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path)


def simulation_plot(sim: Any, path: str) -> None:
    """The simulated outputs against time, one labelled line each (a :class:`~netlistdyn.api.Simulation`)."""
    plt = _figure()
    fig, ax = plt.subplots(figsize=(9, 5))
    for j, name in enumerate(sim.outputs):
        ax.plot(sim.time, sim.values[:, j], label=name, linewidth=1.2)
    ax.set_xlabel("time")
    _eng_axis(ax.xaxis, "s")
    distinct = sorted({u for u in sim.units if u})
    if len(distinct) == 1:
        _eng_axis(ax.yaxis, distinct[0])
        ax.set_ylabel("output")
    else:
        ax.set_ylabel("output" + _units_label(sim.units))
    ax.set_title(f"{_title(sim.title)}\n({sim.method}, {sim.setting})", fontsize=9)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="upper right", framealpha=0.8)
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
    ax.set_title(f"{_title(report.title, 80)}\n{report.nstates} states", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="lower left", framealpha=0.8)
    fig.tight_layout()
    save_figure(fig, path)


def sweep_plot(cases: Any, path: str) -> None:
    """Eigenvalues in the complex plane, coloured by the swept parameter's value (a root locus).

    Each mode, tracked from case to case, is joined by a thin line. The
    real axis is linear when the real parts span less than three decades,
    else symmetric-logarithmic with its linear band at the smallest
    non-zero |Re λ| and ticks only at decades, so labels do not overlap;
    only the half-planes that hold eigenvalues are drawn (with the
    imaginary axis).
    """
    plt = _figure()
    from matplotlib.colors import LogNorm, Normalize  # noqa: PLC0415 (deferred, matplotlib: optional plot extra)

    fig, ax = plt.subplots(figsize=(8, 5.5))
    good = [c for c in cases if "eigenvalues" in c]
    name = next(iter(good[0]["params"]), None) if good else None
    values = (
        np.array([c["params"][name] for c in good], dtype=float)
        if name
        else np.arange(len(good), dtype=float)
    )
    positive = values.size and values.min() > 0
    spread = values.max() / values.min() if positive else 1.0
    norm = (
        LogNorm(values.min(), values.max())
        if positive and (spread > 100 or geometric(values))
        else Normalize(values.min(), values.max() if values.size else 1.0)
    )
    tracks = [np.array(c["eigenvalues"], dtype=float).reshape(-1, 2) for c in good]
    counts = {t.shape[0] for t in tracks}
    if len(counts) == 1 and len(tracks) > 1:
        stacked = np.stack(tracks)  # (case, mode, re/im)
        for k in range(stacked.shape[1]):
            ax.plot(stacked[:, k, 0], stacked[:, k, 1], color="0.75", linewidth=0.6, zorder=1)
    for value, points in zip(values, tracks, strict=True):
        if points.size:
            ax.scatter(
                points[:, 0],
                points[:, 1],
                c=[value] * len(points),
                cmap="viridis",
                norm=norm,
                marker="x",
                zorder=2,
            )
    if good:
        mappable = plt.cm.ScalarMappable(norm=norm, cmap="viridis")
        others = [k for k in good[0]["params"] if k != name]
        label = name + (f" (with {', '.join(others)})" if others else "") if name else "case"
        fig.colorbar(mappable, ax=ax, label=label)
    ax.axvline(0, color="k", linewidth=0.5)
    ax.axhline(0, color="k", linewidth=0.3)
    ax.set_xlabel("Re λ [1/s]")
    ax.set_ylabel("Im λ [1/s]")
    real = np.concatenate([t[:, 0] for t in tracks]) if tracks else np.zeros(0)
    nonzero = np.abs(real[real != 0])
    if nonzero.size and nonzero.max() / nonzero.min() > 1e3:
        linthresh = 10.0 ** math.floor(math.log10(nonzero.min()))
        ax.set_xscale("symlog", linthresh=linthresh, linscale=0.5)
        decades = math.log10(nonzero.max() / linthresh)
        ax.xaxis.set_major_locator(_sparse_symlog_locator(linthresh, max(1, math.ceil(decades / 6))))
        # Only the half-planes that hold eigenvalues, and a sliver beyond the imaginary axis.
        low = 1.6 * real.min() if real.min() < 0 else -0.3 * linthresh
        high = 1.6 * real.max() if real.max() > 0 else 0.3 * linthresh
        ax.set_xlim(low, high)
    ax.set_title("eigenvalues per case (lines follow each mode)", fontsize=9)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path)


def _sparse_symlog_locator(linthresh: float, step: int) -> Any:
    """A locator with ticks at 0 and ±10^k for every ``step``-th decade from ``linthresh``."""
    from matplotlib.ticker import Locator  # noqa: PLC0415 (deferred, matplotlib: optional plot extra)

    class SparseSymlog(Locator):
        def __call__(self) -> Any:
            assert self.axis is not None  # matplotlib calls a locator through the axis it is set on
            low, high = self.axis.get_view_interval()
            return self.tick_values(low, high)

        def tick_values(self, vmin: float, vmax: float) -> Any:
            top = max(abs(vmin), abs(vmax))
            first = math.floor(math.log10(linthresh))
            last = math.ceil(math.log10(top)) if top > 0 else first
            # From the top decade down, every step-th; none at linthresh, whose label would touch 0's.
            powers = [10.0**k for k in range(last, first, -step)]
            ticks = [0.0, *powers, *(-p for p in powers)]
            return np.array(sorted(t for t in ticks if vmin <= t <= vmax))

    return SparseSymlog()


def ac_range(netlist: Any) -> tuple[float, float] | None:
    """``(fstart, fstop)`` in Hz from the netlist's ``.ac`` line, if it has a usable one."""

    path = getattr(netlist, "path", "")
    try:
        text = Path(path).read_text()
        _, lines = read_lines(Path(path), text)
    except Exception:  # text given to the API, or a file that changed: no .ac range
        return None
    for line in lines:
        fields = line.text.replace("(", " ").replace(")", " ").split()
        if fields and fields[0].lower() == ".ac" and len(fields) >= 5:
            start, stop = parse_number(fields[3]), parse_number(fields[4])
            if start is not None and stop is not None and 0 < start < stop:
                return start, stop
    return None


def bode_plot(data: Bode, path: str, title: str) -> None:
    """Magnitude (dB) and phase (degrees) of every input→output pair against frequency.

    The bottom axis is in Hz, the top one in rad/s. ``data`` is the response on its grid
    (:func:`netlistdyn.io.bode.bode`: the netlist's ``.ac`` range, else two decades either side
    of the eigenvalue magnitudes); ``title`` is the model's.
    """
    hz, source = data.frequency_hz, data.source
    db, degrees = data.magnitude_db(), data.phase_deg()
    plt = _figure()
    fig, (mag, phase) = plt.subplots(2, 1, figsize=(9, 6.8), sharex=True)
    for p, (out, inp) in enumerate(data.pairs):  # pairs the input reaches
        mag.semilogx(hz, db[:, p], label=f"{out}/{inp}", linewidth=1.2)
        phase.semilogx(hz, degrees[:, p], linewidth=1.2)
    mag.set_ylabel("|H| [dB]")
    mag.set_title(f"frequency response: {_title(title, 80)} ({source})", fontsize=9)
    mag.grid(True, which="both", alpha=0.3)
    if mag.get_legend_handles_labels()[0]:
        mag.legend(fontsize=8, ncol=2, loc="lower left", framealpha=0.8)
    top = mag.secondary_xaxis("top", functions=(lambda f: 2 * np.pi * f, lambda w: w / (2 * np.pi)))
    top.set_xlabel("ω")
    _eng_axis(top.xaxis, "rad/s")
    phase.set_ylabel("phase [deg]")
    phase.set_xlabel("frequency")
    _eng_axis(phase.xaxis, "Hz")
    phase.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path)
