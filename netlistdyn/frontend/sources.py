"""Source cards' values and waveforms as ngspice 39 reads them: DC, AC, PULSE, SIN, EXP, PWL (with its
repeats and files), SFFM, AM, and the functional and parenthesised forms."""

from __future__ import annotations

import itertools
import re
from pathlib import Path

from netlistdyn.base.errors import NetlistError, SourceLocation
from netlistdyn.base.values import read_number
from netlistdyn.circuit.netlist import Diagnostic
from netlistdyn.circuit.waveforms import Am, Exp, Pulse, Pwl, Random, Sffm, Sin, Waveform
from netlistdyn.devices.cards import CardContext, unwrap
from netlistdyn.frontend.lines import quoted_name, read_source

#: Most points a repeated PWL (``R=``) is unrolled to.
MAX_PWL_POINTS = 1_000_000


SOURCE_FUNCTIONS = ("pulse", "sin", "pwl", "exp", "sffm", "am", "trnoise", "trrandom")


def waveform_parens_only(fields: list[str]) -> list[str]:
    """Keep the outer parentheses of ``PULSE(...)`` and the like; others are delimiters (``dc(5)``)."""
    out: list[str] = []
    depth = 0  # > 0 inside a waveform's parentheses
    for k, token in enumerate(fields):
        if token == "(":
            if depth:
                depth += 1
            elif k > 0 and fields[k - 1].lower() in SOURCE_FUNCTIONS:
                depth = 1
                out.append(token)
            continue
        if token == ")":
            if depth == 1:
                out.append(token)
            depth = max(depth - 1, 0)
            continue
        out.append(token)
    return out


def parse_source(
    fields: list[str], loc: SourceLocation, ctx: CardContext, name: str
) -> tuple[float, Waveform | None, float | None]:
    """``[DC] v [AC mag [phase]] [DISTOF1/2 ...] [PULSE(...)|...] [portnum n] [z0 z]`` of a source.

    Returns
    -------
    dc : float
    waveform : Waveform or None
    z0 : float or None
        Series resistance of an S-parameter port (``portnum``), else ``None``.
    """
    values = ctx.values
    leading: float | None = None
    dc_keyword: float | None = None
    waveform: Waveform | None = None
    portnum: float | None = None
    z0: float | None = None
    seen_any = False
    i = 0
    n = len(fields)

    def take_values(start: int, most: int) -> tuple[list[str], int]:
        out: list[str] = []
        j = start
        while j < n and len(out) < most and fields[j] not in ("(", ")", "=") and values.is_value(fields[j]):
            if j + 1 < n and fields[j + 1] == "=":
                break
            out.append(fields[j])
            j += 1
        return out, j

    def one_value(at: int, label: str, what: str) -> tuple[float, int]:
        """The number after keyword ``fields[at]`` and the index past it; refused when missing."""
        got, after = take_values(at + 1, 1)
        if not got:
            raise NetlistError(f"{name}: {label} needs {what}", loc)
        return values.number(got[0], loc, f"{name} {label}"), after

    while i < n:
        token = fields[i]
        word = token.lower()
        if token in ("(", ")"):
            raise NetlistError(f"{name}: unexpected parenthesis", loc)
        keyword_form = i + 1 < n and fields[i + 1] == "="
        if keyword_form:
            if i + 2 >= n:
                raise NetlistError(f"{name}: {token}= has no value", loc)
            raw = fields[i + 2]
            if word == "dc":
                dc_keyword = values.number(raw, loc, f"{name} dc")
            elif word == "ac":
                values.number(raw, loc, f"{name} ac")
            elif word == "portnum":
                portnum = values.number(raw, loc, f"{name} portnum")
            elif word == "z0":
                z0 = values.number(raw, loc, f"{name} z0")
            else:
                raise NetlistError(
                    f"{name}: unknown parameter {token}= on a source (ngspice refuses it too)", loc
                )
            i += 3
            seen_any = True
            continue
        if word == "dc":
            if take_values(i + 1, 1)[0]:
                dc_keyword, i = one_value(i, "DC", "a value")
            else:  # ngspice 39 reads a DC keyword without a value as DC 0 (measured)
                dc_keyword, i = 0.0, i + 1
                ctx.warnings.append(
                    Diagnostic(loc, f"{name}: DC without a value is DC 0, as ngspice reads it")
                )
        elif word in ("ac", "distof1", "distof2"):
            _, i = take_values(i + 1, 2)  # magnitude and phase: small-signal only
        elif word == "portnum":
            portnum, i = one_value(i, "portnum", "a number")
        elif word == "z0":
            z0, i = one_value(i, "z0", "a value")
        elif word in SOURCE_FUNCTIONS:
            if waveform is not None:
                raise NetlistError(f"{name}: a second waveform {token.upper()}", loc)
            waveform, i = _parse_waveform_call(word, fields, i + 1, loc, ctx, name)
        elif values.is_value(token):
            if seen_any:
                raise NetlistError(
                    f"{name}: unexpected value {token!r} (one DC value per source; ngspice refuses it too)",
                    loc,
                )
            leading = values.number(token, loc, name)
            i += 1
        else:
            raise NetlistError(f"{name}: unexpected field {token!r}", loc)
        seen_any = True
    # ngspice 39: a leading value wins over DC keywords; among DC keywords the last wins.
    dc = leading if leading is not None else (dc_keyword if dc_keyword is not None else 0.0)
    if leading is None and dc_keyword is None and waveform is not None and not isinstance(waveform, Random):
        # ngspice 39 (vsrcload/isrcload): a source without a DC value takes its waveform's value at
        # t = 0 at the operating point (and so at .ac's and .dc's linearisation point).
        dc = float(waveform.resolved(1.0, 1.0).left([0.0])[0])
    if portnum is not None and z0 is None:
        z0 = 50.0
    if z0 is not None and portnum is None:
        raise NetlistError(f"{name}: z0 without portnum", loc)
    if z0 is not None and z0 <= 0:
        raise NetlistError(f"{name}: z0 must be positive", loc)
    return dc, waveform, z0


def _parse_waveform_call(
    kind: str, fields: list[str], i: int, loc: SourceLocation, ctx: CardContext, name: str
) -> tuple[Waveform, int]:
    values = ctx.values
    n = len(fields)
    parens = i < n and fields[i] == "("
    if parens:
        i += 1
    args: list[float] = []
    keywords: dict[str, str] = {}
    while i < n:
        token = fields[i]
        if token == ")":
            if not parens:
                raise NetlistError(f"{name}: unexpected ')'", loc)
            parens = False
            i += 1
            break
        if token == "(":
            raise NetlistError(f"{name}: unexpected '(' in {kind.upper()}", loc)
        if i + 1 < n and fields[i + 1] == "=":
            if i + 2 >= n:
                raise NetlistError(f"{name}: {token}= has no value", loc)
            keywords[token.lower()] = fields[i + 2]
            i += 3
            continue
        if not parens and not values.is_value(token):
            break
        if not values.is_value(token):
            raise NetlistError(f"{name}: unexpected field {token!r} in {kind.upper()}(...)", loc)
        args.append(values.number(token, loc, f"{name} {kind.upper()}"))
        i += 1
    if parens:
        raise NetlistError(f"{name}: missing ')' after {kind.upper()}(", loc)
    # PWL options may also follow the closing parenthesis: PWL(...) TD=1n R=0
    while kind == "pwl" and i + 2 < n + 1 and i + 1 < n and fields[i + 1] == "=":
        keywords[fields[i].lower()] = fields[i + 2]
        i += 3
    return _make_waveform(kind, args, keywords, loc, ctx, name), i


def _make_waveform(
    kind: str, args: list[float], keywords: dict[str, str], loc: SourceLocation, ctx: CardContext, name: str
) -> Waveform:
    def need(low: int, high: int) -> None:
        if not low <= len(args) <= high:
            raise NetlistError(f"{name}: {kind.upper()} takes {low} to {high} values, got {len(args)}", loc)

    if keywords and kind != "pwl":
        raise NetlistError(f"{name}: unknown parameter {next(iter(keywords))}= in {kind.upper()}", loc)
    if kind == "pulse":
        need(2, 8)
        a = args + [None] * (8 - len(args))
        if a[6] is not None and a[6] < 0:
            raise NetlistError(f"{name}: PULSE period is negative", loc)
        # The eighth value: the number of periods (LTspice's Ncycles; ngspice 39 reads it so
        # too, a value <= 0 meaning endless). Then the level stays V1.
        ncycles = a[7] if a[7] is not None and a[7] > 0 else None
        return Pulse(args[0], args[1], a[2] or 0.0, a[3], a[4], a[5], a[6], ncycles)
    if kind == "sin":
        need(2, 7)  # KiCad writes a seventh value; ngspice 39 reads and ignores it (measured)
        a = args + [None] * (7 - len(args))
        return Sin(args[0], args[1], a[2], a[3] or 0.0, a[4] or 0.0, a[5] or 0.0)
    if kind == "am":
        need(2, 7)
        a = args + [None] * (7 - len(args))
        return Am(args[0], args[1], a[2], a[3] or 0.0, a[4] or 0.0, a[5] or 0.0, a[6] or 0.0)
    if kind == "sffm":
        need(2, 7)
        a = args + [None] * (7 - len(args))
        return Sffm(args[0], args[1], a[2], a[3] or 0.0, a[4], a[5] or 0.0, a[6] or 0.0)
    if kind == "exp":
        need(2, 6)
        a = args + [None] * (6 - len(args))
        return Exp(args[0], args[1], a[2] or 0.0, a[3], a[4], a[5])
    if kind == "pwl":
        return _make_pwl(args, keywords, loc, ctx, name)
    if kind in ("trnoise", "trrandom"):
        need(1, 9)  # TRNOISE(NA NT NALPHA NAMP RTSAM RTSCAPT RTSEMT), TRRANDOM(TYPE TS TD P1 P2)
        return Random(kind, name, loc)
    raise NetlistError(f"{name}: {kind.upper()} sources are not supported", loc)


def _make_pwl(
    args: list[float], keywords: dict[str, str], loc: SourceLocation, ctx: CardContext, name: str
) -> Pwl:
    values = ctx.values
    if "file" in keywords:
        if args:
            raise NetlistError(f"{name}: PWL with both FILE= and points", loc)
        target = Path(loc.path).parent / quoted_name(unwrap(keywords.pop("file")))
        text = read_source(target, loc, "PWL file")
        numbers: list[float] = []
        for word in re.split(r"[\s,;]+", text.strip()):
            if not word:
                continue
            reading = read_number(word)
            if reading is None:
                raise NetlistError(f"{name}: PWL file {target.name}: not a number {word!r}", loc)
            numbers.append(reading.value)
        args = numbers
    if len(args) < 2 or len(args) % 2:
        raise NetlistError(f"{name}: PWL needs time-value pairs, got {len(args)} values", loc)
    times = list(args[0::2])
    levels = list(args[1::2])
    if any(b < a for a, b in itertools.pairwise(times)):
        raise NetlistError(f"{name}: PWL times must not decrease", loc)
    td = values.number(keywords.pop("td"), loc, f"{name} TD") if "td" in keywords else 0.0
    repeat = values.number(keywords.pop("r"), loc, f"{name} R") if "r" in keywords else None
    if keywords:
        raise NetlistError(f"{name}: unknown PWL parameter {next(iter(keywords))}=", loc)
    if repeat is not None:
        if ctx.tran is None:
            raise NetlistError(f"{name}: PWL R= (repeat) needs a .tran to know how far to repeat", loc)
        if not times[0] <= repeat < times[-1] or repeat not in times:
            raise NetlistError(
                f"{name}: PWL R={repeat:g} must be one of the PWL's times before the last", loc
            )
        start = times.index(repeat)
        period = times[-1] - repeat
        # Each repetition starts again at the value at R (a jump at the end of the last one).
        seg_t = times[start:]
        seg_v = levels[start:]
        shift = period
        horizon = ctx.tran.tstop - td
        while times[-1] < horizon:
            if len(times) + len(seg_t) > MAX_PWL_POINTS:
                raise NetlistError(f"{name}: PWL R= repeats to more than {MAX_PWL_POINTS} points", loc)
            times.extend(t + shift for t in seg_t)
            levels.extend(seg_v)
            shift += period
    if td:
        times = [t + td for t in times]
        if times[0] > 0:
            times.insert(0, 0.0)
            levels.insert(0, levels[0])
    return Pwl(tuple(times), tuple(levels))
