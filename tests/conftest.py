"""Shared helpers for the test suite."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.frontend.parser import parse_file, parse_text
from netlistdyn.statespace.model import StateSpaceModel

ROOT = Path(__file__).resolve().parent.parent
NETLISTS = ROOT / "netlists"


def compile_file(name: str, params: dict[str, float] | None = None, outputs=None) -> StateSpaceModel:
    return compile_netlist(parse_file(NETLISTS / name, params or {}), outputs)


def compile_string(text: str, outputs=None) -> StateSpaceModel:
    return compile_netlist(parse_text(text), outputs)


def match_spectra(actual, expected, rtol: float, scale: float | None = None) -> float:
    """Pair each expected eigenvalue with the nearest unused actual one; return the worst
    error relative to |expected| (or to ``scale`` when given). Asserts equal counts."""
    actual = list(np.asarray(actual, dtype=complex))
    expected = np.asarray(expected, dtype=complex)
    assert len(actual) == len(expected), f"{len(actual)} eigenvalues, expected {len(expected)}"
    assert scale is None or scale > 0, "a zero scale would make every comparison 0/0 (always passing)"
    worst = 0.0
    for value in sorted(expected, key=lambda z: -abs(z)):
        j = int(np.argmin([abs(a - value) for a in actual]))
        ref = scale if scale is not None else max(abs(value), 1e-300)
        worst = max(worst, abs(actual.pop(j) - value) / ref)
    assert worst <= rtol, f"eigenvalues differ by {worst:.3g} (relative), tolerance {rtol}"
    return worst


@pytest.fixture
def netlists_dir() -> Path:
    return NETLISTS
