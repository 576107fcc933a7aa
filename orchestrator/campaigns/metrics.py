"""Campaign metrics: parsing ``{signal, reduce[, threshold]}`` or ``{event, field, reduce}`` and reducing a
recording's signal, or its events, to one value.

| form | value |
|---|---|
| ``{signal: C.OUT, reduce: R}`` | R over the signal (a vector: its row-wise norm) |
| ``{signal: C.OUT[i:j], reduce: R}`` | R over the norm of elements i..j-1 (a force out of a wrench) |
| ``{event: NAME, field: F}`` | F of the first NAME event (NaN, or '' for text, when there is none) |
| ``{event: NAME, field: F, reduce: first, last, min, max}`` | over the NAME events |
| ``{event: NAME, reduce: count}`` | how many NAME events |
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from components.errors import ConfigError
from components.units import parse_quantity, parse_unit, to_si, unit_scale
from orchestrator.config.specs import RunConfig

REDUCERS = ("final", "min", "max", "mean", "rms", "max_abs", "first_crossing")
EVENT_REDUCERS = ("first", "last", "min", "max", "count")
_SLICE = re.compile(r"^(.+)\[(\d+):(\d+)\]$")


@dataclass(frozen=True)
class Metric:
    """``name``: ``reduce`` of the columns ``columns`` (several: the row-wise norm), or of the
    field ``field`` of the events ``event``."""

    name: str
    signal: str
    reduce: str
    columns: tuple[str, ...]
    threshold: float | None = None
    event: str | None = None
    field: str | None = None
    unit: str = "1"

    def value(self, time: np.ndarray, table: dict[str, np.ndarray], events: Sequence[dict] = ()) -> float | str:
        """The metric of a recording (``table``: column -> values, ``events``: events.jsonl's
        records); NaN if it has no rows (or no such event)."""
        if self.event is not None:
            return event_value(self, [e for e in events if e.get("event") == self.event])
        if not len(time):
            return math.nan
        if len(self.columns) == 1:
            x = np.asarray(table[self.columns[0]], dtype=float)
        else:
            x = np.sqrt(np.sum(np.column_stack([table[c] for c in self.columns]) ** 2, axis=1))
        return reduce_signal(self.reduce, np.asarray(time, dtype=float), x, self.threshold)


def reduce_signal(how: str, t: np.ndarray, x: np.ndarray, threshold: float | None = None) -> float:
    """One number from a signal: final, min, max, mean, rms, max_abs, or first_crossing: the first
    time (s) at which ``x`` reaches ``threshold`` from the side it starts on (NaN if never)."""
    if how == "final":
        return float(x[-1])
    if how == "min":
        return float(np.min(x))
    if how == "max":
        return float(np.max(x))
    if how == "mean":
        return float(np.mean(x))
    if how == "rms":
        return float(np.sqrt(np.mean(x * x)))
    if how == "max_abs":
        return float(np.max(np.abs(x)))
    if how == "first_crossing":
        above = x >= threshold
        crossed = np.flatnonzero(above != above[0]) if x[0] != threshold else np.array([0])
        return float(t[crossed[0]]) if len(crossed) else math.nan
    raise ValueError(f"unknown reducer {how!r}")


def signals_of(config: RunConfig) -> dict[str, tuple[tuple[str, ...], str]]:
    """Every signal a recording of ``config`` holds: ``<component>.<output>`` and each element
    ``...[i]`` -> (its columns, its unit)."""
    out: dict[str, tuple[tuple[str, ...], str]] = {}
    for spec in config.components.values():
        for v in spec.outputs.variables:
            columns = tuple(v.columns(spec.name))
            if not columns:
                continue
            out[f"{spec.name}.{v.name}"] = (columns, v.unit)
            if len(columns) > 1 or columns[0] != f"{spec.name}.{v.name}":
                for c in columns:
                    out[c] = ((c,), v.unit)
    return out


def event_value(m: Metric, events: list[dict]) -> float | str:
    if m.reduce == "count":
        return float(len(events))
    values = [e[m.field] for e in events if m.field in e]
    if not values:
        return math.nan
    if m.reduce in ("first", "last"):
        value = values[0] if m.reduce == "first" else values[-1]
        return (
            value if isinstance(value, str) else float(value) if isinstance(value, (int, float)) else json.dumps(value)
        )
    numbers = [float(v) for v in values if isinstance(v, (int, float)) and not isinstance(v, bool)]
    if not numbers:
        return math.nan
    return min(numbers) if m.reduce == "min" else max(numbers)


def metric(name: str, spec: Any, signals: dict[str, tuple[tuple[str, ...], str]] | None, where: str) -> Metric:
    """Parse ``{signal, reduce[, threshold]}`` (against the signals of the base config) or
    ``{event, field, reduce}``."""
    if not isinstance(spec, dict):
        raise ConfigError(
            where, f"expected {{signal: COMPONENT.OUTPUT, reduce: ...}} or {{event: NAME, field: FIELD}}, got {spec!r}"
        )
    if "event" in spec:
        return _event_metric(name, spec, where)
    unknown = [k for k in spec if k not in ("signal", "reduce", "threshold")]
    if unknown:
        raise ConfigError(
            f"{where}.{unknown[0]}", "unknown key (known: signal, reduce, threshold; or event, field, reduce)"
        )
    for k in ("signal", "reduce"):
        if k not in spec:
            raise ConfigError(f"{where}.{k}", "missing")
    how = spec["reduce"]
    if how not in REDUCERS:
        raise ConfigError(f"{where}.reduce", f"expected one of {', '.join(REDUCERS)}, got {how!r}")
    signal = str(spec["signal"])
    unit = "1"
    columns: tuple[str, ...] = (signal,)
    if signals is not None:
        columns, unit = _columns(signal, signals, where)
    threshold = _threshold(spec, how, unit, where)
    return Metric(name, signal, how, columns, threshold, unit=unit)


def _event_metric(name: str, spec: dict, where: str) -> Metric:
    """``{event, field, reduce}``: a field of the named events, or how many there are."""
    unknown = [k for k in spec if k not in ("event", "field", "reduce")]
    if unknown:
        raise ConfigError(f"{where}.{unknown[0]}", "unknown key (known for an event metric: event, field, reduce)")
    how = spec.get("reduce", "first")
    if how not in EVENT_REDUCERS:
        raise ConfigError(
            f"{where}.reduce", f"expected one of {', '.join(EVENT_REDUCERS)} for an event metric, got {how!r}"
        )
    if how != "count" and "field" not in spec:
        raise ConfigError(
            f"{where}.field", f"missing: which field of the {spec['event']!r} events (e.g. time), or reduce: count"
        )
    if not isinstance(spec["event"], str) or not spec["event"]:
        raise ConfigError(f"{where}.event", f"expected an event name, got {spec['event']!r}")
    field = spec.get("field")
    return Metric(
        name,
        "",
        how,
        (),
        event=spec["event"],
        field=None if field is None else str(field),
        unit="s" if field == "time" else "1",
    )


def _columns(signal: str, signals: dict[str, tuple[tuple[str, ...], str]], where: str) -> tuple[tuple[str, ...], str]:
    """The recorded columns of ``signal`` (``C.OUT`` or a slice ``C.OUT[i:j]``) and their unit (a
    slice's own where the signal's unit list gives it one)."""
    sliced = _SLICE.match(signal)
    whole = sliced.group(1) if sliced else signal
    if whole not in signals:
        near = sorted(k for k in signals if "[" not in k)
        raise ConfigError(
            f"{where}.signal", f"no signal {whole!r} in a recording of the config (signals: {', '.join(near)})"
        )
    columns, unit = signals[whole]
    if sliced:
        i, j = int(sliced.group(2)), int(sliced.group(3))
        if not 0 <= i < j <= len(columns):
            raise ConfigError(
                f"{where}.signal",
                f"expected a slice [i:j] with 0 <= i < j <= {len(columns)} (the size of {whole}), got [{i}:{j}]",
            )
        parts = [u.strip() for u in unit.split(",")]
        if len(columns) % len(parts) == 0:  # "N, N*m" over 6 elements: each unit covers a half
            per = len(columns) // len(parts)
            covered = {parts[k // per] for k in range(i, j)}
            unit = covered.pop() if len(covered) == 1 else unit
        columns = columns[i:j]
    return columns, unit


def _threshold(spec: dict, how: str, unit: str, where: str) -> float | None:
    """first_crossing's threshold in SI (in the signal's unit when it has one); no other takes one."""
    threshold = None
    if how == "first_crossing":
        if "threshold" not in spec:
            raise ConfigError(f"{where}.threshold", "first_crossing needs a threshold, e.g. threshold: 0.1 rad/s")
        value = spec["threshold"]
        if unit not in (None, "1") and unit_scale(unit) is not None:
            threshold = to_si(value, unit, f"{where}.threshold")
        else:
            number, given = parse_quantity(value, f"{where}.threshold")
            threshold = number * (parse_unit(given)[0] if given else 1.0)
    elif "threshold" in spec:
        raise ConfigError(f"{where}.threshold", f"only first_crossing takes a threshold, not {how}")
    return threshold
