"""In-process harness: drive one component's lifecycle without the bus.

    h = Harness("test.integrator", {"gain": 2.0})
    h.inputs["u"] = 1.0
    h.step(1_000_000)                # one 1 ms step
    h.outputs["x"]                   # -> 0.002

Inputs hold their last value (zero-order hold) and start at their declared start value, as on
the bus. Their sample times (the component's ``input_times_ns``): at a step, the step's start
t_ns for every input, unless ``h.input_times_ns`` gives another time (ns) for it, as a
Gauss-Seidel or multi-rate run would; at ``initialize``, only those ``h.input_times_ns`` lists
(the others count as start values, not yet sampled). Outputs go through the same fixed float64
layout the bus uses, and get_state/set_state go through the same byte encoding, so a component
that passes here behaves the same in a run. ``set_state`` stands for ``initialize`` (a restore:
the next ``step`` continues from the state).

A frame input is set like any other (``h.inputs["rgb"] = image``: an array of its declared dtype
and shape, handed to the component read-only, as the bus does); it holds zeros until set, and at
``initialize`` always (a frame is first read at a step). ``h.frames`` holds the frame outputs of
the last step (or ``initialize``).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from components import registry
from components.bus import decode_state, encode_state
from components.errors import ConfigError
from components.sdk import Component, RunSettings


class Harness:
    """One component instance, stepped by hand. ``t_ns`` is the current time. ``epoch``, ``config_dir``
    and ``frames`` (a recording's DIR/frames/<component>) are its RunSettings."""

    def __init__(
        self,
        component_type: str | type[Component],
        params: Mapping[str, Any] | None = None,
        *,
        t0_ns: int = 0,
        epoch: str = "2000-01-01T12:00:00Z",
        config_dir: str | Path = ".",
        frames: str | Path | None = None,
    ):
        try:
            run = RunSettings(epoch, Path(config_dir), frames=None if frames is None else Path(frames))
            resolved = registry.resolve(component_type, params or {}, run)
        except registry.Unresolved as e:
            raise e.errors[0] from None
        self.params, self.input_layout, self.output_layout = resolved.params, resolved.inputs, resolved.outputs
        self.component = resolved.build()
        self.inputs: dict[str, Any] = {v.name: v.start.copy() for v in self.input_layout.variables}
        self.inputs.update((v.name, v.start) for v in self.input_layout.frames)
        self.frames: dict[str, np.ndarray] = {v.name: v.start for v in self.output_layout.frames}
        self._outputs = self.output_layout.start_vector()
        self.t_ns = t0_ns
        self.input_times_ns: dict[str, int] = {}
        self._initialized = False

    @property
    def outputs(self) -> dict[str, np.ndarray]:
        return self.output_layout.unpack(self._outputs.copy())

    def _input_views(self) -> dict[str, np.ndarray]:
        vector = self.input_layout.start_vector()
        for v in self.input_layout.variables:
            value = np.asarray(self.inputs[v.name], dtype=np.float64)
            if value.size != v.size:
                raise ConfigError(v.name, f"input has shape {v.shape}, got {value.size} values")
            vector[self.input_layout.offsets[v.name]] = value.ravel()
        views = self.input_layout.unpack(vector)
        for v in self.input_layout.frames:
            frame = np.asarray(self.inputs[v.name])
            if frame.dtype.name != v.dtype or frame.shape != v.shape:
                raise ConfigError(v.name, f"frame input is {v.dtype} {v.shape}, got {frame.dtype.name} {frame.shape}")
            views[v.name] = frame.view()
            views[v.name].flags.writeable = False
        return views

    def _take(self, result) -> None:
        self.output_layout.pack(result, self._outputs)
        for v in self.output_layout.frames:
            frame = result.get(v.name)
            if not isinstance(frame, np.ndarray) or frame.dtype.name != v.dtype or frame.shape != v.shape:
                raise ConfigError(
                    v.name,
                    f"frame output is {v.dtype} {v.shape}, got "
                    f"{getattr(frame, 'dtype', type(frame).__name__)} {getattr(frame, 'shape', '')}",
                )
            self.frames[v.name] = frame.copy()

    def initialize(self) -> dict[str, np.ndarray]:
        self.component.input_times_ns = dict(self.input_times_ns)
        views = self._input_views()
        views.update((v.name, v.start) for v in self.input_layout.frames)
        self._take(self.component.initialize(self.t_ns, views))
        self._initialized = True
        return self.outputs

    def step(self, h_ns: int) -> dict[str, np.ndarray]:
        """One do_step over [t, t + h_ns); initializes first if needed."""
        if not self._initialized:
            self.initialize()
        self.component.input_times_ns = {
            **{v.name: self.t_ns for v in self.input_layout.variables + self.input_layout.frames},
            **self.input_times_ns,
        }
        self._take(self.component.do_step(self.t_ns, h_ns, self._input_views()))
        self.t_ns += h_ns
        return self.outputs

    def get_state(self) -> bytes:
        """The component state, encoded as it travels on the bus."""
        return encode_state(self.component.get_state())

    def set_state(self, blob: bytes) -> None:
        """Restore an encoded state. On an instance never initialized this is a restore as the
        orchestrator does it (swap, restart): ``set_state`` instead of ``initialize``, and the
        next ``step`` does not initialize (construct the Harness with the state's ``t0_ns``)."""
        self.component.set_state(decode_state(blob))
        self._initialized = True
