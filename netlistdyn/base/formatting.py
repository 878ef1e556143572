"""How numbers look to people: engineering notation with SI prefixes and labelled matrices.

Every layer may use these; JSON output never does (it keeps full-precision numbers)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any, ClassVar

import numpy as np

#: SI prefixes by decimal exponent (a multiple of 3).
PREFIXES: dict[int, str] = {
    -24: "y",
    -21: "z",
    -18: "a",
    -15: "f",
    -12: "p",
    -9: "n",
    -6: "µ",
    -3: "m",
    0: "",
    3: "k",
    6: "M",
    9: "G",
    12: "T",
}


#: Largest model whose matrices the notebook views print entry by entry.
VIEW_MATRIX_LIMIT = 16


#: Most modes listed in a text or HTML view of an eigen analysis.
VIEW_MODE_LIMIT = 40


def eng(value: float, unit: str = "", digits: int = 4) -> str:
    """A number in engineering notation with an SI prefix.

    Parameters
    ----------
    value : float
        The number, in the base unit (s, H, F, Hz ...).
    unit : str
        The unit symbol appended after the prefix (may be empty).
    digits : int
        Significant digits.

    Returns
    -------
    str
        ``eng(1e-5, "H")`` is ``"10 µH"``, ``eng(0.00025, "s")`` is
        ``"250 µs"``, ``eng(2200)`` is ``"2.2k"``; outside 1e-24..1e15 the
        exponent is written out.
    """
    value = float(value)
    space = " " if unit else ""
    if not math.isfinite(value):
        return f"{value}{space}{unit}"
    if value == 0:
        return f"0{space}{unit}"
    exponent = 3 * math.floor(math.log10(abs(value)) / 3)
    if exponent not in PREFIXES:
        return f"{value:.{digits}g}{space}{unit}"
    mantissa = float(f"{value / 10.0**exponent:.{digits}g}")
    if abs(mantissa) >= 1000 and exponent + 3 in PREFIXES:  # 999.96 rounded up to 1000
        exponent += 3
        mantissa = float(f"{value / 10.0**exponent:.{digits}g}")
    if unit:
        return f"{mantissa:.{digits}g} {PREFIXES[exponent]}{unit}"
    return f"{mantissa:.{digits}g}{PREFIXES[exponent]}"  # a bare number: 10k, 2.2µ


def eng_formatter(unit: str) -> Any:
    """A matplotlib tick formatter writing ``unit`` with SI prefixes (µs, kHz ...)."""
    from matplotlib.ticker import EngFormatter  # noqa: PLC0415 (deferred, matplotlib: optional plot extra)

    return EngFormatter(unit=unit, sep=" ")


def element_value(name: str, value: float, unit: str = "") -> str:
    """``L1 = 10 µH``: an element's value with its unit (see :func:`element_unit`).

    A unit that already has a prefix (kg, kg·m²) is written after a plain
    number (``0.0008 kg·m²``, not ``800 µkg·m²``).
    """
    if unit.startswith("kg"):
        return f"{name} = {float(value):.4g} {unit}"
    return f"{name} = {eng(value, unit)}"


def signal_list(names: Sequence[str]) -> str:
    return ", ".join(names) if names else "none"


def plural(count: int, word: str) -> str:
    return f"{count} {word}" + ("" if count == 1 else "s")


def matrix_cell(value: float) -> str:
    return f"{value:.6g}" if value else "0"


def latex_label(name: str) -> str:
    return r"\text{" + name.replace("_", r"\_").replace("#", r"\#") + "}"


def format_matrix(name: str, matrix: np.ndarray, rows: Sequence[str], cols: Sequence[str]) -> list[str]:
    """A labelled matrix as text lines."""
    if matrix.size == 0:
        return [f"{name} = [] ({matrix.shape[0]}x{matrix.shape[1]})"]
    cells = [[f"{v:.6g}" for v in row] for row in matrix]
    width = max(12, *(len(c) + 2 for c in cols), *(len(x) + 2 for row in cells for x in row))
    head = max(len(r) for r in rows) + 2
    lines = [f"{name} ="]
    lines.append(" " * head + "".join(c.rjust(width) for c in cols))
    for label, row in zip(rows, cells, strict=True):
        lines.append(("  " + label).ljust(head) + "".join(x.rjust(width) for x in row))
    return lines


class Rendered:
    """A result that renders itself: ``repr()`` as text, ``_repr_html_`` and ``_repr_latex_`` for Jupyter.

    A subclass names its three renderers, ``RENDERERS = (text, html, latex)`` (the LaTeX one may
    return None: no LaTeX view), each taking the object. A dataclass subclass is declared with
    ``repr=False``, so that its generated ``__repr__`` does not replace this one.
    """

    RENDERERS: ClassVar[tuple[Callable[[Any], str], Callable[[Any], str], Callable[[Any], str | None]]]

    def __repr__(self) -> str:
        return self.RENDERERS[0](self)

    def _repr_html_(self) -> str:
        return self.RENDERERS[1](self)

    def _repr_latex_(self) -> str | None:
        return self.RENDERERS[2](self)
