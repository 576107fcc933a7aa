"""Typed declarations of parameters and config sections (docs/design.md §4).

Every value a config can hold is declared once, as data: a :class:`Parameter` (name, kind,
default, one-line description) whose kind (:mod:`components.kinds`) may nest (a :class:`Record`
of parameters, a ``MapOf`` or ``ListOf`` them, a :class:`Tagged` choice of records). Conversion
to SI, the errors naming the key, ``orchestrator describe``, the components' docstring tables and
the resolved ``config.yaml`` all read that declaration.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from components.errors import ConfigError
from components.kinds import (  # noqa: F401 (the kinds are part of what a declaration imports from here)
    Anything,
    Bool,
    Duration,
    Float,
    Implausible,
    Int,
    Kind,
    ListOf,
    MapOf,
    OneOf,
    Problems,
    Str,
    UtcTime,
    Vector,
    implausible_values,
    join_key,
)

REQUIRED = object()
"""Default of a parameter the config must give."""


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
            shorthand: dict[str, Callable[[], Kind]] = {
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
        kind_unit = getattr(self.kind, "unit", "1")
        if self.unit is None and kind_unit != "1":
            object.__setattr__(self, "unit", kind_unit)
        if self.default is not REQUIRED and self.default is not None:
            try:
                with implausible_values() as found:
                    self.the_kind.convert(self.default, self.name)
            except ConfigError as e:
                raise ValueError(f"parameter {self.name}: its default does not fit its kind: {e}") from None
            if found:
                raise ValueError(f"parameter {self.name}: its default is not plausible: {found[0]}")

    @property
    def the_kind(self) -> Kind:
        """``kind`` as a Kind: ``__post_init__`` turned a shorthand ("float") into one."""
        assert isinstance(self.kind, Kind), "__post_init__ converts a shorthand kind"
        return self.kind

    @property
    def required(self) -> bool:
        return self.default is REQUIRED

    def convert(self, value: Any, key: str | None = None) -> Any:
        """The config value checked and in SI; None stands for "not given" when the default is None."""
        if value is None and self.default is None:
            return None
        return self.the_kind.convert(value, self.name if key is None else key)

    def plain(self, value: Any) -> Any:
        return None if value is None else self.the_kind.plain(value)

    @property
    def default_text(self) -> str:
        if self.required:
            return "required"
        if self.default is None:
            return "-"
        if isinstance(self.kind, Record):
            return "its defaults"
        value = self.plain(self.the_kind.convert(self.default, self.name))
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
                        join_key(key, str(name)), f"unknown {self.noun} (known: {', '.join(self.by_name) or 'none'})"
                    )
                )
        for name, p in self.by_name.items():
            sub = join_key(key, name)
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
            nested += [r for r in p.the_kind.records() if r not in nested]
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
        raise ConfigError(join_key(key, self.tag), f"expected one of {', '.join(tags)}, got {tag!r}")

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
            p.the_kind.text + (f"; plausible {r}" if (r := p.the_kind.plausible_text) else ""),
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
