"""The orchestrator's side of the inbox: applies each message to the run's state, waits for the
answers a step of the run's life expects, and watches the processes; a member that faults or dies
first has the rows it completed recorded (salvaged)."""

from __future__ import annotations

import queue
import time

from components import bus, protocol
from orchestrator.run.control import ControlServer
from orchestrator.run.members import Member, RunFailure, at_fault, death, exited, fault_message
from orchestrator.run.messages import CONTROL, OUTPUTS, REPLY, LinkLost, Liveliness, Outputs, Report, decode
from orchestrator.run.state import RunState
from orchestrator.run.viewer_link import ViewerLink

SYNC_ROUND_S = 0.05  # the start-up handshake is repeated at this interval until everyone hears everyone
GONE_WAIT_S = 2.0  # a dead process's last batches come before its link closes: wait at most this long
SLOW_START_S = 5.0  # an instantiate this long gets a note (a first run on a machine compiles the kernels)


class Listener:
    """Applies the messages of ``run`` (its state; the queue is ``run.inbox``); CLI requests go to
    ``controls``. ``hosts``: the run's bus (orchestrator.hosts.run_bus), which tells of lost links."""

    def __init__(self, run: RunState, controls: ControlServer, hosts, viewer_link: ViewerLink, out):
        self.run, self.controls, self.hosts, self.viewer_link, self.out = run, controls, hosts, viewer_link, out
        self.dropped: dict[str, int] = {}  # key -> messages dropped from it (malformed, stranger, stale)

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
            self.run.log(
                "warning",
                step=self.run.rows.row,
                message=f"dropped a message on {key}: {reason}" + (f" ({n} so far)" if n > 1 else ""),
            )

    def _apply(self, message, expect: dict[str, str]) -> None:
        run = self.run
        if type(message) is Outputs:
            member = run.members.get(message.name)
            if member is None:
                raise bus.Malformed(f"no component {message.name!r} in this run")
            member.receive(message)
            member.heard_at = member.progress_at
            return
        if type(message) is LinkLost:  # the member it was is lost: check_processes says so (hosts.silent)
            self.hosts.link_closed(message.zid, [*run.members.values(), *run.joining.values()])
            return
        name = message.name
        if type(message) is Liveliness:
            if name in (bus.VIEWER, bus.ROS2):
                if message.alive and expect.get(name) == "alive":
                    del expect[name]
                elif not message.alive:
                    what = "the viewer" if name == bus.VIEWER else "the ROS 2 view"
                    run.log("warning", message=f"{what} went away; the run goes on", step=run.rows.row)
                return
            member = self._member(name, message.generation)
            if member is None:
                return
            if message.alive:
                if expect.get(name) == "alive":
                    del expect[name]
                return
            member.token_gone = True
            return  # a token may go with another peer's link: its process or link tells (check_processes)
        report = message.message
        member = self._member(name, message.generation)
        if member is None:
            if type(report) is protocol.Beat or self._replaced(name, message.generation):
                return  # a generation swapped out (or restarted) on purpose may still say its last
            raise bus.Malformed(f"no component {name!r} of generation {message.generation} in this run")
        member.heard_at = time.monotonic()
        if type(report) is protocol.Beat:
            return
        if type(report) is protocol.Reply:
            member.reply = report
            if expect.get(name) == report.op:
                del expect[name]
            return
        if type(report) is protocol.Events:
            for kind, fields in report.events:  # what a component reports cannot rename the line's keys
                run.log(kind, **{**fields, "component": name, "step": report.k})
            return
        if report.k >= 0:  # a fault: it published every output before the failing step's
            member.progress = max(member.progress, report.k)
        self.salvage(member)
        raise RunFailure(fault_message(member, report, run.config.step_ns), member)

    def _member(self, name: str, generation: int) -> Member | None:
        """The live (or joining) member with this name and generation; None for a stale generation."""
        for group in (self.run.members, self.run.joining):
            member = group.get(name)
            if member is not None and member.generation == generation:
                return member
        return None

    def _replaced(self, name: str, generation: int) -> bool:
        """An older generation of a component of this run: one this run replaced."""
        live = [m.generation for m in (self.run.members.get(name), self.run.joining.get(name)) if m is not None]
        return bool(live) and generation < max(live)

    def wait(self, expect: dict[str, str], timeout: float, what: str) -> None:
        """Process inbox messages until every expectation is met, or fail naming the laggards."""
        started = time.monotonic()
        deadline = started + timeout
        noted = what != "instantiate"
        while expect:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise RunFailure(
                    f"component {_names(expect)} did not answer {what} within {timeout:g} s "
                    f"(hung? raise run.step_timeout / run.start_timeout if it is just slow)"
                )
            if not noted and time.monotonic() - started > SLOW_START_S:
                noted = True
                print(
                    f"note: waiting for {_names(expect)} to instantiate: the first run on a machine compiles "
                    f"{'its' if len(expect) == 1 else 'their'} kernels (numba; 20-45 s on 2 cores), later runs "
                    f"load them from the cache (run.start_timeout: {timeout:g} s)",
                    file=self.out,
                    flush=True,
                )
            try:
                message = self.run.inbox.get(timeout=min(remaining, 0.2))
            except queue.Empty:
                self.check_processes(expect)
                continue
            self.handle(message, expect)

    def sync(self, waiting: list[Member]) -> None:
        """Repeat the handshake until each of ``waiting`` has heard every one of its sources: from
        then on, no output published to it can be lost to a subscription still on its way."""
        run = self.run
        expect = {m.name: "synced" for m in waiting}
        deadline = time.monotonic() + run.config.start_timeout_s
        while expect:
            if time.monotonic() > deadline:
                raise RunFailure(
                    f"component {', '.join(map(repr, expect))} did not hear its sources within "
                    f"{run.config.start_timeout_s:g} s (run.start_timeout)"
                )
            for member in run.members.values():
                member.control(protocol.Sync())
            round_end = time.monotonic() + SYNC_ROUND_S
            while expect and time.monotonic() < round_end:
                try:
                    self.handle(run.inbox.get(timeout=max(round_end - time.monotonic(), 0.001)), expect)
                except queue.Empty:
                    pass
            self.check_processes(list(expect))

    def check_processes(self, names) -> None:
        """Fail if the process of one of these members (or the viewer) has exited."""
        for name in names:
            if name in (bus.VIEWER, bus.ROS2):
                if problem := self.viewer_link.exited(name):
                    raise RunFailure(problem)
                continue
            member = self.run.joining.get(name) or self.run.members[name]
            if how := exited(member) or self.hosts.silent(member):
                silent_s = None if exited(member) else time.monotonic() - member.heard_at
                if silent_s is None:
                    self._until_gone(member)
                member = at_fault(member)  # in a process group: the member whose code was running
                self.salvage(member, lost=True)
                raise RunFailure(death(member, how), member, lost=True, silent_s=silent_s)

    def _until_gone(self, member: Member) -> None:
        """A member whose process exited: apply what it sent before it died, still on its way, until
        its liveliness token goes (which comes after it on its link), for at most GONE_WAIT_S. A
        fast run's components run a window ahead of the recorded rows: its rows are in those batches."""
        end = time.monotonic() + GONE_WAIT_S
        while not member.token_gone and (left := end - time.monotonic()) > 0:
            try:
                entry = self.run.inbox.get(timeout=left)
            except queue.Empty:
                return
            self.handle(entry, {})

    def salvage(self, failed: Member, lost: bool = False) -> None:
        """``failed`` failed: record every row up to its last output. The others' outputs for those
        rows may still be on their way (batched; on a loaded machine, seconds late), so wait for
        them as long as they can come: until the rows are in, a row lacks what can no longer
        come, or no output has come for run.step_timeout (what the run takes for hung). No
        wall-clock limit of its own: a fixed 1 s cut off rows that were sent (CI: 32 of 50).
        ``lost``: ``failed``'s process died, hung or lost its link (the members it runs too send
        nothing more)."""
        run = self.run
        if failed.name not in run.members:
            return
        target = min(failed.progress, run.horizon)
        heard = time.monotonic()
        run.rows.advance(run.members, run.horizon)  # outputs handled before the failure may still wait
        while run.rows.row < target and time.monotonic() - heard <= run.config.step_timeout_s:
            row = run.rows.row + 1
            if not all(
                self._deliverable(m, row // m.ratio * m.ratio, failed, lost, set()) for m in run.members.values()
            ):
                break
            if self._take_outputs(0.1):
                heard = time.monotonic()
        else:
            return
        # a row lacks the output of a member fed by one that is gone: whether that member got
        # its last inputs (a killed process's may have left; a cut link's never arrive), only
        # it knows. Ask: a member answers a sync after sending every output it has made.
        asked = {
            m.name
            for m in run.members.values()
            if m is not failed
            and not exited(m)
            and not self.hosts.silent(m)
            and not (lost and m.shared is not None and m.shared is failed.shared)
        }
        for name in asked:
            run.members[name].control(protocol.Sync())
        heard = time.monotonic()
        while asked and time.monotonic() - heard <= run.config.step_timeout_s:
            try:
                kind, key, payload = run.inbox.get(timeout=0.1)
            except queue.Empty:
                continue
            if kind == OUTPUTS:
                self.handle((kind, key, payload), {})
                run.rows.advance(run.members, run.horizon)
                heard = time.monotonic()
            elif kind == REPLY:
                try:
                    reply = decode(kind, key, payload)
                except bus.Malformed:
                    continue
                if type(reply) is Report and type(reply.message) is protocol.Reply and reply.message.op == "synced":
                    asked.discard(reply.name)

    def _take_outputs(self, timeout: float) -> bool:
        """Record what one batch of outputs from the inbox completes; whether one came within ``timeout``."""
        try:
            kind, key, payload = self.run.inbox.get(timeout=timeout)
        except queue.Empty:
            return False
        if kind != OUTPUTS:
            return False
        self.handle((kind, key, payload), {})
        self.run.rows.advance(self.run.members, self.run.horizon)
        return True

    def _deliverable(self, m: Member, tag: int, failed: Member, lost: bool, seen: set) -> bool:
        """Whether ``m``'s output ``tag`` came or surely can still come: sent (a fault's step
        counts: its batch is on the way), or ``m`` steps on and its sources feed that step. A
        source that is gone (process exited, link lost, ``failed``'s process when ``lost``) may
        not have delivered what it sent: False then, and salvage asks."""
        if m.progress >= tag:
            return True
        if (
            m is failed
            or exited(m)
            or self.hosts.silent(m)
            or (lost and m.shared is not None and m.shared is failed.shared)
        ):
            return False
        if (m.name, tag) in seen:  # a loop: the step_timeout bound decides
            return True
        seen.add((m.name, tag))
        k = tag - m.ratio  # the step that makes it
        for route in (*m.routes, *m.frame_routes):
            source = self.run.members.get(route.source)
            if source is None or source is m:
                continue
            if not self._deliverable(source, route.tag(k), failed, lost, seen) or (
                source.progress >= route.tag(k) and self._gone(source, failed, lost)
            ):
                return False
        return True

    def _gone(self, m: Member, failed: Member, lost: bool) -> bool:
        """``m`` sends nothing more, and what it sent may not all have arrived."""
        return (
            (m is failed and lost)
            or exited(m) is not None
            or self.hosts.silent(m) is not None
            or (lost and m.shared is not None and m.shared is failed.shared)
        )

    def discard_stale(self) -> None:
        """Empty the inbox of what stopped generations sent; requests from the CLI are kept."""
        while True:
            try:
                kind, key, _ = self.run.inbox.get_nowait()
            except queue.Empty:
                break
            if kind == CONTROL:
                self.controls.add(key)


def _names(names) -> str:
    """'a', 'b': the components a wait is still on."""
    return ", ".join(f"{n!r}" for n in names)
