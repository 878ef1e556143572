"""PNG figures (matplotlib, Agg backend), written atomically."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np


def _figure() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Any, path: str) -> None:
    """Save through a temporary file and a rename, then close the figure."""
    target = Path(path)
    fd, tmp = tempfile.mkstemp(dir=target.parent or Path("."), prefix=f".{target.name}.", suffix=".png")
    os.close(fd)
    try:
        fig.savefig(tmp, dpi=110, format="png")
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    finally:
        _figure().close(fig)


def _unit(name: str) -> str:
    return "A" if name.startswith("i(") else "V"


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
