"""An FMI co-simulation FMU run as a component, through FMPy (type ``fmu``).

The FMU's ``modelDescription.xml`` declares the variables: its inputs and outputs become the
component's, its parameters take ``start_values``. The lifecycle is FMI's: instantiate, set the
start values, initialization mode with the inputs, ``doStep`` each step; ``get_state`` and
``set_state`` go through ``getFMUstate``/``serializeFMUstate`` when the FMU can.
"""

from __future__ import annotations

import hashlib
import os
import re
import shutil
import subprocess
import sys
import tempfile
import weakref
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from components.constants import NS_PER_S
from components.errors import ComponentError, ConfigError
from components.extras import require
from components.fmi.pythonfmu_exit import hold_binary_until_exit  # pythonfmu's crash at exit, worked around
from components.schema import Anything, MapOf, Str
from components.sdk import Component, Parameter, RunSettings, Variable, layouts
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


class FMUError(ConfigError):
    """A problem with the FMU file itself (missing, corrupt, not co-simulation...)."""


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


def fmu_file(path: str, config_dir: str | None, key: str = "path") -> Path:
    """The FMU a ``path`` parameter names: an .fmu, or a pythonfmu model (.py) built on first use."""
    file = Path(path)
    if not file.is_absolute():
        file = Path(config_dir or ".") / file
    if not file.is_file():
        raise FMUError(key, f"FMU file {path!r} not found (looked for {file})")
    if file.suffix == ".py":
        return build_python_model(file, key)
    if file.suffix != ".fmu":
        raise FMUError(key, f"expected an .fmu file (or a pythonfmu model .py), got {path!r}")
    return file.resolve()


def build_python_model(script: Path, key: str = "path") -> Path:
    """Build a pythonfmu model (an ``Fmi2Slave`` subclass in ``script``) into an FMU with state
    support, cached by content under ``$XDG_CACHE_HOME/zenorbit/fmus`` (built in a child process:
    pythonfmu imports the script)."""
    import pythonfmu

    digest = hashlib.sha256(script.read_bytes() + pythonfmu.__version__.encode()).hexdigest()[:16]
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "zenorbit" / "fmus"
    target = cache / f"{script.stem}-{digest}.fmu"
    if target.is_file():
        return target
    cache.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="zenorbit-build-", dir=cache) as tmp:
        done = subprocess.run(
            [
                sys.executable,
                "-m",
                "pythonfmu",
                "build",
                "-f",
                str(script),
                "-d",
                tmp,
                "--handle-state",
                "--serialize-state",
            ],
            capture_output=True,
            text=True,
        )
        built = list(Path(tmp).glob("*.fmu"))
        if done.returncode != 0 or len(built) != 1:
            last = (done.stderr or done.stdout).strip().splitlines()[-1:] or ["no FMU written"]
            raise FMUError(key, f"pythonfmu could not build {script}: {last[0]}")
        os.replace(built[0], target)  # atomic: a concurrent build writes the same bytes
    return target


@lru_cache(maxsize=32)
def _read(file: Path, mtime_ns: int):
    import fmpy

    try:
        with zipfile.ZipFile(file) as archive:
            if "modelDescription.xml" not in archive.namelist():
                raise FMUError("path", f"{file} is not an FMU: it has no modelDescription.xml")
        return fmpy.read_model_description(str(file))
    except zipfile.BadZipFile:
        raise FMUError("path", f"{file} is not an FMU: not a zip archive (corrupt or truncated?)") from None
    except FMUError:
        raise
    except Exception as e:  # FMPy's schema validation and XML errors
        raise FMUError("path", f"{file}: cannot read its modelDescription.xml: {e}") from None


def model_description(file: Path):
    """FMPy's model description of a co-simulation FMU; FMUError otherwise."""
    md = _read(file, file.stat().st_mtime_ns)
    if md.coSimulation is None:
        kinds = "model exchange" if md.modelExchange is not None else "no interface"
        raise FMUError(
            "path",
            f"{file.name} is an FMI {md.fmiVersion} FMU for {kinds} only; "
            "Zenorbit runs co-simulation FMUs (the FMU brings its own solver)",
        )
    if not md.fmiVersion.startswith(("2.", "3.")):
        raise FMUError("path", f"{file.name} is an FMI {md.fmiVersion} FMU; Zenorbit runs FMI 2.0 and 3.0")
    return md


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
    out = []
    for v in singles:
        shape = (int(v.dimensions[0].start),) if v.dimensions else ()
        out.append(
            Signal(
                _zenorbit_name(v.name),
                v.causality,
                (v,),
                shape,
                _unit(v),
                (v.description or "") + (f" (FMI name {v.name})" if _zenorbit_name(v.name) != v.name else ""),
            )
        )
    for (base, causality), elements in groups.items():
        elements.sort(key=lambda e: e[0])
        indices = [i for i, _ in elements]
        first = indices[0]
        if first in (0, 1) and indices == list(range(first, first + len(indices))):
            refs = tuple(v for _, v in elements)
            units = {_unit(v) for v in refs}
            out.append(
                Signal(
                    _zenorbit_name(base),
                    causality,
                    refs,
                    (len(refs),),
                    units.pop() if len(units) == 1 else "",
                    (refs[0].description or "") + f" (FMI {base}[{first}]..{base}[{indices[-1]}])",
                )
            )
        else:  # not a vector: each element on its own
            out += [
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


def _start(signal: Signal, start_values: Mapping[str, Any]) -> np.ndarray:
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


def _setting(md, name: str, value: Any, key: str) -> tuple[Any, list]:
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


class FMUComponent(Component):
    """An FMI 2.0 or 3.0 co-simulation FMU, run through FMPy (type ``fmu``).

    Its inputs and outputs are the FMU's (``orchestrator describe fmu --set path=X.fmu`` lists
    them, with the units of its modelDescription.xml); FMI ``x[0]..x[n-1]`` (or ``x[1]..x[n]``)
    become a vector ``x``. ``start_values`` sets its parameters (and the values its unconnected
    inputs hold) by FMI name, before initialization. ``path`` may also be a Python model for
    pythonfmu (a ``.py`` with an ``Fmi2Slave`` subclass), built into an FMU, with state support,
    on first use. A step whose FMI status is error or fatal ends the run (exit 1) with the FMU's
    last log messages. Swaps with state and restarts need an FMU whose modelDescription.xml has
    canGetAndSetFMUstate and canSerializeFMUstate.
    """

    type_name = "fmu"
    parameters = (
        Parameter(
            "path",
            Str(hint="an FMU file path"),
            description="the .fmu file (or a pythonfmu model .py), relative to the config file",
        ),
        Parameter(
            "start_values",
            MapOf(Anything(), "FMI variable"),
            default={},
            description="values of the FMU's parameters and inputs by FMI name, set before initialization",
        ),
    )

    @classmethod
    def _model(cls, params, run: RunSettings):
        require("fmi", "type fmu", "path")
        file = fmu_file(params["path"], run.config_dir)
        return file, model_description(file)

    @classmethod
    def validate(cls, params, run):
        file, md = cls._model(params, run)
        for name, value in params["start_values"].items():
            _setting(md, name, value, f"start_values.{name}")
        signals(md, file)
        return params

    @classmethod
    def declare(cls, params, run):
        file, md = cls._model(params, run)
        return [
            Variable(s.name, s.causality, s.shape, s.unit, _start(s, params["start_values"]), s.description)
            for s in signals(md, file)
        ]

    @classmethod
    def state_problem(cls, params, run):
        _file, md = cls._model(params, run)
        cs = md.coSimulation
        if not (cs.canGetAndSetFMUstate and cs.canSerializeFMUstate):
            return (
                f"FMU {Path(params['path']).name} cannot save its state: its modelDescription.xml has canGetAndSetFMUstate="
                f"{str(cs.canGetAndSetFMUstate).lower()} and canSerializeFMUstate="
                f"{str(cs.canSerializeFMUstate).lower()}"
            )
        return None

    @classmethod
    def group_problem(cls, params, run):
        file, md = cls._model(params, run)
        name = Path(params["path"]).name
        with zipfile.ZipFile(file) as archive:
            if "resources/slavemodule.txt" in archive.namelist():
                return (
                    f"FMU {name} embeds a Python interpreter (pythonfmu): in a group its model would run in "
                    f"the process's own interpreter, beside the other members' modules and native libraries "
                    f"(pythonfmu's binary is only safe in a process of its own)"
                )
        if md.coSimulation.canBeInstantiatedOnlyOncePerProcess:
            return (
                f"FMU {name} can be instantiated only once per process (its modelDescription.xml says "
                f"canBeInstantiatedOnlyOncePerProcess=true)"
            )
        return None

    def __init__(self, params, run):
        from fmpy import extract

        super().__init__(params, run)
        self.file, self.md = self._model(params, self.run)
        self.label = Path(params["path"]).name  # as the config names it (not a build cache's file)
        self.fmi3 = self.md.fmiVersion.startswith("3.")
        self.messages: list[str] = []
        self.unzipped = extract(str(self.file), unzipdir=tempfile.mkdtemp(prefix="zenorbit-fmu-"))
        self.fmu = self._instantiate()
        # freed when garbage even if terminate() is never called (a harness)
        self._release = weakref.finalize(self, _release, self.fmu, self.unzipped)
        self._release.atexit = False  # at exit, pythonfmu's binary is finalized instead (below)
        hold_binary_until_exit(Path(self.unzipped) / "resources", self.md.coSimulation.modelIdentifier)
        self.input_layout, self.output_layout = layouts(self.declare(params, run))
        self.input_vector = self.input_layout.start_vector()
        grouped = signals(self.md, self.file)
        self.inputs = self._plan([s for s in grouped if s.causality == "input"])
        self.outputs = self._plan([s for s in grouped if s.causality == "output"])
        self.initialized = False
        self.t_ns = None

    # ------------------------------------------------------------------ FMI calls

    def _log(self, *args):
        """FMI 2 and 3 loggers alike: (..., status, category, message)."""
        status, message = args[-3], args[-1]
        text = message.decode("utf-8", "replace") if isinstance(message, bytes) else str(message)
        label = ["ok", "warning", "discard", "error", "fatal", "pending"][status] if 0 <= status < 6 else str(status)
        self.messages = (self.messages + [f"[{label}] {text.strip()}"])[-5:]

    def _instantiate(self):
        cs = self.md.coSimulation
        name = "zenorbit"
        if self.fmi3:
            from fmpy.fmi3 import FMU3Slave

            fmu = FMU3Slave(
                guid=self.md.instantiationToken,
                unzipDirectory=self.unzipped,
                modelIdentifier=cs.modelIdentifier,
                instanceName=name,
            )
            self._call(fmu.instantiate, "instantiate", logMessage=self._log)
        else:
            from ctypes import byref

            from fmpy import fmi2
            from fmpy.logging import addLoggerProxy

            fmu = fmi2.FMU2Slave(
                guid=self.md.guid, unzipDirectory=self.unzipped, modelIdentifier=cs.modelIdentifier, instanceName=name
            )
            self.callbacks = fmi2.fmi2CallbackFunctions()  # kept: the FMU calls back into them
            self.callbacks.logger = fmi2.fmi2CallbackLoggerTYPE(self._log)
            self.callbacks.allocateMemory = fmi2.fmi2CallbackAllocateMemoryTYPE(fmi2.calloc)
            self.callbacks.freeMemory = fmi2.fmi2CallbackFreeMemoryTYPE(fmi2.free)
            addLoggerProxy(byref(self.callbacks))
            self._call(fmu.instantiate, "instantiate", callbacks=self.callbacks, loggingOn=True)
        return fmu

    def _call(self, function, what: str, *args, **kwargs):
        try:
            return function(*args, **kwargs)
        except Exception as e:
            log = ("; FMU log: " + " | ".join(self.messages)) if self.messages else ""
            raise ComponentError(f"FMU {self.label}: {what} failed ({e}){log}") from None

    def _plan(self, group: list[Signal]):
        """(FMPy setter, getter, value references, slice, cast) per FMI type, for the hot path."""
        plan, offset = {}, 0
        for s in group:
            for v in s.refs:
                n = int(v.dimensions[0].start) if v.dimensions else 1
                suffix, cast = NUMERIC_TYPES[v.type]
                entry = plan.setdefault(suffix, ([], [], cast))
                entry[0].append(v.valueReference)
                entry[1].extend(range(offset, offset + n))
                offset += n
        return [
            (
                getattr(self.fmu, f"set{suffix}"),
                getattr(self.fmu, f"get{suffix}"),
                refs,
                np.array(positions),
                cast,
                len(positions),
            )
            for suffix, (refs, positions, cast) in plan.items()
        ]

    def _set_inputs(self, inputs: Mapping[str, np.ndarray]):
        self.input_layout.pack(inputs, self.input_vector)
        for setter, _, refs, positions, cast, _n in self.inputs:
            values = self.input_vector[positions]
            self._call(
                setter,
                "setting the inputs",
                refs,
                values.tolist() if cast is float else [cast(round(x)) for x in values],
            )

    def _get_outputs(self) -> dict[str, np.ndarray]:
        vector = np.empty(self.output_layout.size)
        for _, getter, refs, positions, _, n in self.outputs:
            if self.fmi3:
                values = self._call(getter, "getting the outputs", refs, nValues=n)
            else:
                values = self._call(getter, "getting the outputs", refs)
            vector[positions] = np.asarray(values, dtype=np.float64)
        return self.output_layout.unpack(vector)

    def _enter(self, t0_s: float):
        """Start values set, initialization mode entered (FMI 2: after setupExperiment)."""
        for name, value in self.params["start_values"].items():
            v, values = _setting(self.md, name, value, f"start_values.{name}")
            suffix = NUMERIC_TYPES[v.type][0] if v.type in NUMERIC_TYPES else "String"
            self._call(getattr(self.fmu, f"set{suffix}"), f"setting start value {name}", [v.valueReference], values)
        if self.fmi3:
            self._call(self.fmu.enterInitializationMode, "enterInitializationMode", startTime=t0_s)
        else:
            self._call(self.fmu.setupExperiment, "setupExperiment", startTime=t0_s)
            self._call(self.fmu.enterInitializationMode, "enterInitializationMode")

    # ------------------------------------------------------------------ lifecycle

    def initialize(self, t0_ns, inputs):
        self._enter(t0_ns / NS_PER_S)
        self._set_inputs(inputs)
        self._call(self.fmu.exitInitializationMode, "exitInitializationMode")
        self.initialized, self.t_ns = True, t0_ns
        return self._get_outputs()

    def do_step(self, t_ns, h_ns, inputs):
        self._set_inputs(inputs)
        t_s = t_ns / NS_PER_S  # h as the difference of the two points: t + h is the next point exactly
        result = self._call(self.fmu.doStep, f"doStep at t = {t_s:.9g} s", t_s, (t_ns + h_ns) / NS_PER_S - t_s)
        if self.fmi3 and result[1]:
            raise ComponentError(
                f"FMU {self.label} asked to terminate the simulation at t = "
                f"{t_ns / NS_PER_S:.9g} s" + (f": {' | '.join(self.messages)}" if self.messages else "")
            )
        self.t_ns = t_ns + h_ns
        return self._get_outputs()

    def get_state(self):
        problem = self.state_problem(self.params, self.run)
        if problem:
            raise ComponentError(problem)
        state = self._call(self.fmu.getFMUState, "getFMUstate")
        blob = self._call(self.fmu.serializeFMUState, "serializeFMUstate", state)
        self._call(self.fmu.freeFMUState, "freeFMUstate", state)
        return {
            "fmu_state": np.frombuffer(bytes(blob), dtype=np.uint8).copy(),
            "t_ns": np.int64(self.t_ns),
            "token": np.frombuffer(self._token().encode(), dtype=np.uint8).copy(),
        }

    def set_state(self, state):
        problem = self.state_problem(self.params, self.run)
        if problem:
            raise ComponentError(problem)
        token = bytes(np.asarray(state["token"], dtype=np.uint8)).decode()
        if token != self._token():  # a swap to another FMU keeps the type: its state would be garbage here
            raise ComponentError(
                f"the state comes from another FMU (token {token}), not {self.label} "
                f"({self._token()}): swap with state only to the same FMU"
            )
        if not self.initialized:  # the FMI state machine restores into an initialized instance
            self._enter(int(state["t_ns"]) / NS_PER_S)
            self._call(self.fmu.exitInitializationMode, "exitInitializationMode")
            self.initialized = True
        restored = self._call(
            self.fmu.deserializeFMUState, "deSerializeFMUstate", bytes(np.asarray(state["fmu_state"]))
        )
        self._call(self.fmu.setFMUState, "setFMUstate", restored)
        self._call(self.fmu.freeFMUState, "freeFMUstate", restored)
        self.t_ns = int(state["t_ns"])

    def _token(self) -> str:
        return self.md.instantiationToken if self.fmi3 else self.md.guid

    def terminate(self):
        if self.initialized:
            try:
                self.fmu.terminate()
            except Exception:  # the run is over either way; the instance is freed below
                pass
        self._release()


def _release(fmu, unzipped: str) -> None:
    """Free an FMU instance and delete its unzipped files (once; weakref.finalize)."""
    try:
        fmu.freeInstance()
    except Exception:
        pass
    shutil.rmtree(unzipped, ignore_errors=True)
