"""A component's process, its step logic: the commands of :mod:`components.protocol` applied to
the component, its inputs gathered from its sources' outputs, its steps run in order below the
horizon (see :mod:`components.schedule`), its outputs sent once per step to each consumer and in
batches to the orchestrator. Nothing here touches Zenoh (:mod:`components.serving` feeds it from
the component's inbox), so the step logic is tested without the bus.
"""

from __future__ import annotations

import collections
import os
import signal
import sys
import threading
import time
import traceback
from typing import cast

import numpy as np

from components import bus, protocol
from components.process_control import ProcessControl
from components.schedule import FrameRoute
from components.sdk import Component, ComponentOutputError

BATCH_STEPS = 32  # outputs go to the orchestrator in batches of this many steps ...
BATCH_MIN_S = 0.002  # ... more (up to BATCH_CAPACITY) while this long has not passed since the last (each
BATCH_CAPACITY = 256  # send costs a light model's several steps; a crash loses at most this long of rows) ...
IDLE_FLUSH_S = 0.02  # ... or sooner: at the horizon, before a reply or fault, after this long idle,
SLOW_STEP_S = 0.05  # or when a step takes this long (a hung step leaves the steps before it recorded)


class Halt(Exception):
    """Stop stepping: a fault was reported to the orchestrator, which ends the run."""


class ComponentProcess(ProcessControl):
    """The adapter's state: the component, its layouts, its routes and the inputs it holds; the
    control commands that set them: :class:`components.process_control.ProcessControl`.

    ``publish_reply`` and ``publish_batch`` send bytes on the component's reply and batch keys,
    ``publish_output(consumers, payload)`` to the inboxes of the named consumers. Nothing here
    touches Zenoh, so the step logic is tested without the bus.
    """

    def __init__(self, name: str, publish_reply, publish_output, publish_batch):
        self.name = name
        self.publish_reply = publish_reply
        self.publish_output = publish_output
        self.publish_batch = publish_batch
        self.consumers: list[str] = []  # get its outputs at every step (they feed it back)
        self.batch_consumers: list[str] = []  # get them in batches, as the orchestrator does (they never hold it up)
        self.batched = 0
        self.flushed_at = 0.0  # perf_counter at the last batch sent
        self.batch_lock = threading.Lock()
        self.stepping_since: float | None = None  # perf_counter at the start of a running do_step
        self.component = None
        self.generation = 0
        self.routes = []
        self.float_sources: set[str] = set()
        self.route_inputs: list[list[str]] = []  # the input variables each route feeds
        self.sources: dict[str, int] = {}  # source -> the generation whose outputs count
        self.held: dict[str, collections.deque] = {}  # source -> (tag, outputs), tags increasing
        self.heard: set[str] = set()  # sources whose sync message arrived
        self.frame_routes: list[FrameRoute] = []
        self.frames_held: dict[tuple[str, str], dict[int, np.ndarray]] = {}  # (source, output) -> tag -> frame
        self.frame_consumers: dict[str, list[str]] = {}  # our frame output -> who gets it
        self.frame_messages: dict[str, bytes] = {}  # our frame output -> its latest message (sent again at sync)
        self.view = None  # a live_frames.LiveFrameSender: our frame outputs for the live views, while one watches
        self.source_sizes: dict[str, int] = {}  # source -> the outputs its routes read
        self.drops: dict[str, int] = {}  # key -> messages dropped from it
        self.synced = False
        self.next_k = 0
        self.horizon = 0
        self.final = True  # terminated because the run is over
        self.halted = False  # a step failed: no further step, whatever horizon comes (the run ends or restarts)
        self.step_ns = 0
        self.ratio = 1
        self.faults: list[tuple[int, str, float]] = []  # (step, kind, seconds) to inject, in step order
        self.idle_since = time.perf_counter()

    # ------------------------------------------------------------------ messages

    def reply(self, op: str, details: dict | None = None, blob: bytes = b"") -> None:
        self.flush()
        self.publish_reply(protocol.Reply(op, details or {}, blob).encode())

    def fault(self, op: str, k: int, error: str) -> None:
        self.flush()
        self.publish_reply(protocol.Fault(op, k, error).encode())

    def command(self, payload: bytes) -> bool:
        """A message from the orchestrator; False when the process should exit."""
        message = protocol.decode_command(payload)
        if type(message) is protocol.Horizon:
            self.horizon = message.horizon
            return True
        try:
            return self.control(message)
        except Exception as error:  # reported to the orchestrator, which stops the run
            traceback.print_exc(file=sys.stderr)
            self.fault(cast(str, message.OP), -1, f"{type(error).__name__}: {error}")
            return True

    def source_output(self, source: str, payload: bytes) -> None:
        """An output (or sync) message of a source; bus.Malformed for one that is not, or that
        does not come from a source of the live generation with outputs of its size."""
        kind = payload[:1]
        if kind == bus.OUTPUT:
            generation, tag, vector = bus.decode_output(payload)
            if self._accepts(source, generation, vector.size) and source in self.float_sources:
                self.held[source].append((tag, vector))
        elif kind == bus.BATCH:
            generation, tags, _, outputs = bus.decode_batch(payload)
            if self._accepts(source, generation, outputs.shape[1]) and source in self.float_sources:
                self.held[source].extend(zip(tags.tolist(), outputs))
        elif kind == bus.FRAME:
            generation, tag, output, frame = bus.decode_frame(payload)
            held = self.frames_held.get((source, output))
            if held is None:
                raise bus.Malformed(f"frame {output!r} of {source!r} feeds no input of {self.name}")
            if self.sources[source] == generation:
                held[tag] = frame  # by tag: a frame sent again (at sync) replaces its copy
        elif kind == bus.SYNC:
            if self.sources.get(source) == bus.decode_sync(payload) and not self.synced:
                self.heard.add(source)
                self._synced_when_complete()
        else:
            raise bus.Malformed(f"not an output message: first byte {bytes(payload[:1])!r}")

    def _accepts(self, source: str, generation: int, size: int) -> bool:
        if source not in self.sources:
            raise bus.Malformed(f"{source!r} is not a source of {self.name}")
        if self.sources[source] != generation:
            return False  # a replaced generation's outputs still in flight
        if size < self.source_sizes.get(source, 0):
            raise bus.Malformed(f"{size} outputs from {source!r}, its routes read {self.source_sizes[source]}")
        return True

    def dropped(self, key: str, reason: str) -> None:
        """Note a dropped message in the component's log (bus.count_drop says when)."""
        if n := bus.count_drop(self.drops, key):
            print(f"warning: dropped a message on {key}: {reason} ({n} so far)", file=sys.stderr, flush=True)

    # ------------------------------------------------------------------ stepping

    def advance(self) -> None:
        """Do every step whose inputs are all held and which lies below the horizon."""
        while not self.halted:
            if self.next_k >= self.horizon:
                self.flush()  # the orchestrator needs these outputs to grant more steps
                return
            k = self.next_k
            vectors, tags = [], []
            for route in self.routes:
                held = self.held[route.source]
                tag = route.tag(k)
                tags.append(tag)
                while held and held[0][0] < tag:
                    held.popleft()
                if not held:
                    return
                if held[0][0] != tag:
                    raise Halt(
                        self._report(
                            "step",
                            k,
                            f"input from {route.source!r} for step {k} (tag {tag}) never arrived; got tag {held[0][0]}",
                        )
                    )
                vectors.append(held[0][1])
            frames = []
            for frame_route in self.frame_routes:
                frame = self.frames_held[frame_route.source, frame_route.output].get(frame_route.tag(k))
                if frame is None:
                    return  # it comes before its step's outputs, unless the bus reordered them
                frames.append(frame)
            for frame_route, frame in zip(self.frame_routes, frames):
                self.input_views[frame_route.input] = frame
                self.input_times[frame_route.input] = frame_route.tag(k) * self.step_ns
                kept = self.frames_held[frame_route.source, frame_route.output]
                for old in [t for t in kept if t < frame_route.tag(k)]:  # never read again: tags only grow
                    del kept[old]
            for route, names, vector, tag in zip(self.routes, self.route_inputs, vectors, tags):
                self.input_vector[route.dst] = vector[route.src]
                for name in names:
                    self.input_times[name] = tag * self.step_ns
            self._step(k)

    def _step(self, k: int) -> None:
        started = self.stepping_since = time.perf_counter()
        fault = self.faults.pop(0)[1:] if self.faults and k >= self.faults[0][0] else None
        if fault:
            _inject(*fault)
        component = cast(Component, self.component)  # built by instantiate, before any step
        try:
            result = component.do_step(k * self.step_ns, self.ratio * self.step_ns, self.input_views)
            self.outputs.pack(result, self.output_vector)
            if fault and fault[0] == "nan":
                self.output_vector[0] = np.nan
            if self.frame_outputs:
                self._frames(result, k + self.ratio, send=True)  # before the outputs: consumers hold it first
                if self.view is not None:
                    taken = component.frame_time_ns
                    for name in self.frame_outputs:
                        self.view.send(
                            name,
                            k * self.step_ns if taken is None else taken,
                            self.generation,
                            k + self.ratio,
                            result[name],
                        )
        except Exception as error:
            traceback.print_exc(file=sys.stderr)
            raise Halt(self._report("step", k, f"{type(error).__name__}: {error}")) from None
        finally:
            self.stepping_since = None
        done = time.perf_counter()
        events = component.take_events()
        if events:
            self.publish_reply(protocol.Events(k, bus.jsonable([[kind, fields] for kind, fields in events])).encode())
        vector = self.output_vector
        variable = self.outputs.first_non_finite(vector)
        if variable is not None:
            raise Halt(self._report("nan", k, variable))
        tag = k + self.ratio
        if self.consumers:
            self.publish_output(self.consumers, bus.encode_output(self.generation, tag, vector))
        if self.name in self.held:  # a component fed by its own outputs
            self.held[self.name].append((tag, vector.copy()))
        with self.batch_lock:
            i = self.batched
            self.batch_tags[i] = tag
            timings = self.batch_timings  # one float at a time: a tuple into a row costs twice as much
            timings[i, 0] = done - started
            timings[i, 1] = started - self.idle_since
            self.batch_rows[i] = vector
            self.batched = i + 1
        if self.batched >= BATCH_STEPS and (done - self.flushed_at >= BATCH_MIN_S or self.batched == BATCH_CAPACITY):
            self.flush()
        self.next_k = tag
        self.idle_since = time.perf_counter()

    def _frames(self, result, tag: int, send: bool) -> None:
        """Encode the frame outputs of ``result`` (tagged ``tag``), checked against their
        declarations; with ``send``, publish each to its consumers."""
        for name, variable in self.frame_outputs.items():
            try:
                frame = result[name]
            except KeyError:
                raise ComponentOutputError(f"frame output {name!r} missing from the step's result") from None
            if not isinstance(frame, np.ndarray) or frame.dtype.name != variable.dtype or frame.shape != variable.shape:
                raise ComponentOutputError(
                    f"frame output {name!r}: expected a {variable.dtype} array of shape "
                    f"{variable.shape}, got {getattr(frame, 'dtype', type(frame).__name__)} "
                    f"{getattr(frame, 'shape', '')}"
                )
            consumers = self.frame_consumers.get(name)
            if consumers:
                payload = self.frame_messages[name] = bus.encode_frame(self.generation, tag, name, frame)
                if send:
                    self.publish_output(consumers, payload)

    def _allocate_batch(self) -> None:
        """The batch's buffers, for outputs of the instantiated component's size."""
        self.batch_tags = np.empty(BATCH_CAPACITY, dtype=np.int64)
        self.batch_timings = np.empty((BATCH_CAPACITY, 2))
        self.batch_rows = np.empty((BATCH_CAPACITY, self.outputs.size))

    def flush(self) -> None:
        """Send the outputs not yet sent to the orchestrator (from any thread)."""
        with self.batch_lock:
            self._flush()

    def flush_if_due(self) -> None:
        """From a watchdog thread: flush when idle for long, or while a step has been running for long."""
        since, now = self.stepping_since, time.perf_counter()
        if self.batched and (now - since > SLOW_STEP_S if since is not None else now - self.idle_since > IDLE_FLUSH_S):
            self.flush()

    def _flush(self) -> None:
        n = self.batched
        if n:
            batch = bus.encode_batch(self.generation, self.batch_tags[:n], self.batch_timings[:n], self.batch_rows[:n])
            self.publish_batch(batch)
            if self.batch_consumers:
                self.publish_output(self.batch_consumers, batch)
            self.batched = 0
            self.flushed_at = time.perf_counter()

    def _report(self, op: str, k: int, error: str) -> str:
        self.fault(op, k, error)
        self.halted = True  # a horizon granted later must not run the failed step again
        return error


def _inject(kind: str, seconds: float) -> None:
    """A fault of the config's ``faults:`` (docs/design.md §7), as a real failure would look."""
    print(f"injecting a fault: {kind}", file=sys.stderr, flush=True)
    if kind == "crash":
        os.kill(os.getpid(), signal.SIGKILL)
    elif kind == "hang":
        while True:
            time.sleep(3600)
    elif kind == "delay":
        time.sleep(seconds)
