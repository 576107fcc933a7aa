"""Quantities with units in configs: ``6778 km``, ``51.6 deg``, ``1 ms``, ``20s``, ``1.5e-3 N*m``.

Everything in code, on the bus and in recordings is SI; units only exist at the config edge.
A declared unit ("m", "rad", "m/s", "N*m", "kg*m^2", "1") fixes the dimension a value must have;
a bare number is taken as already SI.
"""

from __future__ import annotations

import math
import re
from decimal import ROUND_HALF_EVEN, Decimal

from components.errors import ConfigError

DEG = math.pi / 180.0  # rad per degree, for plausible ranges declared in degrees

# symbol -> (factor to SI, dimension exponents over (m, kg, s, rad, A))
_SYMBOLS: dict[str, tuple[float, tuple[int, int, int, int, int]]] = {
    "1": (1.0, (0, 0, 0, 0, 0)),
    "m": (1.0, (1, 0, 0, 0, 0)),
    "km": (1e3, (1, 0, 0, 0, 0)),
    "cm": (1e-2, (1, 0, 0, 0, 0)),
    "mm": (1e-3, (1, 0, 0, 0, 0)),
    "kg": (1.0, (0, 1, 0, 0, 0)),
    "g": (1e-3, (0, 1, 0, 0, 0)),
    "s": (1.0, (0, 0, 1, 0, 0)),
    "ms": (1e-3, (0, 0, 1, 0, 0)),
    "us": (1e-6, (0, 0, 1, 0, 0)),
    "ns": (1e-9, (0, 0, 1, 0, 0)),
    "min": (60.0, (0, 0, 1, 0, 0)),
    "h": (3600.0, (0, 0, 1, 0, 0)),
    "d": (86400.0, (0, 0, 1, 0, 0)),
    "day": (86400.0, (0, 0, 1, 0, 0)),
    "rad": (1.0, (0, 0, 0, 1, 0)),
    "deg": (3.141592653589793 / 180.0, (0, 0, 0, 1, 0)),
    "N": (1.0, (1, 1, -2, 0, 0)),
    "Hz": (1.0, (0, 0, -1, 0, 0)),
    "A": (1.0, (0, 0, 0, 0, 1)),  # magnetic dipoles: A*m^2
    "T": (1.0, (0, 1, -2, 0, -1)),
    "mT": (1e-3, (0, 1, -2, 0, -1)),  # magnetic flux density
    "uT": (1e-6, (0, 1, -2, 0, -1)),
    "nT": (1e-9, (0, 1, -2, 0, -1)),
}
# what a unit expression may be, for messages
_UNIT_FORM = f"symbols among {', '.join(_SYMBOLS)}, joined by * and / with integer powers as in kg*m^2"
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_QUANTITY = re.compile(rf"^\s*({_NUMBER})\s*([A-Za-z][A-Za-z0-9*/^\-]*)?\s*$")


def parse_unit(text: str) -> tuple[float, tuple[int, ...]]:
    """Factor to SI and dimension (exponents over m, kg, s, rad, and A when not 0) of a unit expression such as
    ``km/s`` or ``kg*m^2``: the symbols m km cm mm, kg g, s ms us ns min h d day, rad deg, N, Hz,
    A, T mT uT nT and 1, joined by ``*`` and ``/``, each with an optional integer power ``^n``. Raises ValueError
    naming the symbols it reads otherwise."""
    factor, dim = 1.0, [0, 0, 0, 0, 0]
    sign = 1
    for token in re.split(r"([*/])", text.replace(" ", "")):
        if token in ("*", "/"):
            sign = 1 if token == "*" else -1
            continue
        name, _, power = token.partition("^")
        if name not in _SYMBOLS or (power and not re.fullmatch(r"-?\d+", power)):
            raise ValueError(f"unknown unit {text!r} (expected {_UNIT_FORM})")
        f, d = _SYMBOLS[name]
        p = sign * (int(power) if power else 1)
        factor *= f**p
        dim = [a + p * b for a, b in zip(dim, d)]
    return factor, tuple(dim if dim[4] else dim[:4])  # the ampere's exponent only when a unit has one


def parse_quantity(value, key: str) -> tuple[float, str | None]:
    """The number and the unit of a config value, the number as written (not converted to SI):
    ``"0.1 rad/s"`` -> (0.1, "rad/s"), ``"20s"`` -> (20.0, "s"), ``3`` or ``"3"`` -> (3.0, None)
    (no unit: the number is already SI). :func:`parse_unit` reads the unit; :func:`to_si` converts.

    Raises ConfigError naming ``key``, with what was expected next to what was given, for a value
    that is not a number or ``"<number> <unit>"``, an unknown unit or a number that is not finite.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise ConfigError(key, f"expected a number or a quantity like '0.1 rad/s', got {value!r}")
    if isinstance(value, str):
        m = _QUANTITY.match(value)
        if not m:
            raise ConfigError(key, f"expected a number or a quantity like '0.1 rad/s', got {value!r}")
        number, unit = float(m.group(1)), m.group(2)
        if unit is not None and unit_scale(unit) is None:
            raise ConfigError(key, f"unknown unit {unit!r} in {value!r} (expected {_UNIT_FORM})")
    else:
        number, unit = float(value), None
    if not math.isfinite(number):
        raise ConfigError(key, f"expected a finite number, got {value!r}")
    return number, unit


def unit_scale(text: str) -> tuple[float, tuple[int, ...]] | None:
    """Factor to SI and dimension of a unit expression, or None when it is not one this module reads."""
    try:
        return parse_unit(text)
    except ValueError:
        return None


def normalized_unit(text: str) -> str:
    """An FMI/Modelica unit ("N.m", "kg.m2", "m/s2") in this module's notation ("N*m", "kg*m^2",
    "m/s^2") when it reads so; else the text as given."""
    candidate = re.sub(r"([A-Za-z])(-?\d+)", r"\1^\2", text.strip().replace(".", "*"))
    return candidate if unit_scale(candidate) is not None else text


def to_si(value, unit: str, key: str) -> float:
    """Convert a config value to SI in the dimension of ``unit``.

    ``value`` is a number (taken as SI) or a string "<number> <unit>" whose unit must have the
    same dimension as ``unit``. Raises ConfigError naming ``key`` otherwise.
    """
    if isinstance(value, bool):
        raise ConfigError(key, f"expected a quantity in {unit}, got {value!r}")
    if isinstance(value, (int, float)):
        if not math.isfinite(value):
            raise ConfigError(key, f"expected a finite quantity in {unit}, got {value!r}")
        return float(value)
    if not isinstance(value, str):
        raise ConfigError(key, f"expected a quantity in {unit}, got {value!r}")
    m = _QUANTITY.match(value)
    if not m:
        raise ConfigError(key, f"expected a number with a unit like '6778 km', got {value!r}")
    number, given = float(m.group(1)), m.group(2)
    if not math.isfinite(number):
        raise ConfigError(key, f"expected a finite quantity in {unit}, got {value!r}")
    if given is None:
        return number
    try:
        factor, dim = parse_unit(given)
    except ValueError:
        raise ConfigError(key, f"unknown unit {given!r} in {value!r} (expected a unit of {unit})") from None
    _, want = parse_unit(unit)
    if dim != want:
        raise ConfigError(key, f"unit {given!r} does not measure {unit} (got {value!r})")
    return number * factor


_TIME_NS = {
    "ns": 1,
    "us": 10**3,
    "ms": 10**6,
    "s": 10**9,
    "min": 60 * 10**9,
    "h": 3600 * 10**9,
    "d": 86400 * 10**9,
    "day": 86400 * 10**9,
}


def duration_text(ns: int) -> str:
    """Exact integer nanoseconds in the largest unit that keeps them whole: 3e9 -> ``"3 s"``,
    1_500_000_000 -> ``"1500 ms"``, 5_400_000_000_000 -> ``"90 min"``. duration_ns reads it back."""
    for unit in ("h", "min", "s", "ms", "us", "ns"):
        if ns % _TIME_NS[unit] == 0:
            return f"{ns // _TIME_NS[unit]} {unit}"
    raise AssertionError("unreachable: every integer is whole in ns")


def duration_ns(value, key: str) -> int:
    """A time span as exact integer nanoseconds: ``"1 ms"`` -> 1_000_000, ``0.02`` (s) -> 20_000_000.

    Decimal arithmetic, so decimal input such as ``"0.1 s"`` does not pick up binary rounding.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise ConfigError(key, f"expected a duration like '1 ms', got {value!r}")
    if isinstance(value, str):
        m = _QUANTITY.match(value)
        if not m:
            raise ConfigError(key, f"expected a duration like '1 ms' or '20 s', got {value!r}")
        number, unit = m.group(1), m.group(2) or "s"
        if unit not in _TIME_NS:
            raise ConfigError(key, f"unknown time unit {unit!r} in {value!r} (expected one of {', '.join(_TIME_NS)})")
    else:
        if not math.isfinite(value):
            raise ConfigError(key, f"expected a finite duration like '1 ms', got {value!r}")
        number, unit = repr(value), "s"
    return int((Decimal(number) * _TIME_NS[unit]).to_integral_value(ROUND_HALF_EVEN))


# The unit people read a quantity in, by dimension (m, kg, s, rad): angles in degrees; time and
# length by magnitude (below); every other dimension in its SI unit.
_ANGLE_DISPLAY = {(0, 0, 0, 1): "deg", (0, 0, -1, 1): "deg/s", (0, 0, -2, 1): "deg/s^2"}
_TIME, _LENGTH = (0, 0, 1, 0), (1, 0, 0, 0)
# a bare number the user may have meant in another unit: the units to suggest, by dimension
_MEANT: dict[tuple[int, ...], tuple[str, ...]] = {
    (0, 0, 0, 1): ("deg",),
    (0, 0, -1, 1): ("deg/s",),
    (0, 0, -2, 1): ("deg/s^2",),
    _TIME: ("ms", "us", "min", "h"),
    _LENGTH: ("km", "mm", "cm"),
    (0, 1, 0, 0): ("g",),
}
_UNIT_NAMES = {
    "deg": "degrees",
    "deg/s": "degrees",
    "deg/s^2": "degrees",
    "ms": "milliseconds",
    "us": "microseconds",
    "min": "minutes",
    "h": "hours",
    "km": "kilometres",
    "mm": "millimetres",
    "cm": "centimetres",
    "g": "grams",
}


def figure(x: float) -> str:
    """A number to 3 significant digits, without an exponent between 1e-4 and 1e6: 458.37 -> '458'."""
    return f"{float(f'{x:.3g}'):g}"


def display_unit(si: float, unit: str) -> str:
    """The unit people read ``si`` (a value in ``unit``'s SI) in: rad/s -> deg/s, rad -> deg,
    s -> us, ms, s or h, m -> mm, m or km by magnitude; else ``unit`` itself."""
    _, dim = parse_unit(unit)
    if dim in _ANGLE_DISPLAY:
        return _ANGLE_DISPLAY[dim]
    size = abs(si)
    if dim == _TIME:
        return "s" if size == 0 else "us" if size < 1e-3 else "ms" if size < 1 else "h" if size >= 3600 else "s"
    if dim == _LENGTH:
        return "m" if size == 0 else "mm" if size < 1e-2 else "km" if size >= 1e4 else "m"
    return unit


def say(si: float, unit: str, shown: str | None = None) -> str:
    """``si`` (SI, in ``unit``'s dimension) in the unit people use: say(8, "rad/s") -> '458 deg/s'."""
    shown = shown or display_unit(si, unit)
    number = figure(si / parse_unit(shown)[0])
    return number if shown == "1" else f"{number} {shown}"


def say_range(lo: float, hi: float, unit: str) -> str:
    """A range in the unit people use, the unit once when both ends share it: '0 to 60 deg/s'."""
    a, b = display_unit(lo, unit), display_unit(hi, unit)
    if a == b:
        return f"{figure(lo / parse_unit(a)[0])} to {say(hi, unit, b)}"
    return f"{say(lo, unit, a)} to {say(hi, unit, b)}"


def implausible(written, si: float, unit: str, lo: float, hi: float) -> str | None:
    """Why a value outside its plausible range [lo, hi] (SI, inclusive) is suspect, or None within it.
    It says the value as written, in the unit people use, the range, and for a bare number (SI) a
    unit that would make it plausible: 8 for rad/s -> "8 (read as rad/s) = 458 deg/s, outside the
    plausible 0 to 60 deg/s; write '8 deg/s' for degrees"."""
    if lo <= si <= hi:
        return None
    number, given = parse_quantity(written, "")
    typed = written.strip() if isinstance(written, str) else f"{number:.12g}"  # the user's own text
    shown = display_unit(si, unit)
    if given is None:
        as_written = typed + ("" if unit == "1" else f" (read as {unit})")
        text = as_written if shown == unit else f"{as_written} = {say(si, unit, shown)}"
    else:
        text = typed if shown == given else f"{typed} = {say(si, unit, shown)}"
    text += f", outside the plausible {say_range(lo, hi, unit)}"
    if given is None and unit != "1":
        meant = [u for u in _MEANT.get(parse_unit(unit)[1], ()) if lo <= number * parse_unit(u)[0] <= hi]
        if meant:
            text += f"; write '{typed} {meant[0]}' for {_UNIT_NAMES[meant[0]]}"
    return text
