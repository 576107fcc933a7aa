"""The generic slave inside an FMU that ``orchestrator export-fmu`` writes: a Zenorbit component
behind pythonfmu's FMI 2.0 co-simulation interface. Each element of a Zenorbit variable is one
FMI Real (``r_eci`` of shape (3,) -> ``r_eci[0]``..``r_eci[2]``) with its unit; FMI's lifecycle
drives the component's; for a type with get_state/set_state, the FMU state is the component's state
plus the input and output vectors.
"""

from __future__ import annotations

import base64
import json
import re
import sys
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

import numpy as np
from pythonfmu.enums import Fmi2Causality, Fmi2Status
from pythonfmu.fmi2slave import Fmi2Slave
from pythonfmu.variables import Real, ScalarVariable

from components.constants import NS_PER_S
from components.fmi.pythonfmu_exit import hold_binary_until_exit
from components.fmi.spec import FILES_DIR, SPEC_FILE, instantiate, resolve_spec

STATE_FORMAT = "zenorbit-fmu-state/1"


def element_units(unit: str, size: int) -> list[str | None] | None:
    """The unit of each element of a variable, or None when its unit text cannot be spread over
    the elements ("m/s, rad/s" over 6 elements: 3 each; over 5: None)."""
    units = [u.strip() for u in unit.split(",")] if unit and unit.strip() else []
    if not units:
        return [None] * size
    if size % len(units):
        return None
    per_unit = size // len(units)
    return [units[i // per_unit] for i in range(size)]


def element_names(name: str, shape: tuple[int, ...], size: int) -> list[str]:
    return [name] if shape == () else [f"{name}[{i}]" for i in range(size)]


class UnitReal(Real):
    """An FMI Real with a unit, and a start written so that it reads back to the same double
    (pythonfmu's Real writes 16 significant digits and no unit)."""

    def __init__(self, name: str, unit: str | None = None, **kwargs):
        super().__init__(name, **kwargs)
        self.unit = unit

    def to_xml(self) -> ElementTree.Element:
        variable = ScalarVariable.to_xml(self)
        attributes = {}
        if self.unit:
            attributes["unit"] = self.unit
        if self.start is not None:
            attributes["start"] = repr(float(self.start))
        ElementTree.SubElement(variable, "Real", attributes)
        return variable


def unit_definition(name: str) -> ElementTree.Element:
    """<Unit> with its SI base-unit exponents when components.units reads the unit."""
    from components.units import unit_scale

    unit = ElementTree.Element("Unit", {"name": name})
    scale = unit_scale(name)
    if scale is not None:
        factor, exponents = scale
        base = {symbol: str(power) for symbol, power in zip(("m", "kg", "s", "rad"), exponents) if power}
        if factor != 1.0:
            base["factor"] = repr(factor)
        ElementTree.SubElement(unit, "BaseUnit", base)
    return unit


_HELD_SCRIPT_GLOBALS: list[dict] = []


class ComponentSlave(Fmi2Slave):
    """A Zenorbit component behind pythonfmu's FMI 2.0 co-simulation interface.

    The exported script subclasses it (pythonfmu instantiates the deepest Fmi2Slave subclass
    of the script); everything it needs is in ``resources``.
    """

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        # pythonfmu 0.7's binary drops a reference it does not own to the script module's globals
        # each time it instantiates the FMU: give one back per instance, or the dict is freed and
        # the next instantiation in this process crashes
        script_module = sys.modules.get(type(self).__module__)
        if script_module is not None:
            _HELD_SCRIPT_GLOBALS.append(vars(script_module))

        resources = Path(self.resources)
        self.spec = json.loads((resources / SPEC_FILE).read_text())
        self.files_dir = resources / FILES_DIR
        self.modelName = self.spec["model_identifier"]
        hold_binary_until_exit(resources, self.modelName)
        self.resolved = resolve_spec(self.spec, self.files_dir)
        self.cls = self.resolved.cls
        summary = re.sub(
            r":\w+:`~?([^`]+)`|``([^`]+)``",
            lambda m: m.group(1) or m.group(2),
            " ".join((self.cls.__doc__ or "").strip().split("\n\n")[0].split()),
        )  # rST roles as plain text
        self.description = f"Zenorbit {self.spec['type']}" + (f": {summary}" if summary else "")
        self.input_layout, self.output_layout = self.resolved.inputs, self.resolved.outputs
        self.input_names = [v.name for v in self.input_layout.variables]
        self.inputs = self.input_layout.start_vector()
        self.outputs = self.output_layout.start_vector()
        self.t0_ns = 0
        self.initialized = False
        self.component = instantiate(self.resolved, self.spec)
        self.units: list[str] = []
        for layout, vector, causality in (
            (self.input_layout, self.inputs, Fmi2Causality.input),
            (self.output_layout, self.outputs, Fmi2Causality.output),
        ):
            for v in layout.variables:
                self._register(v, vector, layout.offsets[v.name].start, causality)

    def _register(self, variable, vector: np.ndarray, offset: int, causality: Fmi2Causality) -> None:
        units = element_units(variable.unit, variable.size)
        names = element_names(variable.name, variable.shape, variable.size)
        for i, name in enumerate(names):
            description = variable.description if variable.shape == () else f"{variable.description} (element {i})"
            unit = units[i] if units else None
            if units is None:  # the unit list does not split evenly: keep it readable in the text
                description += f" [units: {variable.unit}]"
            if unit and unit not in self.units:
                self.units.append(unit)
            index = offset + i
            if causality is Fmi2Causality.input:
                setter = self._input_setter(vector, index)
            else:
                setter = self._refuse_output(name)
            # nested=False: names such as robot.tau[0] are not attribute paths
            self.register_variable(
                UnitReal(
                    name,
                    unit=unit,
                    causality=causality,
                    description=description,
                    getter=self._getter(vector, index),
                    setter=setter,
                ),
                nested=False,
            )

    @staticmethod
    def _getter(vector: np.ndarray, index: int):
        return lambda: vector[index]

    @staticmethod
    def _input_setter(vector: np.ndarray, index: int):
        def set_input(value):
            vector[index] = value

        return set_input

    def _refuse_output(self, name: str):
        # logged, not raised: pythonfmu turns an exception into fmi2Fatal and frees the instance
        def refuse(value):
            self.log(f"{name} is an output: setting it to {value!r} is ignored", Fmi2Status.error)

        return refuse

    def to_xml(self, model_options: dict[str, str] | None = None) -> ElementTree.Element:
        """pythonfmu's model description plus the units it cannot write (FMI 2.0 wants every
        unit used declared in UnitDefinitions) and the outputs as initial unknowns."""
        root = super().to_xml(model_options or {})
        if self.units:
            definitions = ElementTree.Element("UnitDefinitions")
            definitions.extend(unit_definition(unit) for unit in self.units)
            after = [i for i, child in enumerate(root) if child.tag in ("ModelExchange", "CoSimulation")]
            root.insert(after[-1] + 1, definitions)
        structure = root.find("ModelStructure")
        outputs = structure.find("Outputs")
        if outputs is not None:  # outputs are initial="calculated" (the default): list them
            initial = ElementTree.SubElement(structure, "InitialUnknowns")
            initial.extend(ElementTree.Element("Unknown", {"index": unknown.get("index")}) for unknown in outputs)
        return root

    # lifecycle -------------------------------------------------------------------------------

    def _input_views(self) -> dict[str, np.ndarray]:
        return self.input_layout.unpack(self.inputs.copy())  # the component may keep them

    def _store(self, result) -> str | None:
        """Pack a result into the outputs; the name of a non-finite output (then nothing changes)."""
        packed = np.empty(self.output_layout.size)
        self.output_layout.pack(result, packed)
        bad = self.output_layout.first_non_finite(packed)
        if bad is None:
            self.outputs[:] = packed
        return bad

    def setup_experiment(self, start_time: float, stop_time=None, tolerance=None):
        self.t0_ns = round(start_time * NS_PER_S)

    def exit_initialization_mode(self):
        self.component.input_times_ns = {}
        try:
            bad = self._store(self.component.initialize(self.t0_ns, self._input_views()))
        except Exception as e:
            message = (
                f"{self.spec['type']}: initialize at t = {self.t0_ns / NS_PER_S:g} s failed: {type(e).__name__}: {e}"
            )
            self.log(message, Fmi2Status.error)
            raise RuntimeError(message) from None
        if bad is not None:
            message = f"{self.spec['type']}: output {bad} is not finite at initialize"
            self.log(message, Fmi2Status.error)
            raise RuntimeError(message)
        self.initialized = True

    def do_step(self, current_time: float, step_size: float) -> bool:
        # communication points come as doubles: the component's clock is integer ns
        t_ns, h_ns = round(current_time * NS_PER_S), round(step_size * NS_PER_S)
        if not self.initialized:
            self.log(f"{self.spec['type']}: do_step before initialization", Fmi2Status.error)
            return False
        self.component.input_times_ns = dict.fromkeys(self.input_names, t_ns)  # held over the step
        try:
            bad = self._store(self.component.do_step(t_ns, h_ns, self._input_views()))
        except Exception as e:
            self.log(
                f"{self.spec['type']}: step at t = {current_time:g} s failed: {type(e).__name__}: {e}", Fmi2Status.error
            )
            return False
        if bad is not None:
            self.log(
                f"{self.spec['type']}: output {bad} is not finite after the step at t = {current_time:g} s",
                Fmi2Status.error,
            )
            return False
        return True

    def terminate(self):
        self.component.terminate()

    # FMU state -------------------------------------------------------------------------------

    def _get_fmu_state(self) -> dict[str, Any]:
        from components.bus import encode_state

        if not self.cls.restorable():
            raise NotImplementedError(f"{self.spec['type']} has no get_state/set_state: its FMU state cannot be taken")
        blob = encode_state(self.component.get_state()) if self.initialized else None
        return {
            "format": STATE_FORMAT,
            "initialized": self.initialized,
            "t0_ns": self.t0_ns,
            "component": None if blob is None else base64.b64encode(blob).decode("ascii"),
            "inputs": _vector_text(self.inputs),
            "outputs": _vector_text(self.outputs),
        }

    def _set_fmu_state(self, state: dict[str, Any]) -> None:
        from components.bus import decode_state

        if not self.cls.restorable():
            raise NotImplementedError(f"{self.spec['type']} has no get_state/set_state: its FMU state cannot be set")
        if not isinstance(state, dict) or state.get("format") != STATE_FORMAT:
            raise ValueError(f"not a {STATE_FORMAT} FMU state")
        # the SDK's contract: set_state restores an instance that was never initialized
        fresh = instantiate(self.resolved, self.spec)
        if state["component"] is not None:
            fresh.set_state(decode_state(base64.b64decode(state["component"])))
        previous, self.component = self.component, fresh
        previous.terminate()
        self.inputs[:] = _vector_from_text(state["inputs"], self.inputs.size)
        self.outputs[:] = _vector_from_text(state["outputs"], self.outputs.size)
        self.t0_ns, self.initialized = int(state["t0_ns"]), bool(state["initialized"])


def _vector_text(vector: np.ndarray) -> str:
    """float64 bytes in base64: exact, NaN and -0.0 included (JSON numbers are not)."""
    return base64.b64encode(np.ascontiguousarray(vector, dtype="<f8").tobytes()).decode("ascii")


def _vector_from_text(text: str, size: int) -> np.ndarray:
    vector = np.frombuffer(base64.b64decode(text), dtype="<f8")
    if vector.size != size:
        raise ValueError(f"FMU state holds {vector.size} values where {size} are expected")
    return vector
