"""A config stepped in this one process, no bus: the reference that a bus run must equal bit for bit.

    rows = run_in_process(load("configs/humanoid_tracking.yaml"), steps=500)

The components are built from the same parameters (through the same JSON the instantiate message
carries), step on the inputs that :mod:`components.schedule` tags for each step, one after another
in config order, and their outputs go through the same float64 layouts as in a bus run. The
result is the recording's signal columns, row k = t_k.
"""

from __future__ import annotations

import json
import time

import numpy as np

from components import bus, schedule
from components.registry import Unresolved, resolve
from components.sdk import RunSettings
from orchestrator.config import shadows
from orchestrator.config.specs import RunConfig


class _Stepped:
    """One component instance with its layouts and the outputs it has produced, by tag."""

    def __init__(self, config: RunConfig, name: str):
        spec = config.components[name]
        raw = json.loads(json.dumps(bus.jsonable(spec.parameters)))
        run = RunSettings.from_json(json.loads(json.dumps(config.run_settings.to_json())))
        try:
            resolved = resolve(spec.cls, raw, run)
        except Unresolved as e:
            raise e.errors[0] from None
        self.inputs, self.outputs = resolved.inputs, resolved.outputs
        self.input_vector = self.inputs.start_vector()
        self.input_views = self.inputs.unpack(self.input_vector)
        self.input_views.update((v.name, v.start) for v in self.inputs.frames)  # none before the first step
        self.component = resolved.build()
        self.ratio = spec.step_ns // config.step_ns
        self.by_tag: dict[int, np.ndarray] = {}
        self.frames_by_tag: dict[int, dict[str, np.ndarray]] = {}  # its frame outputs, read-only copies
        self.routes: list[schedule.Route] = []
        self.frame_routes: list[schedule.FrameRoute] = []
        self.route_inputs: list[list[str]] = []
        self.input_times: dict[str, int] = {}  # input -> when its value was sampled (ns); the component's own
        self.component.input_times_ns = self.input_times

    def take_inputs(self, members: dict[str, _Stepped], k: int, step_ns: int) -> None:
        for route, names in zip(self.routes, self.route_inputs):
            tag = route.tag(k)
            self.input_vector[route.dst] = members[route.source].by_tag[tag][route.src]
            self.input_times.update(dict.fromkeys(names, tag * step_ns))
        for frame_route in self.frame_routes:
            tag = frame_route.tag(k)
            self.input_views[frame_route.input] = members[frame_route.source].frames_by_tag[tag][frame_route.output]
            self.input_times[frame_route.input] = tag * step_ns

    def pack(self, result, tag: int) -> np.ndarray:
        """The float outputs of ``result`` as a vector; its frames kept under ``tag`` (copies, as the bus makes)."""
        vector = np.empty(self.outputs.size)
        self.outputs.pack(result, vector)
        if self.outputs.frames:
            self.frames_by_tag[tag] = {v.name: _frozen(result[v.name]) for v in self.outputs.frames}
        return vector


def _frozen(frame: np.ndarray) -> np.ndarray:
    frame = np.array(frame)
    frame.flags.writeable = False
    return frame


def run_in_process(
    config: RunConfig, steps: int | None = None, timing: dict | None = None, events: list | None = None
) -> np.ndarray:
    """Rows (steps + 1, number of recorded columns) of the config run for ``steps`` steps
    (default: its duration). ``timing``, if given, gets ``loop_s``: the wall time of the stepping
    loop (start-up excluded, as a bus run's ``loop_s``), for benchmarks. ``events``, if given, gets
    the components' events as events.jsonl would hold them (dicts)."""
    steps = config.steps if steps is None else steps
    order = list(config.components)
    members = {name: _Stepped(config, name) for name in order}
    offsets = {name: m.outputs.offsets for name, m in members.items()}
    ratios = {name: m.ratio for name, m in members.items()}
    for name, member in members.items():
        member.routes = schedule.routes(
            name, member.inputs.offsets, config.connections, offsets, ratios, order, config.algorithm
        )
        member.route_inputs = [schedule.fed_inputs(r, member.inputs.offsets) for r in member.routes]
        member.frame_routes = schedule.frame_routes(
            name, [v.name for v in member.inputs.frames], config.connections, ratios, order, config.algorithm
        )
    for name in shadows.initialization_order(config.components, config.connections):
        member = members[name]
        for route, names in zip(member.routes, member.route_inputs):  # sources not initialized yet
            source = members[route.source]  # hold their start values
            member.input_vector[route.dst] = source.by_tag.get(0, source.outputs.start_vector())[route.src]
            if 0 in source.by_tag:
                member.input_times.update(dict.fromkeys(names, 0))
        member.by_tag[0] = member.pack(member.component.initialize(0, member.input_views), 0)

    rows = np.empty((steps + 1, sum(m.outputs.size for m in members.values())))
    rows[0] = np.concatenate([m.by_tag[0] for m in members.values()])
    started = time.perf_counter()
    for k in range(steps):
        for name, member in members.items():
            if schedule.is_due(member.ratio, k):
                member.take_inputs(members, k, config.step_ns)
                result = member.component.do_step(k * config.step_ns, member.ratio * config.step_ns, member.input_views)
                member.by_tag[k + member.ratio] = member.pack(result, k + member.ratio)
                for kind, fields in member.component.take_events():
                    if events is not None:
                        events.append({"event": kind, **bus.jsonable(fields), "component": name, "step": k})
        rows[k + 1] = np.concatenate([m.by_tag[schedule.row_tag(m.ratio, k + 1)] for m in members.values()])
        for member in members.values():  # keep only what a later step can still read
            oldest = schedule.row_tag(member.ratio, k + 1)
            for tag in [t for t in member.by_tag if t < oldest]:
                del member.by_tag[tag]
            for tag in [t for t in member.frames_by_tag if t < oldest]:
                del member.frames_by_tag[tag]
    if timing is not None:
        timing["loop_s"] = time.perf_counter() - started
    return rows
