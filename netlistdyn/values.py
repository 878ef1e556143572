"""SPICE number syntax: ``10uF``, ``4.7k``, ``1meg``, ``2mil``, ``1e-3``.

ngspice reads a number, then an optional scale factor, and ignores any
letters after that. ``m`` and ``M`` are both milli, ``meg`` is mega and
``f``/``F`` is femto (so ``1F`` is one femtofarad, as in every SPICE).
"""

from __future__ import annotations

import re

#: Decimal exponent of each scale factor; ``mil`` (25.4e-6) is handled apart.
SCALE_EXPONENTS: dict[str, int] = {
    "t": 12,
    "g": 9,
    "meg": 6,
    "k": 3,
    "m": -3,
    "u": -6,
    "n": -9,
    "p": -12,
    "f": -15,
}
MIL = 25.4e-6

_NUMBER = re.compile(r"([+-]?(?:\d+\.?\d*|\.\d+))(?:[eE]([+-]?\d+))?")
_SUFFIX_ORDER = ("meg", "mil", "t", "g", "k", "m", "u", "n", "p", "f")


def split_number(text: str) -> tuple[float, str] | None:
    """Read a SPICE number at the start of ``text``.

    Parameters
    ----------
    text : str
        Text starting with a number, e.g. ``"10uF"`` or ``"1e3"``.

    Returns
    -------
    tuple of (float, str) or None
        The value (scale factor applied) and the rest of ``text`` after the
        number and its scale factor; ``None`` when ``text`` does not start
        with a number.
    """
    match = _NUMBER.match(text)
    if match is None:
        return None
    mantissa, exponent = match.group(1), int(match.group(2) or 0)
    rest = text[match.end() :]
    low = rest.lower()
    for suffix in _SUFFIX_ORDER:
        if low.startswith(suffix):
            rest = rest[len(suffix) :]
            if suffix == "mil":
                return float(f"{mantissa}e{exponent}") * MIL, rest
            # Build the decimal string so 10u is exactly the double nearest 1e-5.
            return float(f"{mantissa}e{exponent + SCALE_EXPONENTS[suffix]}"), rest
    return float(f"{mantissa}e{exponent}"), rest


def parse_number(token: str) -> float | None:
    """Value of a whole SPICE number token, or ``None`` if it is not one.

    Letters after the number (units such as ``F``, ``Ohm``, ``H``, ``V``) are
    ignored as ngspice ignores them; anything else (digits, operators) makes
    the token not a number.

    Examples
    --------
    >>> parse_number("10uF"), parse_number("1Meg"), parse_number("47Ohm")
    (1e-05, 1000000.0, 47.0)
    """
    parsed = split_number(token)
    if parsed is None:
        return None
    value, rest = parsed
    if rest and not rest.isalpha():
        return None
    return value
