"""From the bytes of a netlist to its logical lines and their fields.

Decoding (UTF-8, else cp1252), comments, continuation lines, ``.include`` and ``.lib`` (with their
loops and limits), and the field splitting that every card shares. The parser proper
(:mod:`netlistdyn.frontend.parser`) reads cards from these lines."""

from __future__ import annotations

import os
import re
import stat
from dataclasses import dataclass
from pathlib import Path

from netlistdyn.base.errors import NetlistError, SourceLocation
from netlistdyn.circuit.netlist import Diagnostic


@dataclass(frozen=True, slots=True)
class Line:
    """One logical line (continuations joined, comments removed)."""

    text: str
    loc: SourceLocation


_LINE_END = re.compile(r"\r\n|\r|\n")


def decode(data: bytes, where: SourceLocation, what: str = "netlist") -> str:
    """Text of a netlist file: UTF-8 (BOM dropped), else cp1252/Latin-1.

    Raises
    ------
    NetlistError
        For binary data (a NUL byte).
    """
    if b"\0" in data:
        raise NetlistError(f"cannot read {what}: not a text file (binary data)", where)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        try:
            text = data.decode("cp1252")
        except UnicodeDecodeError:
            text = data.decode("latin-1")
    return text.removeprefix("\ufeff")


def read_source(path: Path, where: SourceLocation, what: str = "netlist") -> str:
    """Read a regular text file (never blocks on a FIFO or reads a device).

    Raises
    ------
    NetlistError
        When the file is missing, unreadable, not a regular file or binary.
    """
    try:
        info = os.stat(path)
        if not stat.S_ISREG(info.st_mode):
            raise NetlistError(f"cannot read {what} {str(path)!r}: not a regular file", where)
        data = path.read_bytes()
    except OSError as exc:
        raise NetlistError(f"cannot read {what} {str(path)!r}: {exc.strerror or exc}", where) from None
    return decode(data, where, f"{what} {str(path)!r}")


def _strip_inline_comment(text: str) -> str:
    if ";" not in text and "$" not in text:
        return text
    depth = 0
    quoted = False
    for i, char in enumerate(text):
        if char == "'":
            quoted = not quoted
        elif char == "{":
            depth += 1
        elif char == "}":
            depth -= 1
        elif (
            depth <= 0 and not quoted and (char == ";" or (char == "$" and (i == 0 or text[i - 1] in " \t")))
        ):
            return text[:i].rstrip()
    return text


def _logical_lines(path: Path, text: str, has_title: bool) -> tuple[str, list[Line]]:
    """Join continuations and drop comments of one file's text (linear time)."""
    physical = _LINE_END.split(text)
    if physical and physical[-1] == "":
        physical.pop()
    title = physical[0].strip() if has_title and physical else ""
    start = 1 if has_title else 0
    lines: list[Line] = []
    parts: list[str] = []
    first_loc: SourceLocation | None = None
    name = str(path)

    def flush() -> None:
        if parts:
            assert first_loc is not None
            lines.append(Line(" ".join(parts), first_loc))
            parts.clear()

    for number in range(start, len(physical)):
        stripped = physical[number].strip()
        if not stripped or stripped[0] == "*":
            continue
        body = _strip_inline_comment(stripped)
        if not body:
            continue
        if body[0] == "+":
            if not parts:
                raise NetlistError(
                    "continuation line '+' with no line to continue", SourceLocation(name, number + 1)
                )
            rest = body[1:].strip()
            if rest:
                parts.append(rest)
            continue
        flush()
        parts.append(body)
        first_loc = SourceLocation(name, number + 1)
    flush()
    return title, lines


def quoted_name(text: str) -> str:
    text = text.strip()
    if len(text) >= 2 and text[0] in "'\"" and text[-1] == text[0]:
        return text[1:-1]
    return text


def _lib_section(lines: list[Line], section: str, target: Path, loc: SourceLocation) -> list[Line]:
    out: list[Line] = []
    inside = False
    for line in lines:
        words = line.text.split()
        word = words[0].lower()
        if not inside:
            if word == ".lib" and len(words) == 2 and words[1].lower() == section:
                inside = True
            continue
        if word == ".endl":
            return out
        out.append(line)
    if inside:
        raise NetlistError(f".lib {target.name} {section}: no .endl after the section", loc)
    raise NetlistError(f".lib: section {section!r} not found in {target.name}", loc)


@dataclass
class _Frame:
    lines: list[Line]
    path: Path
    chain: tuple[Path, ...]
    index: int = 0


def read_lines(
    path: Path, text: str, notes: list[Diagnostic] | None = None, opened: list[Path] | None = None
) -> tuple[str, list[Line]]:
    """Split netlist text into its title and logical lines.

    ``.include`` files and ``.lib file section`` sections are read in place
    (paths relative to the including file), with an explicit stack so that
    long include chains do not recurse; an include loop is an error.
    ``.lib name`` ... ``.endl`` blocks met while reading are library
    sections, skipped unless called.

    Parameters
    ----------
    path : Path
        File the text came from (for locations and relative includes).
    text : str
        Contents of the file.
    notes : list of Diagnostic, optional
        Receives notes (e.g. an LTspice ``.lib file`` read as an include).
    opened : list of Path, optional
        Receives every ``.include`` and ``.lib`` file read (resolved), in the order read.

    Returns
    -------
    title : str
        First line.
    lines : list of Line
        Logical lines after the title, up to ``.end``.
    """
    title, first = _logical_lines(path, text, True)
    out: list[Line] = []
    stack = [_Frame(first, path, (path.resolve(),))]
    while stack:
        frame = stack[-1]
        if opened is not None and frame.index == 0 and len(stack) > 1 and frame.path not in opened:
            opened.append(frame.path)
        if frame.index >= len(frame.lines):
            stack.pop()
            continue
        line = frame.lines[frame.index]
        frame.index += 1
        words = line.text.split(None, 1)
        word = words[0].lower()
        if word == ".end":
            if len(stack) == 1:
                break
            continue
        if word in (".include", ".inc", ".incl"):
            if len(words) < 2:
                raise NetlistError(f"{word} needs a file name", line.loc)
            stack.append(_open_include(frame, quoted_name(words[1]), line, word))
            continue
        if word == ".lib":
            args = words[1].split() if len(words) > 1 else []
            if len(args) >= 2:
                child = _open_include(frame, quoted_name(" ".join(args[:-1])), line, ".lib")
                child.lines = _lib_section(child.lines, args[-1].lower(), child.path, line.loc)
                stack.append(child)
                continue
            if len(args) == 1:
                end = next(
                    (
                        k
                        for k in range(frame.index, len(frame.lines))
                        if frame.lines[k].text.split()[0].lower() == ".endl"
                    ),
                    None,
                )
                if end is not None:  # a library section: read only when called
                    frame.index = end + 1
                    continue
                # LTspice: ".lib file" includes the whole file
                if notes is not None:
                    notes.append(
                        Diagnostic(line.loc, f".lib {args[0]} read as an include of the whole file (LTspice)")
                    )
                stack.append(_open_include(frame, quoted_name(args[0]), line, ".lib"))
                continue
            raise NetlistError(".lib needs a file name and a section", line.loc)
        if word == ".endl":
            continue
        out.append(line)
    return title, out


def _open_include(frame: _Frame, name: str, line: Line, word: str) -> _Frame:
    try:
        target = (frame.path.parent / os.path.expanduser(name)).resolve()
    except (RuntimeError, OSError):  # a loop of symbolic links (RuntimeError before Python 3.13)
        raise NetlistError(f"{word} {name}: a loop of symbolic links", line.loc) from None
    if target in frame.chain:
        cycle = " -> ".join(p.name for p in (*frame.chain[frame.chain.index(target) :], target))
        raise NetlistError(f"include loop: {cycle}", line.loc)
    text = read_source(target, line.loc, f"{word} file")
    _, lines = _logical_lines(target, text, False)
    return _Frame(lines, target, (*frame.chain, target))


_CHUNK = re.compile(r"[{}']|[^\s,=(){}']+|=|[()]|[\s,]+")


def split_fields(text: str, keep_parens: bool = False) -> list[str]:
    """Split a logical line into fields (SPICE delimiters; braces and quotes kept whole).

    Raises
    ------
    ValueError
        For an unclosed ``{`` or ``'`` or an unmatched ``}``.
    """
    if "{" not in text and "'" not in text and "}" not in text:
        tokens = re.findall(r"[^\s,=()]+|=|[()]", text)
        return tokens if keep_parens else [t for t in tokens if t not in "()"]
    fields: list[str] = []
    current: list[str] = []
    depth = 0
    quoted = False
    for chunk in _CHUNK.findall(text):
        if quoted:
            current.append(chunk)
            if chunk == "'":
                quoted = False
                if depth == 0:
                    fields.append("".join(current))
                    current.clear()
            continue
        if chunk == "'" and depth == 0:
            if current:
                fields.append("".join(current))
                current.clear()
            current.append(chunk)
            quoted = True
            continue
        if chunk == "{":
            if depth == 0 and current:
                fields.append("".join(current))
                current.clear()
            depth += 1
            current.append(chunk)
            continue
        if chunk == "}":
            if depth == 0:
                raise ValueError("unmatched '}'")
            depth -= 1
            current.append(chunk)
            if depth == 0:
                fields.append("".join(current))
                current.clear()
            continue
        if depth:
            current.append(chunk)
            continue
        if chunk[0].isspace() or chunk[0] == ",":
            if current:
                fields.append("".join(current))
                current.clear()
            continue
        if chunk in ("=", "(", ")"):
            if current:
                fields.append("".join(current))
                current.clear()
            if chunk == "=" or keep_parens:
                fields.append(chunk)
            continue
        current.append(chunk)
    if quoted:
        raise ValueError("unclosed quote (')")
    if depth:
        raise ValueError("unclosed brace '{'")
    if current:
        fields.append("".join(current))
    return fields


def tokenize(text: str) -> list[str]:
    """Split a logical line into fields (parentheses dropped); see :func:`split_fields`."""
    return split_fields(text)
