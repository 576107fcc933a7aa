"""Campaign metrics: parsing ``{signal, reduce[, threshold]}`` and reducing a recording's signal to one number."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from components.errors import ConfigError
from components.units import _unit, to_si
from orchestrator.config import RunConfig
from orchestrator.dispersions import _quantity

REDUCERS = ("final", "min", "max", "mean", "rms", "max_abs", "first_crossing")


@dataclass(frozen=True)
class Metric:
    """``name``: ``reduce`` of the columns ``columns`` (several: the row-wise norm)."""
    name: str
    signal: str
    reduce: str
    columns: tuple[str, ...]
    threshold: float | None = None

    def value(self, time: np.ndarray, table: dict[str, np.ndarray]) -> float:
        """The metric of a recording (``table``: column -> values); NaN if it has no rows."""
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


def metric(name: str, spec: Any, signals: dict[str, tuple[tuple[str, ...], str]] | None, where: str) -> Metric:
    """Parse ``{signal, reduce[, threshold]}`` against the signals of the base config."""
    if not isinstance(spec, dict):
        raise ConfigError(where, f"expected {{signal: COMPONENT.OUTPUT, reduce: ...}}, got {spec!r}")
    unknown = [k for k in spec if k not in ("signal", "reduce", "threshold")]
    if unknown:
        raise ConfigError(f"{where}.{unknown[0]}", "unknown key (known: signal, reduce, threshold)")
    for k in ("signal", "reduce"):
        if k not in spec:
            raise ConfigError(f"{where}.{k}", "missing")
    how = spec["reduce"]
    if how not in REDUCERS:
        raise ConfigError(f"{where}.reduce", f"expected one of {', '.join(REDUCERS)}, got {how!r}")
    signal = spec["signal"]
    unit = "1"
    columns: tuple[str, ...] = (str(signal),)
    if signals is not None:
        if signal not in signals:
            near = sorted(k for k in signals if "[" not in k)
            raise ConfigError(f"{where}.signal", f"no signal {signal!r} in a recording of the config "
                                                 f"(signals: {', '.join(near)})")
        columns, unit = signals[signal]
    threshold = None
    if how == "first_crossing":
        if "threshold" not in spec:
            raise ConfigError(f"{where}.threshold", "first_crossing needs a threshold, e.g. threshold: 0.1 rad/s")
        value = spec["threshold"]
        if unit not in (None, "1") and _unit_known(unit):
            threshold = to_si(value, unit, f"{where}.threshold")
        else:
            number, given = _quantity(value, f"{where}.threshold")
            threshold = number * (_unit(given)[0] if given else 1.0)
    elif "threshold" in spec:
        raise ConfigError(f"{where}.threshold", f"only first_crossing takes a threshold, not {how}")
    return Metric(name, str(signal), how, columns, threshold)


def _unit_known(unit: str) -> bool:
    try:
        _unit(unit)
        return True
    except ValueError:
        return False
