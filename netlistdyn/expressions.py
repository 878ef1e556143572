"""Safe evaluation of ``.param`` values and ``{expression}`` element values.

A small recursive-descent parser over ``+ - * / ** ^``, parentheses, unary
signs, SPICE numbers (``2k``), parameter names and a few functions. No
Python ``eval``: only arithmetic on floats is ever executed.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping

from .values import split_number

FUNCTIONS: dict[str, Callable[..., float]] = {
    "sqrt": math.sqrt,
    "exp": math.exp,
    "log": math.log,
    "ln": math.log,
    "log10": math.log10,
    "sin": math.sin,
    "cos": math.cos,
    "tan": math.tan,
    "atan": math.atan,
    "abs": abs,
    "min": min,
    "max": max,
    "pow": math.pow,
}
CONSTANTS: dict[str, float] = {"pi": math.pi, "e": math.e}

_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_.]*")
_OPERATORS = ("**", "+", "-", "*", "/", "^", "(", ")", ",")


class ExpressionError(ValueError):
    """An expression that cannot be evaluated; the message says why."""


def _tokenize(text: str) -> list[tuple[str, object]]:
    tokens: list[tuple[str, object]] = []
    pos = 0
    while pos < len(text):
        char = text[pos]
        if char.isspace():
            pos += 1
            continue
        if char.isdigit() or (char == "." and pos + 1 < len(text) and text[pos + 1].isdigit()):
            parsed = split_number(text[pos:])
            assert parsed is not None
            value, rest = parsed
            # Letters directly after a number are units, ignored as in SPICE.
            unit = re.match(r"[A-Za-z]*", rest)
            consumed = len(text) - pos - len(rest) + (unit.end() if unit else 0)
            tokens.append(("num", value))
            pos += consumed
            continue
        ident = _IDENT.match(text, pos)
        if ident:
            tokens.append(("name", ident.group(0).lower()))
            pos = ident.end()
            continue
        for op in _OPERATORS:
            if text.startswith(op, pos):
                tokens.append(("op", "**" if op == "^" else op))
                pos += len(op)
                break
        else:
            raise ExpressionError(f"unexpected character {char!r} in expression {text!r}")
    return tokens


class _Parser:
    def __init__(self, text: str, params: Mapping[str, float]) -> None:
        self.text = text
        self.tokens = _tokenize(text)
        self.pos = 0
        self.params = params

    def peek(self) -> tuple[str, object] | None:
        return self.tokens[self.pos] if self.pos < len(self.tokens) else None

    def take(self, op: str) -> bool:
        tok = self.peek()
        if tok == ("op", op):
            self.pos += 1
            return True
        return False

    def parse(self) -> float:
        if not self.tokens:
            raise ExpressionError("empty expression")
        value = self.sum()
        if self.peek() is not None:
            raise ExpressionError(f"unexpected {self.peek()[1]!r} in expression {self.text!r}")
        return value

    def sum(self) -> float:
        value = self.product()
        while True:
            if self.take("+"):
                value += self.product()
            elif self.take("-"):
                value -= self.product()
            else:
                return value

    def product(self) -> float:
        value = self.unary()
        while True:
            if self.take("*"):
                value *= self.unary()
            elif self.take("/"):
                divisor = self.unary()
                if divisor == 0:
                    raise ExpressionError(f"division by zero in {self.text!r}")
                value /= divisor
            else:
                return value

    def unary(self) -> float:
        if self.take("-"):
            return -self.unary()
        if self.take("+"):
            return self.unary()
        return self.power()

    def power(self) -> float:
        base = self.atom()
        if self.take("**"):
            exponent = self.unary()  # right associative: 2**-1, 2**3**2
            try:
                return float(base**exponent)
            except (OverflowError, ZeroDivisionError) as exc:
                raise ExpressionError(f"{exc} in {self.text!r}") from None
        return base

    def atom(self) -> float:
        tok = self.peek()
        if tok is None:
            raise ExpressionError(f"expression {self.text!r} ends too early")
        kind, value = tok
        self.pos += 1
        if kind == "num":
            return float(value)  # type: ignore[arg-type]
        if kind == "op" and value == "(":
            inner = self.sum()
            if not self.take(")"):
                raise ExpressionError(f"missing ')' in {self.text!r}")
            return inner
        if kind == "name":
            name = str(value)
            if self.take("("):
                return self.call(name)
            if name in self.params:
                return self.params[name]
            if name in CONSTANTS:
                return CONSTANTS[name]
            raise ExpressionError(f"unknown parameter {name!r}")
        raise ExpressionError(f"unexpected {value!r} in expression {self.text!r}")

    def call(self, name: str) -> float:
        if name not in FUNCTIONS:
            raise ExpressionError(f"unknown function {name!r}")
        args: list[float] = []
        if not self.take(")"):
            args.append(self.sum())
            while self.take(","):
                args.append(self.sum())
            if not self.take(")"):
                raise ExpressionError(f"missing ')' after arguments of {name}")
        try:
            return float(FUNCTIONS[name](*args))
        except (TypeError, ValueError, OverflowError) as exc:
            raise ExpressionError(f"{name}({', '.join(map(repr, args))}): {exc}") from None


def evaluate(text: str, params: Mapping[str, float]) -> float:
    """Evaluate an arithmetic expression over named parameters.

    Parameters
    ----------
    text : str
        The expression without braces, e.g. ``"1/(2*pi*f0*C1)"``.
    params : Mapping[str, float]
        Parameter values by lower-case name.

    Returns
    -------
    float
        The value.

    Raises
    ------
    ExpressionError
        On syntax errors, unknown names or arithmetic errors.
    """
    return _Parser(text, params).parse()
