"""Figures as an engineer writes them: 62.91 µm, not 6.29073e-05 m.

:func:`quantity` gives a value with its unit, the unit's SI prefix chosen so that the number
is between 1 and 1000 (downward prefixes only: m, µ, n, p, down to 1 p; a unit with an exponent, as m²,
or without a prefix, as deg, keeps its own and the number is written in full); a number
that is still below 0.001 or at least 10⁶ is written as a mantissa × 10 to a superscript
power. Never e-notation.
"""

from __future__ import annotations

import math

SIGNIFICANT = 4  # significant digits of a reported figure
PREFIXES = ((1.0, ""), (1e-3, "m"), (1e-6, "µ"), (1e-9, "n"), (1e-12, "p"))
# units that take a prefix on their first symbol (N m → mN m, rad/s → mrad/s)
PREFIXABLE = ("m", "s", "N", "rad", "J", "W")
COUNTS = ("rows", "modes", "contacts", "switches", "joints", "periods", "control periods")
_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def _strip(text: str) -> str:
    return text.rstrip("0").rstrip(".") if "." in text else text


def number(x: float, digits: int = SIGNIFICANT) -> str:
    """``x`` to ``digits`` significant digits (trailing zeros dropped where the value is
    exactly what is left: 5 s, but 10.00 N for 10.004 N): plain decimals from
    0.001 to below 10⁶, else "m × 10ⁿ"; ∞, n/a for nan."""
    if isinstance(x, bool):
        return "yes" if x else "no"
    x = float(x)
    if math.isnan(x):
        return "n/a"
    if math.isinf(x):
        return "∞" if x > 0 else "−∞"
    if x == 0:
        return "0"
    exponent = math.floor(math.log10(abs(x)))
    if -3 <= exponent < 6:
        decimals = max(0, digits - 1 - exponent)
        text = f"{x:.{decimals}f}"
        if abs(float(text)) < 1e6:
            exact = abs(float(_strip(text)) - x) <= 1e-9 * abs(x)
            return _strip(text) if exact else text  # 5 s, but 10.00 N for 10.004 N
    mantissa = round(x / 10.0**exponent, digits - 1)
    if abs(mantissa) >= 10.0:
        mantissa, exponent = mantissa / 10.0, exponent + 1
    return f"{_strip(f'{mantissa:.{digits - 1}f}')} × 10{str(exponent).translate(_SUPERSCRIPT)}"


def _prefixable(unit: str) -> bool:
    head = unit.split(" ")[0].split("/")[0]
    return head in PREFIXABLE


def split_quantity(x: float, unit: str, digits: int = SIGNIFICANT) -> tuple[str, str]:
    """(number, unit) of ``x`` in ``unit`` (module docstring): the unit with its prefix."""
    if unit in COUNTS and float(x).is_integer():
        return str(int(x)), unit
    x = float(x)
    if not math.isfinite(x) or x == 0 or not _prefixable(unit) or not 1e-12 <= abs(x) < 1.0:
        return number(x, digits), unit
    for factor, prefix in PREFIXES:
        scaled = x / factor
        if abs(scaled) >= 1.0:
            text = number(scaled, digits)
            if abs(scaled) >= 999.95 and factor < 1.0:  # rounds up to 1000: the next prefix up
                return number(x / (factor * 1e3), digits), PREFIXES[PREFIXES.index((factor, prefix)) - 1][
                    1
                ] + unit
            return text, prefix + unit
    return number(x, digits), unit  # not reached: 1e-12 ≤ |x| < 1


def quantity(x: float, unit: str, digits: int = SIGNIFICANT) -> str:
    """``x`` in ``unit`` as one string, "62.91 µm" (module docstring)."""
    text, unit = split_quantity(x, unit, digits)
    return f"{text} {unit}" if unit and unit != "-" else text
