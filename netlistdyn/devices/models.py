"""Nonlinear device equations: behavioural expressions and the SPICE diode.

Two kinds of nonlinear element reach :mod:`netlistdyn.nonlinear`:

- **Behavioural sources** (``B``, ``E``/``G`` with ``value=``): their
  expression is *folded* at parse time (every ``.param`` replaced by its
  number, every ``.func`` expanded), so that the element carries a
  self-contained text in ``v(...)``, ``i(...)`` and ``time`` only.
  :class:`Behaviour` evaluates it together with its exact partial
  derivatives (forward-mode automatic differentiation through
  :func:`netlistdyn.circuit.expressions.walk`, the walker every expression uses),
  with ngspice 39's B-source semantics:
  ``x**y``, ``x^y`` and ``pow(x, y)`` are ``|x|^y``, ``pwr(x, y)`` is
  ``sgn(x)·|x|^y`` (measured with ``ngspice -b``), ``u`` and ``uramp`` are
  the unit step and ramp.
- **Diodes** (``D``): ngspice's level-1 junction, :func:`diode_current` and
  :func:`diode_charge`, including the ``gmin`` conductance ngspice puts in
  parallel with every junction.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from netlistdyn.circuit.expressions import (
    CONSTANTS,
    MAX_EVALUATION_WORK,
    Expression,
    ExpressionError,
    Hooks,
    logic,
    parse,
    walk,
)

#: Boltzmann's constant over the electron charge (V/K), as ngspice 39's const.h.
K_OVER_Q = 1.38064852e-23 / 1.6021766208e-19
#: ngspice's default temperature (K), 27 °C.
REFTEMP = 300.15
#: Conductance ngspice places across every junction (S), ``.options gmin``.
GMIN = 1e-12

Node = tuple


def _sgn(x: float) -> float:
    return float((x > 0) - (x < 0))


def _safe_exp(x: float) -> float:
    # An overflow is an infinite value; Newton's line search then backs off.
    return math.exp(x) if x < 709.0 else math.inf


def _power(x: float, y: float) -> tuple[float, float, float]:
    ax = abs(x)
    if ax == 0.0:
        if y < 0:
            raise ExpressionError("0 raised to a negative power")
        value = 0.0 if y > 0 else 1.0
        return value, (1.0 if y == 1 else 0.0), 0.0
    value = ax**y
    return value, y * ax ** (y - 1) * _sgn(x), value * math.log(ax)


#: name -> (arity range, function returning (value, partials)).
_Func = Callable[..., tuple[float, tuple[float, ...]]]


def _unary(f: Callable[[float], float], df: Callable[[float], float]) -> _Func:
    return lambda x: (f(x), (df(x),))


def _checked(name: str, ok: Callable[[float], bool], f: Callable[[float], float]) -> Callable[[float], float]:
    def inner(x: float) -> float:
        if not ok(x):
            raise ExpressionError(f"{name}({x:g}) is outside its domain")
        return f(x)

    return inner


def _minmax(pick: Callable[..., float]) -> _Func:
    def inner(*args: float) -> tuple[float, tuple[float, ...]]:
        best = pick(args)
        k = args.index(best)
        return best, tuple(1.0 if j == k else 0.0 for j in range(len(args)))

    return inner


def _pow_fn(x: float, y: float) -> tuple[float, tuple[float, ...]]:
    value, dx, dy = _power(x, y)
    return value, (dx, dy)


def _pwr_fn(x: float, y: float) -> tuple[float, tuple[float, ...]]:
    value, dx, dy = _power(x, y)
    s = _sgn(x) if x != 0 else 1.0
    return s * value, (s * dx, s * dy)


FUNCTIONS: dict[str, tuple[int, int, _Func]] = {
    "sqrt": (1, 1, _unary(_checked("sqrt", lambda x: x >= 0, math.sqrt), lambda x: 0.5 / math.sqrt(x))),
    "exp": (1, 1, _unary(_safe_exp, _safe_exp)),
    "log": (1, 1, _unary(_checked("log", lambda x: x > 0, math.log), lambda x: 1.0 / x)),
    "ln": (1, 1, _unary(_checked("ln", lambda x: x > 0, math.log), lambda x: 1.0 / x)),
    "log10": (
        1,
        1,
        _unary(_checked("log10", lambda x: x > 0, math.log10), lambda x: 1.0 / (x * math.log(10.0))),
    ),
    "sin": (1, 1, _unary(math.sin, math.cos)),
    "cos": (1, 1, _unary(math.cos, lambda x: -math.sin(x))),
    "tan": (1, 1, _unary(math.tan, lambda x: 1.0 / math.cos(x) ** 2)),
    "asin": (
        1,
        1,
        _unary(_checked("asin", lambda x: -1 <= x <= 1, math.asin), lambda x: 1 / math.sqrt(1 - x * x)),
    ),
    "acos": (
        1,
        1,
        _unary(_checked("acos", lambda x: -1 <= x <= 1, math.acos), lambda x: -1 / math.sqrt(1 - x * x)),
    ),
    "atan": (1, 1, _unary(math.atan, lambda x: 1.0 / (1.0 + x * x))),
    "sinh": (1, 1, _unary(math.sinh, math.cosh)),
    "cosh": (1, 1, _unary(math.cosh, math.sinh)),
    "tanh": (1, 1, _unary(math.tanh, lambda x: 1.0 - math.tanh(x) ** 2)),
    "asinh": (1, 1, _unary(math.asinh, lambda x: 1.0 / math.sqrt(x * x + 1.0))),
    "acosh": (
        1,
        1,
        _unary(_checked("acosh", lambda x: x >= 1, math.acosh), lambda x: 1.0 / math.sqrt(x * x - 1.0)),
    ),
    "atanh": (
        1,
        1,
        _unary(_checked("atanh", lambda x: -1 < x < 1, math.atanh), lambda x: 1.0 / (1.0 - x * x)),
    ),
    "abs": (1, 1, _unary(abs, _sgn)),
    "sgn": (1, 1, _unary(_sgn, lambda x: 0.0)),
    "u": (1, 1, _unary(lambda x: float(x > 0), lambda x: 0.0)),
    "uramp": (1, 1, _unary(lambda x: max(x, 0.0), lambda x: float(x > 0))),
    "int": (1, 1, _unary(lambda x: float(math.trunc(x)), lambda x: 0.0)),
    "nint": (1, 1, _unary(lambda x: float(round(x)), lambda x: 0.0)),
    "floor": (1, 1, _unary(lambda x: float(math.floor(x)), lambda x: 0.0)),
    "ceil": (1, 1, _unary(lambda x: float(math.ceil(x)), lambda x: 0.0)),
    "min": (2, 64, _minmax(min)),  # ngspice 39 reads min(x) as min(x, 1): refused
    "max": (2, 64, _minmax(max)),
    "pow": (2, 2, _pow_fn),
    "pwr": (2, 2, _pwr_fn),
}

#: Names an expression may use besides numbers, refs and functions.
TIME = "time"


# ----------------------------------------------------------------------- folding


def fold(
    text: str,
    params: Mapping[str, float],
    functions: Mapping[str, tuple[tuple[str, ...], Expression]],
    rename: Callable[[str, str], str] | None = None,
) -> str:
    """The expression with parameters replaced by numbers and ``.func`` calls expanded.

    Parameters
    ----------
    text : str
        Expression without braces.
    params : Mapping[str, float]
        Parameter values in scope (lower-case names).
    functions : Mapping
        User functions in scope: name → (formal names, body).
    rename : callable, optional
        ``rename(kind, name)`` maps the argument of each ``v()`` (kind
        ``"v"``) and ``i()`` (kind ``"i"``): a subcircuit's scope.

    Returns
    -------
    str
        A fully parenthesised text in numbers, ``v()``, ``i()``, ``time`` and
        the functions of :data:`FUNCTIONS` (re-parsed by :class:`Behaviour`).

    Raises
    ------
    ExpressionError
        Unknown parameter or function, wrong argument count, a ``.func`` that
        calls itself.
    """
    return walk(parse(displacement_refs(text)).tree, _Folder(params, functions, rename, {}, 0))


class _Folder(Hooks[str]):
    """:func:`fold`'s hooks: each node becomes its folded text."""

    def __init__(
        self,
        params: Mapping[str, float],
        functions: Mapping[str, tuple[tuple[str, ...], Expression]],
        rename: Callable[[str, str], str] | None,
        local: Mapping[str, str],
        depth: int,
    ) -> None:
        self.params, self.functions, self.rename = params, functions, rename
        self.local, self.depth = local, depth

    def number(self, value: float) -> str:
        return repr(value)

    def name(self, name: str) -> str:
        if name in self.local:
            return self.local[name]
        if name in self.params:
            return repr(float(self.params[name]))
        if name in CONSTANTS:
            return repr(CONSTANTS[name])
        if name == TIME:
            return TIME
        raise ExpressionError(f"unknown parameter {name!r}")

    def ref(self, kind: str, args: tuple[str, ...]) -> str:
        if self.rename is not None:
            args = tuple(self.rename(kind, a) for a in args)
        return f"{kind}({','.join(args)})"

    def unary(self, op: str, x: str) -> str:
        return _folded({"neg": f"(0-{x})", "pos": x, "not": f"(!{x})"}[op])

    def binary(self, op: str, a: str, b: str) -> str:
        return _folded(f"({a}{op}{b})")

    def ternary(self, cond: str, a: str, b: str) -> str:
        return _folded(f"({cond}?{a}:{b})")

    def call(self, name: str, args: list[str]) -> str:
        if name in self.functions:
            formals, body = self.functions[name]
            if len(formals) != len(args):
                raise ExpressionError(f"{name} takes {len(formals)} arguments, got {len(args)}")
            if self.depth >= 64:
                raise ExpressionError(f".func {name} calls itself (or nests too deeply)")
            local = dict(zip(formals, args, strict=True))
            inner = _Folder(self.params, self.functions, self.rename, local, self.depth + 1)
            text = walk(body.tree, inner)
            if len(text) > MAX_EVALUATION_WORK:  # nested calls double it level by level
                raise ExpressionError(
                    f".func {name}: the nested .func calls expand to more than {MAX_EVALUATION_WORK:,} "
                    "characters (a function calling another more than once, many levels deep)"
                )
            return text
        if name == "ternary_fcn" and len(args) == 3:
            return _folded(f"({args[0]}?{args[1]}:{args[2]})")
        if name not in FUNCTIONS:
            raise ExpressionError(f"unknown function {name!r}")
        least, most, _ = FUNCTIONS[name]
        if not least <= len(args) <= most:
            raise ExpressionError(f"{name} takes {least}..{most} argument(s), got {len(args)}")
        return _folded(f"{name}({','.join(args)})")


#: ``x(node)`` of a mechanical expression: a node's displacement (or angle), read as ``i(@x:node)``.
_X_REF = re.compile(r"(?i)(?<![A-Za-z0-9_.])x\s*\(\s*([^(),\s]+)\s*\)")
#: Prefix of the internal reference that stands for a displacement.
DISPLACEMENT = "@x:"


def displacement_refs(text: str) -> str:
    """``x(n)`` written as the internal reference ``i(@x:n)`` (the expression parser reads v() and i())."""
    return _X_REF.sub(lambda m: f"i({DISPLACEMENT}{m.group(1).lower()})", text)


def mechanical_expression(text: str) -> bool:
    """True when a FORCE/TORQUE value reads the motion: ``x(n)``, ``v(n)`` or ``time``."""
    return bool(_X_REF.search(text) or re.search(r"(?i)(?<![A-Za-z0-9_.])(v\s*\(|time\b)", text))


_VARIABLE = re.compile(r"(?i)(?<![A-Za-z0-9_.])(v\s*\(|i\s*\(|time\b)")


def _folded(text: str) -> str:
    """A sub-expression without variables replaced by its value (B-source semantics)."""
    if _VARIABLE.search(text):
        return text
    value = Behaviour.from_text(text).evaluate(np.zeros(0))[0]
    if not math.isfinite(value):
        raise ExpressionError(f"the constant part {text} is not finite")
    return repr(value)


# ------------------------------------------------------------------- evaluation


@dataclass(frozen=True)
class Behaviour:
    """A folded behavioural expression with its variables.

    Attributes
    ----------
    text : str
        The folded text (see :func:`fold`).
    variables : tuple
        ``("v", node)`` (ground excluded), ``("i", element key)`` and
        ``("time", "")``, in order of first appearance.
    """

    text: str
    tree: Node
    variables: tuple[tuple[str, str], ...]

    @classmethod
    def from_text(cls, text: str, ground: str = "0") -> Behaviour:
        """Parse a folded text (node names canonical: ``gnd`` is ground)."""
        expr = parse(text)
        found: dict[tuple[str, str], None] = {}
        walk(expr.tree, _Variables(found, ground))
        # keep a stable order: first appearance in the text
        order = sorted(found, key=lambda k: _position(expr.text, k))
        return cls(text, expr.tree, tuple(order))

    def evaluate(self, values: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
        """Value and gradient at ``values`` (one per entry of :attr:`variables`).

        Raises
        ------
        ExpressionError
            Domain errors (``log`` of a negative number...) or division by zero.
        """
        index = {key: k for k, key in enumerate(self.variables)}
        return walk(self.tree, _Dual(values, index))

    def value(self, values: NDArray[np.float64]) -> float:
        """The value alone at ``values`` (no gradient: several times faster than :meth:`evaluate`)."""
        index = {key: k for k, key in enumerate(self.variables)}
        return walk(self.tree, _Dual(values, index, gradient=False))[0]


#: A value with its gradient over :attr:`Behaviour.variables`.
Dual = tuple[float, NDArray[np.float64]]


class _Variables(Hooks[None]):
    """Collects the variables an expression reads (both branches of every ``? :``)."""

    def __init__(self, found: dict[tuple[str, str], None], ground: str) -> None:
        self.found, self.ground = found, ground

    def number(self, value: float) -> None:
        return None

    def name(self, name: str) -> None:
        if name != TIME:
            raise ExpressionError(f"unknown parameter {name!r}")
        self.found.setdefault(("time", ""), None)

    def ref(self, kind: str, args: tuple[str, ...]) -> None:
        for arg in args:
            key = (kind, self.ground if arg in ("0", "gnd") else arg)
            if key != ("v", self.ground):
                self.found.setdefault(key, None)

    def unary(self, op: str, x: None) -> None:
        return None

    def binary(self, op: str, a: None, b: None) -> None:
        return None

    def ternary(self, cond: None, a: None, b: None) -> None:
        return None

    def call(self, name: str, args: list[None]) -> None:
        return None


class _Dual(Hooks[Dual]):
    """Forward-mode differentiation: each node's value with its gradient (a scalar 0 without ``gradient``)."""

    def __init__(
        self, values: NDArray[np.float64], index: Mapping[tuple[str, str], int], gradient: bool = True
    ) -> None:
        self.values, self.index = values, index
        self.zero: Any = np.zeros(len(index)) if gradient else 0.0
        self.gradient = gradient

    def number(self, value: float) -> Dual:
        return value, self.zero

    def name(self, name: str) -> Dual:
        return self._unit(self.index[("time", "")])

    def _unit(self, k: int) -> Dual:
        if not self.gradient:
            return float(self.values[k]), self.zero
        grad = self.zero.copy()
        grad[k] = 1.0
        return float(self.values[k]), grad

    def ref(self, kind: str, args: tuple[str, ...]) -> Dual:
        value, grad = 0.0, (self.zero.copy() if self.gradient else self.zero)
        for sign, arg in zip((1.0, -1.0), args, strict=False):
            k = self.index.get((kind, "0" if arg in ("0", "gnd") else arg))
            if k is not None:
                value += sign * float(self.values[k])
                if self.gradient:
                    grad[k] += sign
        return value, grad

    def unary(self, op: str, x: Dual) -> Dual:
        if op == "neg":
            return -x[0], -x[1]
        if op == "pos":
            return x
        return float(not x[0]), self.zero

    def binary(self, op: str, a: Dual, b: Dual) -> Dual:
        return _binary(op, a, b, self.zero)

    def choose(self, cond: Dual) -> bool:
        return bool(cond[0])

    def call(self, name: str, args: list[Dual]) -> Dual:
        _, _, func = FUNCTIONS[name]
        try:
            value, partials = func(*(a for a, _ in args))
        except (ValueError, OverflowError, ZeroDivisionError) as exc:
            raise ExpressionError(f"{name}(): {exc}") from None
        grad = self.zero
        for p, (_, da) in zip(partials, args, strict=True):
            if p:
                grad = grad + p * da
        return value, grad


def _position(text: str, key: tuple[str, str]) -> int:
    low = text.lower()
    probe = TIME if key[0] == "time" else f"{key[0]}({key[1]}"
    at = low.find(probe)
    if at < 0 and key[0] == "v":
        at = low.find(f",{key[1]})")
    return at if at >= 0 else len(low)


def _binary(
    op: str,
    a: tuple[float, NDArray[np.float64]],
    b: tuple[float, NDArray[np.float64]],
    zero: NDArray[np.float64],
) -> tuple[float, NDArray[np.float64]]:
    x, dx = a
    y, dy = b
    if op == "+":
        return x + y, dx + dy
    if op == "-":
        return x - y, dx - dy
    if op == "*":
        return x * y, y * dx + x * dy
    if op == "/":
        if y == 0:
            raise ExpressionError("division by zero")
        return x / y, (dx * y - x * dy) / (y * y)
    if op == "%":
        if y == 0:
            raise ExpressionError("modulo by zero")
        return math.fmod(x, y), dx - math.trunc(x / y) * dy
    if op in ("**", "^"):
        value, px, py = _power(x, y)
        return value, px * dx + py * dy
    return logic(op, x, y), zero


# ------------------------------------------------------------------------ diode

#: Model parameters netlistdyn reads, with ngspice's aliases (ngspice 39's ``diompar``/``dio.c``).
DIODE_PARAMS: dict[str, str] = {
    "is": "IS",
    "js": "IS",
    "n": "N",
    "rs": "RS",
    "cjo": "CJO",
    "cj0": "CJO",
    "cj": "CJO",
    "vj": "VJ",
    "pb": "VJ",
    "m": "M",
    "mj": "M",
    "tt": "TT",
    "fc": "FC",
    "bv": "BV",
    "ibv": "IBV",
    "ib": "IBV",
    "nbv": "NBV",
    "ikf": "IKF",
    "ik": "IKF",
    "ikr": "IKR",
    "isr": "ISR",
    "nr": "NR",
    "eg": "EG",
    "xti": "XTI",
    "tnom": "TNOM",
    "tref": "TNOM",
}
#: Parameters accepted when they keep their default (no effect).
DIODE_NEUTRAL: dict[str, float] = {"level": 1.0}
#: Parameters read and ignored, with the reason: they change no operating point, small-signal
#: model or transient (flicker noise: netlistdyn has no noise analysis; safe-operating-area limits:
#: ngspice only warns when they are exceeded).
DIODE_IGNORED: dict[str, str] = {
    "kf": "noise",
    "af": "noise",
    "fv_max": "safe operating area",
    "bv_max": "safe operating area",
    "id_max": "safe operating area",
    "te_max": "safe operating area",
    "pd_max": "safe operating area",
    "d": "model type flag",
}
#: The other parameters of ngspice 39's diode (``dio.c``): they change its numbers and netlistdyn
#: does not compute them, so a card that gives one is refused, naming it. A name ngspice does not
#: know at all it ignores with a warning; so does netlistdyn.
DIODE_REFUSED: frozenset[str] = frozenset(
    {
        "jsw", "ns", "trs", "trs1", "trs2", "ttt1", "ttt2", "tm1", "tm2", "cjp", "cjsw", "php",
        "mjsw", "area", "pj", "tlev", "tlevc", "cta", "ctc", "ctp", "tpb", "tvj", "tphp", "jtun",
        "jtunsw", "ntun", "xtitun", "keg", "fcs", "tcv", "cond", "temperature", "rth0", "cth0",
        "lm", "lp", "wm", "wp", "xom", "xoi", "xm", "xp",
    }
)  # fmt: skip
#: ngspice's IKF/IKR below this (CKTepsmin) disables the knee (with a warning).
KNEE_EPSMIN = 1e-28

#: Boltzmann's constant (J/K) and the electron charge (C), as ngspice 39's const.h.
BOLTZMANN = 1.38064852e-23
CHARGE = 1.6021766208e-19
#: Kelvin at 0 °C (ngspice's CONSTCtoK).
CELSIUS_TO_KELVIN = 273.15
#: Most iterations ngspice 39's ``diotemp`` spends matching the breakdown knee to IBV.
BREAKDOWN_ITERATIONS = 25


@dataclass(frozen=True, slots=True)
class Junction:
    """One diode instance's junction as ngspice 39 computes it at the circuit temperature.

    Currents and capacitances include the area factor (times the multiplier M=). ``math.inf``
    disables BV (no breakdown) and IKF/IKR (no knee); ISR = 0 disables recombination.

    Attributes
    ----------
    isat : float
        Saturation current at the temperature (A).
    n : float
        Emission coefficient.
    vt : float
        Thermal voltage kT/q at the temperature (V).
    bv : float
        Breakdown voltage after matching the knee to IBV (ngspice's ``tBrkdwnV``) (V).
    nbv : float
        Breakdown emission coefficient.
    ikf, ikr : float
        Forward and reverse knee currents (A).
    isr, nr : float
        Recombination saturation current (A) and emission coefficient.
    cjo, vj, m, fc, tt : float
        Zero-bias capacitance (F), junction potential (V), grading coefficient, forward-bias
        depletion coefficient and transit time (s), at the temperature.
    """

    isat: float
    n: float
    vt: float
    bv: float = math.inf
    nbv: float = 1.0
    ikf: float = math.inf
    ikr: float = math.inf
    isr: float = 0.0
    nr: float = 2.0
    cjo: float = 0.0
    vj: float = 1.0
    m: float = 0.5
    fc: float = 0.5
    tt: float = 0.0

    @property
    def vte(self) -> float:
        """N·kT/q (V)."""
        return self.n * self.vt


def _egfet(temp: float) -> float:
    """Silicon band gap at ``temp`` (K) (eV), ngspice's formula."""
    return 1.16 - (7.02e-4 * temp * temp) / (temp + 1108.0)


def _pbfact(temp: float) -> float:
    """ngspice's junction-potential temperature term at ``temp`` (K) (V)."""
    arg = -_egfet(temp) / (2 * BOLTZMANN * temp) + 1.1150877 / (BOLTZMANN * (REFTEMP + REFTEMP))
    return -2 * K_OVER_Q * temp * (1.5 * math.log(temp / REFTEMP) + CHARGE * arg)


def junction(model: Any, area: float) -> Junction:
    """A diode instance's junction at the circuit temperature, as ngspice 39's ``diotemp`` (level 1).

    Parameters
    ----------
    model : DiodeModel
        The ``.model`` card with the instance's temperature and multiplier.
    area : float
        Area factor times the multiplier M= (ngspice scales IS, ISR, IKF, IKR, CJO by it; RS
        is divided by it); ngspice 39 scales IBV by the multiplier alone.
    """
    temp = model.temp + CELSIUS_TO_KELVIN
    tnom = model.TNOM + CELSIUS_TO_KELVIN
    vt = K_OVER_Q * temp
    n, isat, isr, cjo, vj = model.N, model.IS * area, model.ISR * area, model.CJO * area, model.VJ
    if temp != tnom:  # at TNOM every factor is 1: skipped, so the numbers stay exactly the model's
        ratio = temp / tnom
        isat *= math.exp((ratio - 1) * model.EG / (n * vt) + model.XTI / n * math.log(ratio))
        isr *= math.exp((ratio - 1) * model.EG / (model.NR * vt) + model.XTI / model.NR * math.log(ratio))
        fact1, fact2 = tnom / REFTEMP, temp / REFTEMP
        pbo = (model.VJ - _pbfact(tnom)) / fact1
        gmaold = (model.VJ - pbo) / pbo
        cjo /= 1 + model.M * (400e-6 * (tnom - REFTEMP) - gmaold)
        vj = _pbfact(temp) + fact2 * pbo
        gmanew = (vj - pbo) / pbo
        cjo *= 1 + model.M * (400e-6 * (temp - REFTEMP) - gmanew)
    if model.FC * vj > 1.0:  # ngspice limits the junction potential to 1/FC
        vj = 1.0 / model.FC
    nbv = model.NBV if model.NBV is not None else n
    bv = math.inf
    if model.BV is not None:
        bv = _breakdown_knee(model.BV, model.mult * model.IBV, isat, nbv, vt)
    return Junction(
        isat=isat,
        n=n,
        vt=vt,
        bv=bv,
        nbv=nbv,
        ikf=model.IKF * area,
        ikr=model.IKR * area,
        isr=isr,
        nr=model.NR,
        cjo=cjo,
        vj=vj,
        m=model.M,
        fc=model.FC,
        tt=model.TT,
    )


def _breakdown_knee(bv: float, cbv: float, isat: float, nbv: float, vt: float) -> float:
    """ngspice 39's ``tBrkdwnV``: the knee voltage at which the breakdown current is IBV (V).

    ngspice iterates ``xbv = BV − NBV·vt·ln(IBV/IS + 1 − xbv/vt)`` until the current matches IBV to
    its RELTOL; here to rounding (at most :data:`BREAKDOWN_ITERATIONS` steps each way), which is
    ngspice's answer at a tight RELTOL.
    """
    if cbv < isat * bv / vt:
        return bv
    xbv = bv - nbv * vt * math.log(1 + cbv / isat)
    for _ in range(4 * BREAKDOWN_ITERATIONS):
        new = bv - nbv * vt * math.log(cbv / isat + 1 - xbv / vt)
        if abs(new - xbv) <= 4 * math.ulp(abs(xbv)):
            return new
        xbv = new
    return xbv


def thermal_voltage(temp_k: float = REFTEMP) -> float:
    """kT/q (V) with ngspice's constants."""
    return K_OVER_Q * temp_k


def diode_current(
    vd: float, isat: float, n: float, gmin: float = GMIN, vt: float | None = None
) -> tuple[float, float]:
    """Junction current and conductance of ngspice's diode (no breakdown).

    Parameters
    ----------
    vd : float
        Junction voltage (V).
    isat : float
        Saturation current times area (A).
    n : float
        Emission coefficient.
    gmin : float
        Conductance in parallel (S).
    vt : float, optional
        Thermal voltage (V); default at 27 °C.

    Returns
    -------
    (float, float)
        Current (A) and dI/dV (S).
    """
    vte = n * (thermal_voltage() if vt is None else vt)
    if vd >= -3.0 * vte:
        e = _safe_exp(vd / vte)
        return isat * (e - 1.0) + gmin * vd, isat * e / vte + gmin
    arg = 3.0 * vte / (vd * math.e)
    arg = arg * arg * arg
    return -isat * (1.0 + arg) + gmin * vd, isat * 3.0 * arg / vd + gmin


def diode_charge(
    vd: float, current: float, conductance: float, cjo: float, vj: float, m: float, tt: float, fc: float
) -> tuple[float, float]:
    """Junction plus diffusion charge and its derivative (ngspice's formulas).

    Parameters
    ----------
    vd : float
        Junction voltage (V).
    current, conductance : float
        Junction current (A) and dI/dV (S) at ``vd`` (diffusion charge TT·I).
    cjo, vj, m, tt, fc : float
        Zero-bias capacitance times area (F), junction potential (V),
        grading coefficient, transit time (s), forward-bias coefficient.

    Returns
    -------
    (float, float)
        Charge (C) and capacitance dQ/dV (F).
    """
    q = tt * current
    c = tt * conductance
    if cjo == 0:
        return q, c
    depcap = fc * vj
    if vd < depcap:
        arg = 1.0 - vd / vj
        sarg = math.exp(-m * math.log(arg))
        return q + vj * cjo * (1.0 - arg * sarg) / (1.0 - m), c + cjo * sarg
    f1 = vj * (1.0 - (1.0 - fc) ** (1.0 - m)) / (1.0 - m)
    f2 = (1.0 - fc) ** (1.0 + m)
    f3 = 1.0 - fc * (1.0 + m)
    czof2 = cjo / f2
    q += cjo * f1 + czof2 * (f3 * (vd - depcap) + (m / (vj + vj)) * (vd * vd - depcap * depcap))
    return q, c + czof2 * (f3 + m * vd / vj)


def diode_current_array(
    vd: NDArray[np.float64], isat: NDArray[np.float64], n: NDArray[np.float64], gmin: float = GMIN
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """:func:`diode_current` for arrays of junctions (same formulas, elementwise)."""
    vte = n * thermal_voltage()
    forward = vd >= -3.0 * vte
    x = vd / vte
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        e = np.where(x < 709.0, np.exp(np.minimum(x, 709.0)), np.inf)
        safe = np.where(forward, -1.0, vd)
        arg = (3.0 * vte / (safe * math.e)) ** 3
        current = np.where(forward, isat * (e - 1.0), -isat * (1.0 + arg)) + gmin * vd
        conductance = np.where(forward, isat * e / vte, isat * 3.0 * arg / safe) + gmin
    return current, conductance


#: Fields of :class:`Junction` that :func:`junction_arrays` stacks.
JUNCTION_FIELDS = ("isat", "n", "vt", "bv", "nbv", "ikf", "ikr", "isr", "nr", "cjo", "vj", "m", "fc", "tt")


def junction_arrays(junctions: list[Junction]) -> dict[str, NDArray[np.float64]]:
    """The junctions' parameters side by side (one array per :class:`Junction` field)."""
    return {f: np.array([getattr(j, f) for j in junctions], dtype=float) for f in JUNCTION_FIELDS}


def junction_current_array(
    vd: NDArray[np.float64], p: dict[str, NDArray[np.float64]], gmin: float = GMIN
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Current (A) and conductance (S) of junctions as ngspice 39's ``dioload`` (level 1).

    Forward (vd ≥ −3·N·vt): IS·(e^{vd/(N vt)} − 1), plus the recombination current
    ISR·(e^{vd/(NR vt)} − 1)·((1 − vd/VJ)² + 0.005)^{M/2} when ISR is given; reverse: −IS·(1 +
    (3 N vt/(e·vd))³); beyond the knee −BV: −IS·e^{−(BV + vd)/(NBV vt)}. Then the high-injection
    knee IKF (forward) or IKR (reverse): I/(1 + √(I/IK)); then gmin·vd. The conductance is
    ngspice's own expression (its recombination term is not the exact derivative: ngspice's
    ``.ac`` uses it, and so does the small-signal model here).

    Parameters
    ----------
    vd : numpy.ndarray
        Junction voltages (V).
    p : dict of numpy.ndarray
        The junctions' parameters (:func:`junction_arrays`).
    gmin : float
        Conductance in parallel (S).
    """
    vd = np.asarray(vd, dtype=float)
    isat, vt = p["isat"], p["vt"]
    vte = p["n"] * vt
    vtebrk = p["nbv"] * vt
    forward = vd >= -3.0 * vte
    breakdown = ~forward & (vd < -p["bv"])
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        x = np.where(forward, vd / vte, 0.0)
        e = np.where(x < 709.0, np.exp(np.minimum(x, 709.0)), np.inf)
        safe = np.where(forward, -1.0, vd)
        arg = (3.0 * vte / (safe * math.e)) ** 3
        xb = np.where(breakdown, -(p["bv"] + vd) / vtebrk, 0.0)
        evrev = np.where(xb < 709.0, np.exp(np.minimum(xb, 709.0)), np.inf)
        current = np.where(forward, isat * (e - 1.0), np.where(breakdown, -isat * evrev, -isat * (1.0 + arg)))
        conductance = np.where(
            forward, isat * e / vte, np.where(breakdown, isat * evrev / vtebrk, isat * 3.0 * arg / safe)
        )
        rec = forward & (p["isr"] > 0)
        if np.any(rec):
            vterec = p["nr"] * vt
            erec = np.exp(np.minimum(np.where(rec, vd / vterec, 0.0), 709.0))
            c_rec = p["isr"] * (erec - 1.0)
            g_rec = p["isr"] * erec / vterec
            base = 1.0 - vd / p["vj"]
            t1 = base * base + 0.005
            gen = t1 ** (p["m"] / 2)
            gen_vd = -p["m"] * base * t1 ** (p["m"] / 2 - 1)
            c_rec = c_rec * gen
            g_rec = g_rec * gen + c_rec * gen_vd  # as ngspice 39 writes it
            current = np.where(rec, current + c_rec, current)
            conductance = np.where(rec, conductance + g_rec, conductance)
        knee_f = forward & np.isfinite(p["ikf"]) & (current > 1e-18)
        knee_r = ~forward & np.isfinite(p["ikr"]) & (current < -1e-18)
        if np.any(knee_f | knee_r):
            ik = np.where(knee_f, p["ikf"], np.where(knee_r, p["ikr"], 1.0))
            ratio = np.where(knee_f, current / ik, np.where(knee_r, current / -ik, 1.0))
            root = np.sqrt(ratio)
            sign = np.where(knee_f, 1.0, -1.0)
            g_knee = ((1 + root) * conductance - sign * current * conductance / (2 * root * ik)) / (
                1 + 2 * root + sign * current / ik
            )
            kneed = knee_f | knee_r
            conductance = np.where(kneed, g_knee, conductance)
            current = np.where(kneed, current / (1 + root), current)
    return current + gmin * vd, conductance + gmin


def junction_current(vd: float, j: Junction, gmin: float = GMIN) -> tuple[float, float]:
    """:func:`junction_current_array` for one junction: current (A) and conductance (S)."""
    i, g = junction_current_array(np.array([vd]), junction_arrays([j]), gmin)
    return float(i[0]), float(g[0])


def junction_charge(vd: float, current: float, conductance: float, j: Junction) -> tuple[float, float]:
    """:func:`diode_charge` with a junction's parameters: charge (C) and dQ/dV (F)."""
    return diode_charge(vd, current, conductance, j.cjo, j.vj, j.m, j.tt, j.fc)


def diode_charge_array(
    vd: NDArray[np.float64],
    current: NDArray[np.float64],
    conductance: NDArray[np.float64],
    cjo: NDArray[np.float64],
    vj: NDArray[np.float64],
    m: NDArray[np.float64],
    tt: NDArray[np.float64],
    fc: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """:func:`diode_charge` for arrays of junctions (same formulas, elementwise)."""
    q = tt * current
    c = tt * conductance
    depcap = fc * vj
    low = vd < depcap
    arg = np.where(low, 1.0 - vd / vj, 1.0)
    sarg = np.exp(-m * np.log(arg))
    q_low = vj * cjo * (1.0 - arg * sarg) / (1.0 - m)
    c_low = cjo * sarg
    f1 = vj * (1.0 - (1.0 - fc) ** (1.0 - m)) / (1.0 - m)
    f2 = (1.0 - fc) ** (1.0 + m)
    f3 = 1.0 - fc * (1.0 + m)
    czof2 = cjo / f2
    q_high = cjo * f1 + czof2 * (f3 * (vd - depcap) + (m / (vj + vj)) * (vd * vd - depcap * depcap))
    c_high = czof2 * (f3 + m * vd / vj)
    return q + np.where(low, q_low, q_high), c + np.where(low, c_low, c_high)
