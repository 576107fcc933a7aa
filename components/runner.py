"""Bus adapter: runs one component as its own process, in a run driven by the orchestrator.

    python -m components.runner --connect tcp/127.0.0.1:7447 --run-id demo-1a2b3c4d --name orbit

The orchestrator starts it (or a user does, for ``launch: external``) and sends, on the
component's command key: ``instantiate`` (type + parameters), ``wire`` (which sources feed which
inputs), ``initialize``, ``sync``, ``start``, step horizons, ``get_state``/``set_state`` and
``terminate``. Steps need no message from the orchestrator: its sources send their outputs to
its inbox directly and it steps ``k`` as soon as it holds every input tagged for ``k`` and ``k``
is below the horizon (see :mod:`components.schedule`). It sends its outputs once per step to
each consumer, and in batches to the orchestrator. All work happens on the main thread, reading
the one Zenoh FIFO of its inbox (see :mod:`components.bus`); a watchdog thread only flushes
batches. The process exits after ``terminate``, or when the orchestrator's liveliness token
goes away.
"""
from __future__ import annotations

import argparse
import collections
import os
import signal
import sys
import threading
import time
import traceback

import numpy as np

from components import bus, bus_security, registry
from components.schedule import Route, fed_inputs

INBOX_CAPACITY = 4096   # messages waiting in the inbox FIFO (a full one holds the senders back)
BATCH_STEPS = 32   # outputs go to the orchestrator in batches of this many steps ...
IDLE_FLUSH_S = 0.02  # ... or sooner: at the horizon, before a reply or fault, after this long idle,
SLOW_STEP_S = 0.05   # or when a step takes this long (a hung step leaves the steps before it recorded)


CONTROL_OPS = ("instantiate", "wire", "initialize", "sync", "start", "rewire", "get_state", "set_state",
               "terminate")


class Halt(Exception):
    """Stop stepping: a fault was reported to the orchestrator, which ends the run."""


class ComponentProcess:
    """The adapter's state: the component, its layouts, its routes and the inputs it holds.

    ``publish_reply`` and ``publish_batch`` send bytes on the component's reply and batch keys,
    ``publish_output(consumers, payload)`` to the inboxes of the named consumers. Nothing here
    touches Zenoh, so the step logic is tested without the bus.
    """

    def __init__(self, name: str, publish_reply, publish_output, publish_batch):
        self.name = name
        self.publish_reply = publish_reply
        self.publish_output = publish_output
        self.publish_batch = publish_batch
        self.consumers: list[str] = []         # get its outputs at every step (they feed it back)
        self.batch_consumers: list[str] = []   # get them in batches, as the orchestrator does (they never hold it up)
        self.batched = 0
        self.batch_lock = threading.Lock()
        self.stepping_since: float | None = None   # perf_counter at the start of a running do_step
        self.component = None
        self.generation = 0
        self.routes = []
        self.route_inputs: list[list[str]] = []   # the input variables each route feeds
        self.sources: dict[str, int] = {}        # source -> the generation whose outputs count
        self.held: dict[str, collections.deque] = {}   # source -> (tag, outputs), tags increasing
        self.heard: set[str] = set()             # sources whose sync message arrived
        self.source_sizes: dict[str, int] = {}   # source -> the outputs its routes read
        self.drops: dict[str, int] = {}          # key -> messages dropped from it
        self.synced = False
        self.next_k = 0
        self.horizon = 0
        self.final = True     # terminated because the run is over
        self.halted = False   # a step failed: no further step, whatever horizon comes (the run ends or restarts)
        self.step_ns = 0
        self.ratio = 1
        self.faults: list[tuple[int, str, float]] = []   # (step, kind, seconds) to inject, in step order
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
        if payload[:1] != bus.CONTROL:
            raise bus.Malformed(f"neither a horizon nor a control message: first byte {bytes(payload[:1])!r}")
        body, blob = bus.decode_message(payload)
        op = body["op"]
        if op not in CONTROL_OPS:
            raise bus.Malformed(f"unknown control operation {op!r}")
        try:
            return self.control(op, body, blob)
        except Exception as error:  # reported to the orchestrator, which stops the run
            traceback.print_exc(file=sys.stderr)
            self.fault(op, -1, f"{type(error).__name__}: {error}")
            return True

    def source_output(self, source: str, payload: bytes) -> None:
        """An output (or sync) message of a source; bus.Malformed for one that is not, or that
        does not come from a source of the live generation with outputs of its size."""
        kind = payload[:1]
        if kind == bus.OUTPUT:
            generation, tag, vector = bus.decode_output(payload)
            if self._accepts(source, generation, vector.size):
                self.held[source].append((tag, vector))
        elif kind == bus.BATCH:
            generation, tags, _, outputs = bus.decode_batch(payload)
            if self._accepts(source, generation, outputs.shape[1]):
                self.held[source].extend(zip(tags.tolist(), outputs))
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
            return False   # a replaced generation's outputs still in flight
        if size < self.source_sizes.get(source, 0):
            raise bus.Malformed(f"{size} outputs from {source!r}, its routes read {self.source_sizes[source]}")
        return True

    def dropped(self, key: str, reason: str) -> None:
        """Note a dropped message in the component's log (bus.count_drop says when)."""
        if n := bus.count_drop(self.drops, key):
            print(f"warning: dropped a message on {key}: {reason} ({n} so far)", file=sys.stderr, flush=True)

    # ------------------------------------------------------------------ control

    def control(self, op: str, body: dict, blob: bytes) -> bool:
        if op == "instantiate":
            try:
                resolved = registry.resolve(body["type"], body["params"])   # run parameters included
            except registry.Unresolved as e:
                raise e.errors[0] from None
            self.inputs, self.outputs = resolved.inputs, resolved.outputs
            self.input_vector = self.inputs.start_vector()
            self.output_vector = self.outputs.start_vector()
            self.input_views = self.inputs.unpack(self.input_vector)
            self.batch_tags = np.empty(BATCH_STEPS, dtype=np.int64)
            self.batch_timings = np.empty((BATCH_STEPS, 2))
            self.batch_rows = np.empty((BATCH_STEPS, self.outputs.size))
            self.component = resolved.build()
            self.component.input_times_ns = self.input_times = {}
            self.reply(op, {"inputs": self.inputs.size, "outputs": self.outputs.size, "pid": os.getpid()})
        elif op == "wire":
            self.generation, self.step_ns, self.ratio = body["generation"], body["step_ns"], body["ratio"]
            self.consumers, self.batch_consumers = body["consumers"], body["batch_consumers"]
            self.faults = sorted((k, kind, seconds) for k, kind, seconds in body["faults"])
            self.next_k = body["k"]
            self.horizon = body["k"]
            self._set_routes(body["routes"])
            self._set_sources(body["sources"])
            self.reply(op)
        elif op == "initialize":
            self.input_vector[:] = np.frombuffer(blob, dtype=np.float64)
            self.input_times.clear()
            self.input_times.update(body["input_times_ns"])
            result = self.component.initialize(body["t0_ns"], self.input_views)
            self.outputs.pack(result, self.output_vector)
            self.reply(op, {}, self.output_vector.tobytes())
        elif op == "sync":
            # our outputs now reach every consumer that subscribed before this message
            self.publish_output(self.consumers + self.batch_consumers, bus.encode_sync(self.generation))
            if self.synced:
                self.reply("synced")
        elif op == "start":
            # the values each source holds at the first step (its later outputs arrive on the bus)
            self._hold(_held_values(body, blob))
            self.horizon = body["horizon"]
            self.idle_since = time.perf_counter()
        elif op == "rewire":
            self._set_routes(body["routes"])
            self._set_sources(body["sources"])
            self._hold(_held_values(body, blob))
            self.reply(op)
        elif op == "get_state":
            self.reply(op, {}, bus.encode_state(self.component.get_state()))
        elif op == "set_state":
            self.component.set_state(bus.decode_state(blob))
            self.reply(op)
        elif op == "terminate":
            self.final = bool(body.get("final"))   # the run is over (else: a restart may want this component again)
            if self.component is not None:
                self.component.terminate()
            self.reply(op)
            return False
        else:
            raise ValueError(f"unknown control operation {op!r}")
        return True

    def _set_routes(self, routes: list[dict]) -> None:
        self.routes = [Route.from_json(r) for r in routes]
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
        while not self.halted:
            if self.next_k >= self.horizon:
                self.flush()   # the orchestrator needs these outputs to grant more steps
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
                    raise Halt(self._report("step", k, f"input from {route.source!r} for step {k} "
                                                         f"(tag {tag}) never arrived; got tag {held[0][0]}"))
                vectors.append(held[0][1])
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
        try:
            result = self.component.do_step(k * self.step_ns, self.ratio * self.step_ns, self.input_views)
            self.outputs.pack(result, self.output_vector)
            if fault and fault[0] == "nan":
                self.output_vector[0] = np.nan
        except Exception as error:
            traceback.print_exc(file=sys.stderr)
            raise Halt(self._report("step", k, f"{type(error).__name__}: {error}")) from None
        finally:
            self.stepping_since = None
        done = time.perf_counter()
        events = self.component.take_events()
        if events:
            self.publish_reply(bus.encode_message(bus.EVENT, {"op": "events", "k": k, "events": bus.jsonable(
                [[kind, fields] for kind, fields in events])}))
        vector = self.output_vector
        variable = self.outputs.first_non_finite(vector)
        if variable is not None:
            raise Halt(self._report("nan", k, variable))
        tag = k + self.ratio
        if self.consumers:
            self.publish_output(self.consumers, bus.encode_output(self.generation, tag, vector))
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

    def _report(self, op: str, k: int, error: str) -> str:
        self.fault(op, k, error)
        self.halted = True   # a horizon granted later must not run the failed step again
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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m components.runner", description=__doc__.splitlines()[0])
    parser.add_argument("--connect", required=True, help="the orchestrator's Zenoh endpoint, e.g. tcp/127.0.0.1:7447")
    parser.add_argument("--run-id", required=True)
    parser.add_argument("--name", required=True, help="the component's name in the config")
    parser.add_argument("--generation", type=int, default=0)
    parser.add_argument("--listen", help="where the other components reach this one directly "
                                         "(default: port 0 on the address used to reach the orchestrator)")
    parser.add_argument("--cpu", type=int, help="step on this CPU alone (the config's dedicated_cpu)")
    parser.add_argument("--orchestrator", metavar="ZID", help="the Zenoh id of the orchestrator's session: "
                                                              "exit when the link to it closes")
    args = parser.parse_args(argv)
    secret = os.environ.get(bus.SECRET_ENV)
    if not secret:
        parser.error(f"{bus.SECRET_ENV} is not set: give the run's secret in it, as the orchestrator's "
                     f"command for an external component does")
    from components.serving import ORPHANED, serve

    ended = serve(args.connect, args.run_id, args.name, args.generation, args.listen, secret, args.cpu,
                  bus_security.from_env(), args.orchestrator)
    return 1 if ended == ORPHANED else 0


if __name__ == "__main__":
    sys.exit(main())
