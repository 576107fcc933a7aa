"""An FMI co-simulation FMU run as a component, through FMPy (type ``fmu``).

The FMU's ``modelDescription.xml`` declares the variables: its inputs and outputs become the
component's, its parameters take ``start_values``. The lifecycle is FMI's: instantiate, set the
start values, initialization mode with the inputs, ``doStep`` each step; ``get_state`` and
``set_state`` go through ``getFMUstate``/``serializeFMUstate`` when the FMU can.
"""

from __future__ import annotations

import shutil
import tempfile
import weakref
import zipfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from components.constants import NS_PER_S
from components.errors import ComponentError
from components.extras import require
from components.fmi.fmu_file import fmu_file, model_description
from components.fmi.pythonfmu_exit import hold_binary_until_exit  # pythonfmu's crash at exit, worked around
from components.fmi.variables import NUMERIC_TYPES, Signal, signals, start_setting, start_value
from components.schema import Anything, MapOf, Str
from components.sdk import Component, Parameter, RunSettings, Variable, layouts


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
            start_setting(md, name, value, f"start_values.{name}")
        signals(md, file)
        return params

    @classmethod
    def declare(cls, params, run):
        file, md = cls._model(params, run)
        return [
            Variable(s.name, s.causality, s.shape, s.unit, start_value(s, params["start_values"]), s.description)
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
        self.t_ns: int | None = None

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
        plan: dict[str, tuple[list[int], list[int], type]] = {}
        offset = 0
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
            v, values = start_setting(self.md, name, value, f"start_values.{name}")
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
        assert self.t_ns is not None, "get_state before initialize"
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
