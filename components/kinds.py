"""The kinds of a config value (docs/design.md §4): numbers with units, durations, UTC times,
strings, vectors, and lists, mappings and choices of them. A kind's ``convert(value, key)``
returns the checked value in SI (durations as integer ns, vectors as float64 arrays) or raises
ConfigError naming the key; ``plain(value)`` writes a converted value back as YAML.

A quantity may declare a ``plausible`` range (SI, inclusive) beside its unit: a value outside it
converts all the same, and is collected (:func:`implausible_values`) for a warning said in the
unit people use for it (components.units.implausible); ``--strict`` makes it an error.
:mod:`components.schema` puts kinds together into declared parameters and records.
"""

from __future__ import annotations

import datetime as dt
import re
from collections.abc import Mapping
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any

import numpy as np

from components.errors import ConfigError
from components.units import duration_ns, duration_text, implausible, say_range, to_si


class Problems(ConfigError):
    """Several problems found in one record; ``problems`` holds each (the first is the message)."""

    def __init__(self, problems: list[ConfigError]):
        super().__init__(problems[0].key, problems[0].message)
        self.problems = problems


@dataclass(frozen=True)
class Implausible:
    """A value outside its declared plausible range: ``key`` and why, in the unit people use."""

    key: str
    message: str

    def __str__(self) -> str:
        return f"{self.key}: {self.message}" if self.key else self.message


_FOUND: ContextVar[list | None] = ContextVar("implausible_values", default=None)


@contextmanager
def implausible_values():
    """Collect, into the list it yields, every value converted meanwhile that lies outside its
    plausible range (a warning, not an error: the conversion goes on)."""
    found: list[Implausible] = []
    token = _FOUND.set(found)
    try:
        yield found
    finally:
        _FOUND.reset(token)


def _plausible(written: Any, si: float, unit: str, plausible: tuple[float, float] | None, key: str) -> None:
    found = _FOUND.get()
    if plausible is not None and found is not None:
        message = implausible(written, si, unit, *plausible)
        if message:
            found.append(Implausible(key, message))


def _range_text(unit: str, plausible: tuple[float, float] | None) -> str:
    return "" if plausible is None else say_range(*plausible, unit)


def join_key(key: str, sub: str) -> str:
    return f"{key}.{sub}" if key else sub


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float, str)) and not isinstance(value, bool)


def _is_sequence(value: Any) -> bool:
    return isinstance(value, (list, tuple, np.ndarray))


class Kind:
    """The type of a config value; subclasses convert, check and describe it."""

    @property
    def text(self) -> str:
        """Its name in ``describe`` and messages ("float [m]"); a fixed one may be a class attribute."""
        return "any"

    def convert(self, value: Any, key: str) -> Any:
        return value

    def plain(self, value: Any) -> Any:
        """The converted value as plain YAML data."""
        if isinstance(value, np.ndarray):
            return value.tolist()
        if isinstance(value, np.generic):
            return value.item()
        if isinstance(value, Mapping):
            return {k: self.plain(v) for k, v in value.items()}
        if isinstance(value, (list, tuple)):
            return [self.plain(v) for v in value]
        return value

    def accepts(self, value: Any) -> bool:
        """Whether ``value`` has this kind's shape (a number, a list, a mapping...): OneOf picks by it."""
        return True

    def records(self) -> list:
        """The records (components.schema.Record) nested in this kind, for describe."""
        return []

    @property
    def plausible_text(self) -> str:
        """Its plausible range in the unit people use ("0 to 60 deg/s"), or "" when it declares none."""
        return ""


class Anything(Kind):
    """Any YAML value, passed on unchecked (for user components; the shipped ones declare types)."""


@dataclass(frozen=True)
class Float(Kind):
    """A real number in ``unit`` (a bare number is SI; "6778 km" is converted); optional bounds
    (beyond them: an error) and ``plausible`` range (SI; beyond it: a warning)."""

    unit: str = "1"
    minimum: float | None = None  # inclusive
    positive: bool = False
    maximum: float | None = None  # inclusive
    plausible: tuple[float, float] | None = None

    @property
    def plausible_text(self) -> str:
        return _range_text(self.unit, self.plausible)

    @property
    def text(self) -> str:
        return "float" if self.unit == "1" else f"float [{self.unit}]"

    def convert(self, value, key):
        x = to_si(value, self.unit, key)
        if self.positive and not x > 0.0:
            raise ConfigError(key, f"expected a quantity > 0, got {value!r}")
        if self.minimum is not None and not x >= self.minimum:
            raise ConfigError(key, f"expected a quantity >= {self.minimum:g}, got {value!r}")
        if self.maximum is not None and not x <= self.maximum:
            raise ConfigError(key, f"expected a quantity <= {self.maximum:g}, got {value!r}")
        _plausible(value, x, self.unit, self.plausible, key)
        return x

    def accepts(self, value):
        return _is_number(value)


@dataclass(frozen=True)
class Int(Kind):
    minimum: int | None = None
    text = "int"

    def convert(self, value, key):
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(key, f"expected an integer, got {value!r}")
        if self.minimum is not None and value < self.minimum:
            raise ConfigError(key, f"expected an integer >= {self.minimum}, got {value!r}")
        return value

    def accepts(self, value):
        return isinstance(value, int) and not isinstance(value, bool)


class Bool(Kind):
    text = "bool"

    def convert(self, value, key):
        if not isinstance(value, bool):
            raise ConfigError(key, f"expected true or false, got {value!r}")
        return value

    def accepts(self, value):
        return isinstance(value, bool)


@dataclass(frozen=True)
class Str(Kind):
    """A string: one of ``choices``, or matching ``pattern`` (``hint`` says what that means)."""

    choices: tuple[str, ...] = ()
    pattern: str | None = None
    hint: str = ""

    @property
    def text(self) -> str:
        return " | ".join(self.choices) if self.choices else "str"

    def convert(self, value, key):
        if not isinstance(value, str):
            raise ConfigError(key, f"expected {self.hint or 'a string'}, got {value!r}")
        if self.choices and value not in self.choices:
            raise ConfigError(key, f"expected one of {', '.join(self.choices)}, got {value!r}")
        if self.pattern and not re.fullmatch(self.pattern, value):
            raise ConfigError(key, f"expected {self.hint or 'a string matching ' + self.pattern}, got {value!r}")
        return value

    def accepts(self, value):
        return isinstance(value, str)


MAX_DURATION_NS = 100 * 31_557_600 * 10**9  # 100 Julian years: well inside int64 nanoseconds


@dataclass(frozen=True)
class Duration(Kind):
    """A time span, exact integer nanoseconds ("1 ms", "20 s", or a number of seconds);
    ``plausible``: a range in s."""

    positive: bool = True
    plausible: tuple[float, float] | None = None
    text = "duration"

    @property
    def plausible_text(self) -> str:
        return _range_text("s", self.plausible)

    def convert(self, value, key):
        ns = duration_ns(value, key)
        if ns < 0 or (self.positive and ns == 0):
            raise ConfigError(key, f"expected a duration {'>' if self.positive else '>='} 0, got {value!r}")
        if ns > MAX_DURATION_NS:
            raise ConfigError(
                key, f"expected a duration of at most 100 years (times are int64 nanoseconds), got {value!r}"
            )
        _plausible(value, ns / 1e9, "s", self.plausible, key)
        return ns

    def plain(self, value):
        return duration_text(value)

    def accepts(self, value):
        return _is_number(value)


class UtcTime(Kind):
    """A UTC time, e.g. 2022-09-18T12:00:00Z; kept as that ISO-8601 text."""

    text = "UTC time"

    def convert(self, value, key):
        if isinstance(value, dt.datetime):
            moment = value if value.tzinfo else value.replace(tzinfo=dt.UTC)
        elif isinstance(value, str):
            try:
                moment = dt.datetime.fromisoformat(value.replace("Z", "+00:00"))
            except ValueError as e:
                raise ConfigError(key, f"expected a UTC time like 2022-09-18T12:00:00Z, got {value!r} ({e})") from None
            if moment.tzinfo is None:
                raise ConfigError(key, f"give the time zone, e.g. 2022-09-18T12:00:00Z, got {value!r}")
        else:
            raise ConfigError(key, f"expected a UTC time like 2022-09-18T12:00:00Z, got {value!r}")
        return moment.astimezone(dt.UTC).isoformat().replace("+00:00", "Z")

    def accepts(self, value):
        return isinstance(value, (str, dt.datetime))


@dataclass(frozen=True)
class Vector(Kind):
    """``size`` numbers (any number if None) in ``unit``, or in ``units`` element by element;
    ``plausible``: one range (SI) for every element, or one per element (with ``units``)."""

    size: int | None = None
    unit: str = "1"
    units: tuple[str, ...] | None = None
    minimum: float | None = None  # inclusive, for every element
    plausible: tuple | None = None

    def _ranges(self, n: int) -> list:
        if self.plausible is None or not isinstance(self.plausible[0], tuple):
            return [self.plausible] * n
        return list(self.plausible)

    @property
    def plausible_text(self) -> str:
        units = self.units or (self.unit,) * len(self._ranges(1))
        texts = [_range_text(u, r) for u, r in zip(units, self._ranges(len(units)))]
        return ", ".join(dict.fromkeys(t for t in texts if t))

    @property
    def text(self) -> str:
        units = ", ".join(dict.fromkeys(self.units)) if self.units else self.unit
        return f"float[{self.size if self.size is not None else 'n'}]" + (f" [{units}]" if units != "1" else "")

    def convert(self, value, key):
        if not _is_sequence(value):
            raise ConfigError(key, f"expected a list of {self.size or 'some'} numbers, got {value!r}")
        values = list(value)
        if self.size is not None and len(values) != self.size:
            raise ConfigError(key, f"expected {self.size} values, got {len(values)}")
        units = self.units or (self.unit,) * len(values)
        array = np.array([to_si(v, u, f"{key}[{i}]") for i, (v, u) in enumerate(zip(values, units))], dtype=np.float64)
        if self.minimum is not None and np.any(array < self.minimum):
            i = int(np.argmax(array < self.minimum))
            raise ConfigError(f"{key}[{i}]", f"expected a quantity >= {self.minimum:g}, got {values[i]!r}")
        for i, (v, u, r) in enumerate(zip(values, units, self._ranges(len(values)))):
            _plausible(v, float(array[i]), u, r, f"{key}[{i}]")
        return array

    def accepts(self, value):
        return _is_sequence(value)


class _OfItems(Kind):
    """A kind over items of one kind (``item``): its records and plausible range are the item's."""

    item: Kind

    def records(self):
        return self.item.records()

    @property
    def plausible_text(self) -> str:
        return self.item.plausible_text


@dataclass(frozen=True)
class ListOf(_OfItems):
    item: Kind
    min_items: int = 0
    max_items: int | None = None
    unique: bool = False

    @property
    def text(self) -> str:
        if self.max_items is not None and self.max_items == self.min_items:
            return f"list of {self.max_items} {self.item.text}"
        return f"list of {self.item.text}"

    def convert(self, value, key):
        if not _is_sequence(value):
            raise ConfigError(key, f"expected a list of {self.item.text}, got {value!r}")
        if len(value) < self.min_items or (self.max_items is not None and len(value) > self.max_items):
            if self.max_items == self.min_items:
                wanted = f"{self.text}"
            elif len(value) < self.min_items:
                wanted = f"at least {self.min_items} item{'s' * (self.min_items > 1)}"
            else:
                wanted = f"at most {self.max_items} items"
            raise ConfigError(key, f"expected {wanted}, got {len(value)}")
        items = [self.item.convert(v, f"{key}[{i}]") for i, v in enumerate(value)]
        if self.unique:
            repeated = [v for i, v in enumerate(items) if v in items[:i]]
            if repeated:
                raise ConfigError(key, f"{repeated[0]!r} listed twice")
        return items

    def plain(self, value):
        return [self.item.plain(v) for v in value]

    def accepts(self, value):
        return _is_sequence(value)


@dataclass(frozen=True)
class MapOf(_OfItems):
    """A mapping from names (``key_text`` says of what; ``key_pattern`` restricts them) to ``item``."""

    item: Kind
    key_text: str = "name"
    key_pattern: str | None = None
    min_items: int = 0

    @property
    def text(self) -> str:
        return f"{{{self.key_text}: {self.item.text}}}"

    def convert(self, value, key):
        if not isinstance(value, Mapping):
            raise ConfigError(key, f"expected a mapping {self.key_text} -> {self.item.text}, got {value!r}")
        if len(value) < self.min_items:
            raise ConfigError(key, f"expected at least {self.min_items} {self.key_text}, got none")
        out, problems = {}, []
        for name, v in value.items():
            if not isinstance(name, str) or (self.key_pattern and not re.fullmatch(self.key_pattern, name)):
                problems.append(
                    ConfigError(
                        join_key(key, str(name)),
                        f"a {self.key_text} must be an identifier (letters, digits, _), got {name!r}",
                    )
                )
                continue
            try:
                out[name] = self.item.convert(v, join_key(key, name))
            except Problems as e:
                problems += e.problems
            except ConfigError as e:
                problems.append(e)
        if problems:
            raise Problems(problems)
        return out

    def plain(self, value):
        return {k: self.item.plain(v) for k, v in value.items()}

    def accepts(self, value):
        return isinstance(value, Mapping)


@dataclass(frozen=True)
class OneOf(Kind):
    """One of several kinds, told apart by shape: the first option that ``accepts`` the value."""

    options: tuple[Kind, ...]

    @property
    def text(self) -> str:
        return " or ".join(o.text for o in self.options)

    def _option(self, value) -> Kind | None:
        return next((o for o in self.options if o.accepts(value)), None)

    def convert(self, value, key):
        """The first option of the value's shape that converts it (Float("rad") before Float("m"))."""
        first = None
        found = _FOUND.get()
        for option in self.options:
            if option.accepts(value):
                before = len(found) if found is not None else 0
                try:
                    return option.convert(value, key)
                except ConfigError as e:
                    first = first or e
                    if found is not None:  # what a rejected option found is not about the value
                        del found[before:]
        raise first or ConfigError(key, f"expected {self.text}, got {value!r}")

    def plain(self, value):
        if isinstance(value, np.ndarray):
            return value.tolist()
        option = next((o for o in self.options if o.accepts(value)), Kind())
        return option.plain(value)

    def accepts(self, value):
        return self._option(value) is not None

    @property
    def plausible_text(self) -> str:
        return ", ".join(dict.fromkeys(t for o in self.options if (t := o.plausible_text)))

    def records(self):
        return [r for o in self.options for r in o.records()]
