"""An FMU's variables as a Zenorbit component's: its inputs and outputs grouped into signals
(FMI ``x[0]..x[n-1]``, or Modelica's ``x[1]..x[n]``, a vector ``x``; other names made dotted
identifiers), each signal's start, and the ``start_values`` a config sets checked against the
variables they name.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from components.errors import ConfigError
from components.fmi.fmu_file import FMUError
from components.units import normalized_unit

NUMERIC_TYPES = {  # FMI type -> (FMPy setter/getter suffix, numpy dtype of the calls' values)
    "Real": ("Real", float),
    "Integer": ("Integer", int),
    "Enumeration": ("Integer", int),
    "Boolean": ("Boolean", bool),
    "Float64": ("Float64", float),
    "Float32": ("Float32", float),
    "Int8": ("Int8", int),
    "UInt8": ("UInt8", int),
    "Int16": ("Int16", int),
    "UInt16": ("UInt16", int),
    "Int32": ("Int32", int),
    "UInt32": ("UInt32", int),
    "Int64": ("Int64", int),
    "UInt64": ("UInt64", int),
}
SETTABLE = ("parameter", "input")  # causalities start_values may name
ELEMENT = re.compile(r"^(.*)\[(\d+)\]$")
NAME_PART = re.compile(r"[A-Za-z_]\w*")


@dataclass(frozen=True)
class Signal:
    """A Zenorbit variable made of FMI variables: ``refs`` in element order."""

    name: str
    causality: str
    refs: tuple[Any, ...]  # FMPy ModelVariable per element (an FMI 3 array counts once, with its size)
    shape: tuple[int, ...]  # () for a scalar, (n,) for a vector
    unit: str
    description: str

    @property
    def size(self) -> int:
        return self.shape[0] if self.shape else 1


def _zenorbit_name(fmi_name: str) -> str:
    """A name for recording columns and connections: dotted identifiers (``der(x)`` -> ``der_x``)."""
    parts = [re.sub(r"\W+", "_", p).strip("_") or "_" for p in fmi_name.split(".")]
    return ".".join(p if NAME_PART.fullmatch(p) else f"_{p}" for p in parts)


def _unit(v) -> str:
    unit = v.unit or (v.declaredType.unit if v.declaredType is not None else None)
    return normalized_unit(unit) if unit else ""


def signals(md, file: Path) -> list[Signal]:
    """The FMU's inputs and outputs as Zenorbit variables: ``x[0]..x[n-1]`` (or Modelica's
    ``x[1]..x[n]``) of one causality become a vector ``x`` of n; other names are kept, made into
    dotted identifiers."""
    groups, singles = _elements(md, file)
    out = [_single(v) for v in singles]
    for (base, causality), elements in groups.items():
        out += _grouped(base, causality, elements)
    names = [s.name for s in out]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise FMUError(
            "path",
            f"{file.name}: FMI names that differ only in characters Zenorbit names cannot "
            f"hold map to the same name {repeated[0]!r}",
        )
    order = {id(v): i for i, v in enumerate(md.modelVariables)}
    return sorted(out, key=lambda s: order[id(s.refs[0])])


def _elements(md, file: Path) -> tuple[dict[tuple[str, str], list[tuple[int, Any]]], list[Any]]:
    """The inputs and outputs, checked to be numbers, scalars or vectors: (base name, causality)
    -> its (index, FMI variable) elements for names ``base[i]``, and the other variables."""
    groups: dict[tuple[str, str], list[tuple[int, Any]]] = {}
    singles: list[Any] = []
    for v in md.modelVariables:
        if v.causality not in ("input", "output"):
            continue
        if v.type not in NUMERIC_TYPES:
            raise FMUError(
                "path",
                f"{file.name}: {v.causality} {v.name!r} is of type {v.type}; "
                f"Zenorbit signals are numbers ({', '.join(NUMERIC_TYPES)})",
            )
        if (v.dimensions and len(v.dimensions) > 1) or v.dimensionValueReferences:
            raise FMUError(
                "path",
                f"{file.name}: {v.causality} {v.name!r} is an array of variable or "
                "several dimensions; Zenorbit signals are scalars and vectors",
            )
        m = ELEMENT.match(v.name)
        if m and not v.dimensions:
            groups.setdefault((m.group(1), v.causality), []).append((int(m.group(2)), v))
        else:
            singles.append(v)
    return groups, singles


def _single(v) -> Signal:
    """A variable on its own (an FMI 3 array: a vector of its size)."""
    shape = (int(v.dimensions[0].start),) if v.dimensions else ()
    return Signal(
        _zenorbit_name(v.name),
        v.causality,
        (v,),
        shape,
        _unit(v),
        (v.description or "") + (f" (FMI name {v.name})" if _zenorbit_name(v.name) != v.name else ""),
    )


def _grouped(base: str, causality: str, elements: list[tuple[int, Any]]) -> list[Signal]:
    """The elements ``base[i]``: one vector when their indices run from 0 or 1 without a gap,
    else each element on its own."""
    elements.sort(key=lambda e: e[0])
    indices = [i for i, _ in elements]
    first = indices[0]
    if first in (0, 1) and indices == list(range(first, first + len(indices))):
        refs = tuple(v for _, v in elements)
        units = {_unit(v) for v in refs}
        return [
            Signal(
                _zenorbit_name(base),
                causality,
                refs,
                (len(refs),),
                units.pop() if len(units) == 1 else "",
                (refs[0].description or "") + f" (FMI {base}[{first}]..{base}[{indices[-1]}])",
            )
        ]
    return [
        Signal(
            _zenorbit_name(f"{base}_{i}"),
            causality,
            (v,),
            (),
            _unit(v),
            (v.description or "") + f" (FMI name {v.name})",
        )
        for i, v in elements
    ]


def start_value(signal: Signal, start_values: Mapping[str, Any]) -> np.ndarray:
    """The signal's start: the config's start_values, else the FMU's declared start, else 0."""
    values = []
    for v in signal.refs:
        if v.name in start_values:
            given = start_values[v.name]
            values += [float(x) for x in (given if isinstance(given, (list, tuple)) else [given])]
            continue
        text = v.start if v.start is not None else "0"
        words = str(text).replace(",", " ").split() or ["0"]
        values += [1.0 if w == "true" else 0.0 if w == "false" else float(w) for w in words]
    values += [0.0] * (signal.size - len(values))
    return np.array(values[: signal.size]).reshape(signal.shape)


def start_setting(md, name: str, value: Any, key: str) -> tuple[Any, list]:
    """The FMI variable ``name`` and the values to set it to; ConfigError naming ``key``."""
    by_name = {v.name: v for v in md.modelVariables}
    v = by_name.get(name)
    if v is None:
        settable = [v.name for v in md.modelVariables if v.causality in SETTABLE]
        raise ConfigError(
            key,
            f"the FMU has no variable {name!r} (its parameters and inputs: "
            f"{', '.join(settable[:20]) or 'none'}{' ...' if len(settable) > 20 else ''})",
        )
    if v.causality not in SETTABLE or v.variability == "constant":
        raise ConfigError(
            key,
            f"{name!r} is a {v.variability or ''} {v.causality} of the FMU: only its parameters "
            "and inputs take start values",
        )
    values = list(value) if isinstance(value, (list, tuple)) else [value]
    size = int(np.prod([int(d.start) for d in v.dimensions])) if v.dimensions else 1
    if len(values) != size:
        raise ConfigError(key, f"expected {size} value{'s' * (size > 1)} for {name!r}, got {len(values)}")
    if v.type == "String":
        if not all(isinstance(x, str) for x in values):
            raise ConfigError(key, f"{name!r} is a String: expected text, got {value!r}")
    elif v.type == "Boolean":
        if not all(isinstance(x, bool) for x in values):
            raise ConfigError(key, f"{name!r} is a Boolean: expected true or false, got {value!r}")
    elif v.type in NUMERIC_TYPES:
        integral = NUMERIC_TYPES[v.type][1] is int
        for x in values:
            if isinstance(x, bool) or not isinstance(x, (int, float)) or (integral and not isinstance(x, int)):
                raise ConfigError(
                    key, f"{name!r} is of type {v.type}: expected {'an integer' if integral else 'a number'}, got {x!r}"
                )
    else:
        raise ConfigError(key, f"{name!r} is of type {v.type}, which start_values cannot set")
    return v, values
