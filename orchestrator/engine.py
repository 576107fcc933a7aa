"""The lockstep master of a run: starts the components, wires them to each other, grants steps,
records, and stops the run on the first fault (or, for a component with ``on_failure: restart``
that dies or hangs, sends the whole run back to its last checkpoint).

The orchestrator is off the per-step path. Components exchange their outputs directly (see
:mod:`components.bus`) and each steps ``k`` as soon as it holds the inputs tagged for ``k`` and
``k`` lies below the *horizon* the orchestrator grants (rules: :mod:`components.schedule`). The
orchestrator receives every output, assembles the recorded rows, and checks for deaths
(liveliness) and hangs (a component that holds its inputs but does not step within
``run.step_timeout``). Control (swap, stop, events) and checkpoints happen at a step boundary:
the horizon is held there until every component has reached it. A component with no input from the loop (an
orbit) runs ahead up to the horizon, which hides its cost.

Components send the orchestrator their outputs in batches (see :mod:`components.runner`).
Every message the orchestrator receives lands in one inbox queue (callbacks only enqueue) and the
main thread does all the work. Times are integer nanoseconds, step k covers [k*h, (k+1)*h).
"""
from __future__ import annotations

import collections
import datetime as dt
import json
import os
import queue
import secrets
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time
import traceback
import uuid
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from components import bus, schedule
from components.schedule import Route
from orchestrator import runs, supervisor
from orchestrator.config import ComponentSpec, RunConfig, ViewerSpec
from orchestrator.control import ControlServer, SwapFailed
from orchestrator.recording import Recording, RecordingError
from orchestrator import wording
from components.units import duration_ns, duration_text

VIEWER = "_viewer"   # liveliness name of the observer (component names cannot start with _)
SIGNALS_HEADER = struct.Struct("<qd")  # k, time in s; then the row of every output, float64
WINDOW = 256         # steps a component may run ahead of the recorded rows
SYNC_ROUND_S = 0.05  # the start-up handshake is repeated at this interval until everyone hears everyone


class RunFailure(Exception):
    """The run cannot go on: a component crashed, hung, or produced a non-finite value.
    ``lost``: ``member`` died or hung (a restart may cure that), rather than reported a fault."""

    def __init__(self, message: str, member: "Member | None" = None, lost: bool = False):
        super().__init__(message)
        self.member = member
        self.lost = lost


@dataclass
class Checkpoint:
    """Where a restart goes back to: a step boundary, every component's state there and what the
    orchestrator held (the recorded row, each member's last outputs)."""
    row: int
    values: np.ndarray
    specs: list[ComponentSpec]
    states: dict[str, bytes]
    latest: dict[str, tuple[int, np.ndarray]]
    events: list                        # the config's swaps still to come


class StopRequested(Exception):
    """Ctrl-C, SIGTERM or `orchestrator stop`: end the run cleanly."""


@dataclass
class Member:
    """A live component: its spec, its process, its routes, and the outputs seen from it."""
    spec: ComponentSpec
    generation: int
    process: subprocess.Popen | None
    log_path: Path | None
    ratio: int                             # its step in run steps
    command: object = None                 # Zenoh publisher of its command key
    routes: list[Route] = field(default_factory=list)
    out_dst: np.ndarray = None             # where its outputs go in the recorded row ...
    out_src: np.ndarray = None             # ... from these indices of its output vector
    tag: int = 0                           # the tag of ``latest``: what the recorded rows hold now
    latest: np.ndarray = None
    initialized: bool = False              # ``latest`` holds its outputs (not its start values)
    received: collections.deque = field(default_factory=collections.deque)  # (tag, outputs), not yet recorded
    progress: int = 0                      # the highest tag it has published
    progress_at: float = 0.0               # wall time of its last output
    compute_s: float = 0.0
    idle_s: float = 0.0
    steps: int = 0
    reply: dict | None = field(default=None, repr=False)

    @property
    def name(self) -> str:
        return self.spec.name


class Run:
    """One execution of a validated config. ``execute()`` returns the exit code (0, 1, 130)."""

    def __init__(self, config: RunConfig, *, record: str | Path | None = None, profile: bool = False,
                 progress: bool = False, out=sys.stderr, viewer: ViewerSpec | None = None):
        self.config = config
        self.viewer = viewer or config.viewer
        self.viewer_process: subprocess.Popen | None = None
        self.record_dir = Path(record) if record else None
        self.profile = profile
        self.progress = progress
        self.out = out
        self.run_id = f"{config.name}-{uuid.uuid4().hex[:8]}"
        self.secret = secrets.token_hex(32)   # the run's processes hold it; nothing else can join (§7)
        self.child_env = {**os.environ, bus.SECRET_ENV: self.secret}
        self.inbox: queue.SimpleQueue = queue.SimpleQueue()
        self.members: dict[str, Member] = {}
        self.joining: dict[str, Member] = {}   # a swap's new generation, until it takes over
        self.order = list(config.components)
        self.pending_events = list(config.events)
        self.pending_faults = list(config.faults)
        self.tables: dict[str, object] = {}    # component -> its swaps/ table, after a swap to another type
        # checkpoints, only when a component may restart: at the start, every checkpoint_every, after a swap
        self.restartable = any(s.on_failure == "restart" for s in config.components.values())
        self.checkpoint: Checkpoint | None = None
        self.restarts = 0
        self.controls = ControlServer(self)
        self.dropped: dict[str, int] = {}   # key -> messages dropped from it (malformed, stranger, stale)
        self.stop_reason: str | None = None
        self.row = 0                           # the last recorded row = the step boundary reached
        self.horizon = 0                       # steps k < horizon are granted
        self.horizon_at = 0.0
        self.recording: Recording | None = None
        # component logs: kept with the recording, else in a temporary directory removed after a clean run
        self.log_dir = (self.record_dir / "logs") if self.record_dir else Path(
            tempfile.mkdtemp(prefix=f"zenorbit-{self.run_id}-"))
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.loop_s = 0.0
        self.placement = supervisor.place([n for n, c in config.components.items() if c.dedicated_cpu],
                                          os.sched_getaffinity(0))
        self.decimation = 0                    # publish every n-th row to the viewer; 0: no viewer

        # the recorded row: every component's outputs, in config order
        self.columns: list[str] = []
        self.column_index: dict[tuple[str, str], np.ndarray] = {}
        for spec in config.components.values():
            for v in spec.outputs.variables:
                start = len(self.columns)
                self.columns += v.columns(spec.name)
                self.column_index[spec.name, v.name] = np.arange(start, len(self.columns))
        # before initialization every output holds its declared start value
        self.values = np.concatenate([s.outputs.start_vector() for s in config.components.values()] or [np.zeros(0)])

    # ---------------------------------------------------------------- messages

    def _on_output(self, sample) -> None:
        self.inbox.put(("o", str(sample.key_expr), sample.payload.to_bytes()))

    def _on_reply(self, sample) -> None:
        self.inbox.put(("r", str(sample.key_expr), sample.payload.to_bytes()))

    def _on_liveliness(self, sample) -> None:
        import zenoh
        parts = str(sample.key_expr).split("/")
        if not parts[-1].isdigit():
            return   # not a component's token
        alive = sample.kind == zenoh.SampleKind.PUT
        self.inbox.put(("alive" if alive else "dead", parts[-2], int(parts[-1])))

    def _on_control(self, query) -> None:
        self.inbox.put(("ctl", query, None))

    def _handle(self, message, expect: dict[str, str]) -> None:
        """Apply one inbox message; ``expect`` maps component name -> the reply we wait for. A
        malformed message, or one from an unknown component or an old generation, is dropped with
        a warning: whoever can reach the bus cannot end the run (docs/design.md §7)."""
        kind, a, b = message
        try:
            self._apply(kind, a, b, expect)
        except bus.Malformed as e:
            self._drop(a, str(e))   # only output and reply messages ("o", "r") are decoded

    def _drop(self, key: str, reason: str) -> None:
        """Warn of a dropped message in events.jsonl (bus.count_drop says when)."""
        if n := bus.count_drop(self.dropped, key):
            self._log("warning", step=self.row, message=f"dropped a message on {key}: {reason}"
                                                         + (f" ({n} so far)" if n > 1 else ""))

    def _apply(self, kind: str, a, b, expect: dict[str, str]) -> None:
        if kind == "o":
            name = a.rpartition("/")[2]
            member = self.members.get(name)
            if member is None:
                raise bus.Malformed(f"no component {name!r} in this run")
            generation, tags, timings, outputs = bus.decode_batch(b)
            if generation != member.generation:
                raise bus.Malformed(f"generation {generation}, the live one is {member.generation}")
            if outputs.shape[1] != member.spec.outputs.size:
                raise bus.Malformed(f"{outputs.shape[1]} outputs per step, {name} has {member.spec.outputs.size}")
            if tags[0] < 1:
                raise bus.Malformed(f"tag {tags[0]}: the outputs of a step are tagged 1 or later")
            member.received.extend(zip(tags.tolist(), outputs))
            # max: a fault message (which raises progress to its step) may overtake the batches
            # sent before it, which travel under another key
            member.progress, member.progress_at = max(member.progress, int(tags[-1])), time.monotonic()
            compute_s, idle_s = timings.sum(axis=0)
            member.compute_s += compute_s
            member.idle_s += idle_s
            member.steps += len(tags)
        elif kind == "r":
            parts = a.split("/")
            if len(parts) < 3 or not parts[-2].isdigit():
                raise bus.Malformed("not a component's reply key")
            member = self._member(parts[-3], int(parts[-2]))
            if member is None:
                raise bus.Malformed(f"no component {parts[-3]!r} of generation {parts[-2]} in this run")
            tag = b[:1]
            if tag == bus.REPLY:
                body, blob = bus.decode_message(b)
                member.reply = {**body, "blob": blob}
                if expect.get(member.name) == body["op"]:
                    del expect[member.name]
            elif tag == bus.FAULT:
                body, _ = bus.decode_message(b, bus.FAULT_FIELDS)
                if body["k"] >= 0:  # it published every output before the failing step's
                    member.progress = max(member.progress, body["k"])
                self._salvage(member)
                raise RunFailure(self._fault_message(member, body), member)
            else:
                raise bus.Malformed(f"neither a reply nor a fault: first byte {bytes(b[:1])!r}")
        elif kind == "ctl":
            self.controls.add(a)
        else:
            name, generation = a, b
            if name == VIEWER:
                if kind == "alive" and expect.get(name) == "alive":
                    del expect[name]
                elif kind == "dead" and self.recording is not None:
                    self._log("warning", message="the viewer went away; the run goes on", step=self.row)
                return
            member = self._member(name, generation)
            if member is None:
                return
            if kind == "alive":
                if expect.get(name) == "alive":
                    del expect[name]
                return
            self._salvage(member)
            raise RunFailure(self._death(member, "its process disappeared (liveliness lost)"), member, lost=True)

    def _fault_message(self, member: Member, body: dict) -> str:
        k = body["k"]
        when = f"step {k} (t = {k * self.config.step_ns / 1e9:g} s)"
        if body["op"] == "nan":
            return f"component {member.name!r} produced a non-finite value in output {body['error']!r} at {when}"
        where = when if body["op"] == "step" else body["op"]
        return f"component {member.name!r} ({member.spec.type}) failed in {where}: {body['error']}"

    def _member(self, name: str, generation: int) -> Member | None:
        """The live (or joining) member with this name and generation; None for a stale generation."""
        for group in (self.members, self.joining):
            member = group.get(name)
            if member is not None and member.generation == generation:
                return member
        return None

    def _wait(self, expect: dict[str, str], timeout: float, what: str) -> None:
        """Process inbox messages until every expectation is met, or fail naming the laggards."""
        deadline = time.monotonic() + timeout
        while expect:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                late = ", ".join(f"{n!r}" for n in expect)
                raise RunFailure(f"component {late} did not answer {what} within {timeout:g} s "
                                 f"(hung? raise run.step_timeout / run.start_timeout if it is just slow)")
            try:
                message = self.inbox.get(timeout=min(remaining, 0.2))
            except queue.Empty:
                self._check_processes(expect)
                continue
            self._handle(message, expect)

    def _check_processes(self, names) -> None:
        """Fail if the process of one of these members (or the viewer) has exited."""
        for name in names:
            if name == VIEWER:
                if self.viewer_process.poll() is not None:
                    raise RunFailure(f"the viewer exited during start-up with code "
                                     f"{self.viewer_process.returncode} (see its message above)")
                continue
            member = self.joining.get(name) or self.members[name]
            if member.process is not None and member.process.poll() is not None:
                self._salvage(member)
                raise RunFailure(self._death(member, f"its process exited with code {member.process.returncode}"),
                                 member, lost=True)

    def _death(self, member: Member, how: str) -> str:
        return (f"component {member.name!r} ({member.spec.type}) died at step {member.progress}: {how}"
                f"{supervisor.last_words(member.log_path)}")

    # ---------------------------------------------------------------- lifecycle

    def _control(self, member: Member, op: str, body: dict | None = None, blob: bytes = b"") -> None:
        member.command.put(bus.encode_message(bus.CONTROL, {"op": op, **(body or {})}, blob))

    def _ask(self, members: list[Member], op: str, what: str, timeout: float, body=None, blob=b"") -> None:
        for member in members:
            self._control(member, op, body, blob)
        self._wait({m.name: op for m in members}, timeout, what)

    def _launch(self, spec: ComponentSpec, generation: int) -> Member:
        process = log_path = None
        args = supervisor.runner_arguments(self.endpoint, self.run_id, spec.name, generation)
        if spec.launch == "local":
            log_path = self.log_dir / f"{spec.name}.{generation}.log"
            cpu = self.placement.dedicated.get(spec.name)
            process = supervisor.start_component(args + (["--cpu", str(cpu)] if cpu is not None else []),
                                                 log_path, self.placement.shared, self.child_env)
        else:
            print(f"waiting for external component {spec.name!r}: start it with\n"
                  f"    {bus.SECRET_ENV}={self.secret} python -m components.runner {' '.join(args)}",
                  file=self.out, flush=True)
        member = Member(spec=spec, generation=generation, process=process, log_path=log_path,
                        ratio=spec.step_ns // self.config.step_ns, latest=spec.outputs.start_vector())
        member.command = bus.publisher(self.session, bus.command_key(self.run_id, spec.name, generation))
        out_dst, out_src = [], []
        for v in spec.outputs.variables:
            index = self.column_index.get((spec.name, v.name))
            if index is not None and len(index) == v.size:  # a swapped-in type may lack some columns
                out_dst.append(index)
                out_src.append(np.arange(spec.outputs.offsets[v.name].start, spec.outputs.offsets[v.name].stop))
        member.out_dst = np.concatenate(out_dst) if out_dst else np.zeros(0, dtype=np.int64)
        member.out_src = np.concatenate(out_src) if out_src else np.zeros(0, dtype=np.int64)
        return member

    def _start(self, specs: list[ComponentSpec], generation: dict[str, int], into: dict[str, Member]) -> list[Member]:
        """Launch, wait for and instantiate members, registered in ``into`` (members, or joining)."""
        started = []
        for spec in specs:
            member = self._launch(spec, generation[spec.name])
            into[member.name] = member
            started.append(member)
        timeout = self.config.start_timeout_s
        self._wait({m.name: "alive" for m in started}, timeout, "start-up")
        for member in started:
            self._control(member, "instantiate", {"type": member.spec.type, "params": _jsonable(
                {**member.spec.parameters, "_epoch": self.config.epoch,
                 "_config_dir": str(self.config.path.parent.resolve())})})
        self._wait({m.name: "instantiate" for m in started}, timeout, "instantiate")
        return started

    def _routes(self, consumer: ComponentSpec, members: dict[str, Member]) -> list[Route]:
        return schedule.routes(consumer.name, consumer.inputs.offsets, self.config.connections,
                               {n: m.spec.outputs.offsets for n, m in members.items()},
                               {n: m.ratio for n, m in members.items()}, self.order, self.config.algorithm)

    def _wire(self, member: Member, members: dict[str, Member], k: int) -> None:
        """Tell a member which sources feed which of its inputs, and which members it feeds."""
        member.routes = self._routes(member.spec, members)
        self._ask([member], "wire", "wire", self.config.start_timeout_s, {
            "generation": member.generation, "step_ns": self.config.step_ns, "ratio": member.ratio, "k": k,
            "consumers": sorted({d for d, _, s, _ in self.config.connections if s == member.name and d != member.name}),
            "batch_outputs": not schedule.feeds_back(member.name, self.config.connections),
            "routes": [r.to_json() for r in member.routes],
            "sources": {r.source: members[r.source].generation for r in member.routes},
            "faults": [[-(-f.at_ns // self.config.step_ns), f.kind, (f.duration_ns or 0) / 1e9]
                       for f in self.pending_faults if f.component == member.name]})

    def _initialize(self, member: Member, t_ns: int, members: dict[str, Member]) -> np.ndarray:
        inputs = member.spec.inputs.start_vector()
        times = {}
        for route in member.routes:
            source = members[route.source]
            inputs[route.dst] = source.latest[route.src]
            if source.initialized:
                times.update(dict.fromkeys(schedule.fed_inputs(route, member.spec.inputs.offsets),
                                           source.tag * self.config.step_ns))
        self._ask([member], "initialize", "initialize", self.config.start_timeout_s,
                  {"t0_ns": t_ns, "input_times_ns": times}, inputs.tobytes())
        vector = np.frombuffer(member.reply["blob"], dtype=np.float64)
        variable = member.spec.outputs.first_non_finite(vector)
        if variable is not None:
            raise RunFailure(f"component {member.name!r} produced a non-finite value in output {variable!r} "
                             f"after initialize (t = {t_ns / 1e9:g} s)")
        return vector

    def _sync(self, waiting: list[Member]) -> None:
        """Repeat the handshake until each of ``waiting`` has heard every one of its sources: from
        then on, no output published to it can be lost to a subscription still on its way."""
        expect = {m.name: "synced" for m in waiting}
        deadline = time.monotonic() + self.config.start_timeout_s
        while expect:
            if time.monotonic() > deadline:
                raise RunFailure(f"component {', '.join(map(repr, expect))} did not hear its sources within "
                                 f"{self.config.start_timeout_s:g} s (run.start_timeout)")
            for member in self.members.values():
                self._control(member, "sync")
            round_end = time.monotonic() + SYNC_ROUND_S
            while expect and time.monotonic() < round_end:
                try:
                    self._handle(self.inbox.get(timeout=max(round_end - time.monotonic(), 0.001)), expect)
                except queue.Empty:
                    pass
            self._check_processes(list(expect))

    def _held(self, member: Member, only: str | None = None) -> tuple[dict, bytes]:
        """What ``member``'s sources (or just ``only``) hold now: the recorded outputs and any
        published ahead of them, as a ``start``/``rewire`` body part and blob."""
        held, blobs = [], []
        for name in {r.source for r in member.routes if only in (None, r.source)}:
            source = self.members[name]
            for tag, vector in [(source.tag, source.latest), *source.received]:
                held.append([name, tag, int(vector.size)])
                blobs.append(vector.tobytes())
        return {"held": held}, b"".join(blobs)

    def _go(self, member: Member) -> None:
        body, blob = self._held(member)
        self._control(member, "start", {**body, "horizon": self.horizon}, blob)

    def _terminate(self, member: Member, timeout: float = 5.0) -> None:
        """Ask a member to terminate and make sure its process is gone (killed after ``timeout``)."""
        self._control(member, "terminate")
        supervisor.reap(member.process, timeout)
        member.command.undeclare()

    # ---------------------------------------------------------------- swap

    def swap(self, spec: ComponentSpec, planned: bool = False) -> None:
        """Replace a component at the current step boundary (docs/design.md §5).

        Every component is at the boundary (the horizon is held there). The new generation is
        started and wired on the side. One of the same type takes over the old one's state, never
        initialized (initialize would re-anchor what the state already holds), and its outputs at
        this step are the old ones; one of another type is initialized there. Only then does it take
        over and its consumers are rewired to it. If it fails to get there, it is stopped and
        SwapFailed is raised: the old generation runs on. ``planned``: an event of the config
        (else the recorded config gains one, so that it replays the run).
        """
        old = self.members[spec.name]
        t_ns = self.row * self.config.step_ns
        same_type = spec.type == old.spec.type
        problem = old.spec.cls.state_problem(old.spec.resolved) if same_type else None
        if problem:
            raise SwapFailed(f"a swap to the same type hands the state over, and {spec.name} cannot: {problem} "
                             f"(give another type)")
        began = time.perf_counter()
        try:
            new = self._start([spec], {spec.name: old.generation + 1}, self.joining)[0]
            members = {**self.members, spec.name: new}
            self._wire(new, members, self.row)
            if same_type:
                self._ask([old], "get_state", "get_state", self.config.step_timeout_s)
                self._ask([new], "set_state", "set_state", self.config.step_timeout_s, {}, old.reply["blob"])
                outputs = old.latest
            else:
                outputs = self._initialize(new, t_ns, members)
        except RunFailure as failure:
            if old.process is not None and old.process.poll() is not None:
                raise  # the old generation is gone too: nothing to run on
            joining = self.joining.pop(spec.name, None)
            if joining is not None:
                self._terminate(joining, timeout=2.0)
            self._log("warning", message=f"swap of {spec.name} to {spec.type} failed: {failure}", step=self.row)
            raise SwapFailed(str(failure)) from None
        new.tag, new.latest, new.progress, new.initialized = self.row, np.array(outputs), self.row, True
        self.values[old.out_dst] = np.nan   # the old type's columns the new one lacks: NaN from here on
        self.values[new.out_dst] = new.latest[new.out_src]
        self.members[spec.name] = self.joining.pop(spec.name)
        self._terminate(old)  # its late messages carry the old generation: ignored from here on
        consumers = [m for m in self.members.values() if m is not new and any(r.source == spec.name for r in m.routes)]
        for consumer in consumers:
            consumer.routes = self._routes(consumer.spec, self.members)
            body, blob = self._held(consumer, only=spec.name)
            self._control(consumer, "rewire", {**body, "routes": [r.to_json() for r in consumer.routes],
                                               "sources": {r.source: self.members[r.source].generation
                                                           for r in consumer.routes}}, blob)
        self._wait({m.name: "rewire" for m in consumers}, self.config.step_timeout_s, "rewire")
        self._sync([new, *consumers])
        self._go(new)
        parameters = spec.cls.schema.plain(spec.resolved)
        self._record_swap(new, same_type, parameters, planned)
        self._log("swap", component=spec.name, type=spec.type, parameters=parameters, generation=new.generation,
                  step=self.row, time=t_ns / 1e9, state_handed_over=same_type,
                  wall_s=round(time.perf_counter() - began, 4))
        if self.restartable:
            self._take_checkpoint()   # a restart never goes back across a swap

    def _record_swap(self, new: Member, same_type: bool, parameters: dict, planned: bool) -> None:
        """The recording's side of a swap: a new type's outputs get a table of their own; a swap
        from the CLI becomes an event of the recorded config."""
        name = new.name
        if self.recording is None:
            return
        if not same_type:   # (a same-type swap goes on writing the table its type has, if any)
            self.tables.pop(name, None)
            columns = [c for v in new.spec.outputs.variables for c in v.columns(name)]
            table = self.tables[name] = self.recording.add_table(f"{name}.{new.generation}", columns)
            table.append(self.row, self.row * self.config.step_ns / 1e9, new.latest)
        if not planned:
            resolved = self.config.resolved
            resolved["events"] = sorted(
                [*resolved["events"], {"at": duration_text(self.row * self.config.step_ns), "swap": name,
                                       "type": new.spec.type, "parameters": parameters}],
                key=lambda e: duration_ns(e["at"], "at"))
            self.recording.write_config(resolved)

    # ---------------------------------------------------------------- checkpoints and restarts

    def _next_checkpoint(self) -> int | None:
        """The step of the next periodic checkpoint (run.checkpoint_every), or None."""
        if self.checkpoint is None or self.config.checkpoint_ns is None:
            return None
        every = self.config.checkpoint_ns // self.config.step_ns
        return (self.checkpoint.row // every + 1) * every

    def _take_checkpoint(self) -> None:
        """Every component's state at this step boundary, where they all are (docs/design.md §7)."""
        members = list(self.members.values())
        self._ask(members, "get_state", "get_state (checkpoint)", self.config.step_timeout_s)
        self.checkpoint = Checkpoint(self.row, self.values.copy(), [m.spec for m in members],
                                     {m.name: m.reply["blob"] for m in members},
                                     {m.name: (m.tag, m.latest.copy()) for m in members}, list(self.pending_events))
        self._log("checkpoint", step=self.row, time=self.row * self.config.step_ns / 1e9)

    def _may_restart(self, failure: RunFailure) -> bool:
        """A live member that died or hung, and asked to be restarted."""
        member = failure.member
        return (failure.lost and member is not None and member.spec.on_failure == "restart"
                and self.checkpoint is not None and member.name in self.members)

    def _restart(self, failure: RunFailure) -> None:
        """Stop every component and start them all again, in new processes, from the last checkpoint."""
        checkpoint, failed, step_ns = self.checkpoint, failure.member, self.config.step_ns
        began = time.perf_counter()
        self.restarts += 1
        self._log("fault", step=self.row, component=failed.name, message=str(failure))
        print(f"warning: {failure}\nrestarting from step {checkpoint.row} (t = {checkpoint.row * step_ns / 1e9:g} s; "
              f"restart {self.restarts} of at most {self.config.max_restarts})", file=self.out, flush=True)
        if failed.process is not None and failed.process.poll() is None:
            failed.process.kill()   # hung: it would not answer terminate
        for member in [*self.members.values(), *self.joining.values()]:
            self._terminate(member, timeout=2.0)
        self.joining.clear()
        # an injected fault fires once: the one behind this failure, and those the run went past
        cause = next((f for f in self.pending_faults
                      if f.component == failed.name and -(-f.at_ns // step_ns) <= self.horizon), None)
        self.pending_faults = [f for f in self.pending_faults if f is not cause and -(-f.at_ns // step_ns) >= self.row]
        while True:   # what the stopped generations sent is stale; requests from the CLI are kept
            try:
                kind, a, _ = self.inbox.get_nowait()
            except queue.Empty:
                break
            if kind == "ctl":
                self.controls.add(a)
        generations = {n: m.generation + 1 for n, m in self.members.items()}
        self.members = {}
        self._start(checkpoint.specs, generations, self.members)
        for member in self.members.values():
            self._wire(member, self.members, checkpoint.row)
        for member in self.members.values():
            self._control(member, "set_state", {}, checkpoint.states[member.name])
        self._wait({m: "set_state" for m in self.members}, self.config.step_timeout_s, "set_state (restart)")
        now = time.monotonic()
        for member in self.members.values():
            tag, latest = checkpoint.latest[member.name]
            member.tag, member.latest, member.initialized = tag, latest.copy(), True
            member.progress, member.progress_at = checkpoint.row, now
        self.values[:] = checkpoint.values
        self.row = self.horizon = checkpoint.row
        self.horizon_at = now
        self.pending_events = list(checkpoint.events)
        if self.recording is not None:
            self.recording.rewind(checkpoint.row)
        self._sync(list(self.members.values()))
        for member in self.members.values():
            self._go(member)
        self._log("restart", step=checkpoint.row, time=checkpoint.row * step_ns / 1e9, component=failed.name,
                  restart=self.restarts, wall_s=round(time.perf_counter() - began, 4))

    # ---------------------------------------------------------------- control from the CLI

    def status(self) -> dict:
        return {"run_id": self.run_id, "name": self.config.name, "step": self.row,
                "steps": self.config.steps, "time": self.row * self.config.step_ns / 1e9,
                "components": {n: {"type": m.spec.type, "generation": m.generation}
                               for n, m in self.members.items()}}

    def request_stop(self, reason: str) -> None:
        self.stop_reason = reason

    # ---------------------------------------------------------------- the loop

    def _log(self, kind: str, **fields) -> None:
        if self.recording is not None:
            self.recording.event(kind, **fields)

    def _event_step(self) -> int | None:
        if not self.pending_events:
            return None
        return -(-self.pending_events[0].at_ns // self.config.step_ns)

    def _limit(self) -> int:
        """The step boundary the run must stop at next: the end, an event, a swap from the CLI."""
        limit = self.config.steps
        for boundary in (self._event_step(), self.controls.swap_boundary(), self._next_checkpoint()):
            if boundary is not None:
                limit = min(limit, max(boundary, self.row))
        return limit

    def _grant(self, wall_start: float) -> float:
        """Extend the horizon when the recorded rows come near it; return how long the loop may
        sleep before it must look again (realtime pacing)."""
        limit = self._limit()
        target = min(limit, self.row + WINDOW)
        chunk = WINDOW // 2
        wake = 0.2
        if self.config.realtime > 0:
            # step k may start once k steps' worth of time has passed on the wall clock
            step_s = self.config.step_ns / 1e9 / self.config.realtime
            elapsed = time.perf_counter() - wall_start
            target = min(target, int(elapsed / step_s) + 1)
            chunk = max(1, int(0.005 / step_s))
            wake = min(wake, max(step_s * chunk - (elapsed % (step_s * chunk)), 0.0005))
        if target > self.horizon and (target - self.horizon >= chunk or target == limit
                                      or self.horizon - self.row < chunk):
            self.horizon, self.horizon_at = target, time.monotonic()
            grant = bus.encode_horizon(target)
            for member in self.members.values():
                member.command.put(grant)
        return wake

    def _record_rows(self) -> None:
        """Record every row whose outputs have all arrived."""
        step_ns = self.config.step_ns
        members = list(self.members.values())
        while self.row < self.horizon:
            row = self.row + 1
            due = []
            for m in members:
                need = row // m.ratio * m.ratio
                if need == m.tag:
                    continue
                received = m.received
                while received and received[0][0] < need:
                    received.popleft()
                if not received or received[0][0] != need:
                    return
                due.append(m)
            for m in due:
                m.tag, m.latest = m.received.popleft()
                self.values[m.out_dst] = m.latest[m.out_src]
            self.row = row
            if self.recording is not None:
                self.recording.append(row, row * step_ns / 1e9, self.values)
                for name, table in self.tables.items():
                    table.append(row, row * step_ns / 1e9, self.members[name].latest)
            if self.decimation and row % self.decimation == 0:
                self.signals_out.put(SIGNALS_HEADER.pack(row, row * step_ns / 1e9) + self.values.tobytes())

    def _check_hung(self) -> None:
        """A member that has held every input of its next step for ``run.step_timeout`` is hung."""
        now = time.monotonic()
        timeout = self.config.step_timeout_s
        for m in self.members.values():
            k = m.progress
            if k >= self.horizon:
                continue
            sources = [self.members[r.source] for r in m.routes]
            if any(s.progress < r.tag(k) for s, r in zip(sources, m.routes)):
                continue
            since = max([m.progress_at, self.horizon_at, *(s.progress_at for s in sources)])
            if now - since > timeout:
                self._salvage(m)
                raise RunFailure(f"component {m.name!r} did not answer step {k} within {timeout:g} s "
                                 f"(hung? raise run.step_timeout if it is just slow)", m, lost=True)

    def _salvage(self, failed: Member, timeout: float = 1.0) -> None:
        """``failed`` failed: record the rows up to its last output, as far as the others' outputs
        (some still on their way) complete them within ``timeout``."""
        if failed.name not in self.members:
            return
        deadline = time.monotonic() + timeout
        self._record_rows()   # outputs handled before the failure may still wait to be recorded
        while self.row < min(failed.progress, self.horizon) and time.monotonic() < deadline:
            try:
                kind, key, payload = self.inbox.get(timeout=0.05)
            except queue.Empty:
                continue
            if kind == "o":
                self._handle((kind, key, payload), {})
                self._record_rows()

    def _loop(self) -> None:
        """Grant, record and watch until the last row is in or a stop is asked for."""
        steps = self.config.steps
        wall_start = time.perf_counter()
        try:
            while True:
                try:
                    self._step_until(steps, wall_start)
                    return
                except RunFailure as failure:
                    if not self._may_restart(failure):
                        raise
                    if self.restarts >= self.config.max_restarts:
                        raise RunFailure(f"{failure} (after {wording.count(self.restarts, 'restart')}: "
                                         f"run.max_restarts)", failure.member) from None
                    self._restart(failure)
        finally:
            self.loop_s = time.perf_counter() - wall_start

    def _step_until(self, steps: int, wall_start: float) -> None:
        last_progress = last_check = time.monotonic()
        expect: dict[str, str] = {}
        while self.row < steps and not self.stop_reason:
            if self.row == self.horizon:   # everyone is at this boundary: control happens here
                while self._event_step() is not None and self._event_step() <= self.row:
                    try:
                        self.swap(self.pending_events.pop(0).spec, planned=True)
                    except SwapFailed as failure:  # a swap the config asks for is part of the experiment
                        raise RunFailure(str(failure)) from None
                if self.row == self._next_checkpoint():
                    self._take_checkpoint()
                self.controls.serve(quiescent=True)
            elif self.controls.queries:
                self.controls.serve(quiescent=False)
            wake = self._grant(wall_start)
            try:
                self._handle(self.inbox.get(timeout=wake), expect)
                while True:
                    self._handle(self.inbox.get_nowait(), expect)
            except queue.Empty:
                pass
            self._record_rows()
            now = time.monotonic()
            if now - last_check > 0.2:
                last_check = now
                self._check_hung()
                self._check_processes(list(self.members))
            if self.progress and now - last_progress > 0.5:
                last_progress = now
                self._print_progress(time.perf_counter() - wall_start)

    def execute(self) -> int:
        """Run to the end (0), or until a failure (1) or an interruption (130); clean up in every case."""
        config = self.config
        previous = {sig: signal.signal(sig, _raise_stop) for sig in (signal.SIGTERM,)}
        code, message = 0, None
        self.session = None
        self._subscriptions: list = []
        own_cpus = os.sched_getaffinity(0)
        run_start = time.perf_counter()
        try:
            supervisor.keep_to(self.placement.shared)   # this thread, and the bus threads it starts
            self._open_bus()
            if self.record_dir is not None:
                self.recording = Recording(self.record_dir, self.columns, config.resolved)
            self._log("start", run_id=self.run_id, config=str(config.path), steps=config.steps,
                      step_ns=config.step_ns, algorithm=config.algorithm,
                      components={n: s.type for n, s in config.components.items()},
                      cpus={**self.placement.dedicated, "shared": sorted(self.placement.shared)})
            if self.placement.unplaced:
                message = (f"no CPU to spare for {', '.join(self.placement.unplaced)} (dedicated_cpu; "
                           f"{len(own_cpus)} CPU(s) available): they share the others'")
                print(f"note: {message}", file=self.out)
                self._log("warning", message=message, step=0)
            self._start(list(config.components.values()), {n: 0 for n in config.components}, self.members)
            for member in self.members.values():
                self._wire(member, self.members, 0)
            for name in schedule.initialization_order(self.order, config.connections):
                member = self.members[name]
                member.latest = self._initialize(member, 0, self.members)
                member.initialized = True
                self.values[member.out_dst] = member.latest[member.out_src]
            if self.recording is not None:
                self.recording.append(0, 0.0, self.values)
            self.decimation = self._start_viewer()
            if self.decimation:
                self.signals_out.put(SIGNALS_HEADER.pack(0, 0.0) + self.values.tobytes())
            self._sync(list(self.members.values()))
            if self.restartable:
                self._take_checkpoint()
            for member in self.members.values():
                self._go(member)
            self._loop()
        except (RunFailure, RecordingError) as failure:
            code, message = 1, str(failure)
            self._log("fault", step=self.row, message=message)
        except (KeyboardInterrupt, StopRequested):
            self.stop_reason = "interrupted"
            code = 130
        except Exception as error:   # a bug of ours: still a clean end, and no "completed" in events.jsonl
            traceback.print_exc(file=self.out)
            code, message = 1, f"internal error: {type(error).__name__}: {error}"
            self._log("fault", step=self.row, message=message)
        finally:
            # no second Ctrl-C/SIGTERM in the middle of the clean-up: it has bounded waits of its own
            for sig in (signal.SIGINT, signal.SIGTERM):
                signal.signal(sig, signal.SIG_IGN)
            if self.progress:
                print(file=self.out)
            for member in list(self.members.values()) + list(self.joining.values()):
                self._terminate(member, timeout=2.0 if code else 5.0)
            if self.session is not None:
                self._stop_viewer(self.signals_out)
            self._log("end", step=self.row, time=self.row * config.step_ns / 1e9,
                      status="failed" if code == 1 else (self.stop_reason or "completed"))
            if self.recording is not None:
                try:
                    self.recording.close()
                except RecordingError as failure:
                    code, message = 1, message or str(failure)
            runs.unregister(self.run_id)
            self._subscriptions.clear()
            if self.session is not None:
                self.session.close()
            if code == 0 and self.record_dir is None:
                shutil.rmtree(self.log_dir, ignore_errors=True)
            signal.signal(signal.SIGINT, signal.default_int_handler)
            for sig, handler in previous.items():
                signal.signal(sig, handler)
            supervisor.keep_to(frozenset(own_cpus))
        if message:
            print(f"error: {message}", file=self.out)
            logs = ", ".join(str(m.log_path) for m in self.members.values() if m.log_path)
            if logs:
                print(f"component logs: {logs}", file=self.out)
        if self.profile:
            self._print_profile()
        print(self.summary(code, time.perf_counter() - run_start), file=self.out, flush=True)
        return code

    def summary(self, code: int, wall_s: float) -> str:
        """One line for the end of every run: how it ended, how far it got, how fast, where it went."""
        status = {0: "completed", 1: "failed"}.get(code) or self.stop_reason or "interrupted"
        sim_s = self.row * self.config.step_ns / 1e9
        stepping = self.loop_s
        factor = sim_s / stepping if stepping > 0 else 0.0
        rate = f", real-time factor {factor:.{2 if factor < 100 else 0}f}" if factor else ""
        where = f"recording in {self.record_dir}" if self.record_dir is not None else "not recorded (no --record)"
        status += f" after {wording.count(self.restarts, 'restart')}" if self.restarts else ""
        return (f"run {self.config.name} {status}: {wording.count(self.row, 'step')} of {self.config.steps}, "
                f"{sim_s:g} s simulated; {wall_s:.1f} s wall ({stepping:.1f} s stepping{rate}); {where}")

    def _open_bus(self) -> None:
        """The orchestrator's Zenoh session, its subscriptions, and the run's entry for `ps`."""
        import zenoh

        for attempt in range(3):  # a free port picked here may be taken by another run before Zenoh binds it
            listen, self.endpoint = supervisor.resolve_endpoints(self.config.listen)
            try:
                self.session = bus.open_session(listen, mesh=True, secret=self.secret)
                break
            except zenoh.ZError as e:
                if attempt == 2 or not any(e.endswith(":0") for e in self.config.listen):
                    raise RunFailure(f"cannot open the bus on {', '.join(listen)} (bus.listen): {e}") from None
        self._subscriptions = [
            self.session.declare_subscriber(bus.run_key(self.run_id, "r", "*"), self._on_output),
            self.session.declare_subscriber(bus.run_key(self.run_id, "c", "*", "*", "out"), self._on_reply),
            self.session.liveliness().declare_subscriber(bus.run_key(self.run_id, "alive", "*", "*"),
                                                         self._on_liveliness),
            self.session.declare_queryable(bus.run_key(self.run_id, "ctl"), self._on_control),
            self.session.liveliness().declare_token(bus.run_key(self.run_id, "alive", "orchestrator")),
        ]
        self.signals_out = bus.publisher(self.session, bus.run_key(self.run_id, "signals"), drop=True)
        runs.register(self.run_id, self.config.name, self.endpoint, self.config.path, self.secret)

    def _start_viewer(self) -> int:
        """Start the Rerun observer, if asked; return the decimation (publish every n-th row), or 0."""
        if self.viewer is None:
            return 0
        setup = self.log_dir / "viewer.json"
        setup.write_text(json.dumps({
            "columns": self.columns, "config": self.config.resolved, "step_ns": self.config.step_ns,
            "config_dir": str(self.config.path.parent.resolve()), "epoch": self.config.epoch,
            "mode": self.viewer.mode, "file": str(self.viewer.file) if self.viewer.file else None,
            "open_browser": self.viewer.open_browser}))
        self.viewer_process = subprocess.Popen(
            [sys.executable, "-m", "components.viewer.observer", "--connect", self.endpoint,
             "--run-id", self.run_id, "--setup", str(setup)],
            stdin=subprocess.DEVNULL, preexec_fn=supervisor.child_setup, env=self.child_env)
        supervisor.keep_to(self.placement.shared, self.viewer_process.pid)
        self._wait({VIEWER: "alive"}, self.config.start_timeout_s, "viewer start-up")
        self._log("viewer", mode=self.viewer.mode, rate_hz=self.viewer.rate_hz)
        return max(1, round(1e9 / (self.viewer.rate_hz * self.config.step_ns)))

    def _stop_viewer(self, signals_out) -> None:
        """Tell the observer the run is over and let it finish (flush the .rrd; web: until Ctrl-C)."""
        if self.viewer_process is None:
            return
        signals_out.put(b"END")
        try:
            if self.viewer.mode == "web" and sys.stdin.isatty() and self.stop_reason != "interrupted":
                print("run finished; the web viewer stays up until Ctrl-C", file=self.out, flush=True)
                # the clean-up ignores signals; this one wait is what Ctrl-C (or SIGTERM) is for
                signal.signal(signal.SIGINT, signal.default_int_handler)
                signal.signal(signal.SIGTERM, _raise_stop)
                try:
                    self.viewer_process.wait()
                finally:
                    signal.signal(signal.SIGINT, signal.SIG_IGN)
                    signal.signal(signal.SIGTERM, signal.SIG_IGN)
            else:
                self.viewer_process.wait(timeout=30)
        except (KeyboardInterrupt, StopRequested, subprocess.TimeoutExpired):
            pass
        if self.viewer_process.poll() is None:
            self.viewer_process.terminate()
            supervisor.reap(self.viewer_process, 5)

    def _print_progress(self, wall: float) -> None:
        sim = self.row * self.config.step_ns / 1e9
        total = self.config.duration_ns / 1e9
        print(f"\r  t = {sim:9.3f} / {total:g} s   {self.row / wall:8.0f} steps/s   "
              f"real-time factor {sim / wall:6.2f}", end="", file=self.out, flush=True)

    def _print_profile(self) -> None:
        wall = self.loop_s
        print(f"profile: {self.row} steps in {wall:.3f} s wall ({self.row / wall if wall else 0:.0f} steps/s, "
              f"real-time factor {self.row * self.config.step_ns / 1e9 / wall if wall else 0:.2f}), "
              f"{self.config.algorithm}", file=self.out)
        print(f"  {'component':<16}{'compute/step':>14}{'waiting/step':>14}{'busy':>8}", file=self.out)
        for m in self.members.values():
            steps = max(m.steps, 1)
            print(f"  {m.name:<16}{m.compute_s / steps * 1e6:>11.1f} us{m.idle_s / steps * 1e6:>11.1f} us"
                  f"{100 * m.compute_s / wall if wall else 0:>7.1f}%", file=self.out)
        print("  waiting: for inputs or the horizon, and the bus (a component's own compute not included)",
              file=self.out)


def _raise_stop(signum, frame):
    raise StopRequested()


def _jsonable(value):
    """Config values as JSON for the instantiate message (YAML gives datetimes, numpy gives arrays)."""
    if isinstance(value, (dt.datetime, dt.date)):
        return value.isoformat().replace("+00:00", "Z")
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    return value
