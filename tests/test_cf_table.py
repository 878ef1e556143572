"""The stored CF approximations of e^x on (−∞, 0] (netlistdyn/simulation/_cf_table.py), checked against
mpmath's exponential on a dense sampling of the whole axis, independently of the generator."""

from __future__ import annotations

import mpmath as mp
import numpy as np
import pytest

from netlistdyn.simulation._cf_table import CF

#: Halphen's constant: the best type (n, n) error on (−∞, 0] decays as HALPHEN**−n
#: (Cody–Meinardus–Varga; Gonchar–Rakhmanov), asymptotically 2·HALPHEN**(−n−1/2) ≈ 0.66·HALPHEN**−n.
HALPHEN = 9.289025491920818
#: Samples in t ∈ [−1, 1) with x = 9 (t − 1)/(t + 1), clustered at both ends as cos(θ).
SAMPLES = 6000
#: Rounding of r evaluated in double precision: a few ulps of the largest term of the sum.
ROUNDING_ULPS = 8


def _axis() -> np.ndarray:
    t = -np.cos(np.linspace(0.0, np.pi, SAMPLES + 1)[1:-1])
    return 9.0 * (t - 1.0) / (t + 1.0)


def _r(degree: int, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """r(x) in double precision and the size of its largest term (for the rounding allowance)."""
    r_inf, pairs, _ = CF[degree]
    value = np.full(x.shape, r_inf)
    largest = np.full(x.shape, abs(r_inf))
    for z, c in pairs:
        term = 2.0 * np.real(c / (x - z))
        value = value + term
        largest = np.maximum(largest, np.abs(term))
    return value, largest


@pytest.mark.parametrize("degree", sorted(CF))
def test_error_is_near_best_on_the_whole_negative_axis(degree: int) -> None:
    """max |r − e^x| over the axis is the stored bound (to 1 % plus rounding), that bound lies
    between 0.6 and 1.0 times HALPHEN**−n (the best possible is ≈ 0.66 of it, and the
    constraints r(0) = 1, r(−∞) = 0 cost a little), and r∞ = 0: strictly proper, so the
    algebraic unknowns of a descriptor system come out consistent after a step."""
    r_inf, _, bound = CF[degree]
    x = _axis()
    value, largest = _r(degree, x)
    exact = np.array([float(mp.exp(v)) for v in x])
    rounding = ROUNDING_ULPS * np.finfo(float).eps * largest
    assert np.all(np.abs(value - exact) <= 1.01 * bound + rounding)
    assert 0.6 <= bound * HALPHEN**degree <= 1.0
    assert abs(r_inf) < 1e-300


@pytest.mark.parametrize("degree", sorted(CF))
def test_error_equioscillates(degree: int) -> None:
    """The error alternates in sign at ≥ n extrema within 2 % of its maximum (the
    characterisation of the best approximation for the n − 1 free parameters left once
    r(0) = 1 and r(−∞) = 0)."""
    _, _, bound = CF[degree]
    x = _axis()
    with mp.workdps(30):
        r_inf, pairs, _ = CF[degree]
        err = []
        for v in x:
            xv = mp.mpf(v)
            r = mp.mpf(r_inf) + mp.fsum(2 * mp.re(mp.mpc(c) / (xv - mp.mpc(z))) for z, c in pairs)
            err.append(float(r - mp.exp(xv)))
    err = np.array(err)
    inner = (
        np.flatnonzero((np.abs(err[1:-1]) >= np.abs(err[:-2])) & (np.abs(err[1:-1]) >= np.abs(err[2:]))) + 1
    )
    # The coefficients are stored as doubles: rounding them moves r by up to `moved` (at degree
    # 14, residues ~1e2, about a tenth of the bound), so a peak counts within 2 % plus that.
    moved = np.zeros(x.size)
    for z, c in pairs:
        moved += 2 * np.finfo(float).eps * (abs(c) / np.abs(x - z) + abs(c) * abs(z) / np.abs(x - z) ** 2)
    keep = np.abs(err[inner]) >= 0.98 * bound - moved[inner]
    peaks = err[inner][keep]
    alternations = 1 + int(np.count_nonzero(np.sign(peaks[1:]) != np.sign(peaks[:-1])))
    assert alternations >= degree


@pytest.mark.parametrize("degree", sorted(CF))
def test_exact_at_zero_and_first_derivative_close(degree: int) -> None:
    """r(0) = 1 to rounding (no drift of the DC part step after step), and r′(0) = 1 to the
    size an equioscillating error allows near 0: |e′(0)| ≤ 200·bound (its first extremum lies
    ~0.02 from 0 in x)."""
    r_inf, pairs, bound = CF[degree]
    with mp.workdps(30):
        r0 = mp.mpf(r_inf) + mp.fsum(2 * mp.re(mp.mpc(c) / (-mp.mpc(z))) for z, c in pairs)
        d0 = mp.fsum(2 * mp.re(-mp.mpc(c) / mp.mpc(z) ** 2) for z, c in pairs)
    largest = max(abs(2 * c / z) for z, c in pairs)
    assert abs(float(r0) - 1.0) <= ROUNDING_ULPS * np.finfo(float).eps * largest
    assert abs(float(d0) - 1.0) <= 200 * bound
