"""Regenerate :mod:`netlistdyn._cf_table`: rational approximations of e^x on (−∞, 0].

``python -m netlistdyn.simulation._cf_generate > netlistdyn/simulation/_cf_table.py`` (about a minute).

For each even degree n the approximant has type (n, n) in partial fractions,
``r(x) = r∞ + Σ 2·Re(c_j / (x − z_j))`` over n/2 poles in the upper half plane,
and is near-best in the maximum norm on the whole negative real axis (error
about 9.28903⁻ⁿ, the Halphen constant of Cody, Meinardus and Varga).

1. Poles: Carathéodory–Fejér (CF) approximation, following Trefethen,
   Weideman and Schmelzer (BIT 46, 2006, section 4). The axis is mapped onto
   [−1, 1] by ``x = 9 (t − 1)/(t + 1)``; the Chebyshev coefficients ``a_k`` of
   ``exp(x(t))`` fill a Hankel matrix, whose (n+1)-th singular vector ``v``
   gives the poles: the n roots ``q`` of ``Σ v_k q^(K−1−k)`` outside the unit disk,
   mapped back by ``z = 9 (q − 1)²/(q + 1)²``. Computed in mpmath (40 digits;
   the eigenvector by inverse iteration from numpy's estimate).
2. Residues for those poles: a linear Remez exchange in mpmath for the best
   approximation with the constraints ``r(0) = 1`` and ``r(−∞) = r∞ = 0``. An
   error at 0 would multiply the slow (near-DC) part of the state at every
   step, so it would grow with the number of steps; pinned, a slowly decaying
   mode keeps a relative error of at most ``sup |(r(x) − e^x)/x|`` over a
   whole run. With ``r∞ = 0`` the approximant is strictly proper, so the
   algebraic unknowns of a descriptor system (``E`` singular) come out
   consistent with the input after every step; a nonzero ``r∞`` would carry
   ``r∞`` times their previous value (ibmpg1t: 2e-12 of 1.8 V between degrees
   12 and 14, whatever the step, so a check at rtol 1e-12 could never pass).
   The two constraints cost little: 2.31e-12 against 2.20e-12 with ``r(0) = 1``
   alone at degree 12.

The maximum error on the axis (dense sampling in t) and the equioscillation are
printed with the table; ``tests/test_cf_table.py`` checks them independently.
"""

from __future__ import annotations

import sys

import mpmath as mp
import numpy as np
import scipy.linalg as sl

#: Degrees tabulated. Degree 16 (error 3.0e-16) is not: its coefficients rounded to doubles
#: (residues up to ~1e2) move r by ~1e-14, so it would not beat degree 14 (2.6e-14).
DEGREES = (10, 12, 14)
#: Scale of the map x = SCALE (t − 1)/(t + 1) (Trefethen–Weideman–Schmelzer's choice).
SCALE = 9
#: Chebyshev coefficients kept (the last is below 1e-25 of the first).
TERMS = 100
#: Working precision (digits).
DIGITS = 40


def chebyshev_coefficients(terms: int, points: int = 1024) -> list[mp.mpf]:
    """a_k of exp(SCALE (t − 1)/(t + 1)) = Σ a_k T_k(t), k < terms, by a cosine sum at first-kind points."""
    theta = [mp.pi * (j + mp.mpf(1) / 2) / points for j in range(points)]
    values = [mp.exp(SCALE * (mp.cos(th) - 1) / (mp.cos(th) + 1)) for th in theta]
    coefs = []
    for k in range(terms):
        total = mp.fsum(v * mp.cos(k * th) for v, th in zip(values, theta, strict=True))
        coefs.append(total * 2 / points)
    coefs[0] /= 2
    return coefs


def cf_poles(n: int, coefs: list[mp.mpf]) -> list[mp.mpc]:
    """The n CF poles (upper half plane first, then their conjugates) for type (n, n)."""
    c = [a / 2 for a in coefs[1:]]  # coefficients of the analytic part f(z) = Σ c_k z^k
    size = len(c)
    hankel = mp.matrix(size, size)
    for i in range(size):
        for j in range(size):
            hankel[i, j] = c[i + j] if i + j < size else mp.mpf(0)
    # numpy's estimate of the (n+1)-th eigenvalue (largest in modulus first), then inverse iteration
    dense = sl.hankel(np.array([float(x) for x in c]))
    eig, vec = np.linalg.eigh(dense)
    order = np.argsort(-np.abs(eig))
    lam = mp.mpf(float(eig[order[n]]))
    y = mp.matrix([mp.mpf(float(x)) for x in vec[:, order[n]]])
    for _ in range(4):
        shifted = hankel - lam * mp.eye(size)
        y = mp.lu_solve(shifted, y)
        y = y / mp.norm(y)
        lam = (y.T * hankel * y)[0]
    v = [y[k] for k in range(size)]
    guesses = np.roots(np.array([float(x) for x in v]))  # v[0] leads
    outside = [complex(q) for q in guesses if abs(q) > 1]
    if len(outside) != n:
        raise RuntimeError(f"degree {n}: {len(outside)} roots outside the unit disk, expected {n}")

    def poly(q: mp.mpc) -> tuple[mp.mpc, mp.mpc]:
        value, slope = mp.mpc(0), mp.mpc(0)
        for coef in v:
            slope = slope * q + value
            value = value * q + coef
        return value, slope

    poles = []
    for guess in outside:
        q = mp.mpc(guess)
        for _ in range(60):
            value, slope = poly(q)
            step = value / slope
            q -= step
            if abs(step) < mp.mpf(10) ** (-DIGITS + 5) * abs(q):
                break
        poles.append(SCALE * (q - 1) ** 2 / (q + 1) ** 2)
    upper = sorted((z for z in poles if mp.im(z) > 0), key=lambda z: mp.re(z))
    if len(upper) != n // 2:
        raise RuntimeError(f"degree {n}: poles not in conjugate pairs")
    return upper


def _x(t: mp.mpf) -> mp.mpf:
    return SCALE * (t - 1) / (t + 1)


class _Basis:
    """r(x) = r∞ + Σ p_k φ_k(x), φ the real and imaginary parts of 1/(x − z_j), constrained.

    ``proper``: r∞ = 0 and r(0) = 1 (one φ, ψ = φ_m/φ_m(0), carries the constraint), so
    ``e = (ψ − e^x) + Σ_{k≠m} p_k (φ_k − φ_k(0) ψ)``; otherwise r(0) = 1 only, so
    ``e = (1 − e^x) + Σ p_k (φ_k − φ_k(0))``.
    """

    def __init__(self, poles: list[mp.mpc], proper: bool) -> None:
        self.poles = poles
        self.proper = proper
        self.phi0 = self.phi(mp.mpf(0))
        self.m = max(range(len(self.phi0)), key=lambda k: abs(self.phi0[k])) if proper else -1
        self.count = len(self.phi0) - (1 if proper else 0)

    def phi(self, x: mp.mpf) -> list[mp.mpf]:
        out = []
        for z in self.poles:
            w = mp.mpc(0) if mp.isinf(x) else 1 / (x - z)
            out += [2 * mp.re(w), -2 * mp.im(w)]
        return out

    def parts(self, x: mp.mpf) -> tuple[mp.mpf, list[mp.mpf]]:
        """(f0, g) with e(x) = f0(x) + Σ p_k g_k(x)."""
        ex = mp.mpf(0) if mp.isinf(x) else mp.exp(x)
        phi = self.phi(x)
        if not self.proper:
            return 1 - ex, [a - b for a, b in zip(phi, self.phi0, strict=True)]
        psi = phi[self.m] / self.phi0[self.m]
        g = [phi[k] - self.phi0[k] * psi for k in range(len(phi)) if k != self.m]
        return psi - ex, g

    def error(self, p: list[mp.mpf], t: mp.mpf) -> mp.mpf:
        f0, g = self.parts(-mp.inf if t <= -1 else _x(t))
        return f0 + mp.fsum(a * b for a, b in zip(p, g, strict=True))

    def coefficients(self, p: list[mp.mpf]) -> tuple[mp.mpf, list[mp.mpc]]:
        """(r∞, residues c_j) from the free parameters."""
        full = list(p)
        if self.proper:
            rest = mp.fsum(
                a * self.phi0[k]
                for a, k in zip(p, [k for k in range(len(self.phi0)) if k != self.m], strict=True)
            )
            full.insert(self.m, (1 - rest) / self.phi0[self.m])
        coefs = [mp.mpc(full[2 * j], full[2 * j + 1]) for j in range(len(self.poles))]
        r_inf = mp.mpf(0) if self.proper else 1 - mp.fsum(a * b for a, b in zip(full, self.phi0, strict=True))
        return r_inf, coefs


def _extrema(basis: _Basis, p: list[mp.mpf], samples: int = 3000) -> list[tuple[mp.mpf, mp.mpf]]:
    """Local extrema (t, e(t)) of the error on [−1, 1), refined by golden-section search."""
    ts = [-mp.cos(mp.pi * k / samples) for k in range(samples)]  # t = −1 ... just below 1
    es = [basis.error(p, t) for t in ts]
    found = [(ts[0], es[0])]
    for k in range(1, samples - 1):
        if abs(es[k]) >= abs(es[k - 1]) and abs(es[k]) >= abs(es[k + 1]) and es[k] != 0:
            sign = 1 if es[k] > 0 else -1
            a, b = ts[k - 1], ts[k + 1]
            golden = (mp.sqrt(5) - 1) / 2
            for _ in range(40):
                c1, c2 = b - golden * (b - a), a + golden * (b - a)
                if sign * basis.error(p, c1) > sign * basis.error(p, c2):
                    b = c2
                else:
                    a = c1
            t = (a + b) / 2
            found.append((t, basis.error(p, t)))
    return found


def _alternating(points: list[tuple[mp.mpf, mp.mpf]], count: int) -> list[tuple[mp.mpf, mp.mpf]]:
    """``count`` alternating extrema keeping the largest: same-sign neighbours merged (largest
    kept), then the smallest dropped (with its smaller neighbour when inside, to keep the
    alternation; alone at an end)."""
    merged: list[tuple[mp.mpf, mp.mpf]] = []
    for t, e in points:
        if merged and (merged[-1][1] > 0) == (e > 0):
            if abs(e) > abs(merged[-1][1]):
                merged[-1] = (t, e)
        else:
            merged.append((t, e))
    while len(merged) > count:
        k = min(range(len(merged)), key=lambda i: abs(merged[i][1]))
        if k in (0, len(merged) - 1):
            merged.pop(k)
        elif len(merged) - count == 1:
            merged.pop(0 if abs(merged[0][1]) < abs(merged[-1][1]) else -1)
        else:
            j = k - 1 if abs(merged[k - 1][1]) < abs(merged[k + 1][1]) else k + 1
            for i in sorted((k, j), reverse=True):
                merged.pop(i)
    return merged


def _lawson_start(basis: _Basis, samples: int = 4000, iterations: int = 300) -> list[mp.mpf]:
    """A starting reference for the Remez exchange: extrema of a Lawson (iteratively reweighted
    least squares) fit in double precision."""
    t = -np.cos(np.linspace(0.0, np.pi, samples + 1)[:-1])
    rows = [basis.parts(-mp.inf if v <= -1 else _x(mp.mpf(float(v)))) for v in t]
    f0 = np.array([float(f) for f, _ in rows])
    g = np.array([[float(v) for v in gk] for _, gk in rows])
    w = np.full(t.size, 1.0 / t.size)
    for _ in range(iterations):
        sw = np.sqrt(w)
        p = np.linalg.lstsq(g * sw[:, None], -f0 * sw, rcond=None)[0]
        e = f0 + g @ p
        w = w * np.abs(e)
        w /= w.sum()
    ext = [0] + [k for k in range(1, t.size - 1) if abs(e[k]) >= abs(e[k - 1]) and abs(e[k]) >= abs(e[k + 1])]
    picked = _alternating([(mp.mpf(float(t[k])), mp.mpf(float(e[k]))) for k in ext], basis.count + 1)
    return [tk for tk, _ in picked]


def residues(
    poles: list[mp.mpc], proper: bool = True, iterations: int = 20
) -> tuple[mp.mpf, list[mp.mpc], mp.mpf]:
    """(r∞, residues, max error) of the best approximation with these poles, r(0) = 1 (and r∞ = 0)."""
    basis = _Basis(poles, proper)
    n = basis.count
    ref = _lawson_start(basis)
    p: list[mp.mpf] = [mp.mpf(0)] * n
    level = mp.mpf(0)
    for _ in range(iterations):
        rows, rhs = [], []
        for i, t in enumerate(ref):
            f0, g = basis.parts(-mp.inf if t <= -1 else _x(t))
            rows.append([*g, -((-1) ** i)])
            rhs.append(-f0)
        sol = mp.lu_solve(mp.matrix(rows), mp.matrix(rhs))
        p = [sol[k] for k in range(n)]
        level = abs(sol[n])
        ext = _extrema(basis, p)
        worst = max(abs(e) for _, e in ext)
        picked = _alternating(ext, n + 1)
        if len(picked) < n + 1:
            raise RuntimeError("Remez: too few alternating extrema")
        ref = [t for t, _ in picked]
        print(f"#   Remez: level {mp.nstr(level, 6)}, max {mp.nstr(worst, 6)}", file=sys.stderr)
        if worst - level < mp.mpf(10) ** -4 * level:
            break
    r_inf, coefs = basis.coefficients(p)
    return r_inf, coefs, worst


def main() -> int:
    """Print the table module."""
    mp.mp.dps = DIGITS
    coefs = chebyshev_coefficients(TERMS)
    print(f"# last Chebyshev coefficient {mp.nstr(abs(coefs[-1]), 3)}", file=sys.stderr)
    lines = [
        '"""Partial-fraction rational approximations of e^x on (−∞, 0] (CF poles, r(0) = 1, r(−∞) = 0).',
        "",
        "Generated by ``python -m netlistdyn.simulation._cf_generate`` (mpmath, 40 digits); do not edit.",
        "``CF[n] = (r_inf, ((z_j, c_j), ...), max_error)`` with",
        "``r(x) = r_inf + Σ 2·Re(c_j / (x − z_j))`` over the poles z_j in the upper half plane;",
        "``max_error`` is the maximum of ``|r(x) − e^x|`` on the axis found by the generator's Remez.",
        '"""',
        "",
        "from __future__ import annotations",
        "",
        "CF: dict[int, tuple[float, tuple[tuple[complex, complex], ...], float]] = {",
    ]
    for n in [int(a) for a in sys.argv[1:]] or DEGREES:
        poles = cf_poles(n, coefs)
        r_inf, res, worst = residues(poles)
        print(f"# degree {n}: max error {mp.nstr(worst, 4)}, r_inf {mp.nstr(r_inf, 4)}", file=sys.stderr)
        lines.append(f"    {n}: (")
        lines.append(f"        {float(r_inf)!r},")
        lines.append("        (")
        for z, c in zip(poles, res, strict=True):
            lines.append(f"            ({complex(z)!r}, {complex(c)!r}),")
        lines.append("        ),")
        lines.append(f"        {float(worst)!r},")
        lines.append("    ),")
    lines.append("}")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
