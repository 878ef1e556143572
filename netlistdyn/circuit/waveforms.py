"""Independent-source waveforms as SPICE defines them (DC, PULSE, SIN, PWL, EXP).

A waveform does not change the state-space matrices; it is kept with its
source for simulation and validation. Parameters that SPICE leaves to the
analysis (PULSE rise time defaults to TSTEP, ...) are stored as ``None`` and
resolved with :meth:`Waveform.resolved` once ``tstep``/``tstop`` are known.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

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


@dataclass(frozen=True, slots=True)
class Pulse:
    """``PULSE(V1 V2 TD TR TF PW PER)``; times in s, levels in V or A."""

    v1: float
    v2: float
    td: float = 0.0
    tr: float | None = None
    tf: float | None = None
    pw: float | None = None
    per: float | None = None

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
        tr, tf, pw, per = self._times()
        tt = np.asarray(t, dtype=float) - self.td
        # As ngspice 39: wrap only strictly after one period, so t − TD = PER itself is
        # read in the first period (it matters when TR + PW + TF > PER, e.g. at TSTOP).
        local = np.where(tt > per, tt - per * np.floor(tt / per), tt)
        out = np.full(local.shape, self.v1)
        rise = (local > 0) & (local < tr)
        out = np.where(rise, self.v1 + (self.v2 - self.v1) * local / tr, out)
        high = (local >= tr) & (local <= tr + pw)
        out = np.where(high, self.v2, out)
        fall = (local > tr + pw) & (local < tr + pw + tf)
        out = np.where(fall, self.v2 + (self.v1 - self.v2) * (local - tr - pw) / tf, out)
        return out

    def left(self, t: ArrayLike) -> NDArray[np.float64]:
        """Limit from the left at t (the waveform is continuous for t > 0: its value)."""
        return self(t)

    def breakpoint_count(self, tstop: float) -> int:
        """How many corners :meth:`breakpoints` gives in [0, tstop], at most (counted, not listed)."""
        *_, per = self._times()
        if self.td > tstop:
            return 0
        return 4 * (math.floor((tstop - self.td) / per) + 1)

    def breakpoints(self, tstop: float) -> tuple[float, ...]:
        """Corners of the trapezoid in [0, tstop] (s); see :func:`check_breakpoints` for the bound."""
        tr, tf, pw, per = self._times()
        points: list[float] = []
        start = self.td
        while start <= tstop:
            for offset in (0.0, tr, tr + pw, tr + pw + tf):
                if start + offset <= tstop:
                    points.append(start + offset)
            start += per
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
        return f"PULSE({self.v1!r} {self.v2!r} {self.td!r} {tr!r} {tf!r} {pw!r} {per!r})"


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


Waveform = Dc | Pulse | Sin | Pwl | Exp | Random


def breakpoint_limit() -> int:
    """The breakpoint limit: ``$NETLISTDYN_MAX_BREAKPOINTS`` when set to a positive integer."""
    import os

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
