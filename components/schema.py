"""Typed declarations of parameters and config sections (docs/design.md §4).

Every value a config can hold is declared once, as data: a :class:`Parameter` (name, kind,
default, one-line description) whose kind may nest (a :class:`Record` of parameters, a
:class:`MapOf` or :class:`ListOf` them, a :class:`Tagged` choice of records). Conversion to SI,
the errors naming the key, ``orchestrator describe``, the components' docstring tables and the
resolved ``config.yaml`` all read that declaration.

A kind's ``convert(value, key)`` returns the checked value in SI (durations as integer ns,
vectors as float64 arrays, records as dicts with every field) or raises ConfigError naming the
key; ``plain(value)`` writes a converted value back as YAML.

A quantity may declare a ``plausible`` range (SI, inclusive) beside its unit: a value outside it
converts all the same, and is collected (:func:`implausible_values`) for a warning said in the
unit people use for it (components.units.implausible); ``--strict`` makes it an error.
"""

from __future__ import annotations

import datetime as dt
import re
from collections.abc import Mapping
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from components.errors import ConfigError
from components.units import duration_ns, duration_text, implausible, say_range, to_si

REQUIRED = object()
"""Default of a parameter the config must give."""


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


def _join(key: str, sub: str) -> str:
    return f"{key}.{sub}" if key else sub


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float, str)) and not isinstance(value, bool)


def _is_sequence(value: Any) -> bool:
    return isinstance(value, (list, tuple, np.ndarray))


class Kind:
    """The type of a config value; subclasses convert, check and describe it."""

    text = "any"

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

    def records(self) -> list[Record]:
        """The records nested in this kind, for describe."""
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


@dataclass(frozen=True)
class ListOf(Kind):
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

    def records(self):
        return self.item.records()

    @property
    def plausible_text(self) -> str:
        return self.item.plausible_text


@dataclass(frozen=True)
class MapOf(Kind):
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
                        _join(key, str(name)),
                        f"a {self.key_text} must be an identifier (letters, digits, _), got {name!r}",
                    )
                )
                continue
            try:
                out[name] = self.item.convert(v, _join(key, name))
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

    def records(self):
        return self.item.records()

    @property
    def plausible_text(self) -> str:
        return self.item.plausible_text


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


@dataclass(frozen=True)
class Parameter:
    """One declared value: of a component type (its ``parameters``) or a field of a :class:`Record`.

    ``kind`` is a :class:`Kind`, or for short one of "float", "int", "bool", "str", "vector",
    "any" with ``unit``, ``shape``, ``choices`` and ``plausible`` (a range in SI: beyond it, a
    warning). ``default`` REQUIRED makes it required; a default of None makes it optional (null,
    or absent, means "not given"); a default must lie within the plausible range.
    """

    name: str
    kind: Kind | str
    unit: str | None = None
    default: Any = REQUIRED
    description: str = ""
    shape: tuple[int, ...] | None = None
    choices: tuple[str, ...] | None = None
    plausible: tuple[float, float] | None = None

    def __post_init__(self):
        if self.plausible is not None and not (isinstance(self.kind, str) and self.kind in ("float", "vector")):
            raise ValueError(
                f"parameter {self.name}: plausible= goes with kind 'float' or 'vector'; "
                f"give a Kind its own (Float(unit, plausible=...))"
            )
        if isinstance(self.kind, str):
            unit = self.unit or "1"
            shorthand = {
                "float": lambda: Float(unit, plausible=self.plausible),
                "int": Int,
                "bool": Bool,
                "str": lambda: Str(tuple(self.choices or ())),
                "any": Anything,
                "vector": lambda: Vector(self.shape[0] if self.shape else None, unit, plausible=self.plausible),
            }
            if self.kind not in shorthand:
                raise ValueError(
                    f"parameter {self.name}: kind must be a Kind or one of {', '.join(shorthand)}, got {self.kind!r}"
                )
            object.__setattr__(self, "kind", shorthand[self.kind]())
        if self.unit is None and getattr(self.kind, "unit", "1") != "1":
            object.__setattr__(self, "unit", self.kind.unit)
        if self.default is not REQUIRED and self.default is not None:
            try:
                with implausible_values() as found:
                    self.kind.convert(self.default, self.name)
            except ConfigError as e:
                raise ValueError(f"parameter {self.name}: its default does not fit its kind: {e}") from None
            if found:
                raise ValueError(f"parameter {self.name}: its default is not plausible: {found[0]}")

    @property
    def required(self) -> bool:
        return self.default is REQUIRED

    def convert(self, value: Any, key: str | None = None) -> Any:
        """The config value checked and in SI; None stands for "not given" when the default is None."""
        if value is None and self.default is None:
            return None
        return self.kind.convert(value, self.name if key is None else key)

    def plain(self, value: Any) -> Any:
        return None if value is None else self.kind.plain(value)

    @property
    def default_text(self) -> str:
        if self.required:
            return "required"
        if self.default is None:
            return "-"
        if isinstance(self.kind, Record):
            return "its defaults"
        value = self.plain(self.kind.convert(self.default, self.name))
        if isinstance(value, bool):
            return str(value).lower()
        return f"{value:.12g}" if isinstance(value, float) else str(value)


@dataclass(frozen=True)
class Record(Kind):
    """A mapping with declared fields: unknown keys and missing required ones are errors.

    ``noun`` names a field in messages ("key", "parameter of orbit.kepler"); ``extra`` lists
    keys passed through unchecked (the run parameters the orchestrator injects).
    """

    name: str
    fields: tuple[Parameter, ...]
    description: str = ""
    noun: str = "key"
    extra: tuple[str, ...] = ()
    by_name: dict = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        object.__setattr__(self, "by_name", {p.name: p for p in self.fields})

    @property
    def text(self) -> str:
        return self.name

    def resolve(self, raw: Any, key: str = "") -> tuple[dict, list[ConfigError]]:
        """Every field converted (defaults filled) and every problem found, each naming its key."""
        if raw is None:
            raw = {}
        if not isinstance(raw, Mapping):
            return {}, [ConfigError(key, f"expected a mapping ({self.name}), got {raw!r}")]
        out = {k: raw[k] for k in self.extra if k in raw}
        problems: list[ConfigError] = []
        for name in raw:
            if name not in self.by_name and name not in self.extra:
                problems.append(
                    ConfigError(
                        _join(key, str(name)), f"unknown {self.noun} (known: {', '.join(self.by_name) or 'none'})"
                    )
                )
        for name, p in self.by_name.items():
            sub = _join(key, name)
            if name not in raw or (raw[name] is None and not p.required):  # null: not given
                if p.required:
                    problems.append(
                        ConfigError(
                            sub,
                            f"missing required {self.noun.split(' of ')[0]}"
                            + (f" ({p.description})" if p.description else ""),
                        )
                    )
                    continue
                value = p.default
            else:
                value = raw[name]
            try:
                out[name] = p.convert(value, sub)
            except Problems as e:
                problems += e.problems
            except ConfigError as e:
                problems.append(e)
        return out, problems

    def convert(self, value, key):
        out, problems = self.resolve(value, key)
        if problems:
            raise Problems(problems)
        return out

    def plain(self, value):
        return {p.name: p.plain(value.get(p.name)) for p in self.fields}

    def accepts(self, value):
        return isinstance(value, Mapping)

    def records(self):
        nested = [self]
        for p in self.fields:
            nested += [r for r in p.kind.records() if r not in nested]
        return nested


@dataclass(frozen=True)
class Tagged(Kind):
    """A record chosen by its ``tag`` key (e.g. ``type: parabola``); ``default_tag`` when absent."""

    name: str
    tag: str
    variants: tuple[Record, ...]
    default_tag: str | None = None

    @property
    def text(self) -> str:
        return f"{self.name} ({self.tag}: {' | '.join(r.name for r in self.variants)})"

    def _variant(self, value, key) -> Record:
        tags = [r.name for r in self.variants]
        tag = value.get(self.tag, self.default_tag)
        for r in self.variants:
            if r.name == tag:
                return r
        raise ConfigError(_join(key, self.tag), f"expected one of {', '.join(tags)}, got {tag!r}")

    def convert(self, value, key):
        if not isinstance(value, Mapping):
            raise ConfigError(
                key, f"expected a mapping with {self.tag}: {' | '.join(r.name for r in self.variants)}, got {value!r}"
            )
        variant = self._variant(value, key)
        body = {k: v for k, v in value.items() if k != self.tag}
        return {self.tag: variant.name, **variant.convert(body, key)}

    def plain(self, value):
        variant = next(r for r in self.variants if r.name == value[self.tag])
        return {self.tag: variant.name, **variant.plain(value)}

    def accepts(self, value):
        return isinstance(value, Mapping)

    def records(self):
        return [r for v in self.variants for r in v.records()]


def _cell(text: Any) -> str:
    return str(text).replace("|", "\\|")


def table(fields: tuple[Parameter, ...]) -> list[tuple[str, str, str, str]]:
    """Rows (name, type with its unit and plausible range, default, description) of declared parameters."""
    return [
        (
            p.name,
            p.kind.text + (f"; plausible {r}" if (r := p.kind.plausible_text) else ""),
            p.default_text,
            p.description,
        )
        for p in fields
    ]


def markdown(record: Record, where: str = "") -> str:
    """The record's parameter table, then one table per nested record, as Markdown."""
    lines = []
    for r in record.records():
        if r is not record:
            lines += ["", f"``{r.name}``" + (f": {r.description}" if r.description else "") + "", ""]
        lines += ["| parameter | type | default | description |", "|---|---|---|---|"]
        lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in table(r.fields)]
    return "\n".join(lines)
