"""Component SDK: FMU-style components declared as data.

A component type subclasses :class:`Component`, declares its ``parameters`` (static) and, from
the validated parameters, its input and output :class:`Variable` s (``declare``). The lifecycle is
FMI co-simulation's: ``__init__(params)`` (instantiate) -> ``initialize(t0_ns, inputs)`` ->
``do_step(t_ns, h_ns, inputs)`` repeated -> ``terminate()``, with ``get_state``/``set_state``
for swap and restart. The component never sees the bus: :mod:`components.runner` runs it as a
process, :mod:`components.testing.harness` runs it in-process. See docs/component_api.md.
"""

from __future__ import annotations

import inspect
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np

from components.errors import ConfigError
from components.plotting import Plot
from components.protocol import FRAME_DTYPES
from components.rosbag import RosExport
from components.schema import REQUIRED, Parameter, Problems, Record, markdown  # noqa: F401 (SDK surface)

CAUSALITIES = ("input", "output")
warnings.filterwarnings("ignore", "invalid value encountered in dot", RuntimeWarning, __name__)


@dataclass(frozen=True)
class Variable:
    """A signal of a component: an input it reads or an output it publishes each step.

    ``shape`` is () for a scalar or (n,) for a vector; ``start`` is the value an unconnected
    input holds (and an output's value before initialization).

    ``frame=True`` makes it a frame (an image): an array of ``dtype`` (``uint8`` or ``float32``)
    and shape (H, W) or (H, W, C), sent once per step on its own message rather than in the
    float64 payload, and left out of the layouts, the rows and ``signals.parquet``
    (docs/component_api.md, "Images in a step"). Its start value is all zeros, read-only.
    """

    name: str
    causality: str
    shape: tuple[int, ...]
    unit: str
    start: Any
    description: str
    frame: bool = False
    dtype: str = "float64"
    size: int = field(init=False, repr=False, compare=False)  # how many numbers: the product of shape

    def __post_init__(self):
        if self.causality not in CAUSALITIES:
            raise ValueError(f"variable {self.name}: causality must be one of {CAUSALITIES}, got {self.causality!r}")
        if self.frame:
            if self.dtype not in FRAME_DTYPES or len(self.shape) not in (2, 3) or min(self.shape) < 1:
                raise ValueError(
                    f"frame {self.name}: expected a dtype of {FRAME_DTYPES} and a shape (H, W[, C]) "
                    f"of positive sizes, got {self.dtype!r} and {self.shape}"
                )
            start = np.zeros(self.shape, dtype=self.dtype)
            start.flags.writeable = False
        elif self.dtype != "float64":
            raise ValueError(f"variable {self.name}: only a frame has a dtype other than float64, got {self.dtype!r}")
        else:
            start = np.broadcast_to(np.asarray(self.start, dtype=np.float64), self.shape).copy()
        object.__setattr__(self, "start", start)
        object.__setattr__(self, "size", int(np.prod(self.shape, dtype=np.int64)) if self.shape else 1)

    def columns(self, prefix: str) -> list[str]:
        """Recording column names: ``prefix.name`` or ``prefix.name[i]``."""
        if self.shape == ():
            return [f"{prefix}.{self.name}"]
        return [f"{prefix}.{self.name}[{i}]" for i in range(self.size)]


@dataclass(frozen=True)
class Outcome:
    """An end a run comes to, as a component type declares it (its ``outcomes``; the capture:
    captured, aborted, undecided). ``events``: the component's own events that put the run in
    this outcome; at the end the last such event decides, and with none the first outcome declared
    holds. ``says``: the run's summary line for it, a format string over the deciding event's
    fields and ``end`` (the run's end, s), e.g. ``"captured at {time:g} s"``."""

    name: str
    says: str
    events: tuple[str, ...] = ()
    description: str = ""

    def text(self, fields: Mapping[str, Any], end_s: float) -> str:
        """``says`` filled in; a field the event lacks reads '?' (the line is still written)."""

        class Missing(dict):
            def __missing__(self, key):
                return "?"

        try:
            return self.says.format_map(Missing({**fields, "end": end_s}))
        except (ValueError, TypeError):  # a field of another type than the format expects
            return self.name


class Component:
    """Base class of a component type. Subclasses set ``type_name`` and ``parameters``, and
    ``variables`` when they do not depend on the parameters (else they override ``declare``).

    The docstring gets its parameter and variable tables from those declarations.
    """

    type_name: ClassVar[str] = ""
    parameters: ClassVar[tuple[Parameter, ...]] = ()
    #: The parameters as one Record (``resolve_parameters`` checks a config's against it); each
    #: subclass gets its own when it is defined.
    schema: ClassVar[Record]
    variables: ClassVar[tuple[Variable, ...] | None] = None
    #: Set by the framework before ``initialize`` and each ``do_step``: for each input fed by a
    #: connection, the time (ns) at which its value was sampled, which is not always t_ns: under
    #: Gauss-Seidel an input from a component earlier in config order holds that component's
    #: output at the end of the step (t_ns + its step); a slower source's output is held from its
    #: last step. At ``initialize`` an input whose source is not initialized yet (it holds its
    #: start value) is absent.
    input_times_ns: Mapping[str, int] = MappingProxyType({})
    #: When the frame outputs of the latest ``do_step`` were taken (run time, ns), for the live
    #: views' stamps; None: at the step's time t_ns.
    frame_time_ns: int | None = None
    #: The form of the state ``get_state`` returns, when other types share it: a swap from a type
    #: of the same ``state_form`` hands the state over (``set_state``, no ``initialize``) as a swap
    #: to the same type does. None: the state is the type's own.
    state_form: ClassVar[str | None] = None
    #: The figures ``orchestrator plot`` draws from a recording for a component of this type, in
    #: this order (:class:`components.plotting.Plot`: file name, description, draw function).
    plots: ClassVar[tuple[Plot, ...]] = ()
    #: What the Rerun viewer draws for a component of this type: a
    #: :class:`components.viewer.scene.View` subclass. None: its outputs are plotted as plain signals.
    view: ClassVar[type | None] = None
    #: What ``orchestrator export DIR --rosbag2 OUT`` writes for a component of this type, as ROS 2
    #: messages (:class:`components.rosbag.RosExport`). None: nothing (the exporter names it).
    rosbag: ClassVar[RosExport | None] = None
    #: The ends a run with a component of this type comes to (:class:`Outcome`): the summary line
    #: states it, ``run --expect NAME`` checks it, events.jsonl's end event records it. Empty: none.
    outcomes: ClassVar[tuple[Outcome, ...]] = ()
    #: The parameter naming the run's bodies (name -> a mapping with the body's ``urdf``): the dynamics'.
    bodies_parameter: ClassVar[str | None] = None
    #: A parameter (name -> URDF) that, left out of the config, is the run's bodies: the config fills
    #: it from the one component whose type has ``bodies_parameter`` (the camera's scene).
    scene_parameter: ClassVar[str | None] = None

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        _check_outcomes(cls)
        cls.schema = Record(
            cls.type_name or cls.__name__, tuple(cls.parameters), noun=f"parameter of {cls.type_name or cls.__name__}"
        )
        doc = cls.__dict__.get("__doc__")
        if doc:  # its own docstring, not an inherited one
            cls.__doc__ = inspect.cleandoc(doc) + "\n\n" + declaration_tables(cls)

    @classmethod
    def declare(cls, params: Any, run: RunSettings) -> list[Variable]:
        """Inputs and outputs, given the typed parameters (what ``validate`` returned). Must be cheap
        (no heavy imports)."""
        if cls.variables is None:
            raise NotImplementedError(f"{cls.__name__} declares neither variables nor declare()")
        return list(cls.variables)

    @classmethod
    def validate(cls, params: Mapping[str, Any], run: RunSettings) -> Any:
        """Checks across the checked parameters beyond their kinds (raise ConfigError(key, message));
        returns the typed parameters that ``declare``, ``preflight`` and ``__init__`` get, so that
        what the checks work out (a URDF read, gains per joint) is worked out once. Default: the
        checked parameters themselves."""
        return params

    @classmethod
    def preflight(cls, params: Any, run: RunSettings, step_s: float, full: bool = False) -> list[str]:
        """What the orchestrator warns about before a run with these (validated) parameters and
        this step (s): physics that runs but is suspect, one line each naming the figure. With
        ``full`` (``orchestrator check``) it may also load what ``__init__`` would (a physics
        engine's model), raising ConfigError(key, message) for what fails. Default: nothing."""
        return []

    def __init__(self, params: Any, run: RunSettings):
        self.params, self.run = params, run

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

    def interrupt(self) -> None:
        """Called from another thread when the run is ending (a terminate, or the orchestrator gone)
        while a step may be under way: a ``do_step`` that waits for something outside the run (a
        ROS 2 node) ends that wait now, raising. Default: nothing (a step that computes ends soon)."""

    @classmethod
    def interruptible(cls) -> bool:
        """Whether the type's steps may wait on the outside (it overrides ``interrupt``)."""
        return cls.interrupt is not Component.interrupt

    def emit(self, kind: str, **fields: Any) -> None:
        """Report an event of the step being taken (a capture, say): the orchestrator writes it to
        ``events.jsonl`` as ``{"event": kind, **fields, "component": ..., "step": ...}`` (step: the
        step that emitted it). ``kind`` is an identifier that is not one of the orchestrator's own
        events; fields are JSON values."""
        if not kind.isidentifier() or kind in ORCHESTRATOR_EVENTS:
            raise ValueError(
                f"emit: expected an event name that is an identifier and not one of "
                f"{', '.join(ORCHESTRATOR_EVENTS)}, got {kind!r}"
            )
        if "kind" in fields:
            raise ValueError("emit: 'kind' cannot be a field name (it is the event's)")
        self.__dict__.setdefault("pending_events", []).append((kind, fields))

    def take_events(self) -> list[tuple[str, dict]]:
        """The events emitted since the last call (the framework's side of ``emit``)."""
        return self.__dict__.pop("pending_events", [])

    @classmethod
    def restorable(cls) -> bool:
        """Whether the type implements get_state and set_state (swaps with state, restarts)."""
        return cls.get_state is not Component.get_state and cls.set_state is not Component.set_state

    @classmethod
    def takes_state_of(cls, other: type[Component]) -> bool:
        """Whether an instance of this type continues from the state of an ``other`` (a swap
        hands it over instead of initializing): the same type, or one of the same ``state_form``."""
        return other is cls or (cls.state_form is not None and cls.state_form == other.state_form)

    @classmethod
    def group_problem(cls, params: Any, run: RunSettings) -> str | None:
        """Why an instance with these (typed) parameters cannot share a process with other
        components (``process:``, a process group), or None: ``check`` refuses the group with it.
        Default: it can (its code runs in the process's Python like any other member's)."""
        return None

    @classmethod
    def state_problem(cls, params: Any, run: RunSettings) -> str | None:
        """Why an instance with these (typed) parameters cannot hand its state over, or None.
        Swaps that hand the state over (``takes_state_of``) and restarts are refused with this reason."""
        return None if cls.restorable() else f"{cls.type_name or cls.__name__} has no get_state/set_state"


def resolve_parameters(
    cls: type[Component], raw: Mapping[str, Any] | None, run: RunSettings
) -> tuple[dict, Any, list[ConfigError]]:
    """Validate raw config parameters against the type's declaration (``cls.schema``).

    Returns the converted parameters (defaults filled, SI), the typed parameters the type's own
    ``validate`` makes of them (None when there are errors) and every error found (unknown keys,
    missing required keys, wrong kinds, units, then ``validate``'s).
    """
    params, errors = cls.schema.resolve(raw)
    typed = None
    if not errors:
        try:
            typed = cls.validate(params, run)
        except Problems as e:
            errors += e.problems
        except ConfigError as e:
            errors.append(e)
        else:
            if typed is None:  # a validate written as a check only: its parameters would be lost
                raise TypeError(f"{cls.__name__}.validate returned None: expected the typed parameters (return params)")
    return params, typed, errors


def declaration_tables(cls: type[Component]) -> str:
    """Markdown tables of a type's parameters (nested ones too) and, when fixed, its variables."""
    parts = ["Parameters:", "", markdown(cls.schema) if cls.parameters else "(none)", ""]
    if cls.variables is None:
        parts.append(
            f"Its variables depend on its parameters: ``orchestrator describe {cls.type_name or cls.__name__} "
            "--set PARAM=VALUE`` lists them."
        )
    else:
        parts += ["Variables:", "", "| variable | causality | shape | unit | description |", "|---|---|---|---|---|"]
        parts += [
            f"| {v.name} | {v.causality} | {v.shape}{f' {v.dtype} frame' if v.frame else ''} | {v.unit} | "
            f"{v.description} |"
            for v in cls.variables
        ]
    if cls.plots:
        parts += ["", "Plots (``orchestrator plot``):", "", "| file | content |", "|---|---|"]
        parts += [f"| ``{plot.file}`` | {plot.description} |" for plot in cls.plots]
    if cls.outcomes:
        parts += [
            "",
            "Outcomes (the run's summary line, ``run --expect NAME``; the first holds until an event decides):",
            "",
            "| outcome | decided by the event | description |",
            "|---|---|---|",
        ]
        parts += [
            f"| {o.name} | {', '.join(o.events) or '(none: the start)'} | {o.description} |" for o in cls.outcomes
        ]
    if cls.rosbag is not None:
        parts += ["", f"ROS 2 messages (``orchestrator export --rosbag2``): {cls.rosbag.description}."]
    return "\n".join(parts)


def _check_outcomes(cls) -> None:
    """A type's outcomes: distinct names, each event deciding one outcome at most."""
    names = [o.name for o in cls.outcomes]
    events = [e for o in cls.outcomes for e in o.events]
    if len(set(names)) < len(names) or len(set(events)) < len(events):
        raise TypeError(
            f"{cls.type_name or cls.__name__}: outcomes need distinct names and an event deciding one "
            f"outcome at most, got {[(o.name, o.events) for o in cls.outcomes]}"
        )


# The events the orchestrator itself writes to events.jsonl; a component's emit() cannot use them.
ORCHESTRATOR_EVENTS = ("start", "end", "fault", "warning", "swap", "checkpoint", "restart", "viewer")


@dataclass(frozen=True)
class RunSettings:
    """What every component of a run gets from the orchestrator besides its own parameters, as its
    own argument (``validate``, ``declare``, ``preflight``, ``__init__``). One left None (or empty)
    was not given; a type that needs it says so (a ConfigError naming ``EPOCH_KEY``, say)."""

    epoch: str | None = None  # run.epoch: the UTC of t = 0, ISO-8601 text
    config_dir: Path | None = None  # where the config's relative paths start
    packages: Mapping[str, str] = field(default_factory=dict)  # run.packages: ROS package -> absolute directory
    frames: Path | None = None  # with --record DIR: DIR/frames/<component>, for files of its own (camera frames)

    def to_json(self) -> dict[str, Any]:
        """As the instantiate message carries it."""
        return {
            "epoch": self.epoch,
            "config_dir": None if self.config_dir is None else str(self.config_dir),
            "packages": {str(k): str(v) for k, v in self.packages.items()},
            "frames": None if self.frames is None else str(self.frames),
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> RunSettings:
        return cls(
            epoch=data["epoch"],
            config_dir=None if data["config_dir"] is None else Path(data["config_dir"]),
            packages=dict(data["packages"]),
            frames=None if data["frames"] is None else Path(data["frames"]),
        )


# The key a ConfigError names when a type needs the run's epoch and was given none.
EPOCH_KEY = "_epoch"


@dataclass
class Layout:
    """Fixed float64 layout of a list of variables, for binary payloads and recording columns.
    Frame variables among them are set aside in ``frames``: they have no place in the layout."""

    variables: list[Variable]
    offsets: dict[str, slice] = field(init=False)
    size: int = field(init=False)
    frames: list[Variable] = field(init=False)

    def __post_init__(self):
        self.frames = [v for v in self.variables if v.frame]
        self.variables = [v for v in self.variables if not v.frame]
        self.offsets, start = {}, 0
        for v in self.variables:
            self.offsets[v.name] = slice(start, start + v.size)
            start += v.size
        self.size = start
        # (name, slice, size, shape) once, for the per-step pack/unpack
        self._plan = [(v.name, self.offsets[v.name], v.size, v.shape) for v in self.variables]
        # unpack's: the shape to reshape a slice to, None for a vector (its slice has its shape)
        self._views = [
            (v.name, self.offsets[v.name], None if tuple(v.shape) == (v.size,) else v.shape) for v in self.variables
        ]
        self._zeros = np.zeros(self.size)

    def start_vector(self) -> np.ndarray:
        out = np.empty(self.size)
        for v in self.variables:
            out[self.offsets[v.name]] = v.start.ravel()
        return out

    def pack(self, values: Mapping[str, Any] | np.ndarray, into: np.ndarray) -> None:
        """Write named values into ``into``; every variable of the layout must be present. Or
        ``values`` is the whole vector, a float64 array of the layout's size holding the variables
        in declaration order (a step with no Python object per output: a layout without frames)."""
        if values.__class__ is np.ndarray:
            if values.shape != into.shape or values.dtype != np.float64 or self.frames:
                raise ComponentOutputError(self._not_the_vector(values))
            into[:] = values
            return
        for name, where, size, shape in self._plan:
            try:
                value = values[name]
            except KeyError:
                raise ComponentOutputError(f"output {name!r} missing from the step's result") from None
            # per step and per output: an array's own size and ravel (numpy's functions of the
            # same name cost a dispatch more), anything else through numpy
            if value.__class__ is np.ndarray and value.size == size:
                into[where] = value if value.ndim == 1 else value.ravel()
                continue
            if np.size(value) != size:
                raise ComponentOutputError(f"output {name!r} has {np.size(value)} values, declared shape {shape}")
            into[where] = np.ravel(value)

    def _not_the_vector(self, values: np.ndarray) -> str:
        if self.frames:
            return (
                f"outputs as one vector: not with frame outputs ({', '.join(v.name for v in self.frames)}); "
                f"return the outputs by name"
            )
        return (
            f"outputs as one vector: expected {self.size} float64 values ({', '.join(v.name for v in self.variables)}, "
            f"in that order), got {values.dtype} of shape {values.shape}"
        )

    def first_non_finite(self, vector: np.ndarray) -> str | None:
        """The name of the first variable holding a NaN or infinity in ``vector``, or None."""
        # one BLAS call: 0 * x is 0 for every finite x, NaN for NaN and inf (numpy's warning about
        # that NaN is filtered out below: the caller reports the variable)
        if vector.dot(self._zeros) == 0.0:
            return None
        bad = int(np.flatnonzero(~np.isfinite(vector))[0])
        return next(name for name, where, _, _ in self._plan if bad < where.stop)

    def unpack(self, vector: np.ndarray) -> dict[str, np.ndarray]:
        """Views of ``vector`` by variable name (scalars as 0-d arrays)."""
        return {
            name: vector[where] if shape is None else vector[where].reshape(shape) for name, where, shape in self._views
        }


def layouts(variables: list[Variable]) -> tuple[Layout, Layout]:
    """The input and the output layout of declared variables, each in declaration order."""
    return (
        Layout([v for v in variables if v.causality == "input"]),
        Layout([v for v in variables if v.causality == "output"]),
    )


class ComponentOutputError(Exception):
    """A component returned outputs that do not match its declaration."""
