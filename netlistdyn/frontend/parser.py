"""Netlist text → :class:`~netlistdyn.circuit.netlist.Netlist`, read as ngspice 39 reads it.

SPICE conventions: the first line is the title; ``*`` starts a comment line;
``;`` (and ``$`` after white space) starts an inline comment; ``+`` continues
the previous line; names are case-insensitive; ``0`` and ``gnd`` are ground;
``.end`` ends the netlist. Fields are separated by white space, commas,
``=`` and parentheses, except inside ``{...}`` or ``'...'`` expressions. Only
``\\n``, ``\\r\\n`` and ``\\r`` end a line. Files are UTF-8, or Latin-1/cp1252
(LTspice exports) when they are not valid UTF-8.

Stages, none recursive in the size of the input:

1. :func:`read_lines` reads logical lines, following ``.include`` and
   ``.lib file section`` with an explicit stack.
2. ``.if/.elseif/.else/.endif`` blocks are resolved, ``.subckt`` blocks split
   off, ``.param`` definitions evaluated (ngspice semantics: the last
   definition of a name wins everywhere, evaluated in dependency order).
3. The expansion size of the subcircuit hierarchy is counted before anything
   is expanded (refused above ``max_elements``), then the elements are built.
"""

from __future__ import annotations

import math
import os
import re
from collections import ChainMap
from collections.abc import Iterable, Mapping, MutableMapping
from dataclasses import dataclass, field, replace
from pathlib import Path

from netlistdyn.base.errors import NetlistError, SourceLocation, UsageError
from netlistdyn.base.values import read_number
from netlistdyn.circuit.checks import check_netlist
from netlistdyn.circuit.expressions import (
    Expression,
    ExpressionError,
    evaluate,
    parse,
)
from netlistdyn.circuit.netlist import (
    GROUND,
    STORAGE_KINDS,
    Diagnostic,
    Element,
    InitialCondition,
    Kind,
    Netlist,
    StepSpec,
    TranSpec,
)
from netlistdyn.circuit.waveforms import Waveform, scaled
from netlistdyn.devices.cards import CardLine, canonical_node, is_expr, short, unwrap
from netlistdyn.devices.mechanics import KEYWORDS, resolve_rods
from netlistdyn.devices.models import DISPLACEMENT, fold
from netlistdyn.devices.planar import PLANAR_KEYWORDS, PlanarCard, build_planar
from netlistdyn.devices.registry import REGISTRY, Registry
from netlistdyn.frontend.lines import Line, read_lines, read_source, split_fields
from netlistdyn.frontend.sources import parse_source, waveform_parens_only

#: Default limit on the number of elements after subcircuit expansion; raise it
#: with ``parse_text/parse_file(..., max_elements=N)`` or the environment
#: variable ``NETLISTDYN_MAX_ELEMENTS``.
MAX_ELEMENTS = 1_000_000
MAX_ELEMENTS_VARIABLE = "NETLISTDYN_MAX_ELEMENTS"
#: Deepest subcircuit instance nesting accepted.
MAX_SUBCIRCUIT_DEPTH = 100


# Directives that do not change the model: accepted with a warning.
IGNORED_DIRECTIVES = frozenset(
    {
        ".print",
        ".plot",
        ".op",
        ".ac",
        ".dc",
        ".save",
        ".probe",
        ".meas",
        ".measure",
        ".width",
        ".four",
        ".fourier",
        ".noise",
        ".disto",
        ".sens",
        ".tf",
        ".nodeset",
        ".csparam",
        ".pz",
        ".sp",
        ".pss",
        ".title",
    }
)
NONLINEAR_DEVICES = {
    "d": "a diode",
    "q": "a bipolar transistor",
    "m": "a MOSFET",
    "j": "a JFET",
    "z": "a MESFET",
    "s": "a voltage-controlled switch",
    "w": "a current-controlled switch",
    "a": "an XSPICE code model",
    "n": "a numerical (OSDI/Verilog-A) device",
}
#: Letters of the transistors (ngspice's BJT, MOSFET, JFET, MESFET).
TRANSISTORS = frozenset("qmjz")
OTHER_UNSUPPORTED = {
    "t": "transmission line",
    "o": "lossy transmission line",
    "u": "distributed RC line",
    "y": "lossy transmission line",
    "p": "coupled transmission line",
}

# --------------------------------------------------------------------------------------------
# Reading files


# --------------------------------------------------------------------------------------------
# Fields


def _fields(line: CardLine, keep_parens: bool = False) -> list[str]:
    try:
        return split_fields(line.text, keep_parens)
    except ValueError as exc:
        name = line.text.split()[0]
        raise NetlistError(f"{name}: {exc} (ngspice refuses it too)", line.loc) from None


# --------------------------------------------------------------------------------------------
# Parameters

_EQ_SCAN = re.compile(r"==|!=|<=|>=|[{}()'=]")
_LAST_IDENT = re.compile(r"([A-Za-z_][A-Za-z0-9_.]*)\s*$")


def param_assignments(text: str, loc: SourceLocation, what: str = ".param") -> list[tuple[str, str]]:
    """``name=value`` pairs of a ``.param`` line (or ``params:`` list), in linear time.

    A value may be a bare expression with spaces (``.param x = 2*a + 1``);
    an ``=`` inside braces, quotes, parentheses or a comparison does not
    start a new assignment.
    """
    equals: list[int] = []
    depth = 0
    quoted = False
    for match in _EQ_SCAN.finditer(text):
        token = match.group(0)
        if token == "'":
            quoted = not quoted
        elif quoted:
            continue
        elif token in "{(":
            depth += 1
        elif token in "})":
            depth -= 1
        elif token == "=" and depth == 0:
            equals.append(match.start())
    if not equals:
        raise NetlistError(f"{what}: expected name=value, got {text.strip()!r}", loc)
    out: list[tuple[str, str]] = []
    names: list[tuple[str, int, int]] = []  # name, start of name, end of "="
    prev = 0
    for pos in equals:
        segment = text[prev:pos]
        found = _LAST_IDENT.search(segment)
        if found is None:
            raise NetlistError(f"{what}: expected a name before '=' in {text.strip()!r}", loc)
        names.append((found.group(1), prev + found.start(), pos + 1))
        prev = pos + 1
    if text[: names[0][1]].strip():
        raise NetlistError(f"{what}: unexpected {text[: names[0][1]].strip()!r}", loc)
    for k, (name, _, value_start) in enumerate(names):
        value_end = names[k + 1][1] if k + 1 < len(names) else len(text)
        expr = text[value_start:value_end].strip().rstrip(",").strip()
        if not expr:
            raise NetlistError(f"{what} {name}: missing value", loc)
        out.append((name, expr))
    return out


@dataclass(frozen=True, slots=True)
class _Definition:
    name: str  # as written
    expr: str
    loc: SourceLocation


_Functions = dict[str, tuple[tuple[str, ...], Expression]]
_NUMBER_START = frozenset("0123456789.+-")


def _chain(first: MutableMapping[str, float], *rest: Mapping[str, float]) -> Mapping[str, float]:
    """Look-ups in ``first``, then in each of ``rest``: a ChainMap, which writes only to ``first``."""
    # typeshed asks every map of a ChainMap to be mutable; only the first is ever written
    return ChainMap(first, *rest)  # type: ignore[arg-type]


def _value_expression(expr: str) -> str:
    return unwrap(expr.strip())


def evaluate_definitions(
    definitions: Iterable[_Definition],
    scope: Mapping[str, float],
    functions: _Functions,
    warnings: list[Diagnostic] | None,
    fixed: Mapping[str, float] | None = None,
) -> dict[str, float]:
    """Evaluate parameter definitions as ngspice 39 does.

    The last definition of a name (case-insensitive) wins, also in
    expressions written before it; definitions are evaluated in dependency
    order (iteratively). A redefinition is warned about.

    Parameters
    ----------
    definitions : iterable of _Definition
        In file order.
    scope : Mapping[str, float]
        Enclosing parameter values (globals, or an instance's caller).
    functions : dict
        ``.func`` definitions.
    warnings : list of Diagnostic, optional
        Receives redefinition warnings.
    fixed : Mapping[str, float], optional
        Values that replace a definition (command-line overrides, instance
        parameters).

    Returns
    -------
    dict
        The new parameter values by lower-case name.
    """
    final: dict[str, _Definition] = {}
    for definition in definitions:
        key = definition.name.lower()
        previous = final.get(key)
        if previous is not None and warnings is not None:
            same = "" if previous.name == definition.name else f" (as {previous.name})"
            warnings.append(
                Diagnostic(
                    definition.loc,
                    f"parameter {definition.name} is defined again (first{same} at {previous.loc}); "
                    "names are case-insensitive, and as in ngspice the last definition is used everywhere",
                )
            )
        final[key] = definition
    fixed = fixed or {}
    values: dict[str, float] = {k: v for k, v in fixed.items() if k in final}
    parsed: dict[str, Expression] = {}
    for key, definition in final.items():
        if key in values:
            continue
        text = _value_expression(definition.expr)
        if text[:1] in _NUMBER_START:  # a plain number: no expression to parse
            reading = read_number(text)
            if reading is not None and math.isfinite(reading.value) and not reading.note:
                values[key] = reading.value
                continue
        try:
            parsed[key] = parse(text)
        except ExpressionError as exc:
            raise NetlistError(f".param {definition.name}: {exc}", definition.loc) from None
    chain: Mapping[str, float] = _chain(values, scope) if scope else values
    state: dict[str, int] = {}  # 1: in progress, 2: done
    for root in parsed:
        if root in values:
            continue
        stack = [root]
        while stack:
            key = stack[-1]
            if key in values:
                stack.pop()
                continue
            if state.get(key) == 1:
                # all dependencies done: evaluate
                definition = final[key]
                try:
                    values[key] = evaluate(parsed[key], chain, functions)
                except ExpressionError as exc:
                    raise NetlistError(f".param {definition.name}: {exc}", definition.loc) from None
                state[key] = 2
                stack.pop()
                continue
            state[key] = 1
            for dep in parsed[key].names:
                if dep in parsed and dep not in values:
                    if state.get(dep) == 1:
                        raise NetlistError(
                            f".param {final[dep].name}: defined in terms of itself (via {final[key].name})",
                            final[dep].loc,
                        )
                    stack.append(dep)
    return values


def evaluate_params(lines: list[Line], overrides: Mapping[str, float]) -> dict[str, float]:
    """Evaluate every top-level ``.param`` (see :func:`evaluate_definitions`), applying overrides.

    Raises
    ------
    UsageError
        An override names a parameter the netlist does not define.
    """
    definitions = [
        _Definition(name, expr, line.loc)
        for line in lines
        if line.text.split()[0].lower() == ".param"
        for name, expr in _param_line(line)
    ]
    lowered = {k.lower(): v for k, v in overrides.items()}
    defined = {d.name.lower() for d in definitions}
    missing = sorted(set(lowered) - defined)
    if missing:
        raise UsageError(f"--param {missing[0]}: the netlist defines no .param {missing[0]}")
    return evaluate_definitions(definitions, {}, {}, None, lowered)


def _param_line(line: Line) -> list[tuple[str, str]]:
    parts = line.text.split(None, 1)
    if len(parts) < 2:
        raise NetlistError(".param needs name=value", line.loc)
    _check_closed(line)
    return param_assignments(parts[1], line.loc)


def _check_closed(line: Line) -> None:
    _fields(line)


# --------------------------------------------------------------------------------------------
# Values


class _Values:
    """Evaluates value fields against a parameter scope."""

    def __init__(
        self, params: Mapping[str, float], functions: _Functions, warnings: list[Diagnostic]
    ) -> None:
        self.params = params
        self.functions = functions
        self.warnings = warnings

    def scoped(self, params: Mapping[str, float]) -> _Values:
        return _Values(params, self.functions, self.warnings)

    def number(self, token: str, loc: SourceLocation, what: str) -> float:
        if is_expr(token):
            try:
                value = evaluate(unwrap(token), self.params, self.functions)
            except ExpressionError as exc:
                raise NetlistError(f"{what}: {exc}", loc) from None
        else:
            reading = read_number(token)
            if reading is None:
                low = token.lower()
                if low in self.params:  # ngspice 39 accepts a bare parameter name as a value
                    return self.params[low]
                raise NetlistError(f"{what}: expected a number, got {short(token)!r}", loc)
            if reading.note:
                self.warnings.append(Diagnostic(loc, f"{what}: {reading.note}"))
            value = reading.value
        if not math.isfinite(value):
            raise NetlistError(f"{what}: value is not finite ({short(token)} is out of range)", loc)
        return value

    def is_value(self, token: str) -> bool:
        return is_expr(token) or read_number(token) is not None or token.lower() in self.params


# --------------------------------------------------------------------------------------------
# Element lines


@dataclass
class _Context:
    """What element builders need besides the line (:class:`~netlistdyn.devices.cards.CardContext`)."""

    values: _Values
    warnings: list[Diagnostic]
    models: dict[str, tuple[str, dict[str, str], SourceLocation]]
    temp: float | None
    tran: TranSpec | None
    tnom: float = 27.0
    devices: Registry = REGISTRY

    def fields(self, line: CardLine, keep_parens: bool = False) -> list[str]:
        return _fields(line, keep_parens)

    def split(self, text: str) -> list[str]:
        return split_fields(text)

    def source(
        self, fields: list[str], loc: SourceLocation, name: str
    ) -> tuple[float, Waveform | None, float | None]:
        return parse_source(waveform_parens_only(fields), loc, self, name)


def _build_element(line: Line, ctx: _Context) -> list[Element]:
    """The elements of one element line, from the builder its device family registered."""
    word = line.text.split(None, 1)[0]
    letter = word[0].lower()
    loc = line.loc
    name = word
    build = ctx.devices.card(word)
    if build is not None:
        return build(line, ctx)
    what = NONLINEAR_DEVICES.get(letter)
    if what and letter in TRANSISTORS:
        raise NetlistError(f"{name}: {what}: transistors are not supported yet", loc)
    if what:
        raise NetlistError(
            f"{name}: {what} is not supported (netlistdyn compiles linear elements, diodes and "
            "behavioural sources)",
            loc,
        )
    other = OTHER_UNSUPPORTED.get(letter)
    if other:
        raise NetlistError(f"{name}: {other} elements are not supported (lumped elements only)", loc)
    raise NetlistError(f"{name}: unknown element type {name[0]!r}", loc)


# --------------------------------------------------------------------------------------------
# Directives


def _parse_tran(line: Line, values: _Values, warnings: list[Diagnostic]) -> TranSpec:
    spec = _parse_tran_times(line, values, warnings)
    uic = any(f.lower() == "uic" for f in _fields(line)[1:])
    return replace(spec, uic=True) if uic else spec


def _parse_tran_times(line: Line, values: _Values, warnings: list[Diagnostic]) -> TranSpec:
    fields = [f for f in _fields(line)[1:] if f.lower() not in ("uic", "startup")]
    nums = [values.number(f, line.loc, ".tran") for f in fields[:4]]
    if not nums:
        raise NetlistError(".tran needs TSTEP TSTOP", line.loc)
    if len(nums) == 1 or nums[0] == 0:
        # LTspice: ".tran TSTOP" and ".tran 0 TSTOP ..." (ngspice 39 refuses both).
        tstop = nums[0] if len(nums) == 1 else nums[1]
        if tstop <= 0:
            raise NetlistError(".tran: TSTOP must be positive", line.loc)
        tstep = tstop / 50
        warnings.append(
            Diagnostic(line.loc, f".tran in LTspice form (no TSTEP): TSTEP taken as TSTOP/50 = {tstep:g} s")
        )
        rest = nums[2:] if len(nums) > 1 else []
        return TranSpec(tstep, tstop, rest[0] if rest else 0.0, rest[1] if len(rest) > 1 else None, line.loc)
    if nums[0] <= 0 or nums[1] <= 0:
        raise NetlistError(".tran: TSTEP and TSTOP must be positive", line.loc)
    return TranSpec(
        nums[0], nums[1], nums[2] if len(nums) > 2 else 0.0, nums[3] if len(nums) > 3 else None, line.loc
    )


def _parse_func(line: Line) -> tuple[str, tuple[str, ...], Expression]:
    match = re.match(r"(?is)\.func\s+([A-Za-z_][\w]*)\s*\(([^)]*)\)\s*=?\s*(.+)$", line.text)
    if match is None:
        raise NetlistError(".func: expected .func name(args) = {expression}", line.loc)
    formals = tuple(a.strip().lower() for a in match.group(2).split(",") if a.strip())
    twice = next((a for k, a in enumerate(formals) if a in formals[:k]), None)
    if twice is not None:  # ngspice 39 silently takes the first; a guess either way
        raise NetlistError(f".func {match.group(1)}: parameter {twice!r} is named twice", line.loc)
    try:
        body = parse(unwrap(match.group(3).strip()))
    except ExpressionError as exc:
        raise NetlistError(f".func {match.group(1)}: {exc}", line.loc) from None
    return match.group(1).lower(), formals, body


def _parse_model(line: Line) -> tuple[str, str, dict[str, str]]:
    fields = _fields(line)
    if len(fields) < 3:
        raise NetlistError(".model needs a name and a type", line.loc)
    params: dict[str, str] = {}
    rest = fields[3:]
    i = 0
    while i < len(rest):
        if i + 2 < len(rest) + 1 and i + 1 < len(rest) and rest[i + 1] == "=":
            params[rest[i].lower()] = rest[i + 2] if i + 2 < len(rest) else ""
            i += 3
        else:
            params[rest[i].lower()] = "1"
            i += 1
    return fields[1].lower(), fields[2].lower(), params


def _parse_step(line: Line, values: _Values) -> StepSpec:
    fields = _fields(line)[1:]
    words = [f.lower() for f in fields]
    mode = "lin"
    if words and words[0] in ("lin", "dec", "oct"):
        mode = words.pop(0)
        fields = fields[1:]
    if not words or words[0] != "param" or len(fields) < 3:
        raise NetlistError(".step: only '.step [lin|dec|oct] param NAME ...' is supported", line.loc)
    pname = fields[1].lower()
    rest = fields[2:]
    if rest[0].lower() == "list":
        items = tuple(values.number(f, line.loc, ".step") for f in rest[1:])
        if not items:
            raise NetlistError(".step list needs values", line.loc)
        return StepSpec(pname, items, line.loc)
    if len(rest) != 3:
        raise NetlistError(".step param NAME START STOP STEP (or list v1 v2 ...)", line.loc)
    start, stop, step = (values.number(f, line.loc, ".step") for f in rest)
    if mode == "lin":
        if step == 0 or (stop - start) / step < 0:
            raise NetlistError(".step: the step does not go from START to STOP", line.loc)
        count = math.floor((stop - start) / step + 1e-9) + 1
        if count > 100_000:
            raise NetlistError(f".step: {count} values (more than 100000)", line.loc)
        return StepSpec(pname, tuple(start + k * step for k in range(count)), line.loc)
    if start <= 0 or stop <= 0 or step <= 0:
        raise NetlistError(f".step {mode}: START, STOP and points must be positive", line.loc)
    per = int(step)
    base = 10.0 if mode == "dec" else 2.0
    count = math.floor(math.log(stop / start, base) * per + 1e-9) + 1
    if count > 100_000:
        raise NetlistError(f".step: {count} values (more than 100000)", line.loc)
    return StepSpec(pname, tuple(start * base ** (k / per) for k in range(count)), line.loc)


def _parse_ic(line: Line, values: _Values) -> list[InitialCondition]:
    fields = _fields(line)[1:]
    out: list[InitialCondition] = []
    i = 0
    while i < len(fields):
        if fields[i].lower() == "v" and i + 3 < len(fields) and fields[i + 2] == "=":
            node = canonical_node(fields[i + 1])
            out.append(InitialCondition(node, values.number(fields[i + 3], line.loc, ".ic"), line.loc))
            i += 4
            continue
        raise NetlistError(f".ic: expected v(node)=value, got {fields[i]!r}", line.loc)
    return out


def _resolve_conditionals(
    lines: list[Line], params: Mapping[str, float], functions: _Functions
) -> list[Line]:
    """Keep the lines of the taken branches of ``.if/.elseif/.else/.endif``."""
    if not any(line.text[:3].lower() == ".if" for line in lines):
        return lines
    out: list[Line] = []
    # stack entries: [parent_active, this_branch_active, some_branch_taken, loc, else_seen]
    stack: list[list[object]] = []
    active = True
    for line in lines:
        words = line.text.split(None, 1)
        word = words[0].lower()
        if word in (".if", ".elseif"):
            cond_text = words[1].strip() if len(words) > 1 else ""
            if word == ".if":
                stack.append([active, False, False, line.loc, False])
            elif not stack:
                raise NetlistError(".elseif without .if", line.loc)
            frame = stack[-1]
            if frame[4]:
                raise NetlistError(f".elseif after the .else of the .if at {frame[3]}", line.loc)
            parent = bool(frame[0])
            if frame[2] or not parent:
                frame[1] = False
            else:
                try:
                    taken = bool(
                        evaluate(
                            unwrap(cond_text.strip("()").strip()) if cond_text else "", params, functions
                        )
                    )
                except ExpressionError as exc:
                    raise NetlistError(f"{word}: {exc}", line.loc) from None
                frame[1] = taken
                frame[2] = taken
            active = bool(frame[1])
            continue
        if word == ".else":
            if not stack:
                raise NetlistError(".else without .if", line.loc)
            frame = stack[-1]
            if frame[4]:
                raise NetlistError(f"a second .else in the .if at {frame[3]}", line.loc)
            frame[4] = True
            frame[1] = bool(frame[0]) and not frame[2]
            frame[2] = True
            active = bool(frame[1])
            continue
        if word == ".endif":
            if not stack:
                raise NetlistError(".endif without .if", line.loc)
            frame = stack.pop()
            active = bool(frame[0])
            continue
        if active:
            out.append(line)
    if stack:
        raise NetlistError(".if without .endif", stack[-1][3])  # type: ignore[arg-type]
    return out


# --------------------------------------------------------------------------------------------
# Subcircuits


@dataclass
class Subcircuit:
    """A ``.subckt name ports... [params: p=v ...]`` definition with its nested definitions."""

    name: str
    ports: tuple[str, ...]
    defaults: tuple[_Definition, ...]
    body: list[Line]
    definitions: dict[str, Subcircuit]
    loc: SourceLocation
    parent: Subcircuit | None = None
    count: int | None = field(default=None, repr=False)


def _subckt_header(line: Line) -> tuple[str, tuple[str, ...], tuple[_Definition, ...]]:
    fields = _fields(line)
    if len(fields) < 2:
        raise NetlistError(".subckt needs a name", line.loc)
    name = fields[1]
    ports: list[str] = []
    i = 2
    while (
        i < len(fields)
        and fields[i].lower() != "params:"
        and not (i + 1 < len(fields) and fields[i + 1] == "=")
    ):
        ports.append(canonical_node(fields[i]))
        i += 1
    defaults: tuple[_Definition, ...] = ()
    if i < len(fields):
        match = re.search(r"(?i)\bparams:", line.text)
        # "params:" list, or the HSPICE form: from the first "name=" after the ports
        tail = line.text[match.end() :] if match is not None else _tail_from(line, fields[i])
        defaults = tuple(
            _Definition(n, e, line.loc) for n, e in param_assignments(tail, line.loc, f".subckt {name}")
        )
    return name, tuple(ports), defaults


def _split_subcircuits(lines: list[Line]) -> tuple[list[Line], dict[str, Subcircuit]]:
    """Separate ``.subckt ... .ends`` blocks (nested ones scoped to their parent), iteratively."""
    top: list[Line] = []
    definitions: dict[str, Subcircuit] = {}
    stack: list[Subcircuit] = []
    for line in lines:
        word = line.text.split(None, 1)[0].lower()
        if word == ".subckt":
            name, ports, defaults = _subckt_header(line)
            parent = stack[-1] if stack else None
            sub = Subcircuit(name, ports, defaults, [], {}, line.loc, parent)
            scope = parent.definitions if parent else definitions
            key = name.lower()
            if key in scope:
                raise NetlistError(f".subckt {name}: defined twice (first at {scope[key].loc})", line.loc)
            scope[key] = sub
            stack.append(sub)
            continue
        if word == ".ends":
            if not stack:
                raise NetlistError(".ends without .subckt", line.loc)
            stack.pop()
            continue
        if stack:
            if word in (".tran", ".global", ".step", ".ic", ".end"):
                raise NetlistError(f"{word} inside .subckt {stack[-1].name} is not supported", line.loc)
            stack[-1].body.append(line)
        else:
            top.append(line)
    if stack:
        raise NetlistError(f".subckt {stack[-1].name}: no matching .ends", stack[-1].loc)
    return top, definitions


def _tail_from(line: Line, name: str) -> str:
    """The text of ``line`` from the first ``name=`` on (a parameter list)."""
    found = re.search(r"(?i)(?<![\w.])" + re.escape(name) + r"\s*=", line.text)
    if found is None:
        raise NetlistError(f"{line.text.split()[0]}: cannot read the parameter list at {name!r}", line.loc)
    return line.text[found.start() :]


def _instance_target(line: Line, fields: list[str]) -> tuple[list[str], str, str]:
    """Nodes, subcircuit name and the ``p=v`` text of an ``X`` line."""
    positional: list[str] = []
    i = 1
    while (
        i < len(fields)
        and fields[i].lower() != "params:"
        and not (i + 1 < len(fields) and fields[i + 1] == "=")
    ):
        positional.append(fields[i])
        i += 1
    if not positional:
        raise NetlistError(f"{fields[0]}: expected X name nodes... subcircuit", line.loc)
    tail = ""
    if i < len(fields):
        match = re.search(r"(?i)\bparams:", line.text)
        tail = line.text[match.end() :] if match is not None else _tail_from(line, fields[i])
    return positional[:-1], positional[-1], tail


def _lookup(
    scope_chain: Subcircuit | None, definitions: dict[str, Subcircuit], key: str
) -> Subcircuit | None:
    sub = scope_chain
    while sub is not None:
        if key in sub.definitions:
            return sub.definitions[key]
        sub = sub.parent
    return definitions.get(key)


def _count_elements(lines: list[Line], definitions: dict[str, Subcircuit], limit: int) -> int:
    """Number of element lines after full expansion, computed without expanding (iteratively)."""

    def instances(body: list[Line], owner: Subcircuit | None) -> tuple[int, list[tuple[Subcircuit, Line]]]:
        leaves = 0
        children: list[tuple[Subcircuit, Line]] = []
        for line in body:
            word = line.text.split(None, 1)[0].lower()
            if word.startswith("."):
                continue
            if word[0] == "x" and word not in KEYWORDS:
                fields = _fields(line)
                _, sub_name, _ = _instance_target(line, fields)
                sub = _lookup(owner, definitions, sub_name.lower())
                if sub is None:
                    raise NetlistError(f"{fields[0]}: unknown subcircuit {sub_name!r}", line.loc)
                children.append((sub, line))
            else:
                leaves += 1
        return leaves, children

    total, roots = instances(lines, None)
    for root, root_line in roots:
        if root.count is None:
            # iterative post-order over the definition graph
            stack: list[tuple[Subcircuit, Line, int, list[tuple[Subcircuit, Line]], int]] = []
            leaves, children = instances(root.body, root)
            stack.append((root, root_line, leaves, children, 0))
            on_path = {id(root)}
            while stack:
                sub, via, leaves, children, k = stack[-1]
                if k < len(children):
                    stack[-1] = (sub, via, leaves, children, k + 1)
                    child, child_line = children[k]
                    if child.count is not None:
                        continue
                    if id(child) in on_path:
                        raise NetlistError(
                            f"{child_line.text.split()[0]}: subcircuit {child.name} instantiates itself",
                            child_line.loc,
                        )
                    if len(stack) >= MAX_SUBCIRCUIT_DEPTH:
                        where = child_line.text.split()[0]
                        raise NetlistError(
                            f"{where}: subcircuits nested over {MAX_SUBCIRCUIT_DEPTH} levels deep",
                            child_line.loc,
                        )
                    c_leaves, c_children = instances(child.body, child)
                    stack.append((child, child_line, c_leaves, c_children, 0))
                    on_path.add(id(child))
                    continue
                count = leaves + sum(c.count or 0 for c, _ in children)
                sub.count = min(count, limit + 1)
                on_path.discard(id(sub))
                stack.pop()
        total += root.count or 0
        if total > limit:
            raise NetlistError(
                f"{root_line.text.split()[0]}: the subcircuits expand to more than {limit} elements "
                f"(set {MAX_ELEMENTS_VARIABLE} to raise the limit)",
                root_line.loc,
            )
    return total


@dataclass
class _Build:
    """State of one netlist's element building."""

    ctx: _Context
    definitions: dict[str, Subcircuit]
    globals_: frozenset[str]
    elements: list[Element] = field(default_factory=list)
    planar: list[PlanarCard] = field(default_factory=list)


def _expand_body(
    build: _Build,
    body: list[Line],
    values: _Values,
    owner: Subcircuit | None,
    prefix: str,
    port_map: dict[str, str],
    depth: int,
    multiplied: bool = False,
) -> None:
    """Build the elements of ``body``; ``multiplied``: an enclosing instance has M=."""
    ctx = replace(build.ctx, values=values)
    for line in body:
        word = line.text.split(None, 1)[0].lower()
        if word.startswith("."):
            continue
        if word[0] == "x" and word not in KEYWORDS:
            _expand_instance(build, line, values, owner, prefix, port_map, depth, multiplied)
            continue
        if multiplied and _OWN_MULTIPLIER.search(line.text):
            raise NetlistError(
                f"{line.text.split(None, 1)[0]}: m= on an element inside a subcircuit instance that has "
                "m= (ngspice 39 replaces the element's by the instance's): not supported",
                line.loc,
            )
        if word in PLANAR_KEYWORDS:
            build.planar.append(_build_planar(line, ctx, prefix))
            continue
        built = _build_element(line, ctx)
        if prefix:
            built = [_rename(e, prefix, port_map, build.globals_) for e in built]
        build.elements.extend(built)


def _expand_instance(
    build: _Build,
    line: Line,
    values: _Values,
    owner: Subcircuit | None,
    prefix: str,
    port_map: dict[str, str],
    depth: int,
    multiplied: bool = False,
) -> None:
    fields = _fields(line)
    name = fields[0]
    nodes, sub_name, tail = _instance_target(line, fields)
    sub = _lookup(owner, build.definitions, sub_name.lower())
    if sub is None:
        raise NetlistError(f"{name}: unknown subcircuit {sub_name!r}", line.loc)
    if depth >= MAX_SUBCIRCUIT_DEPTH:
        raise NetlistError(f"{name}: subcircuits nested deeper than {MAX_SUBCIRCUIT_DEPTH} levels", line.loc)
    if len(nodes) != len(sub.ports):
        raise NetlistError(
            f"{name}: subcircuit {sub.name} has {len(sub.ports)} ports, got {len(nodes)} nodes", line.loc
        )
    # Instance parameters (measured on ngspice 39): a value given on the X line replaces the
    # subcircuit's default *and* a body .param of that name; its expression may use the other
    # parameters of the instance (par3='par1+par2'), and otherwise the caller's scope. An
    # expression naming its own parameter (r={r*2}) means the caller's value.
    overrides: dict[str, float] = {}
    given: list[_Definition] = []
    multiplier, given_m = 1.0, False
    if tail:
        known = {d.name.lower() for d in sub.defaults}
        for pname, expr in param_assignments(tail, line.loc, name):
            key = pname.lower()
            if key == "m" and key not in known:  # ngspice's instance multiplier: m copies in parallel
                try:
                    multiplier = evaluate(parse(_value_expression(expr)), values.params, values.functions)
                except ExpressionError as exc:
                    raise NetlistError(f"{name} m: {exc}", line.loc) from None
                if not multiplier > 0:
                    raise NetlistError(f"{name}: m must be positive, got {multiplier:g}", line.loc)
                given_m = True
                continue
            if key not in known:
                raise NetlistError(f"{name}: subcircuit {sub.name} has no parameter {pname}", line.loc)
            text = _value_expression(expr)
            try:
                parsed = parse(text)
                if key in parsed.names:
                    overrides[key] = evaluate(parsed, values.params, values.functions)
                else:
                    given.append(_Definition(pname, expr, line.loc))
            except ExpressionError as exc:
                raise NetlistError(f"{name} {pname}: {exc}", line.loc) from None
    replaced = set(overrides) | {d.name.lower() for d in given}
    local_defs = (
        [d for d in sub.defaults if d.name.lower() not in replaced]
        + [
            _Definition(n, e, b.loc)
            for b in sub.body
            if b.text.split(None, 1)[0].lower() == ".param"
            for n, e in _param_line(b)
            if n.lower() not in replaced
        ]
        + given
    )
    scope: Mapping[str, float] = values.params
    if local_defs or overrides:
        base: Mapping[str, float] = _chain(overrides, values.params) if overrides else values.params
        local = evaluate_definitions(local_defs, base, values.functions, None)
        local.update(overrides)
        scope = _chain(local, values.params)
    outer = [_map_node(canonical_node(n), prefix, port_map, build.globals_) for n in nodes]
    inner_prefix = f"{prefix}.{name}" if prefix else name
    inner_ports = dict(zip(sub.ports, outer, strict=True))
    # ngspice 39 writes an instance's m= onto every line of its body, replacing theirs: the
    # outermost m= wins over the m= of instances (and elements) inside it (measured).
    applies = given_m and not multiplied
    first = len(build.elements)
    _expand_body(
        build,
        sub.body,
        values.scoped(scope),
        sub,
        inner_prefix,
        inner_ports,
        depth + 1,
        multiplied or given_m,
    )
    if applies and multiplier != 1.0:
        build.elements[first:] = [_multiplied(e, multiplier, name) for e in build.elements[first:]]


#: An element's own ``m=`` (or ``M =``) keyword on its line.
_OWN_MULTIPLIER = re.compile(r"(?i)(?<![\w.{(])m\s*=")
#: Element kinds an instance multiplier M= scales, as ngspice 39 does (measured: R and L divided,
#: C (also C={...}), G, F, I and the diode's area multiplied); V, E, H, B sources (and E/G
#: value=) and transformers are not scaled. A coupling K between multiplied inductors is not what
#: k·√(L1·L2/m²) gives (measured): refused.
_MULTIPLIED = {
    Kind.RESISTOR: -1,
    Kind.INDUCTOR: -1,
    Kind.CAPACITOR: 1,
    Kind.VCCS: 1,
    Kind.CCCS: 1,
    Kind.ISOURCE: 1,
}
_NOT_MULTIPLIED = frozenset(
    {Kind.VSOURCE, Kind.VCVS, Kind.CCVS, Kind.TRANSFORMER, Kind.BVOLTAGE, Kind.BCURRENT}
)


def _multiplied(element: Element, m: float, instance: str) -> Element:
    """``element`` of a subcircuit instance with ``M=m``: m copies in parallel, as ngspice 39 reads it."""
    kind = element.kind
    if element.keyword is not None:
        raise NetlistError(
            f"{instance}: m= on an instance holding the mechanical {element.label}", element.loc
        )
    if kind in _NOT_MULTIPLIED or (element.expression is not None and kind in _MULTIPLIED):
        return element  # behavioural terms (B, E/G value=) are not scaled by ngspice either
    if kind in _MULTIPLIED:
        value = element.value * m if _MULTIPLIED[kind] > 0 else element.value / m
        waveform = element.waveform
        if waveform is not None:
            waveform = scaled(waveform, m)
        return replace(element, value=value, waveform=waveform)
    if kind is Kind.DIODE:
        assert element.diode is not None
        return replace(
            element, value=element.value * m, diode=replace(element.diode, mult=element.diode.mult * m)
        )
    if kind is Kind.CAPACITANCE:
        return replace(element, expression=f"({m!r})*({element.expression})")
    raise NetlistError(
        f"{instance}: m= on a subcircuit instance holding {element.label} ({kind.name}) is not supported",
        element.loc,
    )


def _map_node(n: str, prefix: str, port_map: dict[str, str], globals_: frozenset[str]) -> str:
    if not prefix or n == GROUND or n in globals_:
        return n
    return port_map.get(n, f"{prefix.lower()}.{n}")


def _rename(element: Element, prefix: str, port_map: dict[str, str], globals_: frozenset[str]) -> Element:
    """Place an element of a subcircuit body into its instance's scope."""

    def node(n: str) -> str:
        return _map_node(n, prefix, port_map, globals_)

    low = prefix.lower()

    def ref(key: str | None) -> str | None:
        return None if key is None else f"{low}.{key}"

    expression = element.expression
    if element.kind in (Kind.BVOLTAGE, Kind.BCURRENT, *STORAGE_KINDS) and expression is not None:

        def scoped(kind: str, n: str) -> str:
            if kind == "v":
                return node(n)
            if n.startswith(DISPLACEMENT):
                return DISPLACEMENT + node(n[len(DISPLACEMENT) :])
            return f"{low}.{n}"

        expression = fold(expression, {}, {}, scoped)
    return replace(
        element,
        expression=expression,
        name=f"{prefix}.{element.name}",
        nodes=tuple(node(n) for n in element.nodes),
        control_nodes=None
        if element.control_nodes is None
        else (node(element.control_nodes[0]), node(element.control_nodes[1])),
        control_source=ref(element.control_source),
        coupled=None
        if element.coupled is None
        else (f"{low}.{element.coupled[0]}", f"{low}.{element.coupled[1]}"),
    )


# --------------------------------------------------------------------------------------------
# Entry points


def parse_text(
    text: str,
    path: str = "<string>",
    overrides: Mapping[str, float] | None = None,
    max_elements: int | None = None,
    devices: Registry = REGISTRY,
) -> Netlist:
    """Parse netlist text.

    Parameters
    ----------
    text : str
        The netlist; its first line is the title.
    path : str
        Name used in messages and for resolving ``.include``.
    overrides : Mapping[str, float], optional
        ``.param`` values to replace (``--param NAME=VALUE``).
    max_elements : int, optional
        Refuse netlists whose subcircuits expand to more elements than this
        (default: ``$NETLISTDYN_MAX_ELEMENTS``, else :data:`MAX_ELEMENTS`).
    devices : Registry
        Where the builder of each element line is looked up, by the line's first letter.

    Returns
    -------
    Netlist

    Raises
    ------
    NetlistError
        With the location of the first problem.
    """
    if max_elements is None:
        max_elements = _limit_from_environment()
    warnings: list[Diagnostic] = []
    title, lines = read_lines(Path(path), text, warnings)
    functions: _Functions = {}
    for line in lines:
        if line.text.split(None, 1)[0].lower() == ".func":
            fname, formals, expression = _parse_func(line)
            functions[fname] = (formals, expression)
    if any(line.text[:3].lower() == ".if" for line in lines):
        outside = [
            _Definition(n, e, line.loc)
            for line in _outside_conditionals(lines)
            if line.text.split(None, 1)[0].lower() == ".param"
            for n, e in _param_line(line)
        ]
        early = evaluate_definitions(
            outside, {}, functions, None, {k.lower(): v for k, v in (overrides or {}).items()}
        )
        lines = _resolve_conditionals(lines, early, functions)
    top, definitions = _split_subcircuits(lines)
    definitions_list = [
        _Definition(n, e, line.loc)
        for line in top
        if line.text.split(None, 1)[0].lower() == ".param"
        for n, e in _param_line(line)
    ]
    lowered = {k.lower(): v for k, v in (overrides or {}).items()}
    missing = sorted(set(lowered) - {d.name.lower() for d in definitions_list})
    if missing:
        raise UsageError(f"--param {missing[0]}: the netlist defines no .param {missing[0]}")
    params = evaluate_definitions(definitions_list, {}, functions, warnings, lowered)
    values = _Values(params, functions, warnings)
    models: dict[str, tuple[str, dict[str, str], SourceLocation]] = {}
    globals_: set[str] = set()
    tran: TranSpec | None = None
    temp: float | None = None
    tnom = 27.0
    steps: list[StepSpec] = []
    ics: list[InitialCondition] = []
    skipping_control = False
    body: list[Line] = []
    all_model_lines = [line for line in lines if line.text.split(None, 1)[0].lower() == ".model"]
    for line in all_model_lines:
        mname, mtype, mparams = _parse_model(line)
        models[mname] = (mtype, mparams, line.loc)
    for line in top:
        word = line.text.split(None, 1)[0].lower()
        if skipping_control:
            skipping_control = word != ".endc"
            continue
        if not word.startswith("."):
            body.append(line)
            continue
        if word in (".param", ".func", ".model"):
            continue
        if word == ".control":
            skipping_control = True
            warnings.append(Diagnostic(line.loc, ".control block ignored"))
        elif word == ".tran":
            tran = _parse_tran(line, values, warnings)
        elif word == ".global":
            globals_.update(canonical_node(n) for n in _fields(line)[1:])
        elif word == ".temp":
            got = _fields(line)[1:]
            if len(got) != 1:
                raise NetlistError(".temp takes one temperature", line.loc)
            temp = values.number(got[0], line.loc, ".temp")
        elif word == ".ic":
            ics.extend(_parse_ic(line, values))
        elif word == ".step":
            steps.append(_parse_step(line, values))
        elif word == ".backanno":
            warnings.append(
                Diagnostic(line.loc, ".backanno ignored (LTspice back-annotation; no effect on the model)")
            )
        elif word in (".options", ".option", ".opt", ".opti"):
            opts = {f.lower() for f in _fields(line)[1:]}
            if opts & {"temp", "tnom"}:
                warnings.append(
                    Diagnostic(line.loc, f"{word} temp/tnom: used by temperature coefficients, diodes")
                )
                temp, tnom = _options_temperature(line, values, temp, tnom)
            else:
                warnings.append(Diagnostic(line.loc, f"{word} ignored (it does not affect the model)"))
        elif word in IGNORED_DIRECTIVES:
            warnings.append(Diagnostic(line.loc, f"{word} ignored (it does not affect the model)"))
        elif word == ".global_param":
            # Xyce's global parameters: ngspice 39 skips the line, so its names stay undefined
            # (measured: a value {bar} after ".global_param bar=1" is "Undefined parameter").
            warnings.append(
                Diagnostic(line.loc, ".global_param ignored, as ngspice does: it defines nothing")
            )
        else:
            raise NetlistError(f"unsupported directive {word}", line.loc)
    _count_elements(body, definitions, max_elements)
    ctx = _Context(values, warnings, models, temp, tran, tnom, devices)
    build = _Build(ctx, definitions, frozenset(globals_))
    _expand_body(build, body, values, None, "", {}, 0)
    elements = build.elements
    seen: dict[str, SourceLocation] = {}
    for element in elements:
        if element.key in seen:
            raise NetlistError(
                f"{element.name}: duplicate element name (first defined at {seen[element.key]})", element.loc
            )
        seen[element.key] = element.loc
    if not elements and not build.planar:
        raise NetlistError("the netlist has no elements", SourceLocation(path, 1))
    elements = resolve_rods(elements)
    netlist = Netlist(
        title,
        path,
        tuple(elements),
        params,
        tran,
        tuple(warnings),
        tuple(ics),
        tuple(steps),
        tuple(build.planar),
    )
    check_netlist(netlist)  # the references every command relies on, checked once for all
    return netlist


def _build_planar(line: Line, ctx: _Context, prefix: str) -> PlanarCard:
    """A planar-mechanism card (:mod:`netlistdyn.devices.planar`); not inside a subcircuit."""
    fields = _fields(line)
    if prefix:
        raise NetlistError(f"{fields[0].upper()}: planar cards are not allowed inside a subcircuit", line.loc)
    return build_planar(
        fields[0].lower(),
        fields[1:],
        line.loc,
        lambda token, what: ctx.values.number(token, line.loc, what),
        lambda tokens, what: parse_source(list(tokens), line.loc, ctx, what)[:2],
    )


def _options_temperature(
    line: Line, values: _Values, temp: float | None, tnom: float
) -> tuple[float | None, float]:
    """``temp=`` and ``tnom=`` of an ``.options`` line (°C)."""
    fields = _fields(line)[1:]
    for i, f in enumerate(fields):
        low = f.lower()
        if low in ("temp", "tnom") and i + 2 < len(fields) and fields[i + 1] == "=":
            value = values.number(fields[i + 2], line.loc, low)
            if low == "temp":
                temp = value
            else:
                tnom = value
    return temp, tnom


def _outside_conditionals(lines: list[Line]) -> list[Line]:
    out: list[Line] = []
    depth = 0
    for line in lines:
        word = line.text.split(None, 1)[0].lower()
        if word == ".if":
            depth += 1
        elif word == ".endif":
            depth -= 1
        elif depth == 0:
            out.append(line)
    return out


def _limit_from_environment() -> int:
    raw = os.environ.get(MAX_ELEMENTS_VARIABLE)
    if raw is None or not raw.strip():
        return MAX_ELEMENTS
    if not raw.strip().isdigit():
        raise UsageError(f"{MAX_ELEMENTS_VARIABLE}={raw!r}: expected a whole number")
    return int(raw.strip())


def netlist_files(path: str | Path, text: str | None = None) -> tuple[Path, ...]:
    """Every file a netlist reads: itself (unless ``text`` is given: standard input), then its
    ``.include`` and ``.lib`` files, resolved (symbolic links followed).

    Raises
    ------
    NetlistError
        As :func:`parse_text` for a file that cannot be read.
    """
    opened: list[Path] = []
    source = Path(path)
    if text is None:
        text = read_source(source, SourceLocation(str(path), 0))
        opened.append(source.resolve())
    read_lines(source, text, None, opened)
    return tuple(opened)


def parse_file(
    path: str | Path, overrides: Mapping[str, float] | None = None, max_elements: int | None = None
) -> Netlist:
    """Read and parse a netlist file (see :func:`parse_text`)."""
    text = read_source(Path(path), SourceLocation(str(path), 0))
    return parse_text(text, str(path), overrides, max_elements)


__all__ = [
    "MAX_ELEMENTS",
    "Subcircuit",
    "evaluate_params",
    "netlist_files",
    "parse_file",
    "parse_text",
    "read_lines",
    "read_source",
    "split_fields",
]
