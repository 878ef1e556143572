"""Independent-source waveforms as SPICE defines them (DC, PULSE, SIN, PWL, EXP, AM, SFFM).

A waveform does not change the state-space matrices; it is kept with its
source for simulation and validation. Parameters that SPICE leaves to the
analysis (PULSE rise time defaults to TSTEP, ...) are stored as ``None`` and
resolved with :meth:`Waveform.resolved` once ``tstep``/``tstop`` are known.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import jv

from netlistdyn.base.errors import NetlistError, SourceLocation

#: Most waveform breakpoints (corners of PULSE and PWL sources, summed over the sources) that a
#: transient accepts: each one is a step boundary of every method. Raise it with the environment
#: variable ``NETLISTDYN_MAX_BREAKPOINTS``.
MAX_BREAKPOINTS = 1_000_000
MAX_BREAKPOINTS_VARIABLE = "NETLISTDYN_MAX_BREAKPOINTS"


@dataclass(frozen=True, slots=True)
class Dc:
    """Constant value, applied as a step at t = 0 (V or A)."""

    value: float

    def resolved(self, tstep: float, tstop: float) -> Dc:
        """Return the waveform with SPICE's analysis-dependent defaults filled in."""
        return self

    def __call__(self, t: ArrayLike) -> NDArray[np.float64]:
        return np.full(np.shape(t), self.value, dtype=float)

    def left(self, t: ArrayLike) -> NDArray[np.float64]:
        """Limit from the left at t (the waveform is continuous for t > 0: its value)."""
        return self(t)

    def breakpoints(self, tstop: float) -> tuple[float, ...]:
        """Times in [0, tstop] where the waveform or its slope jumps (s)."""
        return ()

    @property
    def piecewise_linear(self) -> bool:
        """True when the waveform is linear between its breakpoints."""
        return True

    def exponential_terms(self) -> tuple[tuple[float, complex, complex], ...]:
        """Exponential parts (start, c, μ): c·e^{μ(t − start)} from ``start`` on; none here."""
        return ()

    def spice(self) -> str:
        """The waveform in ngspice syntax."""
        return f"DC {self.value!r}"


#: A time within this many rounding units (of t − TD) of a PULSE period boundary is read as on
#: it (the boundary computed as TD + k·PER and the phase (t − TD)/PER differ by rounding only).
PULSE_PHASE_SNAP = 8


def pulse_values(
    t: ArrayLike,
    p: dict[str, NDArray[np.float64]] | Pulse,
    left: bool = False,
) -> NDArray[np.float64]:
    """PULSE values at ``t`` as ngspice 39's ``vsrcload`` computes them, period by period (V or A).

    Each period starts again at V1: when TR + PW + TF exceeds PER the period is cut at PER
    (ngspice reads the time modulo PER before it looks at TR, PW and TF), so the waveform jumps
    back to V1 at TD + k·PER. The value there is the one after that jump; ``left`` gives the
    limit from the left (the level the previous period reached at PER). After NCYCLES periods
    (LTspice's, ngspice's eighth value) the level is V1.

    Parameters
    ----------
    t : array_like
        Times (s).
    p : Pulse or dict of arrays
        A resolved :class:`Pulse`, or its fields as arrays broadcast against ``t`` (many pulses
        at once).
    left : bool
        Limits from the left instead of values.
    """
    get = (lambda f: np.asarray(getattr(p, f), dtype=float)) if isinstance(p, Pulse) else p.__getitem__
    v1, v2, td, tr, tf, pw, per = (get(f) for f in ("v1", "v2", "td", "tr", "tf", "pw", "per"))
    if isinstance(p, Pulse):
        ncycles = np.asarray(np.inf if p.ncycles is None else p.ncycles, dtype=float)
    else:
        ncycles = p["ncycles"]
    local = np.asarray(t, dtype=float) - td
    k = np.floor(local / per)
    phase = local - k * per
    slack = PULSE_PHASE_SNAP * np.finfo(float).eps * np.abs(local)
    snap = phase > per - slack
    k = np.where(snap, k + 1, k)
    phase = np.where(snap | (phase < slack), 0.0, phase)
    if left:  # on a boundary (k ≥ 1) the left limit is where the previous period ended, at PER
        on_edge = (phase == 0.0) & (k >= 1)
        k = np.where(on_edge, k - 1, k)
        phase = np.where(on_edge, per, phase)
    out = np.where(phase < tr, v1 + (v2 - v1) * phase / tr, v2)
    fall = phase - tr - pw
    out = np.where(fall > 0, np.where(fall < tf, v2 + (v1 - v2) * fall / tf, v1), out)
    with np.errstate(invalid="ignore"):  # inf·PER
        cut = ncycles * per
    ended = (local > cut) if left else (local >= cut)
    return np.where((local <= 0) | ended, v1, out)


@dataclass(frozen=True, slots=True)
class Pulse:
    """``PULSE(V1 V2 TD TR TF PW PER [NCYCLES])``; times in s, levels in V or A.

    NCYCLES (LTspice's eighth value, which ngspice 39 reads the same way): the number of periods,
    after which the level stays V1; ``None``: endless.
    """

    v1: float
    v2: float
    td: float = 0.0
    tr: float | None = None
    tf: float | None = None
    pw: float | None = None
    per: float | None = None
    ncycles: float | None = None

    def resolved(self, tstep: float, tstop: float) -> Pulse:
        """Fill TR, TF (default TSTEP), PW and PER (default TSTOP) as ngspice 39 does.

        A zero TR, TF, PW or PER counts as not given (ngspice 39's ``vsrcload``:
        ``PULSE(0 1 1u 1u 1u 0 4u)`` has PW = TSTOP; measured).
        """
        return replace(
            self,
            tr=self.tr if self.tr else tstep,
            tf=self.tf if self.tf else tstep,
            pw=self.pw if self.pw else tstop,
            per=self.per if self.per else tstop,
        )

    def _times(self) -> tuple[float, float, float, float]:
        assert self.tr is not None and self.tf is not None
        assert self.pw is not None and self.per is not None
        return self.tr, self.tf, self.pw, self.per

    def __call__(self, t: ArrayLike) -> NDArray[np.float64]:
        self._times()
        return pulse_values(t, self)

    def left(self, t: ArrayLike) -> NDArray[np.float64]:
        """Limit from the left at t: differs from the value where a period is cut at PER."""
        self._times()
        return pulse_values(t, self, left=True)

    def _periods(self, tstop: float) -> int:
        """How many periods start in [0, tstop] (NCYCLES bounds them)."""
        *_, per = self._times()
        if self.td > tstop:
            return 0
        count = math.floor((tstop - self.td) / per) + 1
        return count if self.ncycles is None else min(count, math.ceil(self.ncycles))

    def breakpoint_count(self, tstop: float) -> int:
        """How many corners :meth:`breakpoints` gives in [0, tstop], at most (counted, not listed)."""
        return 4 * self._periods(tstop) + 1

    def breakpoints(self, tstop: float) -> tuple[float, ...]:
        """Corners in [0, tstop] (s): each period's start, and its trapezoid's corners before PER.

        A period's start is TD + k·PER (a product, as the value is computed, not a running sum);
        see :func:`check_breakpoints` for the bound.
        """
        tr, tf, pw, per = self._times()
        offsets = [x for x in (tr, tr + pw, tr + pw + tf) if x < per]
        points: list[float] = []
        for k in range(self._periods(tstop)):
            start = self.td + k * per
            end = math.inf if self.ncycles is None else self.td + self.ncycles * per
            for x in [start, *(start + o for o in offsets)]:
                if x <= tstop and x < end:
                    points.append(x)
        if self.ncycles is not None and self.td + self.ncycles * per <= tstop:
            points.append(self.td + self.ncycles * per)  # the last period ends, cut or not, at V1
        return tuple(points)

    @property
    def piecewise_linear(self) -> bool:
        """PULSE is piecewise linear."""
        return True

    def exponential_terms(self) -> tuple[tuple[float, complex, complex], ...]:
        """Exponential parts (start, c, μ): c·e^{μ(t − start)} from ``start`` on; none here."""
        return ()

    def spice(self) -> str:
        """The waveform in ngspice syntax."""
        tr, tf, pw, per = self._times()
        tail = "" if self.ncycles is None else f" {self.ncycles!r}"
        return f"PULSE({self.v1!r} {self.v2!r} {self.td!r} {tr!r} {tf!r} {pw!r} {per!r}{tail})"


@dataclass(frozen=True, slots=True)
class Sin:
    """``SIN(VO VA FREQ TD THETA PHASE)``: VO + VA e^(-θ(t-TD)) sin(2πf(t-TD) + φ).

    FREQ in Hz, TD in s, THETA in 1/s, PHASE in degrees.
    """

    vo: float
    va: float
    freq: float | None = None
    td: float = 0.0
    theta: float = 0.0
    phase: float = 0.0

    def resolved(self, tstep: float, tstop: float) -> Sin:
        """FREQ defaults to 1/TSTOP."""
        return replace(self, freq=self.freq if self.freq else 1.0 / tstop)

    def __call__(self, t: ArrayLike) -> NDArray[np.float64]:
        assert self.freq is not None
        tt = np.asarray(t, dtype=float)
        phi = math.radians(self.phase)
        shifted = np.maximum(tt - self.td, 0.0)
        wave = self.vo + self.va * np.exp(-self.theta * shifted) * np.sin(
            2 * math.pi * self.freq * shifted + phi
        )
        return np.where(tt < self.td, self.vo + self.va * math.sin(phi), wave)

    def left(self, t: ArrayLike) -> NDArray[np.float64]:
        """Limit from the left at t (the waveform is continuous for t > 0: its value)."""
        return self(t)

    def breakpoints(self, tstop: float) -> tuple[float, ...]:
        """The start of the oscillation, if inside the horizon (s)."""
        return (self.td,) if 0 < self.td <= tstop else ()

    @property
    def piecewise_linear(self) -> bool:
        """A sine is smooth, not piecewise linear."""
        return False

    def exponential_terms(self) -> tuple[tuple[float, complex, complex], ...]:
        """From TD on, VA e^(−θs) sin(ωs + φ) = c e^{μs} + conj, c = VA e^{iφ}/(2i), μ = −θ + iω.

        The rest of the waveform is then constant on each side of TD.
        """
        assert self.freq is not None
        if self.va == 0:
            return ()
        c = self.va * complex(math.cos(math.radians(self.phase)), math.sin(math.radians(self.phase))) / 2j
        mu = complex(-self.theta, 2 * math.pi * self.freq)
        return ((self.td, c, mu), (self.td, c.conjugate(), mu.conjugate()))

    def spice(self) -> str:
        """The waveform in ngspice syntax."""
        return f"SIN({self.vo!r} {self.va!r} {self.freq!r} {self.td!r} {self.theta!r} {self.phase!r})"


def _sine_terms(
    start: float, amplitude: float, omega: float, phase: float
) -> list[tuple[float, complex, complex]]:
    """A·sin(ω(t − start) + φ) from ``start`` on as two exponential terms c·e^{μ(t − start)} + conj."""
    if amplitude == 0:
        return []
    c = amplitude * complex(math.cos(phase), math.sin(phase)) / 2j
    return [(start, c, complex(0.0, omega)), (start, c.conjugate(), complex(0.0, -omega))]


@dataclass(frozen=True, slots=True)
class Am:
    """``AM(VA VO MF FC TD PHASEC PHASES)`` as ngspice 39's ``vsrcload`` computes it (V or A).

    From TD on, with s = t − TD: VA·(VO + sin(2π·MF·s + φs))·sin(2π·FC·s + φs); 0 before TD.
    ngspice 39 applies PHASES to both sines and reads PHASEC but does not use it (its source
    code; measured with ``ngspice -b``). MF defaults to 1/TSTOP; FC to 0. ``offset`` is a
    constant added (0 as written; :mod:`netlistdyn.simulation.initial` subtracts an operating
    point with it).
    """

    va: float
    vo: float
    mf: float | None = None
    fc: float = 0.0
    td: float = 0.0
    phasec: float = 0.0
    phases: float = 0.0
    offset: float = 0.0

    def resolved(self, tstep: float, tstop: float) -> Am:
        """MF defaults to 1/TSTOP (a zero MF counts as not given, as in ngspice 39)."""
        return replace(self, mf=self.mf if self.mf else 1.0 / tstop)

    def _value(self, t: ArrayLike, left: bool) -> NDArray[np.float64]:
        assert self.mf is not None
        s = np.asarray(t, dtype=float) - self.td
        ps = math.radians(self.phases)
        carrier = np.sin(2 * math.pi * self.fc * s + ps)
        wave = self.va * (self.vo + np.sin(2 * math.pi * self.mf * s + ps)) * carrier
        return self.offset + np.where((s <= 0) if left else (s < 0), 0.0, wave)

    def __call__(self, t: ArrayLike) -> NDArray[np.float64]:
        """Value at t; at TD the value just after it (a jump there when PHASES is not 0)."""
        return self._value(t, left=False)

    def left(self, t: ArrayLike) -> NDArray[np.float64]:
        """Limit from the left at t: 0 at TD itself (ngspice's value there)."""
        return self._value(t, left=True)

    def breakpoints(self, tstop: float) -> tuple[float, ...]:
        """The start of the modulation, if inside the horizon (s)."""
        return (self.td,) if 0 < self.td <= tstop else ()

    @property
    def piecewise_linear(self) -> bool:
        """A modulated sine is smooth, not piecewise linear."""
        return False

    @property
    def rate(self) -> float:
        """Fastest angular frequency in the waveform (rad/s)."""
        assert self.mf is not None
        return 2 * math.pi * (abs(self.mf) + abs(self.fc))

    def exponential_terms(self) -> tuple[tuple[float, complex, complex], ...]:
        """From TD on: VA·VO·sin(ωc s + φ) + VA/2·[sin((ωm − ωc)s + π/2) − sin((ωm + ωc)s + 2φ + π/2)].

        (sin a · sin b = [cos(a − b) − cos(a + b)]/2.) The rest of the waveform is 0.
        """
        assert self.mf is not None
        wm, wc, ps = 2 * math.pi * self.mf, 2 * math.pi * self.fc, math.radians(self.phases)
        terms = _sine_terms(self.td, self.va * self.vo, wc, ps)
        terms += _sine_terms(self.td, self.va / 2, wm - wc, math.pi / 2)
        terms += _sine_terms(self.td, -self.va / 2, wm + wc, 2 * ps + math.pi / 2)
        return tuple(terms)

    def spice(self) -> str:
        """The waveform in ngspice syntax (an ``offset`` is not expressible: refused)."""
        if self.offset:
            raise ValueError("an offset AM waveform has no ngspice form")
        return (
            f"AM({self.va!r} {self.vo!r} {self.mf!r} {self.fc!r} {self.td!r} {self.phasec!r} {self.phases!r})"
        )


#: SFFM's Bessel series (see :meth:`Sffm.exponential_terms`) stops where |J_k(MDI)| is below this
#: (relative to 1): far below double rounding of the waveform itself.
SFFM_BESSEL_CUTOFF = 1e-18


@dataclass(frozen=True, slots=True)
class Sffm:
    """``SFFM(VO VA FC MDI FS PHASEC PHASES)``: VO + VA·sin(2π·FC·t + φc + MDI·sin(2π·FS·t + φs)).

    As ngspice 39's ``vsrcload``: no delay; FC and FS default to 1/TSTOP (a zero counts as not
    given), MDI to 0; phases in degrees.
    """

    vo: float
    va: float
    fc: float | None = None
    mdi: float = 0.0
    fs: float | None = None
    phasec: float = 0.0
    phases: float = 0.0

    def resolved(self, tstep: float, tstop: float) -> Sffm:
        """FC and FS default to 1/TSTOP."""
        return replace(self, fc=self.fc if self.fc else 1.0 / tstop, fs=self.fs if self.fs else 1.0 / tstop)

    def __call__(self, t: ArrayLike) -> NDArray[np.float64]:
        assert self.fc is not None and self.fs is not None
        tt = np.asarray(t, dtype=float)
        inner = self.mdi * np.sin(2 * math.pi * self.fs * tt + math.radians(self.phases))
        return self.vo + self.va * np.sin(2 * math.pi * self.fc * tt + math.radians(self.phasec) + inner)

    def left(self, t: ArrayLike) -> NDArray[np.float64]:
        """Limit from the left at t (continuous: its value)."""
        return self(t)

    def breakpoints(self, tstop: float) -> tuple[float, ...]:
        """None: the waveform is smooth from t = 0 on."""
        return ()

    @property
    def piecewise_linear(self) -> bool:
        """A frequency-modulated sine is smooth, not piecewise linear."""
        return False

    @property
    def rate(self) -> float:
        """Fastest angular frequency in the waveform (rad/s): carrier plus peak deviation (Carson)."""
        assert self.fc is not None and self.fs is not None
        return 2 * math.pi * (abs(self.fc) + abs(self.mdi * self.fs) + abs(self.fs))

    def exponential_terms(self) -> tuple[tuple[float, complex, complex], ...]:
        """VA·sin(a + MDI·sin b) = VA·Σ_k J_k(MDI)·sin(a + k·b) (Jacobi–Anger), from t = 0.

        The series stops where the Bessel factors fall below :data:`SFFM_BESSEL_CUTOFF`; the
        remainder (VO and the dropped tail, below 1e-17·VA) is taken as piecewise linear.
        """
        assert self.fc is not None and self.fs is not None
        wc, ws = 2 * math.pi * self.fc, 2 * math.pi * self.fs
        pc, ps = math.radians(self.phasec), math.radians(self.phases)
        if self.mdi == 0:
            return tuple(_sine_terms(0.0, self.va, wc, pc))
        reach = int(abs(self.mdi)) + 30
        while abs(jv(reach, self.mdi)) > SFFM_BESSEL_CUTOFF:
            reach *= 2
        terms: list[tuple[float, complex, complex]] = []
        for k in range(-reach, reach + 1):
            weight = float(jv(k, self.mdi))
            if abs(weight) > SFFM_BESSEL_CUTOFF:
                terms += _sine_terms(0.0, self.va * weight, wc + k * ws, pc + k * ps)
        return tuple(terms)

    def spice(self) -> str:
        """The waveform in ngspice syntax."""
        fields = (self.vo, self.va, self.fc, self.mdi, self.fs, self.phasec, self.phases)
        return f"SFFM({' '.join(repr(x) for x in fields)})"


@dataclass(frozen=True, slots=True)
class Pwl:
    """``PWL(T1 V1 T2 V2 ...)``: linear interpolation, held after the last point."""

    times: tuple[float, ...]
    values: tuple[float, ...]

    def resolved(self, tstep: float, tstop: float) -> Pwl:
        """PWL has no analysis-dependent defaults."""
        return self

    def __call__(self, t: ArrayLike) -> NDArray[np.float64]:
        """Value at t; at a repeated time point (a jump) the value after the jump."""
        return self._interpolate(t, "right")

    def left(self, t: ArrayLike) -> NDArray[np.float64]:
        """Limit from the left at t: at a repeated time point, the value before the jump."""
        return self._interpolate(t, "left")

    def _interpolate(self, t: ArrayLike, side: str) -> NDArray[np.float64]:
        """Linear interpolation, held before the first and after the last point.

        A time written twice (``PWL(0 1 1 1 1 -1 ...)``) is a jump; ``side``
        says which of its two values a point exactly at that time takes.
        """
        tt = np.asarray(t, dtype=float)
        times = np.asarray(self.times, dtype=float)
        values = np.asarray(self.values, dtype=float)
        if side == "right":
            lo = np.searchsorted(times, tt, side="right") - 1  # last corner at or before t
        else:
            lo = np.searchsorted(times, tt, side="left") - 1  # last corner strictly before t
        lo = np.clip(lo, 0, times.size - 1)
        hi = np.minimum(lo + 1, times.size - 1)
        span = times[hi] - times[lo]
        safe = np.where(span > 0, span, 1.0)
        frac = np.clip(np.where(span > 0, (tt - times[lo]) / safe, 0.0), 0.0, 1.0)
        out = values[lo] + frac * (values[hi] - values[lo])
        out = np.where(tt < times[0], values[0], out)
        if side == "left":
            out = np.where(tt <= times[0], values[0], out)
        return np.where(tt > times[-1], values[-1], out)

    def breakpoints(self, tstop: float) -> tuple[float, ...]:
        """The corner times in [0, tstop] (s)."""
        return tuple(x for x in self.times if 0 <= x <= tstop)

    @property
    def piecewise_linear(self) -> bool:
        """PWL is piecewise linear."""
        return True

    def exponential_terms(self) -> tuple[tuple[float, complex, complex], ...]:
        """Exponential parts (start, c, μ): c·e^{μ(t − start)} from ``start`` on; none here."""
        return ()

    def spice(self) -> str:
        """The waveform in ngspice syntax."""
        pairs = " ".join(f"{t!r} {v!r}" for t, v in zip(self.times, self.values, strict=True))
        return f"PWL({pairs})"


@dataclass(frozen=True, slots=True)
class Exp:
    """``EXP(V1 V2 TD1 TAU1 TD2 TAU2)``: exponential rise at TD1, fall at TD2 (s)."""

    v1: float
    v2: float
    td1: float = 0.0
    tau1: float | None = None
    td2: float | None = None
    tau2: float | None = None

    def resolved(self, tstep: float, tstop: float) -> Exp:
        """TAU1, TAU2 default to TSTEP and TD2 to TD1 + TSTEP, as in SPICE."""
        return replace(
            self,
            tau1=self.tau1 if self.tau1 else tstep,
            td2=self.td2 if self.td2 else self.td1 + tstep,
            tau2=self.tau2 if self.tau2 else tstep,
        )

    def __call__(self, t: ArrayLike) -> NDArray[np.float64]:
        assert self.tau1 is not None and self.td2 is not None and self.tau2 is not None
        tt = np.asarray(t, dtype=float)
        dv = self.v2 - self.v1
        rise = dv * (1.0 - np.exp(-np.maximum(tt - self.td1, 0.0) / self.tau1))
        fall = -dv * (1.0 - np.exp(-np.maximum(tt - self.td2, 0.0) / self.tau2))
        return self.v1 + rise + np.where(tt > self.td2, fall, 0.0)

    def left(self, t: ArrayLike) -> NDArray[np.float64]:
        """Limit from the left at t (the waveform is continuous for t > 0: its value)."""
        return self(t)

    def breakpoints(self, tstop: float) -> tuple[float, ...]:
        """The two delay times, where inside the horizon (s)."""
        assert self.td2 is not None
        return tuple(x for x in (self.td1, self.td2) if 0 < x <= tstop)

    @property
    def piecewise_linear(self) -> bool:
        """Exponentials are smooth, not piecewise linear."""
        return False

    def exponential_terms(self) -> tuple[tuple[float, complex, complex], ...]:
        """−ΔV e^{−(t−TD1)/TAU1} from TD1 and +ΔV e^{−(t−TD2)/TAU2} from TD2 (ΔV = V2 − V1).

        The rest of the waveform is then constant between the delays.
        """
        assert self.tau1 is not None and self.td2 is not None and self.tau2 is not None
        dv = self.v2 - self.v1
        if dv == 0:
            return ()
        return (
            (self.td1, complex(-dv), complex(-1.0 / self.tau1)),
            (self.td2, complex(dv), complex(-1.0 / self.tau2)),
        )

    def spice(self) -> str:
        """The waveform in ngspice syntax."""
        return f"EXP({self.v1!r} {self.v2!r} {self.td1!r} {self.tau1!r} {self.td2!r} {self.tau2!r})"


@dataclass(frozen=True, slots=True)
class Random:
    """``TRNOISE(...)`` or ``TRRANDOM(...)``: ngspice's random transient waveforms.

    The source is an input of the model like any other (its DC value is its operating-point and
    ``.ac`` value, as in ngspice), but its transient is a random draw that no other run can
    reproduce: a transient of it is refused, naming the source.
    """

    kind: str
    name: str
    loc: SourceLocation

    def _refuse(self) -> NetlistError:
        return NetlistError(
            f"{self.name}: {self.kind.upper()} is a random waveform: simulate and validate cannot "
            "reproduce it (analyze uses the source's DC value)",
            self.loc,
        )

    def resolved(self, tstep: float, tstop: float) -> Random:
        """Refused: a random waveform has no transient here."""
        raise self._refuse()

    def __call__(self, t: ArrayLike) -> NDArray[np.float64]:
        raise self._refuse()

    def left(self, t: ArrayLike) -> NDArray[np.float64]:
        """Refused, as every transient query of a random waveform."""
        raise self._refuse()

    def breakpoints(self, tstop: float) -> tuple[float, ...]:
        """Refused, as every transient query of a random waveform."""
        raise self._refuse()

    @property
    def piecewise_linear(self) -> bool:
        """Refused, as every transient query of a random waveform."""
        raise self._refuse()

    def exponential_terms(self) -> tuple[tuple[float, complex, complex], ...]:
        """Refused, as every transient query of a random waveform."""
        raise self._refuse()

    def spice(self) -> str:
        """Refused: the ngspice text is written from the resolved waveform, which is refused."""
        raise self._refuse()


Waveform = Dc | Pulse | Sin | Pwl | Exp | Am | Sffm | Random


def scaled(wave: Waveform, factor: float) -> Waveform:
    """The waveform times ``factor`` (the same shape and breakpoints): M= parallel current sources."""
    if isinstance(wave, Dc):
        return replace(wave, value=wave.value * factor)
    if isinstance(wave, Pulse | Exp):
        return replace(wave, v1=wave.v1 * factor, v2=wave.v2 * factor)
    if isinstance(wave, Sin | Sffm):
        return replace(wave, vo=wave.vo * factor, va=wave.va * factor)
    if isinstance(wave, Am):
        return replace(wave, va=wave.va * factor, offset=wave.offset * factor)
    if isinstance(wave, Pwl):
        return replace(wave, values=tuple(v * factor for v in wave.values))
    raise wave._refuse()


def breakpoint_limit() -> int:
    """The breakpoint limit: ``$NETLISTDYN_MAX_BREAKPOINTS`` when set to a positive integer."""
    text = os.environ.get(MAX_BREAKPOINTS_VARIABLE, "").strip()
    if text.isdigit() and int(text) > 0:
        return int(text)
    return MAX_BREAKPOINTS


def check_breakpoints(sources: Sequence[tuple[str, SourceLocation, Waveform]], tstop: float) -> None:
    """Refuse a transient whose resolved waveforms have more breakpoints than the limit.

    Counted before any is listed, so a PULSE with a 1 ps period over 1 s is refused at once.

    Parameters
    ----------
    sources : sequence of (name, location, waveform)
        Each source's name, where it was written and its resolved waveform.
    tstop : float
        Horizon (s).

    Raises
    ------
    NetlistError
        At the source with the most breakpoints, naming the count and the limit.
    """
    limit = breakpoint_limit()
    counts = [
        (w.breakpoint_count(tstop) if isinstance(w, Pulse) else len(w.breakpoints(tstop)), name, loc, w)
        for name, loc, w in sources
    ]
    total = sum(c[0] for c in counts)
    if total <= limit:
        return
    count, name, loc, wave = max(counts, key=lambda c: c[0])
    what = f"a PULSE period of {wave.per:g} s" if isinstance(wave, Pulse) else "its corners"
    raise NetlistError(
        f"{name}: {what} gives {count} breakpoints over the {tstop:g} s horizon"
        + (f" ({total} with the other sources)" if total > count else "")
        + f", more than {limit}; shorten the horizon or set {MAX_BREAKPOINTS_VARIABLE}",
        loc,
    )
