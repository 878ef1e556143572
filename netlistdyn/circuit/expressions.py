"""Expressions of ``.param`` values, ``{...}`` fields and behavioural sources.

The grammar and arithmetic follow ngspice 39 (checked against ``ngspice -b``):

- precedence, low to high: ``c ? a : b``; ``||``; ``&&``; ``== !=``;
  ``< > <= >=``; ``+ -``; ``* / %``; ``** ^``; a sign that follows an
  operator. ``**`` and ``^`` associate to the *left* (``2^3^2`` = 64) and
  take the magnitude of the base (``(-2)**3`` = 8, ``(-8)**(1/3)`` = 2).
- a sign at the start of an expression (or after ``(``, ``,``, ``?``, ``:``)
  is a subtraction from zero, so it binds *looser* than ``**``
  (``-2**2`` = -4), while a sign after an operator binds tighter
  (``3 - -2**2`` = -1, ``2*-3**2`` = 18).
- ``%`` is C's ``fmod``; ``int`` truncates; ``nint`` rounds half to even;
  comparisons and logic give 1 or 0.

Parsing is a shunting-yard pass and every evaluation goes through
:func:`walk`, one explicit-stack walker with per-node hooks (floats and
affine forms here; values with gradients and folded text in
:mod:`netlistdyn.devices`), so neither recurses: 5000 nested signs or
parentheses are fine. No Python ``eval``: only arithmetic on floats is
ever executed.

The same evaluator runs over :class:`Linear` values when an expression
refers to node voltages ``v(a)``, ``v(a,b)`` or branch currents ``i(V1)``;
any operation that is not linear in those raises :class:`NonlinearError`
naming it (behavioural sources are compiled only when linear).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Generic, TypeVar

from netlistdyn.base.values import split_number

CONSTANTS: dict[str, float] = {"pi": math.pi, "e": math.e}

#: Largest number of tokens an expression may have.
MAX_TOKENS = 1_000_000
#: Nesting depth of user ``.func`` calls (a recursive ``.func`` is an error).
MAX_CALL_DEPTH = 64
#: Work one evaluation may do in user ``.func`` calls, counted as the characters of the bodies
#: evaluated: the depth limit alone lets a ``.func`` calling the previous one twice, 40 levels
#: deep, make 2**40 calls. 2,000,000 is about a second of evaluation; real netlists use far less.
MAX_EVALUATION_WORK = 2_000_000


class _Work:
    """What is left of :data:`MAX_EVALUATION_WORK` for one evaluation (shared by its nested calls)."""

    __slots__ = ("left",)

    def __init__(self) -> None:
        self.left = MAX_EVALUATION_WORK

    def spend(self, amount: int, name: str) -> None:
        self.left -= amount
        if self.left < 0:
            raise ExpressionError(
                f".func {name}: the nested .func calls need more than {MAX_EVALUATION_WORK:,} steps "
                "to evaluate (a function calling another more than once, many levels deep)"
            )


class ExpressionError(ValueError):
    """An expression that cannot be evaluated; the message says why."""


class NonlinearError(ExpressionError):
    """An expression that is not linear in node voltages and branch currents."""


def _pwr(x: float, y: float) -> float:
    # ngspice 39's ** and ^ (and pwr): |x|**y.
    if x == 0 and y < 0:
        raise ExpressionError("0 raised to a negative power")
    return math.pow(abs(x), y)


def _pow(x: float, y: float) -> float:
    if x == 0 and y < 0:
        raise ExpressionError("0 raised to a negative power")
    if x < 0 and not float(y).is_integer():
        raise ExpressionError(f"pow({x:g}, {y:g}) has no real value")
    return math.pow(x, y)


def _log(x: float) -> float:
    if x <= 0:
        raise ExpressionError(f"log of a non-positive number ({x:g})")
    return math.log(x)


def _log10(x: float) -> float:
    if x <= 0:
        raise ExpressionError(f"log10 of a non-positive number ({x:g})")
    return math.log10(x)


def _sqrt(x: float) -> float:
    if x < 0:
        raise ExpressionError(f"sqrt of a negative number ({x:g})")
    return math.sqrt(x)


def _sgn(x: float) -> float:
    return float((x > 0) - (x < 0))


#: Functions of B sources only (ngspice 39: "Undefined parameter" in a .param): the step u(x)
#: and the ramp uramp(x) of a node voltage, branch current or time.
BEHAVIOURAL_ONLY = frozenset({"u", "uramp"})

#: Functions by name: (callable, least, most arguments).
FUNCTIONS: dict[str, tuple[Callable[..., float], int, int]] = {
    "sqrt": (_sqrt, 1, 1),
    "exp": (math.exp, 1, 1),
    "log": (_log, 1, 1),
    "ln": (_log, 1, 1),
    "log10": (_log10, 1, 1),
    "sin": (math.sin, 1, 1),
    "cos": (math.cos, 1, 1),
    "tan": (math.tan, 1, 1),
    "asin": (math.asin, 1, 1),
    "acos": (math.acos, 1, 1),
    "atan": (math.atan, 1, 1),
    "sinh": (math.sinh, 1, 1),
    "cosh": (math.cosh, 1, 1),
    "tanh": (math.tanh, 1, 1),
    "asinh": (math.asinh, 1, 1),
    "acosh": (math.acosh, 1, 1),
    "atanh": (math.atanh, 1, 1),
    "abs": (abs, 1, 1),
    "sgn": (_sgn, 1, 1),
    "int": (lambda x: float(math.trunc(x)), 1, 1),
    "nint": (lambda x: float(round(x)), 1, 1),
    "floor": (lambda x: float(math.floor(x)), 1, 1),
    "ceil": (lambda x: float(math.ceil(x)), 1, 1),
    # As ngspice 39 reads them (measured): min(x) is min(x, 1) and max(x) is max(x, 1).
    "min": (lambda *a: min(a) if len(a) > 1 else min(a[0], 1.0), 1, 64),
    "max": (lambda *a: max(a) if len(a) > 1 else max(a[0], 1.0), 1, 64),
    "pow": (_pow, 2, 2),
    "pwr": (_pwr, 2, 2),
    "ternary_fcn": (lambda c, a, b: a if c else b, 3, 3),
}

_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_.]*")
#: The digits of a number (ASCII only: ngspice 39 refuses full-width and Arabic-Indic digits).
_DIGITS = frozenset("0123456789")
_OPERATORS = ("**", "==", "!=", "<=", ">=", "&&", "||", "+", "-", "*", "/", "%", "^", "<", ">", "!", "?", ":")
#: Binary operators: (precedence, left associative).
_BINARY: dict[str, int] = {
    "||": 2,
    "&&": 3,
    "==": 4,
    "!=": 4,
    "<": 5,
    ">": 5,
    "<=": 5,
    ">=": 5,
    "+": 6,
    "-": 6,
    "*": 7,
    "/": 7,
    "%": 7,
    "**": 8,
    "^": 8,
}
_TERNARY_PREC = 1
_PREFIX_PREC = 9

# AST nodes are tuples: ("num", v) ("name", n) ("ref", "v"|"i", args) ("neg"|"not", x)
# ("bin", op, a, b) ("tern", c, a, b) ("call", name, args).
Node = tuple
#: The value type a :class:`Hooks` computes.
T = TypeVar("T")


@dataclass(frozen=True)
class Expression:
    """A parsed expression (an immutable tree) with its source text."""

    text: str
    tree: Node
    names: frozenset[str] = field(default_factory=frozenset)
    refs: bool = False


def _tokenize(text: str) -> list[tuple[str, object]]:
    tokens: list[tuple[str, object]] = []
    pos = 0
    n = len(text)
    while pos < n:
        if len(tokens) > MAX_TOKENS:
            raise ExpressionError(f"expression longer than {MAX_TOKENS} tokens")
        char = text[pos]
        if char.isspace():
            pos += 1
            continue
        if char in _DIGITS or (char == "." and pos + 1 < n and text[pos + 1] in _DIGITS):
            end = pos
            while end < n and (text[end].isalnum() or text[end] in ".\u00b5\u03bc"):
                end += 1
            if end < n and text[end] in "+-" and text[end - 1] in "eE" and _is_exponent(text, pos, end):
                end += 1
                while end < n and text[end].isalnum():
                    end += 1
            word = text[pos:end]
            parsed = split_number(word, mil=False)
            assert parsed is not None
            value, rest = parsed
            if rest and not rest.isalpha():
                raise ExpressionError(f"malformed number {word!r}")
            tokens.append(("num", value))
            pos = end
            continue
        ident = _IDENT.match(text, pos)
        if ident:
            name = ident.group(0).lower()
            pos = ident.end()
            rest = text[pos:].lstrip()
            if name in ("v", "i") and rest.startswith("("):
                start = text.index("(", pos) + 1
                close = text.find(")", start)
                if close < 0:
                    raise ExpressionError(f"missing ')' after {name}(")
                args = tuple(a.strip().lower() for a in text[start:close].split(","))
                if not all(args) or len(args) > (2 if name == "v" else 1):
                    raise ExpressionError(f"bad {name}({text[start:close]})")
                tokens.append(("ref", (name, args)))
                pos = close + 1
                continue
            tokens.append(("name", name))
            continue
        if char in "(),":
            tokens.append(("op", char))
            pos += 1
            continue
        for op in _OPERATORS:
            if text.startswith(op, pos):
                tokens.append(("op", op))
                pos += len(op)
                break
        else:
            raise ExpressionError(f"unexpected character {char!r}")
    return tokens


def _is_exponent(text: str, start: int, end: int) -> bool:
    """True when text[start:end] is a mantissa followed by ``e`` (``1e`` of ``1e-3``)."""
    return re.fullmatch(r"(?:\d+\.?\d*|\.\d+)[eE]", text[start:end]) is not None


class _ShuntingYard:
    """The state of :func:`parse`: Dijkstra's shunting yard over the tokens, one at a time.

    ``out`` holds the finished operands (tree nodes); ``ops`` the pending operators as
    ``(kind, payload)`` with kinds ``"bin"``, ``"pre"``, ``"("``, ``"call"``, ``"?"`` and ``":"``;
    ``arg_counts`` each open call's commas. ``expect_operand`` says which of :meth:`operand` and
    :meth:`operator` the next token goes to.
    """

    def __init__(self) -> None:
        self.out: list[Node] = []
        self.ops: list[tuple[str, object]] = []
        self.arg_counts: list[int] = []
        self.names: set[str] = set()
        self.refs = False
        self.expect_operand = True
        self.at_start = True  # a sign here is "0 - x"

    def reduce_top(self) -> None:
        """Apply the top operator to the operands it takes."""
        out = self.out
        kind, payload = self.ops.pop()
        if kind == "bin":
            if len(out) < 2:
                raise ExpressionError(f"operator {payload} lacks an operand")
            b = out.pop()
            a = out.pop()
            out.append(("bin", payload, a, b))
        elif kind == "pre":
            if not out:
                raise ExpressionError(f"operator {payload} lacks an operand")
            out.append(("neg" if payload == "-" else "not" if payload == "!" else "pos", out.pop()))
        elif kind == ":":
            if len(out) < 3:
                raise ExpressionError("incomplete '? :'")
            b = out.pop()
            a = out.pop()
            c = out.pop()
            out.append(("tern", c, a, b))
        elif kind == "?":
            raise ExpressionError("'?' without ':'")
        else:
            raise ExpressionError("unbalanced parentheses")

    @staticmethod
    def precedence(entry: tuple[str, object]) -> int:
        """How tightly a pending operator binds; -1 for the barriers ``(`` and a call."""
        kind, payload = entry
        if kind == "bin":
            return _BINARY[str(payload)]
        if kind == "pre":
            return _PREFIX_PREC
        if kind in ("?", ":"):
            return _TERNARY_PREC
        return -1  # "(" and "call" are barriers

    def push_binary(self, op: str) -> None:
        """A binary operator: reduce what binds at least as tightly, then wait for its right side."""
        prec = _BINARY[op]
        while self.ops and self.precedence(self.ops[-1]) >= prec:
            self.reduce_top()
        self.ops.append(("bin", op))

    def reduce_to_barrier(self) -> None:
        """Reduce down to the innermost ``(`` or call."""
        while self.ops and self.ops[-1][0] not in ("(", "call"):
            self.reduce_top()

    def operand(self, kind: str, value: object) -> None:
        """A token where an operand is expected: a number, a name, a reference, ``(`` or a sign."""
        if kind == "num":
            self.out.append(("num", value))
            self.expect_operand, self.at_start = False, False
        elif kind == "ref":
            self.out.append(("ref", *value))  # type: ignore[misc]
            self.refs = True
            self.expect_operand, self.at_start = False, False
        elif kind == "name":
            self.out.append(("name", value))
            self.names.add(str(value))
            self.expect_operand, self.at_start = False, False
        elif value == "(":
            self.ops.append(("(", None))
            self.at_start = True
        elif value in ("-", "+", "!"):
            if self.at_start and value != "!":
                self.out.append(("num", 0.0))
                self.push_binary(str(value))
                self.at_start = False
            else:
                self.ops.append(("pre", value))
        else:
            raise ExpressionError(f"unexpected {value!r}")

    def operator(self, kind: str, value: object) -> None:
        """A token where an operator is expected: ``(`` of a call, ``)``, ``,``, ``?``, ``:``, binary."""
        if kind != "op":
            raise ExpressionError(f"missing operator before {value!r}")
        if value == "(":
            self._call()
        elif value == ")":
            self._close()
        elif value == ",":
            self.reduce_to_barrier()
            if not self.ops or self.ops[-1][0] != "call":
                raise ExpressionError("',' outside a function call")
            self.arg_counts[-1] += 1
            self.expect_operand, self.at_start = True, True
        elif value == "?":
            while self.ops and self.precedence(self.ops[-1]) > _TERNARY_PREC:
                self.reduce_top()
            self.ops.append(("?", None))
            self.expect_operand, self.at_start = True, True
        elif value == ":":
            self._colon()
        elif value in _BINARY:
            self.push_binary(str(value))
            self.expect_operand, self.at_start = True, False
        else:
            raise ExpressionError(f"unexpected {value!r}")

    def _call(self) -> None:
        """``(`` after an operand: a call, whose operand just pushed must be a bare name."""
        if not self.out or self.out[-1][0] != "name":
            raise ExpressionError("unexpected '('")
        fname = self.out.pop()[1]
        self.names.discard(str(fname))
        self.ops.append(("call", fname))
        self.arg_counts.append(0)
        self.expect_operand, self.at_start = True, True

    def _close(self) -> None:
        """``)``: reduce to its ``(`` or call; a call takes its arguments."""
        self.reduce_to_barrier()
        if not self.ops:
            raise ExpressionError("unbalanced ')'")
        kind_top, payload = self.ops.pop()
        if kind_top == "call":
            count = self.arg_counts.pop() + 1
            args = tuple(self.out[-count:])
            del self.out[-count:]
            self.out.append(("call", payload, args))

    def _colon(self) -> None:
        """``:``: reduce to its ``?``, which becomes the ternary's ``:``."""
        while self.ops and self.ops[-1][0] != "?":
            if self.ops[-1][0] in ("(", "call"):
                raise ExpressionError("':' without '?'")
            self.reduce_top()
        if not self.ops:
            raise ExpressionError("':' without '?'")
        self.ops[-1] = (":", None)
        self.expect_operand, self.at_start = True, True

    def finish(self) -> Node:
        """The tree, once every token is in: the pending operators reduced."""
        if self.expect_operand:
            # "f()" leaves a call with no argument: allowed only right after "("
            raise ExpressionError("expression ends too early")
        while self.ops:
            if self.ops[-1][0] in ("(", "call"):
                raise ExpressionError("missing ')'")
            self.reduce_top()
        if len(self.out) != 1:
            raise ExpressionError("malformed expression")
        return self.out[0]


def parse(text: str) -> Expression:
    """Parse an expression into a tree (no recursion, linear time).

    Parameters
    ----------
    text : str
        The expression without braces, e.g. ``"1/(2*pi*f0*C1)"``.

    Returns
    -------
    Expression

    Raises
    ------
    ExpressionError
        On a syntax error.
    """
    tokens = _tokenize(text)
    if not tokens:
        raise ExpressionError("empty expression")
    yard = _ShuntingYard()
    for kind, value in tokens:
        if yard.expect_operand:
            yard.operand(kind, value)
        else:
            yard.operator(kind, value)
    tree = yard.finish()
    return Expression(text, tree, frozenset(yard.names), yard.refs)


@dataclass(frozen=True, slots=True)
class Linear:
    """An affine form ``const + Σ coeff·x`` in node voltages and branch currents.

    Keys of ``terms`` are ``("v", node)`` or ``("i", element)``.
    """

    const: float
    terms: tuple[tuple[tuple[str, str], float], ...] = ()

    @property
    def is_constant(self) -> bool:
        """True when no voltage or current term is left."""
        return not self.terms

    def scaled(self, k: float) -> Linear:
        """``k`` times this form."""
        return Linear(self.const * k, tuple((key, c * k) for key, c in self.terms))

    def plus(self, other: Linear, sign: float = 1.0) -> Linear:
        """This form plus ``sign`` times ``other``, like terms merged."""
        merged = dict(self.terms)
        for key, c in other.terms:
            merged[key] = merged.get(key, 0.0) + sign * c
        return Linear(self.const + sign * other.const, tuple((k, c) for k, c in merged.items() if c != 0))


def logic(op: str, a: float, b: float) -> float:
    """A comparison or logical operator (``==``, ``<``, ``&&``...): 1.0 or 0.0."""
    return float(
        {
            "==": a == b,
            "!=": a != b,
            "<": a < b,
            ">": a > b,
            "<=": a <= b,
            ">=": a >= b,
            "&&": bool(a) and bool(b),
            "||": bool(a) or bool(b),
        }[op]
    )


class Hooks(Generic[T]):
    """What :func:`walk` does at each kind of node; subclasses give the arithmetic.

    Every method receives the values of the node's children, already
    computed, and returns the node's value. The default :meth:`choose` walks
    both branches of ``c ? a : b`` and hands them to :meth:`ternary`.
    """

    def number(self, value: float) -> T:
        """A numeric literal."""
        raise NotImplementedError

    def name(self, name: str) -> T:
        """A bare name (parameter, constant, ``time``)."""
        raise NotImplementedError

    def ref(self, kind: str, args: tuple[str, ...]) -> T:
        """``v(a)``, ``v(a,b)`` (kind ``"v"``) or ``i(X)`` (kind ``"i"``)."""
        raise NotImplementedError

    def unary(self, op: str, x: T) -> T:
        """``op`` is ``"neg"``, ``"pos"`` or ``"not"``."""
        raise NotImplementedError

    def binary(self, op: str, a: T, b: T) -> T:
        """An infix operator (``+``, ``**``, ``&&``...)."""
        raise NotImplementedError

    def choose(self, cond: T) -> bool | None:
        """The branch of ``c ? a : b`` to walk (True: ``a``), or None for both."""
        return None

    def ternary(self, cond: T, a: T, b: T) -> T:
        """``c ? a : b`` when :meth:`choose` asked for both branches."""
        raise NotImplementedError

    def call(self, name: str, args: list[T]) -> T:
        """A function call with its evaluated arguments."""
        raise NotImplementedError


def walk(tree: Node, hooks: Hooks[T]) -> T:
    """Evaluate a parsed tree bottom-up with ``hooks``, on an explicit stack (no recursion).

    Parameters
    ----------
    tree : tuple
        :attr:`Expression.tree`.
    hooks : Hooks
        The arithmetic: floats, affine forms, values with gradients, text...

    Returns
    -------
    object
        The value ``hooks`` computes for the root.
    """
    # state 0: children not yet walked; 1: children on `values`; 2: both branches of a ternary.
    stack: list[tuple[Node, int]] = [(tree, 0)]
    values: list[T] = []
    while stack:
        node, state = stack.pop()
        tag = node[0]
        if tag == "num":
            values.append(hooks.number(float(node[1])))
        elif tag == "name":
            values.append(hooks.name(str(node[1])))
        elif tag == "ref":
            values.append(hooks.ref(str(node[1]), tuple(node[2])))
        elif tag in ("neg", "pos", "not"):
            if state == 0:
                stack.append((node, 1))
                stack.append((node[1], 0))
            else:
                values.append(hooks.unary(tag, values.pop()))
        elif tag == "bin":
            if state == 0:
                stack.append((node, 1))
                stack.append((node[3], 0))
                stack.append((node[2], 0))
            else:
                b = values.pop()
                a = values.pop()
                values.append(hooks.binary(str(node[1]), a, b))
        elif tag == "tern":
            if state == 0:
                stack.append((node, 1))
                stack.append((node[1], 0))
            elif state == 1:
                pick = hooks.choose(values[-1])
                if pick is None:
                    stack.append((node, 2))
                    stack.append((node[3], 0))
                    stack.append((node[2], 0))
                else:
                    values.pop()
                    stack.append((node[2] if pick else node[3], 0))
            else:
                b = values.pop()
                a = values.pop()
                values.append(hooks.ternary(values.pop(), a, b))
        elif tag == "call":
            if state == 0:
                stack.append((node, 1))
                for arg in reversed(node[2]):
                    stack.append((arg, 0))
            else:
                count = len(node[2])
                args = values[len(values) - count :]
                del values[len(values) - count :]
                values.append(hooks.call(str(node[1]), args))
        else:  # pragma: no cover - the parser makes no other node
            raise ExpressionError(f"bad node {tag}")
    return values.pop()


class _Evaluator(Hooks[float | Linear]):
    """Arithmetic over floats or :class:`Linear` values (``.param`` values, linear B sources)."""

    def __init__(
        self,
        params: Mapping[str, float],
        functions: Mapping[str, tuple[tuple[str, ...], Expression]],
        depth: int = 0,
        work: _Work | None = None,
    ) -> None:
        self.params = params
        self.functions = functions
        self.depth = depth
        self.work = work if work is not None else _Work()

    def run(self, tree: Node) -> float | Linear:
        result = walk(tree, self)
        if isinstance(result, Linear):
            if result.is_constant:
                result = result.const
            else:
                return result
        if not math.isfinite(result):
            raise ExpressionError(f"the value is not finite ({result})")
        return result

    def number(self, value: float) -> float:
        return value

    def name(self, name: str) -> float:
        return self.lookup(name)

    def ref(self, kind: str, args: tuple[str, ...]) -> Linear:
        if kind == "v":
            form = Linear(0.0, ((("v", args[0]), 1.0),))
            if len(args) == 2:
                form = form.plus(Linear(0.0, ((("v", args[1]), 1.0),)), -1.0)
            return _normal_ground(form)
        return Linear(0.0, ((("i", args[0]), 1.0),))

    def unary(self, op: str, x: float | Linear) -> float | Linear:
        if op == "neg":
            return x.scaled(-1.0) if isinstance(x, Linear) else -x
        if op == "pos":
            return x
        return float(not self.number_of(x, "'!'"))

    def choose(self, cond: float | Linear) -> bool:
        return bool(self.number_of(cond, "a condition '? :'"))

    def lookup(self, name: str) -> float:
        if name in self.params:
            return float(self.params[name])
        if name in CONSTANTS:
            return CONSTANTS[name]
        if name in ("time", "temper", "hertz", "freq"):
            raise NonlinearError(f"'{name}' (a time- or analysis-dependent value)")
        raise ExpressionError(f"unknown parameter {name!r}")

    @staticmethod
    def number_of(x: float | Linear, what: str) -> float:
        if isinstance(x, Linear):
            if not x.is_constant:
                raise NonlinearError(f"{what} of a node voltage or branch current")
            return x.const
        return x

    def binary(self, op: str, a: float | Linear, b: float | Linear) -> float | Linear:
        if isinstance(a, Linear) or isinstance(b, Linear):
            la = a if isinstance(a, Linear) else Linear(a)
            lb = b if isinstance(b, Linear) else Linear(b)
            if op in ("+", "-"):
                return la.plus(lb, 1.0 if op == "+" else -1.0)
            if op == "*":
                if la.is_constant:
                    return lb.scaled(la.const)
                if lb.is_constant:
                    return la.scaled(lb.const)
                raise NonlinearError("a product of node voltages or branch currents")
            if op == "/" and lb.is_constant:
                if lb.const == 0:
                    raise ExpressionError("division by zero")
                return la.scaled(1.0 / lb.const)
            if la.is_constant and lb.is_constant:
                a, b = la.const, lb.const
            else:
                raise NonlinearError(f"operator '{op}' on a node voltage or branch current")
        a, b = float(a), float(b)
        try:
            if op == "+":
                return a + b
            if op == "-":
                return a - b
            if op == "*":
                return a * b
            if op == "/":
                if b == 0:
                    raise ExpressionError("division by zero")
                return a / b
            if op == "%":
                if b == 0:
                    raise ExpressionError("modulo by zero")
                return math.fmod(a, b)
            if op in ("**", "^"):
                return _pwr(a, b)
        except OverflowError:
            raise ExpressionError(f"overflow in {a:g} {op} {b:g}") from None
        return logic(op, a, b)

    def call(self, name: str, args: list[float | Linear]) -> float | Linear:
        if name in self.functions:
            formals, body = self.functions[name]
            if len(formals) != len(args):
                raise ExpressionError(f"{name} takes {len(formals)} arguments, got {len(args)}")
            if self.depth >= MAX_CALL_DEPTH:
                raise ExpressionError(f".func {name} calls itself (or nests deeper than {MAX_CALL_DEPTH})")
            if any(isinstance(a, Linear) and not a.is_constant for a in args):
                raise NonlinearError(f".func {name} applied to a node voltage or branch current")
            self.work.spend(len(body.text) + 1, name)
            local = dict(self.params)
            local.update({f: self.number_of(a, name) for f, a in zip(formals, args, strict=True)})
            return _Evaluator(local, self.functions, self.depth + 1, self.work).run(body.tree)
        if name in BEHAVIOURAL_ONLY:  # the B-source reading (a NonlinearError sends it there)
            raise NonlinearError(f"{name}() is a B-source function (ngspice reads it only in B sources)")
        if name not in FUNCTIONS:
            if name in ("agauss", "gauss", "aunif", "unif", "limit", "rand", "sunif", "sgauss"):
                raise ExpressionError(f"random function {name}() is not supported (Monte Carlo)")
            raise ExpressionError(f"unknown function {name!r}")
        func, least, most = FUNCTIONS[name]
        if not least <= len(args) <= most:
            want = str(least) if least == most else f"{least} to {most}"
            extra = " (ngspice 39 silently uses the last of two)" if name == "log" and len(args) == 2 else ""
            raise ExpressionError(f"{name} takes {want} argument(s), got {len(args)}{extra}")
        numbers = [self.number_of(a, f"{name}()") for a in args]
        try:
            result = float(func(*numbers))
        except (ValueError, OverflowError, TypeError) as exc:
            raise ExpressionError(f"{name}({', '.join(f'{x:g}' for x in numbers)}): {exc}") from None
        return result


def _normal_ground(form: Linear) -> Linear:
    return Linear(form.const, tuple((k, c) for k, c in form.terms if k[1] not in ("0", "gnd")))


def evaluate(
    text: str | Expression,
    params: Mapping[str, float],
    functions: Mapping[str, tuple[tuple[str, ...], Expression]] | None = None,
) -> float:
    """Evaluate an arithmetic expression over named parameters.

    Parameters
    ----------
    text : str or Expression
        The expression without braces, e.g. ``"1/(2*pi*f0*C1)"``.
    params : Mapping[str, float]
        Parameter values by lower-case name.
    functions : Mapping, optional
        User functions (``.func``): name → (argument names, body).

    Returns
    -------
    float
        The value (finite).

    Raises
    ------
    ExpressionError
        On syntax errors, unknown names, arithmetic errors, a non-finite
        result, or a reference to a node voltage or branch current.
    """
    expr = text if isinstance(text, Expression) else parse(text)
    result = _Evaluator(params, functions or {}).run(expr.tree)
    if isinstance(result, Linear):
        raise ExpressionError(
            "v() and i() make a value depend on the circuit's solution (a nonlinear element); "
            "they are read only in B sources and E/G value=, vol=, cur="
        )
    return result


def linear_form(
    text: str | Expression,
    params: Mapping[str, float],
    functions: Mapping[str, tuple[tuple[str, ...], Expression]] | None = None,
) -> Linear:
    """An expression in ``v(...)`` and ``i(...)`` as an affine form.

    The coefficients are the expression's derivatives with respect to each
    node voltage and branch current (exact: only linear operations are
    accepted).

    Raises
    ------
    NonlinearError
        Naming the first operation that is not linear.
    ExpressionError
        On any other error.
    """
    expr = text if isinstance(text, Expression) else parse(text)
    result = _Evaluator(params, functions or {}).run(expr.tree)
    return result if isinstance(result, Linear) else Linear(result)
