"""A component process's control: the orchestrator's commands of :mod:`components.protocol`
(instantiate, wire, initialize, sync, start, rewire, get and set state, terminate) applied to its
state, and the routes and sources they set. The state itself, its stepping and its messages:
:class:`components.process.ComponentProcess`, which takes these methods from :class:`ProcessControl`.
"""

from __future__ import annotations

import collections
import os
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, cast

import numpy as np

from components import bus, protocol, registry
from components.schedule import FrameRoute, Route, fed_inputs
from components.sdk import Component, Layout, RunSettings

if TYPE_CHECKING:
    from components.live_frames import LiveFrameSender


class ProcessControl:
    """The control commands of :class:`components.process.ComponentProcess` (a mixin: the state
    they set is declared there)."""

    # The state ComponentProcess.__init__ sets (typed here, where the commands read it first); the
    # rest comes with the first command that sets it.
    name: str
    component: Component | None
    publish_output: Callable[[list[str], bytes], None]
    consumers: list[str]
    batch_consumers: list[str]
    generation: int
    routes: list[Route]
    float_sources: set[str]
    route_inputs: list[list[str]]
    sources: dict[str, int]
    held: dict[str, collections.deque[tuple[int, np.ndarray]]]
    heard: set[str]
    frame_routes: list[FrameRoute]
    frames_held: dict[tuple[str, str], dict[int, np.ndarray]]
    frame_consumers: dict[str, list[str]]
    frame_messages: dict[str, bytes]
    view: LiveFrameSender | None
    source_sizes: dict[str, int]
    synced: bool
    next_k: int
    horizon: int
    final: bool
    step_ns: int
    ratio: int
    faults: list[tuple[int, str, float]]
    idle_since: float
    inputs: Layout
    outputs: Layout
    input_vector: np.ndarray
    output_vector: np.ndarray
    input_views: dict[str, np.ndarray]
    input_times: dict[str, int]

    if TYPE_CHECKING:  # ComponentProcess's own, which the commands call

        def reply(self, op: str, details: dict | None = None, blob: bytes = b"") -> None: ...
        def _frames(self, result, tag: int, send: bool) -> None: ...
        def _allocate_batch(self) -> None: ...

    def control(self, message: protocol.Message) -> bool:
        # dispatched on the exact type; each branch names the message's type for the checker
        op, kind = cast(str, message.OP), type(message)  # a command's OP is set
        if kind is protocol.Instantiate:
            self._instantiate(cast(protocol.Instantiate, message))
        elif kind is protocol.Wire:
            self._wire(cast(protocol.Wire, message))
        elif kind is protocol.Initialize:
            self._initialize(cast(protocol.Initialize, message))
        elif kind is protocol.Sync:
            # our outputs now reach every consumer that subscribed before this message; the
            # latest frames go (again) first, as a step's do: a consumer synced holds them
            for output, payload in self.frame_messages.items():
                self.publish_output(self.frame_consumers.get(output, []), payload)
            self.publish_output(self.consumers + self.batch_consumers, bus.encode_sync(self.generation))
            if self.synced:
                self.reply("synced")
        elif kind is protocol.Start:
            # the values each source holds at the first step (its later outputs arrive on the bus)
            start = cast(protocol.Start, message)
            self._hold(start.held_values())
            self.horizon = start.horizon
            self.idle_since = time.perf_counter()
        elif kind is protocol.Rewire:
            rewire = cast(protocol.Rewire, message)
            self._set_routes(rewire.routes)
            self._set_sources(rewire.sources)
            self._hold(rewire.held_values())
            self.reply(op)
        elif kind is protocol.GetState:
            self.reply(op, {}, bus.encode_state(self._built().get_state()))
        elif kind is protocol.SetState:
            self._built().set_state(bus.decode_state(cast(protocol.SetState, message).state))
            self.reply(op)
        elif kind is protocol.Terminate:
            self.final = cast(
                protocol.Terminate, message
            ).final  # the run is over (else: a restart may want this component again)
            if self.component is not None:
                self.component.terminate()
            self.reply(op)
            return False
        else:
            raise ValueError(f"not a command: {message!r:.60}")
        return True

    def _built(self) -> Component:
        """The component, which a command after instantiate finds built."""
        return cast(Component, self.component)

    def _initialize(self, message: protocol.Initialize) -> None:
        self.input_vector[:] = message.inputs
        self.input_times.clear()
        self.input_times.update(message.input_times_ns)
        self.input_views.update((v.name, v.start) for v in self.inputs.frames)  # no frame before the first step
        result = self._built().initialize(message.t0_ns, self.input_views)
        self.outputs.pack(result, self.output_vector)
        self._frames(result, self.next_k, send=False)
        self.reply(message.OP, {}, self.output_vector.tobytes())

    def _instantiate(self, message: protocol.Instantiate) -> None:
        try:
            resolved = registry.resolve(message.type, message.params, RunSettings.from_json(message.run))
        except registry.Unresolved as e:
            raise e.errors[0] from None
        self.inputs, self.outputs = resolved.inputs, resolved.outputs
        self.input_vector = self.inputs.start_vector()
        self.output_vector = self.outputs.start_vector()
        self.input_views = self.inputs.unpack(self.input_vector)
        self.input_views.update((v.name, v.start) for v in self.inputs.frames)
        self.frame_outputs = {v.name: v for v in self.outputs.frames}
        if self.view is not None:
            self.view.declare(self.frame_outputs)
        self._allocate_batch()
        self.component = component = resolved.build()
        component.input_times_ns = self.input_times = {}
        self.reply(message.OP, {"inputs": self.inputs.size, "outputs": self.outputs.size, "pid": os.getpid()})

    def _wire(self, message: protocol.Wire) -> None:
        self.generation, self.step_ns, self.ratio = message.generation, message.step_ns, message.ratio
        self.consumers, self.batch_consumers = message.consumers, message.batch_consumers
        self.faults = sorted(message.faults)
        self.next_k = message.k
        self.horizon = message.k
        self._set_routes(message.routes)
        self._set_sources(message.sources)
        self.frame_routes = [FrameRoute(*route) for route in message.frame_routes]
        self.frames_held = {(r.source, r.output): {} for r in self.frame_routes}
        self.frame_consumers = message.frame_consumers
        self.reply(message.OP)

    def _set_routes(self, routes: list[Route]) -> None:
        self.routes = list(routes)
        self.float_sources = {route.source for route in self.routes}  # a source of frames alone: none held
        self.source_sizes = {}
        for route in self.routes:
            needed = int(route.src.max()) + 1 if route.src.size else 0
            self.source_sizes[route.source] = max(self.source_sizes.get(route.source, 0), needed)
        self.route_inputs = [fed_inputs(route, self.inputs.offsets) for route in self.routes]

    def _set_sources(self, sources: dict[str, int]) -> None:
        for source in sources:
            self.held.setdefault(source, collections.deque())
        self.sources = dict(sources)
        self.heard = set()
        self.synced = not any(s != self.name for s in self.sources)

    def _hold(self, held: list[tuple[str, int, np.ndarray]]) -> None:
        """Take source outputs from the orchestrator, (source, tag, outputs) in tag order per
        source, keeping any newer ones that came on the bus first (a source may step as soon as
        it is started, before this message arrives)."""
        values: dict[str, collections.deque[tuple[int, np.ndarray]]] = {}
        for source, tag, vector in held:
            values.setdefault(source, collections.deque()).append((tag, vector))
        for source, entries in values.items():
            last = entries[-1][0]
            entries.extend(entry for entry in self.held.get(source, ()) if entry[0] > last)
            self.held[source] = entries

    def _synced_when_complete(self) -> None:
        if not self.synced and all(s in self.heard for s in self.sources if s != self.name):
            self.synced = True
            self.reply("synced")
