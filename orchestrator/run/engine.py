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

This module is the run's life and its loop; the parts it drives: :mod:`.messages` (decoding the
inbox), :mod:`.members` (the processes), :mod:`.wiring` (who feeds whom), :mod:`.pacing` (the
horizon), :mod:`.rows` (the recorded row), :mod:`.recovery` (swap, checkpoint, restart),
:mod:`.viewer_link` and :mod:`.report`.
"""
from __future__ import annotations

import os
import queue
import secrets
import shutil
import signal
import sys
import tempfile
import time
import traceback
import uuid
from pathlib import Path

from components import bus, protocol, schedule
from components.constants import NS_PER_S
from orchestrator.run import pacing, recovery, report, runs, supervisor, wiring
from orchestrator.config import shadows
from orchestrator.config.specs import ComponentSpec, RunConfig, ViewerSpec
from orchestrator.run.control import ControlServer, StopRequested, SwapFailed, raise_stop
from orchestrator.run.members import Crew, Member, RunFailure, death, exited, fault_message, terminate
from orchestrator.run.messages import CONTROL, Beat, Events, LinkLost, Liveliness, Outputs, Reply, decode, subscribe
from orchestrator.run.recording import Recording, RecordingError
from orchestrator.run.rows import Rows
from orchestrator.hosts.run_bus import RunBus
from orchestrator.run.viewer_link import ViewerLink

SYNC_ROUND_S = 0.05  # the start-up handshake is repeated at this interval until everyone hears everyone
SLOW_START_S = 5.0   # an instantiate this long gets a note (a first run on a machine compiles the kernels)


class Run:
    """One execution of a validated config. ``execute()`` returns the exit code (0, 1, 130)."""

    def __init__(self, config: RunConfig, *, record: str | Path | None = None, profile: bool = False,
                 progress: bool = False, out=sys.stderr, viewer: ViewerSpec | None = None):
        self.config = config
        self.viewer = viewer or config.viewer
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
        self.pending_events = list(config.events)
        self.pending_faults = list(config.faults)
        self.rows = Rows(config.components.values(), config.step_ns)
        self.recovery = recovery.Recovery(self)
        self.controls = ControlServer(self)
        self.dropped: dict[str, int] = {}   # key -> messages dropped from it (malformed, stranger, stale)
        self.stop_reason: str | None = None
        self.horizon = 0                       # steps k < horizon are granted
        self.horizon_at = 0.0
        # component logs: kept with the recording, else in a temporary directory removed after a clean run
        self.log_dir = (self.record_dir / "logs") if self.record_dir else Path(
            tempfile.mkdtemp(prefix=f"zenorbit-{self.run_id}-"))
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.loop_s = 0.0
        self.placement = supervisor.place([n for n, c in config.components.items() if c.dedicated_cpu],
                                          os.sched_getaffinity(0))
        self.session = self.crew = self.viewer_link = self.hosts = None
        self._subscriptions: list = []

    # ---------------------------------------------------------------- what the control server sees

    @property
    def row(self) -> int:
        """The last recorded row = the step boundary reached."""
        return self.rows.row

    def specs(self) -> dict[str, ComponentSpec]:
        return {n: m.spec for n, m in self.members.items()}

    def status(self) -> dict:
        return {"run_id": self.run_id, "name": self.config.name, "step": self.rows.row,
                "steps": self.config.steps, "time": self.rows.row * self.config.step_ns / NS_PER_S,
                "components": {n: {"type": m.spec.type, "generation": m.generation,
                                   **({"shadow_of": m.spec.shadow_of} if m.spec.shadow_of else {})}
                               for n, m in self.members.items()}}

    def request_stop(self, reason: str) -> None:
        self.stop_reason = reason

    def swap(self, spec: ComponentSpec, planned: bool = False) -> int:
        return self.recovery.swap(spec, planned)

    def log(self, kind: str, **fields) -> None:
        """An event in events.jsonl, if the run is recorded."""
        if self.rows.recording is not None:
            self.rows.recording.event(kind, **fields)

    # ---------------------------------------------------------------- messages

    def handle(self, message, expect: dict[str, str]) -> None:
        """Apply one inbox message; ``expect`` maps component name -> the reply we wait for. A
        malformed message, or one from an unknown component or an old generation, is dropped with
        a warning: whoever can reach the bus cannot end the run (docs/design.md §7)."""
        kind, key, payload = message
        if kind == CONTROL:
            self.controls.add(key)
            return
        try:
            decoded = decode(kind, key, payload)
            if decoded is not None:
                self._apply(decoded, expect)
        except bus.Malformed as e:
            self._drop(key, str(e))

    def _drop(self, key: str, reason: str) -> None:
        """Warn of a dropped message in events.jsonl (bus.count_drop says when)."""
        if n := bus.count_drop(self.dropped, key):
            self.log("warning", step=self.rows.row, message=f"dropped a message on {key}: {reason}"
                                                            + (f" ({n} so far)" if n > 1 else ""))

    def _apply(self, message, expect: dict[str, str]) -> None:
        if type(message) is Outputs:
            member = self.members.get(message.name)
            if member is None:
                raise bus.Malformed(f"no component {message.name!r} in this run")
            member.receive(message)
            member.heard_at = member.progress_at
            return
        if type(message) is LinkLost:   # the member it was is lost: _check_processes says so (hosts.silent)
            self.hosts.link_closed(message.zid, [*self.members.values(), *self.joining.values()])
            return
        name = message.name
        if type(message) is Liveliness:
            if name == bus.VIEWER:
                if message.alive and expect.get(name) == "alive":
                    del expect[name]
                elif not message.alive:
                    self.log("warning", message="the viewer went away; the run goes on", step=self.rows.row)
                return
            member = self._member(name, message.generation)
            if member is None:
                return
            if message.alive:
                if expect.get(name) == "alive":
                    del expect[name]
                return
            return   # a token may go with another peer's link: its process or link tells (_check_processes)
        member = self._member(name, message.generation)
        if member is None:
            if type(message) is Beat or self._replaced(name, message.generation):
                return   # a generation swapped out (or restarted) on purpose may still say its last
            raise bus.Malformed(f"no component {name!r} of generation {message.generation} in this run")
        member.heard_at = time.monotonic()
        if type(message) is Beat:
            return
        if type(message) is Reply:
            member.reply = {**message.body, "blob": message.blob}
            if expect.get(name) == message.body["op"]:
                del expect[name]
            return
        if type(message) is Events:
            for kind, fields in message.events:   # what a component reports cannot rename the line's keys
                self.log(kind, **{**fields, "component": name, "step": message.k})
            return
        if message.k >= 0:  # a fault: it published every output before the failing step's
            member.progress = max(member.progress, message.k)
        self.recovery.salvage(member)
        raise RunFailure(fault_message(member, message, self.config.step_ns), member)

    def _member(self, name: str, generation: int) -> Member | None:
        """The live (or joining) member with this name and generation; None for a stale generation."""
        for group in (self.members, self.joining):
            member = group.get(name)
            if member is not None and member.generation == generation:
                return member
        return None

    def _replaced(self, name: str, generation: int) -> bool:
        """An older generation of a component of this run: one this run replaced."""
        live = [m.generation for m in (self.members.get(name), self.joining.get(name)) if m is not None]
        return bool(live) and generation < max(live)

    def wait(self, expect: dict[str, str], timeout: float, what: str) -> None:
        """Process inbox messages until every expectation is met, or fail naming the laggards."""
        started = time.monotonic()
        deadline = started + timeout
        noted = what != "instantiate"
        while expect:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise RunFailure(f"component {_names(expect)} did not answer {what} within {timeout:g} s "
                                 f"(hung? raise run.step_timeout / run.start_timeout if it is just slow)")
            if not noted and time.monotonic() - started > SLOW_START_S:
                noted = True
                print(f"note: waiting for {_names(expect)} to instantiate: the first run on a machine compiles "
                      f"{'its' if len(expect) == 1 else 'their'} kernels (numba; 20-45 s on 2 cores), later runs "
                      f"load them from the cache (run.start_timeout: {timeout:g} s)", file=self.out, flush=True)
            try:
                message = self.inbox.get(timeout=min(remaining, 0.2))
            except queue.Empty:
                self._check_processes(expect)
                continue
            self.handle(message, expect)

    def sync(self, waiting: list[Member]) -> None:
        """Repeat the handshake until each of ``waiting`` has heard every one of its sources: from
        then on, no output published to it can be lost to a subscription still on its way."""
        expect = {m.name: "synced" for m in waiting}
        deadline = time.monotonic() + self.config.start_timeout_s
        while expect:
            if time.monotonic() > deadline:
                raise RunFailure(f"component {', '.join(map(repr, expect))} did not hear its sources within "
                                 f"{self.config.start_timeout_s:g} s (run.start_timeout)")
            for member in self.members.values():
                member.control(protocol.Sync())
            round_end = time.monotonic() + SYNC_ROUND_S
            while expect and time.monotonic() < round_end:
                try:
                    self.handle(self.inbox.get(timeout=max(round_end - time.monotonic(), 0.001)), expect)
                except queue.Empty:
                    pass
            self._check_processes(list(expect))

    def _check_processes(self, names) -> None:
        """Fail if the process of one of these members (or the viewer) has exited."""
        for name in names:
            if name == bus.VIEWER:
                if problem := self.viewer_link.exited():
                    raise RunFailure(problem)
                continue
            member = self.joining.get(name) or self.members[name]
            if how := exited(member) or self.hosts.silent(member):
                self.recovery.salvage(member)
                raise RunFailure(death(member, how), member, lost=True)

    # ---------------------------------------------------------------- the loop

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
                    if not self.recovery.may_restart(failure):
                        raise
                    self.recovery.restart(failure)   # or, past run.max_restarts, fail
        finally:
            self.loop_s = time.perf_counter() - wall_start

    def _step_until(self, steps: int, wall_start: float) -> None:
        last_progress = last_check = time.monotonic()
        expect: dict[str, str] = {}
        rows = self.rows
        while rows.row < steps and not self.stop_reason:
            if rows.row == self.horizon:   # everyone is at this boundary: control happens here
                while self._event_step() is not None and self._event_step() <= rows.row:
                    try:
                        self.recovery.swap(self.pending_events.pop(0).spec, planned=True)
                    except SwapFailed as failure:  # a swap the config asks for is part of the experiment
                        raise RunFailure(str(failure)) from None
                if rows.row == self._next_checkpoint():
                    self.recovery.take_checkpoint()
                self.controls.serve(quiescent=True)
            elif self.controls.queries:
                self.controls.serve(quiescent=False)
            wake = self._grant(wall_start)
            try:
                self.handle(self.inbox.get(timeout=wake), expect)
                while True:
                    self.handle(self.inbox.get_nowait(), expect)
            except queue.Empty:
                pass
            rows.advance(self.members, self.horizon)
            now = time.monotonic()
            if now - last_check > 0.2:
                last_check = now
                self.recovery.check_hung()
                self._check_processes(list(self.members))
            if self.progress and now - last_progress > 0.5:
                last_progress = now
                print(report.progress(rows.row, self.config.step_ns, self.config.duration_ns,
                                      time.perf_counter() - wall_start), end="", file=self.out, flush=True)

    def _event_step(self) -> int | None:
        if not self.pending_events:
            return None
        return schedule.first_step_at(self.pending_events[0].at_ns, self.config.step_ns)

    def _next_checkpoint(self) -> int | None:
        return recovery.next_checkpoint(self.recovery.checkpoint, self.config.checkpoint_ns, self.config.step_ns)

    def _grant(self, wall_start: float) -> float:
        """Extend the horizon (pacing.grant) and tell everyone; how long the loop may sleep."""
        config = self.config
        limit = config.steps   # the step boundary the run must stop at next: the end, an event, a swap, a checkpoint
        for boundary in (self._event_step(), self.controls.swap_boundary(), self._next_checkpoint()):
            if boundary is not None:
                limit = min(limit, max(boundary, self.rows.row))
        realtime = config.realtime
        horizon, wake = pacing.grant(self.rows.row, self.horizon, limit, realtime, config.step_ns,
                                     time.perf_counter() - wall_start if realtime > 0 else 0.0)
        if horizon is not None:
            self.horizon, self.horizon_at = horizon, time.monotonic()
            grant = protocol.Horizon(horizon).encode()
            for member in self.members.values():
                member.command.put(grant)
        return wake

    # ---------------------------------------------------------------- the run's life

    def execute(self) -> int:
        """Run to the end (0), or until a failure (1) or an interruption (130); clean up in every case."""
        previous = {sig: signal.signal(sig, raise_stop) for sig in (signal.SIGTERM,)}
        # Ctrl-C is ours whatever was inherited: a run started with `&` from a script has SIGINT
        # ignored (POSIX), and would otherwise go on under a Ctrl-C or `kill -INT`
        previous[signal.SIGINT] = signal.signal(signal.SIGINT, signal.default_int_handler)
        code, message = 0, None
        own_cpus = os.sched_getaffinity(0)
        run_start = time.perf_counter()
        try:
            supervisor.keep_to(self.placement.shared)   # this thread, and the bus threads it starts
            self._open_bus()
            self._start(len(own_cpus))
            self._loop()
        except (RunFailure, RecordingError) as failure:
            code, message = 1, str(failure)
            self.log("fault", step=self.rows.row, message=message)
        except (KeyboardInterrupt, StopRequested):
            self.stop_reason = "interrupted"
            code = 130
        except Exception as error:   # a bug of ours: still a clean end, and no "completed" in events.jsonl
            traceback.print_exc(file=self.out)
            code, message = 1, f"internal error: {type(error).__name__}: {error}"
            self.log("fault", step=self.rows.row, message=message)
        finally:
            # no second Ctrl-C/SIGTERM in the middle of the clean-up: it has bounded waits of its own
            for sig in (signal.SIGINT, signal.SIGTERM):
                signal.signal(sig, signal.SIG_IGN)
            code, message = self._clean_up(code, message)
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
            print("\n".join(report.profile(self.members.values(), self.rows.row, self.config.step_ns, self.loop_s,
                                           self.config.algorithm)), file=self.out)
        # as events.jsonl's end line says it ("stopped by request" ends with exit code 0 too)
        status = "failed" if code == 1 else (self.stop_reason or ("completed" if code == 0 else "interrupted"))
        print(report.summary(self.config.name, status, self.rows.row, self.config.steps, self.config.step_ns,
                             time.perf_counter() - run_start, self.loop_s, self.recovery.restarts, self.record_dir),
              file=self.out, flush=True)
        return code

    def _open_bus(self) -> None:
        """The orchestrator's Zenoh session, its subscriptions, and the run's entry for `ps`."""
        self.hosts = RunBus(self.config, self.run_id, self.secret, self.record_dir, self.out)
        self.child_env.update(self.hosts.child_env(None))
        self.session = session = self.hosts.open()
        run_id = self.run_id
        self._subscriptions = subscribe(session, run_id, self.inbox.put)
        self.viewer_link = ViewerLink(self.viewer, session, run_id)
        self.crew = Crew(self.config, run_id=run_id, session=session, endpoint=self.hosts.local, secret=self.secret,
                         env=self.child_env, log_dir=self.log_dir, placement=self.placement, out=self.out,
                         place=self.rows.placement, wait=self.wait, hosts=self.hosts)
        runs.register(run_id, self.config.name, self.hosts.local, self.config.path, self.secret,
                      self.hosts.settings("cli"))

    def _start(self, cpus: int) -> None:
        """Start, wire and initialize every component, the recording and the viewer; let them go.
        ``cpus``: how many the run may use."""
        config, rows = self.config, self.rows
        if self.record_dir is not None:
            rows.recording = Recording(self.record_dir, rows.columns, config.resolved, flush_s=config.record_flush_s)
        self.log("start", run_id=self.run_id, config=str(config.path.resolve()), steps=config.steps,
                 step_ns=config.step_ns, algorithm=config.algorithm,
                 components={n: s.type for n, s in config.components.items()},
                 shadows={n: s.shadow_of for n, s in config.components.items() if s.shadow_of},
                 cpus={**self.placement.dedicated, "shared": sorted(self.placement.shared)})
        for note in config.notes:       # suspect physics the check found (orchestrator check shows them too)
            print(f"warning: {note}", file=self.out)
            self.log("warning", message=note, step=0)
        if self.placement.unplaced:
            message = (f"no CPU to spare for {', '.join(self.placement.unplaced)} (dedicated_cpu; "
                       f"{cpus} CPU(s) available): they share the others'")
            print(f"note: {message}", file=self.out)
            self.log("warning", message=message, step=0)
        self.crew.start(list(config.components.values()), {n: 0 for n in config.components}, self.members)
        for member in self.members.values():
            wiring.wire(self.crew, member, self.members, self.pending_faults, 0)
        for name in shadows.initialization_order(config.components, config.connections):
            member = self.members[name]
            member.latest = wiring.initialize(self.crew, member, self.members, 0)
            member.initialized = True
            rows.take(member)
        if rows.recording is not None:
            rows.recording.append(0, 0.0, rows.values)
        rows.decimation = self.viewer_link.start(config, rows.columns, setup=self.log_dir / "viewer.json",
                                                 endpoint=self.crew.endpoint, run_id=self.run_id,
                                                 env=self.child_env, cpus=self.placement.shared, wait=self.wait)
        if rows.decimation:
            self.log("viewer", mode=self.viewer.mode, rate_hz=self.viewer.rate_hz)
            rows.signals = self.viewer_link.signals.put
            rows.publish()
        self.sync(list(self.members.values()))
        if self.recovery.restartable:
            self.recovery.take_checkpoint()
        for member in self.members.values():
            wiring.go(member, self.members, self.horizon)

    def _clean_up(self, code: int, message: str | None) -> tuple[int, str | None]:
        """Stop every process, close the recording and the bus; the exit code and error message,
        which a recording that cannot be closed changes."""
        if self.progress:
            print(file=self.out)
        if self.hosts is not None:
            self.hosts.close()   # joins from now on are told the run is over
        for member in list(self.members.values()) + list(self.joining.values()):
            terminate(member, timeout=2.0 if code else 5.0, final=True)
        if self.viewer_link is not None:
            self.viewer_link.stop(self.stop_reason == "interrupted", self.out)
        self.log("end", step=self.rows.row, time=self.rows.row * self.config.step_ns / NS_PER_S,
                 status="failed" if code == 1 else (self.stop_reason or "completed"))
        if self.rows.recording is not None:
            try:
                self.rows.recording.close()
            except RecordingError as failure:
                code, message = 1, message or str(failure)
        runs.unregister(self.run_id)
        self._subscriptions.clear()
        if self.session is not None:
            self.session.close()
        if self.hosts is not None:
            self.hosts.remove(join_files=self.record_dir is None)
        if code == 0 and self.record_dir is None:
            shutil.rmtree(self.log_dir, ignore_errors=True)
        return code, message


def _names(names) -> str:
    """'a', 'b': the components a wait is still on."""
    return ", ".join(f"{n!r}" for n in names)
