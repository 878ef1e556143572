"""Netlist text → :class:`~netlistdyn.netlist.Netlist`.

SPICE conventions: the first line is the title; ``*`` starts a comment line;
``;`` (and ``$`` after white space) starts an inline comment; ``+`` continues
the previous line; names are case-insensitive; ``0`` and ``gnd`` are ground;
``.end`` ends the netlist. Fields are separated by white space, commas,
``=`` and parentheses, except inside ``{...}`` or ``'...'`` expressions.

The parser works in two passes: it first reads logical lines (following
``.include``), collects ``.param`` definitions and evaluates them in order
(with command-line overrides), then builds the elements.
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path

from .errors import NetlistError, SourceLocation, UsageError
from .expressions import ExpressionError, evaluate
from .mechanics import KEYWORDS, build_mechanical, resolve_rods
from .netlist import GROUND, Diagnostic, Element, Kind, Netlist, TranSpec
from .values import parse_number
from .waveforms import Exp, Pulse, Pwl, Sin, Waveform


@dataclass(frozen=True, slots=True)
class Line:
    """One logical line (continuations joined, comments removed)."""

    text: str
    loc: SourceLocation


# Directives that do not change the model: accepted with a warning.
IGNORED_DIRECTIVES = frozenset(
    {
        ".print",
        ".plot",
        ".options",
        ".option",
        ".opt",
        ".opti",
        ".op",
        ".ac",
        ".dc",
        ".save",
        ".probe",
        ".meas",
        ".measure",
        ".temp",
        ".width",
        ".four",
        ".noise",
        ".disto",
        ".sens",
        ".tf",
        ".nodeset",
        ".ic",
        ".global",
        ".csparam",
        ".func",
        ".model",
        ".pz",
    }
)
UNSUPPORTED_LETTERS = {
    "d": "diode",
    "q": "bipolar transistor",
    "m": "MOSFET",
    "j": "JFET",
    "z": "MESFET",
    "b": "behavioural source",
    "s": "voltage-controlled switch",
    "w": "current-controlled switch",
    "t": "transmission line",
    "o": "lossy line",
    "u": "distributed RC line",
    "a": "XSPICE code model",
    "y": "lossy line",
    "x": "subcircuit",
    "p": "coupled lines",
    "n": "numerical device",
}
SOURCE_FUNCTIONS = ("pulse", "sin", "pwl", "exp", "sffm", "am", "trnoise", "trrandom")


def _strip_inline_comment(text: str) -> str:
    out = []
    depth = 0
    for i, char in enumerate(text):
        if char == "{":
            depth += 1
        elif char == "}":
            depth -= 1
        if depth == 0 and (char == ";" or (char == "$" and (i == 0 or text[i - 1].isspace()))):
            break
        out.append(char)
    return "".join(out).rstrip()


def read_lines(path: Path, text: str, stack: tuple[Path, ...] = ()) -> tuple[str, list[Line]]:
    """Split netlist text into its title and logical lines.

    ``.include`` files are read in place (paths relative to the including
    file); an include loop is an error.

    Parameters
    ----------
    path : Path
        File the text came from (for locations and relative includes).
    text : str
        Contents of the file.
    stack : tuple of Path
        Files currently being included (to detect loops).

    Returns
    -------
    title : str
        First line (empty for an included file).
    lines : list of Line
        Logical lines after the title, up to ``.end``.
    """
    physical = text.splitlines()
    title = physical[0].strip() if physical and not stack else ""
    start = 1 if not stack else 0
    lines: list[Line] = []
    for number, raw in enumerate(physical[start:], start=start + 1):
        loc = SourceLocation(str(path), number)
        stripped = raw.strip()
        if not stripped or stripped.startswith("*"):
            continue
        body = _strip_inline_comment(stripped)
        if not body:
            continue
        if body.startswith("+"):
            if not lines:
                raise NetlistError("continuation line '+' with no line to continue", loc)
            prev = lines[-1]
            lines[-1] = Line(prev.text + " " + body[1:].strip(), prev.loc)
            continue
        lines.append(Line(body, loc))
    out: list[Line] = []
    for line in lines:
        if not tokenize(line.text):
            raise NetlistError(f"cannot read {line.text!r}: no element or command in it", line.loc)
        word = line.text.split()[0].lower()
        if word == ".end":
            break
        if word in (".include", ".inc"):
            out.extend(_include(path, line, stack))
            continue
        out.append(line)
    return title, out


def _include(path: Path, line: Line, stack: tuple[Path, ...]) -> list[Line]:
    parts = line.text.split(None, 1)
    if len(parts) < 2:
        raise NetlistError(".include needs a file name", line.loc)
    name = parts[1].strip().strip("'\"")
    target = (path.parent / name).resolve()
    chain = (*stack, path.resolve())
    if target in chain:
        cycle = " -> ".join(p.name for p in (*chain[chain.index(target) :], target))
        raise NetlistError(f"include loop: {cycle}", line.loc)
    try:
        text = target.read_text()
    except OSError as exc:
        raise NetlistError(f".include {name}: {exc.strerror or exc}", line.loc) from None
    _, lines = read_lines(target, text, chain)
    return lines


_TOKEN = re.compile(r"\{[^}]*\}|'[^']*'|[^\s,=()]+|=")


def tokenize(text: str) -> list[str]:
    """Split a logical line into fields (SPICE delimiters; braces kept whole)."""
    return _TOKEN.findall(text)


class _Values:
    """Evaluates value fields against the netlist's parameters."""

    def __init__(self, params: Mapping[str, float]) -> None:
        self.params = params

    def number(self, token: str, loc: SourceLocation, what: str) -> float:
        if token.startswith("{") or token.startswith("'"):
            expr = token[1:-1]
            try:
                value = evaluate(expr, self.params)
            except ExpressionError as exc:
                raise NetlistError(f"{what}: {exc}", loc) from None
        else:
            parsed = parse_number(token)
            if parsed is None:
                hint = f" (write {{{token}}} to use a parameter)" if token.lower() in self.params else ""
                raise NetlistError(f"{what}: expected a number, got {token!r}{hint}", loc)
            value = parsed
        if not math.isfinite(value):
            raise NetlistError(f"{what}: value is not finite ({value})", loc)
        return value

    def is_value(self, token: str) -> bool:
        return token[0] in "{'" or parse_number(token) is not None


def _node(name: str) -> str:
    low = name.lower()
    return GROUND if low in ("0", "gnd") else low


_PARAM_ASSIGN = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)\s*=\s*")


def _param_assignments(line: Line) -> list[tuple[str, str]]:
    body = line.text.split(None, 1)
    if len(body) < 2:
        raise NetlistError(".param needs name=value", line.loc)
    text = body[1]
    matches = list(_PARAM_ASSIGN.finditer(text))
    # Only assignments at top level (outside braces) start a new parameter.
    starts = [m for m in matches if text[: m.start()].count("{") == text[: m.start()].count("}")]
    if not starts or text[: starts[0].start()].strip():
        raise NetlistError(f".param: expected name=value, got {text!r}", line.loc)
    out = []
    for i, match in enumerate(starts):
        end = starts[i + 1].start() if i + 1 < len(starts) else len(text)
        expr = text[match.end() : end].strip().rstrip(",").strip()
        if not expr:
            raise NetlistError(f".param {match.group(1)}: missing value", line.loc)
        out.append((match.group(1).lower(), expr))
    return out


def evaluate_params(lines: list[Line], overrides: Mapping[str, float]) -> dict[str, float]:
    """Evaluate every ``.param`` in file order, applying overrides.

    Parameters
    ----------
    lines : list of Line
        Logical lines of the netlist.
    overrides : Mapping[str, float]
        Values given on the command line; they replace the definition of the
        parameter of that name, so parameters derived from it follow.

    Returns
    -------
    dict
        Parameter values by lower-case name.

    Raises
    ------
    UsageError
        An override names a parameter the netlist does not define.
    """
    params: dict[str, float] = {}
    overrides = {k.lower(): v for k, v in overrides.items()}
    for line in lines:
        if line.text.split()[0].lower() != ".param":
            continue
        for name, expr in _param_assignments(line):
            if name in overrides:
                params[name] = overrides[name]
                continue
            text = expr[1:-1] if expr[:1] in "{'" and expr[-1:] in "}'" else expr
            try:
                params[name] = evaluate(text, params)
            except ExpressionError as exc:
                raise NetlistError(f".param {name}: {exc}", line.loc) from None
    missing = sorted(set(overrides) - set(params))
    if missing:
        raise UsageError(f"--param {missing[0]}: the netlist defines no .param {missing[0]}")
    return params


def _parse_waveform(
    fields: list[str], loc: SourceLocation, values: _Values, name: str
) -> tuple[float, Waveform | None]:
    """Parse ``[DC] v [AC mag [phase]] [PULSE(...)|...]`` after a source's nodes."""
    dc = 0.0
    waveform: Waveform | None = None
    i = 0
    while i < len(fields):
        word = fields[i].lower()
        if word == "dc":
            if i + 1 >= len(fields):
                raise NetlistError(f"{name}: DC needs a value", loc)
            dc = values.number(fields[i + 1], loc, name)
            i += 2
        elif word == "ac":
            i += 1
            for _ in range(2):  # magnitude and optional phase: small-signal only
                if i < len(fields) and values.is_value(fields[i]):
                    i += 1
        elif word in SOURCE_FUNCTIONS:
            args: list[float] = []
            j = i + 1
            while j < len(fields) and values.is_value(fields[j]):
                args.append(values.number(fields[j], loc, f"{name} {word.upper()}"))
                j += 1
            if j < len(fields) and fields[j].lower() not in ("dc", "ac", *SOURCE_FUNCTIONS):
                raise NetlistError(f"{name}: unsupported field {fields[j]!r} in {word.upper()}(...)", loc)
            waveform = _make_waveform(word, args, loc, name)
            i = j
        elif values.is_value(fields[i]):
            dc = values.number(fields[i], loc, name)
            i += 1
        else:
            raise NetlistError(f"{name}: unexpected field {fields[i]!r}", loc)
    return dc, waveform


def _make_waveform(kind: str, args: list[float], loc: SourceLocation, name: str) -> Waveform:
    def need(low: int, high: int) -> None:
        if not low <= len(args) <= high:
            raise NetlistError(f"{name}: {kind.upper()} takes {low} to {high} values, got {len(args)}", loc)

    if kind == "pulse":
        need(2, 8)
        a = args + [None] * (7 - len(args))
        return Pulse(args[0], args[1], a[2] or 0.0, a[3], a[4], a[5], a[6])
    if kind == "sin":
        need(2, 6)
        a = args + [None] * (6 - len(args))
        return Sin(args[0], args[1], a[2], a[3] or 0.0, a[4] or 0.0, a[5] or 0.0)
    if kind == "exp":
        need(2, 6)
        a = args + [None] * (6 - len(args))
        return Exp(args[0], args[1], a[2] or 0.0, a[3], a[4], a[5])
    if kind == "pwl":
        if len(args) < 2 or len(args) % 2:
            raise NetlistError(f"{name}: PWL needs time-value pairs, got {len(args)} values", loc)
        times = tuple(args[0::2])
        if any(b < a for a, b in itertools.pairwise(times)):
            raise NetlistError(f"{name}: PWL times must not decrease", loc)
        return Pwl(times, tuple(args[1::2]))
    raise NetlistError(f"{name}: {kind.upper()} sources are not supported", loc)


def _build_element(line: Line, fields: list[str], values: _Values, warnings: list[Diagnostic]) -> Element:
    name = fields[0]
    letter = name[0].lower()
    loc = line.loc
    if name.lower() in KEYWORDS:
        return build_mechanical(
            name.lower(),
            fields[1:],
            loc,
            lambda token, what: values.number(token, loc, what),
            _node,
            lambda tokens, what: _parse_waveform(tokens, loc, values, what),
            warnings,
        )

    def nodes(count: int) -> tuple[str, ...]:
        if len(fields) < 1 + count:
            raise NetlistError(f"{name}: expected {count} nodes, got {len(fields) - 1}", loc)
        return tuple(_node(n) for n in fields[1 : 1 + count])

    def single_value(index: int, what: str) -> float:
        if len(fields) <= index:
            raise NetlistError(f"{name}: missing {what}", loc)
        if len(fields) > index + 1:
            raise NetlistError(f"{name}: unexpected field {fields[index + 1]!r}", loc)
        return values.number(fields[index], loc, name)

    if letter in "rlc":
        kind = {"r": Kind.RESISTOR, "l": Kind.INDUCTOR, "c": Kind.CAPACITOR}[letter]
        value = single_value(3, "value")
        element = Element(kind, name, nodes(2), value, loc)
        _check_value(element, warnings)
        return element
    if letter in "vi":
        kind = Kind.VSOURCE if letter == "v" else Kind.ISOURCE
        dc, waveform = _parse_waveform(fields[3:], loc, values, name)
        return Element(kind, name, nodes(2), dc, loc, waveform=waveform)
    if letter in "eg":
        kind = Kind.VCVS if letter == "e" else Kind.VCCS
        if len(fields) > 3 and fields[3].lower() in ("poly", "value", "table", "laplace", "vol", "cur"):
            raise NetlistError(f"{name}: {fields[3].upper()} sources are not linear; give a gain", loc)
        n = nodes(4)
        gain = single_value(5, "gain")
        return Element(kind, name, n[:2], gain, loc, control_nodes=(n[2], n[3]))
    if letter in "fh":
        kind = Kind.CCCS if letter == "f" else Kind.CCVS
        n = nodes(2)
        if len(fields) < 4:
            raise NetlistError(f"{name}: missing controlling voltage source", loc)
        gain = single_value(4, "gain")
        return Element(kind, name, n, gain, loc, control_source=fields[3].lower())
    if letter == "k":
        if len(fields) < 4:
            raise NetlistError(f"{name}: expected K name L1 L2 k", loc)
        k = single_value(3, "coupling coefficient")
        if not 0 < abs(k) < 1:
            raise NetlistError(
                f"{name}: coupling coefficient must satisfy 0 < |k| < 1, got {k:g}"
                + (" (perfect coupling is an ideal transformer; use k < 1)" if abs(k) == 1 else ""),
                loc,
            )
        return Element(Kind.COUPLING, name, (), k, loc, coupled=(fields[1].lower(), fields[2].lower()))
    what = UNSUPPORTED_LETTERS.get(letter)
    if what:
        raise NetlistError(f"{name}: {what} elements are not supported (linear lumped elements only)", loc)
    raise NetlistError(f"{name}: unknown element type {name[0]!r}", loc)


def _check_value(element: Element, warnings: list[Diagnostic]) -> None:
    if element.value == 0:
        raise NetlistError(f"{element.label}: value is zero", element.loc)
    if element.value < 0:
        warnings.append(Diagnostic(element.loc, f"{element.label} has a negative value ({element.value:g})"))


def _parse_tran(line: Line, values: _Values) -> TranSpec:
    fields = [f for f in tokenize(line.text)[1:] if f.lower() != "uic"]
    if len(fields) < 2:
        raise NetlistError(".tran needs TSTEP TSTOP", line.loc)
    nums = [values.number(f, line.loc, ".tran") for f in fields[:4]]
    if nums[0] <= 0 or nums[1] <= 0:
        raise NetlistError(".tran: TSTEP and TSTOP must be positive", line.loc)
    return TranSpec(
        nums[0], nums[1], nums[2] if len(nums) > 2 else 0.0, nums[3] if len(nums) > 3 else None, line.loc
    )


def parse_text(text: str, path: str = "<string>", overrides: Mapping[str, float] | None = None) -> Netlist:
    """Parse netlist text.

    Parameters
    ----------
    text : str
        The netlist; its first line is the title.
    path : str
        Name used in messages and for resolving ``.include``.
    overrides : Mapping[str, float], optional
        ``.param`` values to replace (``--param NAME=VALUE``).

    Returns
    -------
    Netlist

    Raises
    ------
    NetlistError
        With the location of the first problem.
    """
    title, lines = read_lines(Path(path), text)
    top, definitions = _split_subcircuits(lines)
    params = evaluate_params(top, overrides or {})
    values = _Values(params)
    warnings: list[Diagnostic] = []
    elements: list[Element] = []
    seen: dict[str, SourceLocation] = {}
    tran: TranSpec | None = None
    skipping_control = False
    for line in top:
        fields = tokenize(line.text)
        word = fields[0].lower()
        if skipping_control:
            skipping_control = word != ".endc"
            continue
        if word.startswith("."):
            if word == ".param":
                continue
            if word == ".control":
                skipping_control = True
                warnings.append(Diagnostic(line.loc, ".control block ignored"))
            elif word == ".tran":
                tran = _parse_tran(line, values)
            elif word in IGNORED_DIRECTIVES:
                warnings.append(Diagnostic(line.loc, f"{word} ignored (it does not affect the model)"))
            else:
                raise NetlistError(f"unsupported directive {word}", line.loc)
            continue
        if word[0] == "x" and word not in KEYWORDS:
            built = _expand_instance(line, fields, definitions, values, warnings, ())
        else:
            built = [_build_element(line, fields, values, warnings)]
        for element in built:
            if element.key in seen:
                raise NetlistError(
                    f"{element.name}: duplicate element name (first defined at {seen[element.key]})",
                    element.loc,
                )
            seen[element.key] = element.loc
            elements.append(element)
    if not elements:
        raise NetlistError("the netlist has no elements", SourceLocation(path, 1))
    elements = resolve_rods(elements)
    return Netlist(title, path, tuple(elements), params, tran, tuple(warnings))


@dataclass(frozen=True)
class Subcircuit:
    """A ``.subckt name ports...`` definition with its own nested definitions."""

    name: str
    ports: tuple[str, ...]
    body: tuple[Line, ...]
    definitions: dict[str, Subcircuit]
    loc: SourceLocation


def _split_subcircuits(lines: list[Line]) -> tuple[list[Line], dict[str, Subcircuit]]:
    """Separate ``.subckt ... .ends`` blocks (nested ones scoped to their parent)."""
    top: list[Line] = []
    definitions: dict[str, Subcircuit] = {}
    i = 0
    while i < len(lines):
        fields = tokenize(lines[i].text)
        word = fields[0].lower()
        if word == ".ends":
            raise NetlistError(".ends without .subckt", lines[i].loc)
        if word != ".subckt":
            top.append(lines[i])
            i += 1
            continue
        if len(fields) < 2:
            raise NetlistError(".subckt needs a name", lines[i].loc)
        if any(f == "=" for f in fields) or any(f.lower() == "params:" for f in fields):
            raise NetlistError(f".subckt {fields[1]}: subcircuit parameters are not supported", lines[i].loc)
        depth, j = 1, i + 1
        while j < len(lines) and depth:
            inner = lines[j].text.split()[0].lower()
            depth += inner == ".subckt"
            depth -= inner == ".ends"
            j += 1
        if depth:
            raise NetlistError(f".subckt {fields[1]}: no matching .ends", lines[i].loc)
        body, nested = _split_subcircuits(lines[i + 1 : j - 1])
        for line in body:
            if line.text.split()[0].lower() in (".param", ".tran"):
                raise NetlistError(
                    f"{line.text.split()[0]} inside .subckt {fields[1]} is not supported", line.loc
                )
        key = fields[1].lower()
        if key in definitions:
            raise NetlistError(f".subckt {fields[1]}: defined twice", lines[i].loc)
        ports = tuple(_node(n) for n in fields[2:])
        definitions[key] = Subcircuit(fields[1], ports, tuple(body), nested, lines[i].loc)
        i = j
    return top, definitions


MAX_SUBCIRCUIT_DEPTH = 50


def _expand_instance(
    line: Line,
    fields: list[str],
    definitions: dict[str, Subcircuit],
    values: _Values,
    warnings: list[Diagnostic],
    stack: tuple[str, ...],
) -> list[Element]:
    """Flatten ``Xname nodes... subname``: elements renamed ``Xname.elem``, nodes ``xname.node``."""
    name = fields[0]
    if any(f == "=" for f in fields):
        raise NetlistError(f"{name}: subcircuit parameters are not supported", line.loc)
    if len(fields) < 2:
        raise NetlistError(f"{name}: expected X name nodes... subcircuit", line.loc)
    sub_name = fields[-1].lower()
    sub = definitions.get(sub_name)
    if sub is None:
        raise NetlistError(f"{name}: unknown subcircuit {fields[-1]!r}", line.loc)
    if sub_name in stack or len(stack) > MAX_SUBCIRCUIT_DEPTH:
        raise NetlistError(f"{name}: subcircuit {sub.name} instantiates itself", line.loc)
    outer = [_node(n) for n in fields[1:-1]]
    if len(outer) != len(sub.ports):
        raise NetlistError(
            f"{name}: subcircuit {sub.name} has {len(sub.ports)} ports, got {len(outer)} nodes", line.loc
        )
    prefix = name
    port_map = dict(zip(sub.ports, outer, strict=True))
    scope = {**definitions, **sub.definitions}
    out: list[Element] = []
    for inner_line in sub.body:
        inner_fields = tokenize(inner_line.text)
        word = inner_fields[0].lower()
        if word.startswith("."):
            if word in IGNORED_DIRECTIVES:
                continue
            raise NetlistError(f"{word} inside .subckt {sub.name} is not supported", inner_line.loc)
        if word[0] == "x" and word not in KEYWORDS:
            built = _expand_instance(inner_line, inner_fields, scope, values, warnings, (*stack, sub_name))
        else:
            built = [_build_element(inner_line, inner_fields, values, warnings)]
        out.extend(_rename(e, prefix, port_map) for e in built)
    return out


def _rename(element: Element, prefix: str, port_map: dict[str, str]) -> Element:
    """Place an element of a subcircuit body into its instance's scope."""

    def node(n: str) -> str:
        if n == GROUND:
            return GROUND
        return port_map.get(n, f"{prefix.lower()}.{n}")

    def ref(key: str | None) -> str | None:
        return None if key is None else f"{prefix.lower()}.{key}"

    return replace(
        element,
        name=f"{prefix}.{element.name}",
        nodes=tuple(node(n) for n in element.nodes),
        control_nodes=None
        if element.control_nodes is None
        else (node(element.control_nodes[0]), node(element.control_nodes[1])),
        control_source=ref(element.control_source),
        coupled=None
        if element.coupled is None
        else (f"{prefix.lower()}.{element.coupled[0]}", f"{prefix.lower()}.{element.coupled[1]}"),
    )


def parse_file(path: str | Path, overrides: Mapping[str, float] | None = None) -> Netlist:
    """Read and parse a netlist file (see :func:`parse_text`)."""
    file = Path(path)
    try:
        text = file.read_text()
    except OSError as exc:
        where = SourceLocation(str(path), 0)
        raise NetlistError(f"cannot read netlist: {exc.strerror or exc}", where) from None
    except UnicodeDecodeError:
        raise NetlistError("cannot read netlist: not a text file", SourceLocation(str(path), 0)) from None
    return parse_text(text, str(path), overrides)
