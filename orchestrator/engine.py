"""The lockstep master: launches component processes, routes signals, steps time, records.

One Zenoh session; every message the components send lands in a single inbox queue (callbacks
only enqueue), and the main thread does all the work. Step k covers [k*h, (k+1)*h); times are
integer nanoseconds computed by multiplication. Components are addressed by name and generation,
so a component can be replaced at a step boundary (swap) without anyone else noticing.

Jacobi: every component due at step k gets its inputs from the outputs at t_k, all step in
parallel. Gauss-Seidel: components step one after another in config order, each seeing the
outputs at t_(k+1) of those before it.
"""
from __future__ import annotations

import copy
import datetime as dt
import json
import queue
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from components import bus
from orchestrator import runs
from orchestrator.config import (ComponentSpec, Event, RunConfig, ViewerSpec, check_replacement,
                                 component_spec)
from orchestrator.recording import Recording


VIEWER = "_viewer"   # liveliness name of the observer (component names cannot start with _)
SIGNALS_HEADER = struct.Struct("<qd")  # k, time in s; then the row of every output, float64


class RunFailure(Exception):
    """The run cannot go on: a component crashed, hung, or produced a non-finite value."""


class SwapFailed(Exception):
    """A replacement could not start; the component it was to replace runs on."""


class StopRequested(Exception):
    """Ctrl-C, SIGTERM or `orchestrator stop`: end the run cleanly."""


@dataclass
class Member:
    """A live component: its spec, process, and where its signals live in the global vectors."""
    spec: ComponentSpec
    generation: int
    process: subprocess.Popen | None
    log_path: Path | None
    command: object = None                 # Zenoh publisher of its command key
    inputs: np.ndarray = None
    route_dst: np.ndarray = None           # input indices fed from ...
    route_src: np.ndarray = None           # ... these indices of the global output vector
    out_dst: np.ndarray = None             # where its outputs go in the global output vector
    out_src: np.ndarray = None             # ... from these indices of its output vector
    ratio: int = 1                         # its step in run steps
    pending: np.ndarray | None = None      # a slower member's outputs, not yet due
    compute_s: float = 0.0
    steps: int = 0
    reply: dict | None = field(default=None, repr=False)

    @property
    def name(self) -> str:
        return self.spec.name


def _child_setup():
    """In a component process: leave Ctrl-C to the orchestrator (which stops everyone in order),
    and die with the orchestrator even if it is SIGKILLed (Linux PR_SET_PDEATHSIG)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        import ctypes
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except OSError:
        pass


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def resolve_endpoints(listen: list[str]) -> tuple[list[str], str]:
    """Fill port 0 with a free port; return (listen endpoints, the one local components connect to)."""
    resolved = []
    for endpoint in listen:
        proto, _, address = endpoint.partition("/")
        host, _, port = address.rpartition(":")
        if port == "0":
            port = str(_free_port())
        resolved.append(f"{proto}/{host}:{port}")
    proto, _, address = resolved[0].partition("/")
    host, _, port = address.rpartition(":")
    local_host = "127.0.0.1" if host in ("0.0.0.0", "[::]") else host
    return resolved, f"{proto}/{local_host}:{port}"


class Run:
    """One execution of a validated config. ``execute()`` returns the exit code (0, 1)."""

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
        self.inbox: queue.Queue = queue.Queue()
        self.members: dict[str, Member] = {}
        self.pending_events: list[Event] = list(config.events)
        self.controls: list = []            # queries from the CLI, handled at step boundaries
        self.stop_reason: str | None = None
        self.k = 0
        self.recording: Recording | None = None
        # component logs: kept with the recording, else in a temporary directory removed after a clean run
        self.log_dir = (self.record_dir / "logs") if self.record_dir else Path(
            tempfile.mkdtemp(prefix=f"zenorbit-{self.run_id}-"))
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.joining: dict[str, Member] = {}   # a swap's new generation, until it is ready
        self.wait_s = 0.0                   # time spent waiting on the barrier
        self.loop_s = 0.0

        # the global output vector: every component's outputs, in config order = recorded columns
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
        self.inbox.put(("out", str(sample.key_expr), sample.payload.to_bytes()))

    def _on_liveliness(self, sample) -> None:
        import zenoh
        parts = str(sample.key_expr).split("/")
        alive = sample.kind == zenoh.SampleKind.PUT
        self.inbox.put(("alive" if alive else "dead", parts[-2], int(parts[-1])))

    def _on_control(self, query) -> None:
        self.inbox.put(("ctl", query, None))

    def _handle(self, message, expect: dict[str, str]) -> None:
        """Apply one inbox message; ``expect`` maps component name -> what we wait for."""
        kind, a, b = message
        if kind == "ctl":
            self.controls.append(a)
            return
        if kind in ("alive", "dead"):
            name, generation = a, b
            if name == VIEWER:
                if kind == "alive" and expect.get(name) == "alive":
                    del expect[name]
                elif kind == "dead" and self.recording is not None:
                    self._log("warning", message="the viewer went away; the run goes on", step=self.k)
                return
            member = self._member(name, generation)
            if member is None:
                return
            if kind == "alive":
                if expect.get(name) == "alive":
                    del expect[name]
                return
            raise RunFailure(self._death(member, "its process disappeared (liveliness lost)"))
        parts = a.split("/")
        name, generation = parts[-3], int(parts[-2])
        member = self._member(name, generation)
        if member is None:
            return  # a replaced generation: ignore
        tag = b[:1]
        if tag == bus.OUTPUT:
            k, compute_s, vector = bus.decode_output(b)
            if expect.get(name) != "step" or k != self.k:
                raise RunFailure(f"component {name!r}: output for step {k} while waiting for step {self.k}")
            self._check_finite(member, vector, f"at step {k} (t = {(k * self.config.step_ns) / 1e9:g} s)")
            if member.ratio == 1:
                self.values[member.out_dst] = vector[member.out_src]
            else:  # a slower component's outputs are for t_k + its step: they show from then on
                member.pending = vector[member.out_src].copy()
            member.compute_s += compute_s
            member.steps += 1
            del expect[name]
        elif tag == bus.REPLY:
            body, blob = bus.decode_message(b)
            member.reply = {**body, "blob": blob}
            if expect.get(name) == body["op"]:
                del expect[name]
        elif tag == bus.FAULT:
            body, _ = bus.decode_message(b)
            where = f"step {body['k']} (t = {body['k'] * self.config.step_ns / 1e9:g} s)" if body["op"] == "step" \
                else body["op"]
            raise RunFailure(f"component {name!r} ({member.spec.type}) failed in {where}: {body['error']}")

    def _member(self, name: str, generation: int) -> Member | None:
        """The live (or joining) member with this name and generation; None for a stale generation."""
        for group in (self.members, self.joining):
            member = group.get(name)
            if member is not None and member.generation == generation:
                return member
        return None

    def _check_finite(self, member: Member, vector: np.ndarray, when: str) -> None:
        if not np.isfinite(vector).all():
            bad = int(np.flatnonzero(~np.isfinite(vector))[0])
            var = next(v for v in member.spec.outputs.variables if bad < member.spec.outputs.offsets[v.name].stop)
            raise RunFailure(f"component {member.name!r} produced a non-finite value in output {var.name!r} {when}")

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
                for name in expect:
                    if name == VIEWER:
                        if self.viewer_process.poll() is not None:
                            raise RunFailure(f"the viewer exited during start-up with code "
                                             f"{self.viewer_process.returncode} (see its message above)")
                        continue
                    member = self.joining.get(name) or self.members[name]
                    if member.process is not None and member.process.poll() is not None:
                        raise RunFailure(self._death(member, f"its process exited with code {member.process.returncode}"))
                continue
            self._handle(message, expect)

    def _death(self, member: Member, how: str) -> str:
        tail = ""
        if member.log_path and member.log_path.exists():
            lines = [line for line in member.log_path.read_text(errors="replace").splitlines() if line.strip()]
            if lines:
                tail = f"; last output: {lines[-1].strip()}"
        return f"component {member.name!r} ({member.spec.type}) died at step {self.k}: {how}{tail}"

    # ---------------------------------------------------------------- lifecycle

    def _control(self, member: Member, op: str, body: dict | None = None, blob: bytes = b"") -> None:
        member.command.put(bus.encode_message(bus.CONTROL, {"op": op, **(body or {})}, blob))

    def _launch(self, spec: ComponentSpec, generation: int) -> Member:
        process = log_path = None
        args = ["--connect", self.endpoint, "--run-id", self.run_id, "--name", spec.name,
                "--generation", str(generation)]
        if spec.launch == "local":
            log_path = self.log_dir / f"{spec.name}.{generation}.log"
            with open(log_path, "wb") as log:
                process = subprocess.Popen([sys.executable, "-m", "components.runner", *args],
                                           stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                                           preexec_fn=_child_setup)
        else:
            print(f"waiting for external component {spec.name!r}: start it with\n"
                  f"    python -m components.runner {' '.join(args)}", file=self.out, flush=True)
        member = Member(spec=spec, generation=generation, process=process, log_path=log_path,
                        ratio=spec.step_ns // self.config.step_ns)
        member.command = bus.publisher(self.session, bus.component_key(self.run_id, spec.name, generation, "cmd"))
        self._wire(member)
        return member

    def _wire(self, member: Member) -> None:
        """Index arrays that route the global output vector into this member's inputs, and back."""
        spec = member.spec
        member.inputs = spec.inputs.start_vector()
        dst, src = [], []
        for d, dv, s, sv in self.config.connections:
            if d == spec.name:
                dst.append(np.arange(spec.inputs.offsets[dv].start, spec.inputs.offsets[dv].stop))
                src.append(self.column_index[s, sv])
        member.route_dst = np.concatenate(dst) if dst else np.zeros(0, dtype=np.int64)
        member.route_src = np.concatenate(src) if src else np.zeros(0, dtype=np.int64)
        out_dst, out_src = [], []
        for v in spec.outputs.variables:
            index = self.column_index.get((spec.name, v.name))
            if index is not None and len(index) == v.size:  # a swapped-in type may lack some columns
                out_dst.append(index)
                out_src.append(np.arange(spec.outputs.offsets[v.name].start, spec.outputs.offsets[v.name].stop))
        member.out_dst = np.concatenate(out_dst) if out_dst else np.zeros(0, dtype=np.int64)
        member.out_src = np.concatenate(out_src) if out_src else np.zeros(0, dtype=np.int64)

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

    def _initialize(self, member: Member, t_ns: int, *, take_outputs: bool = True) -> None:
        member.inputs[member.route_dst] = self.values[member.route_src]
        self._control(member, "initialize", {"t0_ns": t_ns}, member.inputs.tobytes())
        self._wait({member.name: "initialize"}, self.config.start_timeout_s, "initialize")
        vector = np.frombuffer(member.reply["blob"], dtype=np.float64)
        self._check_finite(member, vector, f"after initialize (t = {t_ns / 1e9:g} s)")
        if take_outputs:
            self.values[member.out_dst] = vector[member.out_src]

    def _initialization_order(self) -> list[str]:
        """Sources before the components they feed; config order breaks cycles."""
        feeds = {n: {s for d, _, s, _ in self.config.connections if d == n and s != n} for n in self.config.components}
        done: list[str] = []
        while len(done) < len(feeds):
            pending = [n for n in feeds if n not in done]
            ready = [n for n in pending if feeds[n] <= set(done)]
            done.append(ready[0] if ready else pending[0])
        return done

    def _terminate(self, member: Member, timeout: float = 5.0) -> None:
        """Ask a member to terminate and make sure its process is gone (killed after ``timeout``)."""
        self._control(member, "terminate")
        if member.process is not None:
            try:
                member.process.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                member.process.kill()
                member.process.wait()
        member.command.undeclare()

    # ---------------------------------------------------------------- swap

    def swap(self, spec: ComponentSpec) -> None:
        """Replace a component at the current step boundary, handing over its state (same type).

        The new generation is started, initialized and given the state on the side; only then does
        it take over. If it fails to get there, it is stopped and SwapFailed is raised: the old
        generation runs on.
        """
        old = self.members[spec.name]
        t_ns = self.k * self.config.step_ns
        same_type = spec.type == old.spec.type
        self._control(old, "get_state")
        self._wait({old.name: "get_state"}, self.config.step_timeout_s, "get_state")
        state = old.reply["blob"]
        try:
            new = self._start([spec], {spec.name: old.generation + 1}, self.joining)[0]
            # same type: the state carries over and the outputs at t_k stay the old ones
            self._initialize(new, t_ns, take_outputs=not same_type)
            if same_type:
                self._control(new, "set_state", {}, state)
                self._wait({new.name: "set_state"}, self.config.step_timeout_s, "set_state")
        except RunFailure as failure:
            if old.process is not None and old.process.poll() is not None:
                raise  # the old generation is gone too: nothing to run on
            joining = self.joining.pop(spec.name, None)
            if joining is not None:
                self._terminate(joining, timeout=2.0)
            self._log("warning", message=f"swap of {spec.name} to {spec.type} failed: {failure}", step=self.k)
            raise SwapFailed(str(failure)) from None
        self.members[spec.name] = self.joining.pop(spec.name)
        self._terminate(old)  # its late messages carry the old generation: ignored from here on
        self._log("swap", component=spec.name, type=spec.type, generation=new.generation,
                  step=self.k, time=t_ns / 1e9, state_handed_over=same_type)

    # ---------------------------------------------------------------- control from the CLI

    def _serve_controls(self) -> None:
        waiting = []
        for query in self.controls:
            try:
                request = json.loads(query.payload.to_bytes()) if query.payload is not None else {}
            except ValueError:
                request = {}
            target = self.members.get(request.get("component", ""))
            if request.get("op") == "swap" and target is not None and self.k % target.ratio:
                waiting.append(query)  # a slower component is replaced at one of its own step boundaries
                continue
            try:
                answer = self._control_request(request)
            except SwapFailed as error:
                answer = {"ok": False, "error": str(error), "usage": False}
            except (KeyError, TypeError, ValueError) as error:  # a bad request must not end the run
                answer = {"ok": False, "error": f"malformed request: {error}", "usage": True}
            query.reply(query.key_expr, json.dumps(answer))
            query.drop()
        self.controls = waiting

    def _control_request(self, request: dict) -> dict:
        op = request.get("op")
        if op == "status":
            return {"ok": True, "run_id": self.run_id, "name": self.config.name, "step": self.k,
                    "steps": self.config.steps, "time": self.k * self.config.step_ns / 1e9,
                    "components": {n: {"type": m.spec.type, "generation": m.generation}
                                   for n, m in self.members.items()}}
        if op == "stop":
            self.stop_reason = "stopped by request"
            return {"ok": True}
        if op == "swap":
            from orchestrator.config import ConfigErrors, apply_overrides
            name = request["component"]
            if name not in self.members:
                return {"ok": False, "error": f"no component {name!r} (components: {', '.join(self.members)})",
                        "usage": True}
            old = self.members[name].spec
            entry = {"type": request.get("type") or old.type, "parameters": copy.deepcopy(
                old.parameters if not request.get("type") or request["type"] == old.type else {})}
            try:
                apply_overrides(entry, [f"parameters.{s}" for s in request.get("set", [])])
                spec = component_spec(name, {**entry, "step": f"{old.step_ns} ns"}, self.config.step_ns,
                                      self.config.path.parent.resolve(), self.config.epoch, f"components.{name}")
                problems = check_replacement(spec, self.config.connections)
                if problems:
                    raise ConfigErrors(problems)
            except ConfigErrors as e:
                return {"ok": False, "error": "; ".join(e.errors), "usage": True}
            self.swap(spec)
            return {"ok": True, "step": self.k, "generation": self.members[name].generation}
        return {"ok": False, "error": f"unknown operation {op!r} (status, stop, swap)"}

    # ---------------------------------------------------------------- the loop

    def _log(self, kind: str, **fields) -> None:
        if self.recording is not None:
            self.recording.event(kind, **fields)

    def _commit(self, member: Member) -> None:
        """A slower member's outputs become visible once their time has come."""
        self.values[member.out_dst] = member.pending
        member.pending = None

    def _step(self) -> None:
        k, h = self.k, self.config.step_ns
        t_ns = k * h
        step_timeout = self.config.step_timeout_s
        started = time.perf_counter()
        if self.config.algorithm == "jacobi":
            due = [m for m in self.members.values() if k % m.ratio == 0]
            for m in due:
                m.inputs[m.route_dst] = self.values[m.route_src]
            for m in due:
                m.command.put(bus.encode_step(k, t_ns, m.ratio * h, m.inputs))
            self._wait({m.name: "step" for m in due}, step_timeout, f"step {k}")
        else:
            for m in self.members.values():
                if m.pending is not None and (k + 1) % m.ratio == 0:
                    self._commit(m)  # those after it in config order see its value for t_(k+1)
                if k % m.ratio == 0:
                    m.inputs[m.route_dst] = self.values[m.route_src]
                    m.command.put(bus.encode_step(k, t_ns, m.ratio * h, m.inputs))
                    self._wait({m.name: "step"}, step_timeout, f"step {k}")
        for m in self.members.values():
            if m.pending is not None and (k + 1) % m.ratio == 0:
                self._commit(m)
        self.wait_s += time.perf_counter() - started

    def execute(self) -> int:
        """Run to the end (0), or until a failure (1) or an interruption (130); clean up in every case."""
        config = self.config
        previous = {sig: signal.signal(sig, _raise_stop) for sig in (signal.SIGTERM,)}
        code, message = 0, None
        self.session = None
        self._subscriptions: list = []
        wall_start = time.perf_counter()
        try:
            self._open_bus()
            if self.record_dir is not None:
                self.recording = Recording(self.record_dir, self.columns, config.resolved)
            self._log("start", run_id=self.run_id, config=str(config.path), steps=config.steps,
                      step_ns=config.step_ns, algorithm=config.algorithm,
                      components={n: s.type for n, s in config.components.items()})
            self._start(list(config.components.values()), {n: 0 for n in config.components}, self.members)
            for name in self._initialization_order():
                self._initialize(self.members[name], 0)
            self._record(0)
            decimation = self._start_viewer()
            if decimation:
                self.signals_out.put(SIGNALS_HEADER.pack(0, 0.0) + self.values.tobytes())
            wall_start = time.perf_counter()
            last_progress = wall_start
            for self.k in range(config.steps):
                self._boundary()
                if self.stop_reason:
                    break
                self._step()
                self._record(self.k + 1)
                if decimation and (self.k + 1) % decimation == 0:
                    self.signals_out.put(SIGNALS_HEADER.pack(self.k + 1, (self.k + 1) * config.step_ns / 1e9)
                                         + self.values.tobytes())
                now = time.perf_counter()
                if config.realtime > 0:
                    ahead = (self.k + 1) * config.step_ns / 1e9 / config.realtime - (now - wall_start)
                    if ahead > 0:
                        time.sleep(ahead)
                if self.progress and now - last_progress > 0.5:
                    last_progress = now
                    self._print_progress(now - wall_start)
            else:
                self.k = config.steps
        except RunFailure as failure:
            code, message = 1, str(failure)
            self._log("fault", step=self.k, message=message)
        except (KeyboardInterrupt, StopRequested):
            self.stop_reason = "interrupted"
            code = 130
        finally:
            # no second Ctrl-C/SIGTERM in the middle of the clean-up: it has bounded waits of its own
            for sig in (signal.SIGINT, signal.SIGTERM):
                signal.signal(sig, signal.SIG_IGN)
            self.loop_s = time.perf_counter() - wall_start
            if self.progress:
                print(file=self.out)
            for member in list(self.members.values()) + list(self.joining.values()):
                self._terminate(member, timeout=2.0 if code else 5.0)
            if self.session is not None:
                self._stop_viewer(self.signals_out)
            self._log("end", step=self.k, time=self.k * config.step_ns / 1e9,
                      status="failed" if code == 1 else (self.stop_reason or "completed"))
            if self.recording is not None:
                self.recording.close()
            runs.unregister(self.run_id)
            self._subscriptions.clear()
            if self.session is not None:
                self.session.close()
            if code == 0 and self.record_dir is None:
                shutil.rmtree(self.log_dir, ignore_errors=True)
            signal.signal(signal.SIGINT, signal.default_int_handler)
            for sig, handler in previous.items():
                signal.signal(sig, handler)
        if message:
            print(f"error: {message}", file=self.out)
            logs = ", ".join(str(m.log_path) for m in self.members.values() if m.log_path)
            if logs:
                print(f"component logs: {logs}", file=self.out)
        if self.profile:
            self._print_profile()
        return code

    def _open_bus(self) -> None:
        """The orchestrator's Zenoh session, its subscriptions, and the run's entry for `ps`."""
        import zenoh

        for attempt in range(3):  # a free port picked here may be taken by another run before Zenoh binds it
            listen, self.endpoint = resolve_endpoints(self.config.listen)
            try:
                self.session = zenoh.open(bus.session_config(listen=listen))
                break
            except zenoh.ZError as e:
                if attempt == 2 or not any(e.endswith(":0") for e in self.config.listen):
                    raise RunFailure(f"cannot open the bus on {', '.join(listen)} (bus.listen): {e}") from None
        self._subscriptions = [
            self.session.declare_subscriber(bus.run_key(self.run_id, "c", "*", "*", "out"), self._on_output),
            self.session.liveliness().declare_subscriber(bus.run_key(self.run_id, "alive", "*", "*"),
                                                         self._on_liveliness),
            self.session.declare_queryable(bus.run_key(self.run_id, "ctl"), self._on_control),
            self.session.liveliness().declare_token(bus.run_key(self.run_id, "alive", "orchestrator")),
        ]
        self.signals_out = bus.publisher(self.session, bus.run_key(self.run_id, "signals"), drop=True)
        runs.register(self.run_id, self.config.name, self.endpoint, self.config.path)

    def _boundary(self) -> None:
        """Work done between steps: control requests from the CLI, scheduled events."""
        while True:
            try:
                self._handle(self.inbox.get_nowait(), {})
            except queue.Empty:
                break
        if self.controls:
            self._serve_controls()
        t_ns = self.k * self.config.step_ns
        while self.pending_events and self.pending_events[0].at_ns <= t_ns:
            try:
                self.swap(self.pending_events.pop(0).spec)
            except SwapFailed as failure:  # a swap the config asks for is part of the experiment
                raise RunFailure(str(failure)) from None

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
            stdin=subprocess.DEVNULL, preexec_fn=_child_setup)
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
            try:
                self.viewer_process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.viewer_process.kill()
                self.viewer_process.wait()

    def _record(self, k: int) -> None:
        if self.recording is not None:
            self.recording.append(k, k * self.config.step_ns / 1e9, self.values)

    def _print_progress(self, wall: float) -> None:
        sim = (self.k + 1) * self.config.step_ns / 1e9
        total = self.config.duration_ns / 1e9
        print(f"\r  t = {sim:9.3f} / {total:g} s   {(self.k + 1) / wall:8.0f} steps/s   "
              f"real-time factor {sim / wall:6.2f}", end="", file=self.out, flush=True)

    def _print_profile(self) -> None:
        steps = max(self.k, 1)
        wall = self.loop_s
        print(f"profile: {self.k} steps in {wall:.3f} s wall ({self.k / wall if wall else 0:.0f} steps/s), "
              f"{self.config.algorithm}", file=self.out)
        print(f"  {'component':<16}{'compute/step':>14}{'share of wall':>15}", file=self.out)
        compute_total = 0.0
        for m in self.members.values():
            per = m.compute_s / max(m.steps, 1)
            compute_total += m.compute_s
            print(f"  {m.name:<16}{per * 1e6:>11.1f} us{100 * m.compute_s / wall if wall else 0:>14.1f}%",
                  file=self.out)
        barrier = self.wait_s / steps
        slowest = max((m.compute_s / max(m.steps, 1) for m in self.members.values()), default=0.0) \
            if self.config.algorithm == "jacobi" else compute_total / steps
        print(f"  barrier wait     {barrier * 1e6:>8.1f} us/step (of which bus + adapter overhead "
              f"~{max(barrier - slowest, 0) * 1e6:.1f} us)", file=self.out)
        print(f"  orchestrator     {(wall - self.wait_s) / steps * 1e6:>8.1f} us/step (routing, recording)",
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
