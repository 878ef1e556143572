"""SPICE number syntax: ``10uF``, ``4.7k``, ``1meg``, ``2mil``, ``1e-3``, ``10µ``.

ngspice 39 reads a number, then an optional scale factor, and ignores the
letters after that. ``m`` and ``M`` are both milli, ``meg`` is mega and
``f``/``F`` is femto (so ``1F`` is one femtofarad, as in every SPICE). The
micro sign ``µ`` (U+00B5, in UTF-8 or Latin-1 files) is micro, as ngspice
reads it; the Greek letter ``μ`` (U+03BC) is *not* micro to ngspice 39 (it is
skipped like a unit letter), so ``10μ`` is 10, with a warning.

ngspice 39 has no RKM notation: ``4k7`` is read as 4k (the ``7`` after the
scale factor is skipped). netlistdyn reads it the same way and warns.
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass

#: Decimal exponent of each scale factor; ``mil`` (25.4e-6) is handled apart.
SCALE_EXPONENTS: dict[str, int] = {
    "t": 12,
    "g": 9,
    "meg": 6,
    "k": 3,
    "m": -3,
    "u": -6,
    "\u00b5": -6,
    "n": -9,
    "p": -12,
    "f": -15,
}
MIL = 25.4e-6
GREEK_MU = "\u03bc"

# re.ASCII: a digit is 0-9 only; Python's \d (and float()) would read full-width "１" and
# Arabic-Indic "١" as digits, which ngspice 39 refuses.
_MANTISSA = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)", re.ASCII)
_EXPONENT = re.compile(r"[eE]([+-]?)(\d+)", re.ASCII)
# Explicit cases, not re.IGNORECASE: that would fold the Greek μ (U+03BC) onto µ (U+00B5).
_SUFFIX = re.compile("[mM][eE][gG]|[mM][iI][lL]|[tTgGkKmMuUnNpPfF\u00b5]")
_PLAIN = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d{1,4})?", re.ASCII)
_RKM_REST = re.compile(r"[^\W\d_]*\d[\w.]*")
#: An exponent beyond this many digits overflows (or underflows) any float.
_MAX_EXPONENT_DIGITS = 6


def _float(mantissa: str, exponent: int) -> float:
    """``mantissa × 10**exponent`` rounded once (exact decimal string)."""
    return float(f"{mantissa}e{exponent}")


def split_number(text: str, mil: bool = True) -> tuple[float, str] | None:
    """Read a SPICE number at the start of ``text``.

    Parameters
    ----------
    text : str
        Text starting with a number, e.g. ``"10uF"`` or ``"1e3"``.
    mil : bool
        Whether ``mil`` (25.4 µm) is a scale factor. ngspice 39 reads it in
        a value field but not inside an expression, where ``1mil`` is 1m.

    Returns
    -------
    tuple of (float, str) or None
        The value (scale factor applied; ``inf`` or 0 when out of the float
        range) and the rest of ``text`` after the number and its scale
        factor; ``None`` when ``text`` does not start with a number.
    """
    match = _MANTISSA.match(text)
    if match is None:
        return None
    mantissa = match.group(0)
    end = match.end()
    exponent = 0
    exp_match = _EXPONENT.match(text, end)
    if exp_match is not None:
        digits = exp_match.group(2).lstrip("0") or "0"
        if len(digits) > _MAX_EXPONENT_DIGITS:
            digits = "9" * _MAX_EXPONENT_DIGITS  # saturates: inf or 0 either way
        exponent = int(digits) * (-1 if exp_match.group(1) == "-" else 1)
        end = exp_match.end()
    rest = text[end:]
    scale = _SUFFIX.match(rest)
    if scale is not None:
        suffix = scale.group(0).lower()
        if suffix == "mil" and not mil:
            suffix = "m"
        rest = rest[len(suffix) :]
        if suffix == "mil":
            return _float(mantissa, exponent) * MIL, rest
        # Build the decimal string so 10u is exactly the double nearest 1e-5.
        return _float(mantissa, exponent + SCALE_EXPONENTS[suffix]), rest
    return _float(mantissa, exponent), rest


@dataclass(frozen=True, slots=True)
class Reading:
    """A value field as ngspice 39 reads it.

    Attributes
    ----------
    value : float
        The number (may be infinite when out of range).
    note : str or None
        Why a user may not have meant this number (RKM notation, Greek mu),
        or ``None``.
    """

    value: float
    note: str | None = None


@functools.lru_cache(maxsize=4096)
def read_number(token: str) -> Reading | None:
    """Read a whole value field as ngspice 39 does, or ``None`` if it is not a number.

    Letters after the number (units such as ``F``, ``Ohm``, ``H``, ``V``) are
    ignored as ngspice ignores them. Digits after them (``4k7``, ``2R2``)
    are skipped as ngspice 39 skips them, with a note; any other character
    makes the field not a number (refused rather than guessed).

    Parameters
    ----------
    token : str
        One field of a netlist line.

    Returns
    -------
    Reading or None
    """
    if _PLAIN.fullmatch(token):
        return Reading(float(token))
    parsed = split_number(token)
    if parsed is None:
        return None
    value, rest = parsed
    if not rest:
        return Reading(value)
    if GREEK_MU in rest:
        if rest.replace(GREEK_MU, "").isalpha() or rest == GREEK_MU:
            return Reading(
                value,
                f"{token!r} is read as {value:g}: ngspice 39 does not take the Greek letter "
                "\u03bc (U+03BC) as micro; write u or \u00b5 (U+00B5) for micro",
            )
        return None
    if rest.isalpha():
        return Reading(value)
    if _RKM_REST.fullmatch(rest):
        return Reading(
            value,
            f"{token!r} is read as {value:g}, as ngspice 39 reads it (it skips everything after "
            "the scale factor; RKM notation such as 4k7 = 4.7k is not SPICE syntax)",
        )
    return None


def parse_number(token: str) -> float | None:
    """Value of a whole SPICE number token, or ``None`` if it is not one.

    Examples
    --------
    >>> parse_number("10uF"), parse_number("1Meg"), parse_number("47Ohm")
    (1e-05, 1000000.0, 47.0)
    """
    reading = read_number(token)
    return None if reading is None else reading.value
