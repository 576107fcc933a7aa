"""Bus adapter: runs one component as its own process, in a run driven by the orchestrator.

    python -m components.runner --connect tcp/127.0.0.1:7447 --run-id demo-1a2b3c4d --name orbit

The orchestrator starts it (or a user does, for ``launch: external``) and sends, on the
component's command key: ``instantiate`` (type + parameters), ``wire`` (which sources feed which
inputs), ``initialize``, ``sync``, ``start``, step horizons, ``get_state``/``set_state`` and
``terminate``. Steps need no message from the orchestrator: the component subscribes to its
sources' outputs directly and steps ``k`` as soon as it holds every input tagged for ``k`` and
``k`` is below the horizon (see :mod:`components.schedule`). It publishes its outputs once per
step, for its consumers and the orchestrator. All work happens on the main thread, reading one
queue that the Zenoh callbacks fill; the process exits after ``terminate``, or when the
orchestrator's liveliness token goes away.
"""
from __future__ import annotations

import argparse
import collections
import os
import queue
import sys
import threading
import time
import traceback

import numpy as np

from components import bus, registry
from components.schedule import Route
from components.sdk import Layout, resolve_parameters

COMMAND = ""   # queue tag of messages from the orchestrator (a source is tagged with its name)
BATCH_STEPS = 32   # outputs go to the orchestrator in batches of this many steps ...
IDLE_FLUSH_S = 0.02  # ... or sooner: at the horizon, before a reply or fault, after this long idle,
SLOW_STEP_S = 0.05   # or when a step takes this long (a hung step leaves the steps before it recorded)


class Halt(Exception):
    """Stop stepping: a fault was reported to the orchestrator, which ends the run."""


class ComponentProcess:
    """The adapter's state: the component, its layouts, its routes and the inputs it holds.

    ``publish_reply``, ``publish_output`` and ``publish_batch`` send bytes on the component's
    reply, output and batch keys; ``subscribe(source)`` makes the source's outputs arrive in the
    queue. Nothing here touches Zenoh, so the step logic is tested without the bus.
    """

    def __init__(self, name: str, publish_reply, publish_output, publish_batch, subscribe):
        self.name = name
        self.publish_reply = publish_reply
        self.publish_output = publish_output
        self.publish_batch = publish_batch
        self.subscribe = subscribe
        self.has_consumers = False
        self.batch_outputs = False    # consumers get outputs in batches too (they never hold it up)
        self.batched = 0
        self.batch_lock = threading.Lock()
        self.stepping_since: float | None = None   # perf_counter at the start of a running do_step
        self.component = None
        self.generation = 0
        self.routes = []
        self.sources: dict[str, int] = {}        # source -> the generation whose outputs count
        self.held: dict[str, collections.deque] = {}   # source -> (tag, outputs), tags increasing
        self.heard: set[str] = set()             # sources whose sync message arrived
        self.synced = False
        self.next_k = 0
        self.horizon = 0
        self.step_ns = 0
        self.ratio = 1
        self.idle_since = time.perf_counter()

    # ------------------------------------------------------------------ messages

    def reply(self, op: str, body: dict | None = None, blob: bytes = b"") -> None:
        self.flush()
        self.publish_reply(bus.encode_message(bus.REPLY, {"op": op, **(body or {})}, blob))

    def fault(self, op: str, k: int, error: str) -> None:
        self.flush()
        self.publish_reply(bus.encode_message(bus.FAULT, {"op": op, "k": k, "error": error}))

    def command(self, payload: bytes) -> bool:
        """A message from the orchestrator; False when the process should exit."""
        if payload[:1] == bus.HORIZON:
            self.horizon = bus.decode_horizon(payload)
            return True
        body, blob = bus.decode_message(payload)
        op = body["op"]
        try:
            return self.control(op, body, blob)
        except Exception as error:  # reported to the orchestrator, which stops the run
            traceback.print_exc(file=sys.stderr)
            self.fault(op, -1, f"{type(error).__name__}: {error}")
            return True

    def source_output(self, source: str, payload: bytes) -> None:
        """An output (or sync) message of a source."""
        kind = payload[:1]
        if kind == bus.OUTPUT:
            generation, tag, vector = bus.decode_output(payload)
            if self.sources.get(source) == generation:
                self.held[source].append((tag, vector))
        elif kind == bus.BATCH:
            generation, tags, _, outputs = bus.decode_batch(payload)
            if self.sources.get(source) == generation:
                self.held[source].extend(zip(tags.tolist(), outputs))
        elif kind == bus.SYNC and self.sources.get(source) == bus.decode_sync(payload) and not self.synced:
            self.heard.add(source)
            self._synced_when_complete()

    # ------------------------------------------------------------------ control

    def control(self, op: str, body: dict, blob: bytes) -> bool:
        if op == "instantiate":
            cls = registry.load(body["type"], body["params"].get("_config_dir"))
            params, errors = resolve_parameters(cls, body["params"])
            if errors:
                raise errors[0]
            variables = cls.declare(params)
            self.inputs = Layout([v for v in variables if v.causality == "input"])
            self.outputs = Layout([v for v in variables if v.causality == "output"])
            self.input_vector = self.inputs.start_vector()
            self.output_vector = self.outputs.start_vector()
            self.input_views = self.inputs.unpack(self.input_vector)
            self.batch_tags = np.empty(BATCH_STEPS, dtype=np.int64)
            self.batch_timings = np.empty((BATCH_STEPS, 2))
            self.batch_rows = np.empty((BATCH_STEPS, self.outputs.size))
            self.component = cls(params)
            self.reply(op, {"inputs": self.inputs.size, "outputs": self.outputs.size, "pid": os.getpid()})
        elif op == "wire":
            self.generation, self.step_ns, self.ratio = body["generation"], body["step_ns"], body["ratio"]
            self.has_consumers = body["consumers"]
            self.batch_outputs = body["batch_outputs"]
            self.next_k = body["k"]
            self.horizon = body["k"]
            self.routes = [Route.from_json(r) for r in body["routes"]]
            self._set_sources(body["sources"])
            self.reply(op)
        elif op == "initialize":
            self.input_vector[:] = np.frombuffer(blob, dtype=np.float64)
            result = self.component.initialize(body["t0_ns"], self.input_views)
            self.outputs.pack(result, self.output_vector)
            self.reply(op, {}, self.output_vector.tobytes())
        elif op == "sync":
            # our outputs now reach every consumer that subscribed before this message
            self.publish_output(bus.encode_sync(self.generation))
            if self.synced:
                self.reply("synced")
        elif op == "start":
            # the values each source holds at the first step (its later outputs arrive on the bus)
            self._hold(_held_values(body, blob))
            self.horizon = body["horizon"]
            self.idle_since = time.perf_counter()
        elif op == "rewire":
            self.routes = [Route.from_json(r) for r in body["routes"]]
            self._set_sources(body["sources"])
            self._hold(_held_values(body, blob))
            self.reply(op)
        elif op == "get_state":
            self.reply(op, {}, bus.encode_state(self.component.get_state()))
        elif op == "set_state":
            self.component.set_state(bus.decode_state(blob))
            self.reply(op)
        elif op == "terminate":
            if self.component is not None:
                self.component.terminate()
            self.reply(op)
            return False
        else:
            raise ValueError(f"unknown control operation {op!r}")
        return True

    def _set_sources(self, sources: dict[str, int]) -> None:
        for source, generation in sources.items():
            if source not in self.sources and source != self.name:
                self.subscribe(source)
            self.held.setdefault(source, collections.deque())
        self.sources = dict(sources)
        self.heard = set()
        self.synced = not any(s != self.name for s in self.sources)

    def _hold(self, values: dict[str, collections.deque]) -> None:
        """Take source outputs from the orchestrator, keeping any newer ones that came on the bus
        first (a source may step as soon as it is started, before this message arrives)."""
        for source, entries in values.items():
            last = entries[-1][0]
            entries.extend(entry for entry in self.held.get(source, ()) if entry[0] > last)
            self.held[source] = entries

    def _synced_when_complete(self) -> None:
        if not self.synced and all(s in self.heard for s in self.sources if s != self.name):
            self.synced = True
            self.reply("synced")

    # ------------------------------------------------------------------ stepping

    def advance(self) -> None:
        """Do every step whose inputs are all held and which lies below the horizon."""
        while True:
            if self.next_k >= self.horizon:
                self.flush()   # the orchestrator needs these outputs to grant more steps
                return
            k = self.next_k
            vectors = []
            for route in self.routes:
                held = self.held[route.source]
                tag = route.tag(k)
                while held and held[0][0] < tag:
                    held.popleft()
                if not held:
                    return
                if held[0][0] != tag:
                    raise Halt(self._report("step", k, f"input from {route.source!r} for step {k} "
                                                         f"(tag {tag}) never arrived; got tag {held[0][0]}"))
                vectors.append(held[0][1])
            for route, vector in zip(self.routes, vectors):
                self.input_vector[route.dst] = vector[route.src]
            self._step(k)

    def _step(self, k: int) -> None:
        started = self.stepping_since = time.perf_counter()
        try:
            result = self.component.do_step(k * self.step_ns, self.ratio * self.step_ns, self.input_views)
            self.outputs.pack(result, self.output_vector)
        except Exception as error:
            traceback.print_exc(file=sys.stderr)
            raise Halt(self._report("step", k, f"{type(error).__name__}: {error}")) from None
        finally:
            self.stepping_since = None
        done = time.perf_counter()
        vector = self.output_vector
        variable = self.outputs.first_non_finite(vector)
        if variable is not None:
            raise Halt(self._report("nan", k, variable))
        tag = k + self.ratio
        if self.has_consumers and not self.batch_outputs:
            self.publish_output(bus.encode_output(self.generation, tag, vector))
        if self.name in self.held:   # a component fed by its own outputs
            self.held[self.name].append((tag, vector.copy()))
        with self.batch_lock:
            i = self.batched
            self.batch_tags[i] = tag
            self.batch_timings[i] = done - started, started - self.idle_since
            self.batch_rows[i] = vector
            self.batched = i + 1
        if self.batched == BATCH_STEPS:
            self.flush()
        self.next_k = tag
        self.idle_since = time.perf_counter()

    def flush(self) -> None:
        """Send the outputs not yet sent to the orchestrator (from any thread)."""
        with self.batch_lock:
            self._flush()

    def flush_if_stuck(self) -> None:
        """From a watchdog thread: flush while a step has been running for long."""
        since = self.stepping_since
        if since is not None and time.perf_counter() - since > SLOW_STEP_S and self.batched:
            self.flush()

    def _flush(self) -> None:
        n = self.batched
        if n:
            batch = bus.encode_batch(self.generation, self.batch_tags[:n], self.batch_timings[:n], self.batch_rows[:n])
            self.publish_batch(batch)
            if self.has_consumers and self.batch_outputs:
                self.publish_output(batch)
            self.batched = 0

    def _report(self, op: str, k: int, error: str) -> str:
        self.fault(op, k, error)
        self.horizon = self.next_k   # no further step; the orchestrator ends the run
        return error


def _watchdog(process: ComponentProcess) -> None:
    while True:
        time.sleep(SLOW_STEP_S)
        process.flush_if_stuck()


def _held_values(body: dict, blob: bytes) -> dict[str, collections.deque]:
    """Source outputs sent by the orchestrator, {source: deque of (tag, outputs)}, from the body's
    ``held`` list of [source, tag, size] and the outputs packed in ``blob`` in that order."""
    values: dict[str, collections.deque] = {}
    offset = 0
    everything = np.frombuffer(blob, dtype=np.float64)
    for source, tag, size in body["held"]:
        values.setdefault(source, collections.deque()).append((tag, everything[offset:offset + size].copy()))
        offset += size
    return values


def serve(connect: str, run_id: str, name: str, generation: int, listen: str) -> int:
    import zenoh

    session = zenoh.open(bus.session_config(listen=[listen], connect=[connect], mesh=True))
    inbox: queue.SimpleQueue = queue.SimpleQueue()
    keep = []   # subscribers live as long as the session
    try:
        keep.append(session.declare_subscriber(bus.component_key(run_id, name, generation, "cmd"),
                                               lambda s: inbox.put((COMMAND, s.payload.to_bytes()))))
        replies = bus.publisher(session, bus.component_key(run_id, name, generation, "out"))
        outputs = bus.publisher(session, bus.output_key(run_id, name))
        batches = bus.publisher(session, bus.batch_key(run_id, name))

        def subscribe(source: str) -> None:
            keep.append(session.declare_subscriber(bus.output_key(run_id, source),
                                                   lambda s: inbox.put((source, s.payload.to_bytes()))))

        # the orchestrator gone (killed, machine lost): wake the main loop with a QUIT message
        keep.append(session.liveliness().declare_subscriber(
            bus.run_key(run_id, "alive", "orchestrator"),
            lambda s: inbox.put((COMMAND, bus.QUIT)) if s.kind == zenoh.SampleKind.DELETE else None))
        keep.append(session.liveliness().declare_token(bus.run_key(run_id, "alive", name, str(generation))))
        process = ComponentProcess(name, replies.put, outputs.put, batches.put, subscribe)
        threading.Thread(target=_watchdog, args=(process,), daemon=True).start()
        while True:
            try:
                source, payload = inbox.get(timeout=IDLE_FLUSH_S) if process.batched else inbox.get()
            except queue.Empty:
                process.flush()
                continue
            if source == COMMAND:
                if payload == bus.QUIT:
                    print("the orchestrator went away: exiting", file=sys.stderr)
                    return 1
                if not process.command(payload):
                    return 0
            else:
                process.source_output(source, payload)
            try:
                process.advance()
            except Halt:
                pass
    finally:
        keep.clear()
        session.close()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m components.runner", description=__doc__.splitlines()[0])
    parser.add_argument("--connect", required=True, help="the orchestrator's Zenoh endpoint, e.g. tcp/127.0.0.1:7447")
    parser.add_argument("--run-id", required=True)
    parser.add_argument("--name", required=True, help="the component's name in the config")
    parser.add_argument("--generation", type=int, default=0)
    parser.add_argument("--listen", help="where the other components reach this one directly "
                                         "(default: port 0 on the address used to reach the orchestrator)")
    args = parser.parse_args(argv)
    return serve(args.connect, args.run_id, args.name, args.generation, args.listen or bus.listen_beside(args.connect))


if __name__ == "__main__":
    sys.exit(main())
