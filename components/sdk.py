"""Component SDK: FMU-style components declared as data.

A component type subclasses :class:`Component`, declares its ``parameters`` (static) and, from
the validated parameters, its input and output :class:`Variable` s (``declare``). The lifecycle is
FMI co-simulation's: ``__init__(params)`` (instantiate) -> ``initialize(t0_ns, inputs)`` ->
``do_step(t_ns, h_ns, inputs)`` repeated -> ``terminate()``, with ``get_state``/``set_state``
for swap and restart. The component never sees the bus: :mod:`components.runner` runs it as a
process, :mod:`components.testing.harness` runs it in-process. See docs/component_api.md.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, ClassVar, Mapping

import numpy as np

from components.errors import ConfigError
from components.units import to_si

REQUIRED = object()
"""Default of a parameter the config must give."""

CAUSALITIES = ("input", "output")
PARAMETER_KINDS = ("float", "int", "bool", "str", "vector", "any")


@dataclass(frozen=True)
class Parameter:
    """A configuration value of a component type, fixed for a run.

    kind: float | int | bool | str | vector | any. ``unit`` (SI, e.g. "m", "rad") lets the config
    give "6778 km"; ``shape`` applies to vectors; ``choices`` restricts str values.
    """
    name: str
    kind: str
    unit: str | None = None
    default: Any = REQUIRED
    description: str = ""
    shape: tuple[int, ...] | None = None
    choices: tuple[str, ...] | None = None

    def __post_init__(self):
        if self.kind not in PARAMETER_KINDS:
            raise ValueError(f"parameter {self.name}: kind must be one of {PARAMETER_KINDS}, got {self.kind!r}")

    @property
    def required(self) -> bool:
        return self.default is REQUIRED

    def convert(self, value: Any) -> Any:
        """Check and convert a config value to its SI Python value; ConfigError naming the key."""
        key = self.name
        if self.kind == "any":
            return value
        if self.kind == "bool":
            if not isinstance(value, bool):
                raise ConfigError(key, f"expected true or false, got {value!r}")
            return value
        if self.kind == "str":
            if not isinstance(value, str):
                raise ConfigError(key, f"expected a string, got {value!r}")
            if self.choices and value not in self.choices:
                raise ConfigError(key, f"expected one of {', '.join(self.choices)}, got {value!r}")
            return value
        if self.kind == "int":
            if isinstance(value, bool) or not isinstance(value, int):
                raise ConfigError(key, f"expected an integer, got {value!r}")
            return value
        if self.kind == "float":
            return to_si(value, self.unit or "1", key)
        # vector
        if not isinstance(value, (list, tuple)):
            raise ConfigError(key, f"expected a list of {self._shape_text()} numbers, got {value!r}")
        array = np.array([to_si(v, self.unit or "1", f"{key}[{i}]") for i, v in enumerate(value)])
        if self.shape is not None and array.shape != self.shape:
            raise ConfigError(key, f"expected {self._shape_text()} values, got {len(value)}")
        return array

    def _shape_text(self) -> str:
        return "x".join(map(str, self.shape)) if self.shape else "some"


@dataclass(frozen=True)
class Variable:
    """A signal of a component: an input it reads or an output it publishes each step.

    ``shape`` is () for a scalar or (n,) for a vector; ``start`` is the value an unconnected
    input holds (and an output's value before initialization).
    """
    name: str
    causality: str
    shape: tuple[int, ...]
    unit: str
    start: Any
    description: str

    def __post_init__(self):
        if self.causality not in CAUSALITIES:
            raise ValueError(f"variable {self.name}: causality must be one of {CAUSALITIES}, got {self.causality!r}")
        start = np.broadcast_to(np.asarray(self.start, dtype=np.float64), self.shape).copy()
        object.__setattr__(self, "start", start)
        object.__setattr__(self, "size", int(np.prod(self.shape, dtype=np.int64)) if self.shape else 1)

    def columns(self, prefix: str) -> list[str]:
        """Recording column names: ``prefix.name`` or ``prefix.name[i]``."""
        if self.shape == ():
            return [f"{prefix}.{self.name}"]
        return [f"{prefix}.{self.name}[{i}]" for i in range(self.size)]


class Component:
    """Base class of a component type. Subclasses set ``type_name`` and ``parameters``."""

    type_name: ClassVar[str] = ""
    parameters: ClassVar[tuple[Parameter, ...]] = ()
    #: Set by the framework before ``initialize`` and each ``do_step``: for each input fed by a
    #: connection, the time (ns) at which its value was sampled, which is not always t_ns: under
    #: Gauss-Seidel an input from a component earlier in config order holds that component's
    #: output at the end of the step (t_ns + its step); a slower source's output is held from its
    #: last step. At ``initialize`` an input whose source is not initialized yet (it holds its
    #: start value) is absent.
    input_times_ns: Mapping[str, int] = MappingProxyType({})

    @classmethod
    def declare(cls, params: Mapping[str, Any]) -> list[Variable]:
        """Inputs and outputs, given validated parameters. Must be cheap (no heavy imports)."""
        raise NotImplementedError

    @classmethod
    def validate(cls, params: Mapping[str, Any]) -> None:
        """Checks across parameters beyond their kinds; raise ConfigError(key, message)."""

    def __init__(self, params: Mapping[str, Any]):
        self.params = params

    def initialize(self, t0_ns: int, inputs: Mapping[str, np.ndarray]) -> Mapping[str, Any]:
        """Prepare for the first step at ``t0_ns``; return the outputs at t0."""
        raise NotImplementedError

    def do_step(self, t_ns: int, h_ns: int, inputs: Mapping[str, np.ndarray]) -> Mapping[str, Any]:
        """Advance over [t_ns, t_ns + h_ns) with the inputs held; return outputs at t_ns + h_ns."""
        raise NotImplementedError

    def get_state(self) -> dict[str, Any]:
        """The complete internal state as a dict of numpy arrays or scalars."""
        raise NotImplementedError(f"{self.type_name} does not support get_state")

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Restore a state made by ``get_state`` (possibly in another process)."""
        raise NotImplementedError(f"{self.type_name} does not support set_state")

    def terminate(self) -> None:
        """Release resources at the end of the run."""


# Injected by the orchestrator into every component's parameters; not declared by the types.
RUN_PARAMETERS = ("_epoch", "_config_dir")


def resolve_parameters(cls: type[Component], raw: Mapping[str, Any] | None) -> tuple[dict, list[ConfigError]]:
    """Validate raw config parameters against ``cls.parameters``.

    Returns the converted parameters (defaults filled) and every error found (unknown keys,
    missing required keys, wrong kinds, units, then the type's own ``validate``).
    """
    raw = dict(raw or {})
    if not isinstance(raw, dict):
        return {}, [ConfigError("", f"parameters must be a mapping, got {raw!r}")]
    declared = {p.name: p for p in cls.parameters}
    errors: list[ConfigError] = []
    params: dict[str, Any] = {k: raw.pop(k) for k in RUN_PARAMETERS if k in raw}
    for key in raw:
        if key not in declared:
            errors.append(ConfigError(key, f"unknown parameter of {cls.type_name} (known: {', '.join(declared) or 'none'})"))
    for name, p in declared.items():
        if name in raw:
            try:
                params[name] = p.convert(raw[name])
            except ConfigError as e:
                errors.append(e)
        elif p.required:
            errors.append(ConfigError(name, f"missing required parameter of {cls.type_name} ({p.description})"))
        else:
            params[name] = p.default
    if not errors:
        try:
            cls.validate(params)
        except ConfigError as e:
            errors.append(e)
    return params, errors


@dataclass
class Layout:
    """Fixed float64 layout of a list of variables, for binary payloads and recording columns."""
    variables: list[Variable]
    offsets: dict[str, slice] = field(init=False)
    size: int = field(init=False)

    def __post_init__(self):
        self.offsets, start = {}, 0
        for v in self.variables:
            self.offsets[v.name] = slice(start, start + v.size)
            start += v.size
        self.size = start
        # (name, slice, size, shape) once, for the per-step pack/unpack
        self._plan = [(v.name, self.offsets[v.name], v.size, v.shape) for v in self.variables]

    def start_vector(self) -> np.ndarray:
        out = np.empty(self.size)
        for v in self.variables:
            out[self.offsets[v.name]] = v.start.ravel()
        return out

    def pack(self, values: Mapping[str, Any], into: np.ndarray) -> None:
        """Write named values into ``into``; every variable of the layout must be present."""
        for name, where, size, shape in self._plan:
            try:
                value = values[name]
            except KeyError:
                raise ComponentOutputError(f"output {name!r} missing from the step's result") from None
            if np.size(value) != size:
                raise ComponentOutputError(f"output {name!r} has {np.size(value)} values, declared shape {shape}")
            into[where] = np.ravel(value)

    def first_non_finite(self, vector: np.ndarray) -> str | None:
        """The name of the first variable holding a NaN or infinity in ``vector``, or None."""
        if np.isfinite(vector).all():
            return None
        bad = int(np.flatnonzero(~np.isfinite(vector))[0])
        return next(name for name, where, _, _ in self._plan if bad < where.stop)

    def unpack(self, vector: np.ndarray) -> dict[str, np.ndarray]:
        """Views of ``vector`` by variable name (scalars as 0-d arrays)."""
        return {name: vector[where].reshape(shape) for name, where, _, shape in self._plan}


class ComponentOutputError(Exception):
    """A component returned outputs that do not match its declaration."""
