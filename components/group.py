"""Serving a process group: several components of a run in one process (the config's
``components.<name>.process``), on one Zenoh session and one stepping thread.

Each member keeps everything a component process has: its own keys (inbox, commands, replies,
batches, liveliness token) and its own :class:`components.process.ComponentProcess`. What differs
is the routing: the members' inbox subscriptions feed one queue, read by the stepping thread; an
output for a consumer hosted here is put on that same queue (the encoded bytes, as the bus would
carry them: the consumer decodes exactly what it would have received), and one for any other
consumer goes over Zenoh. So a member never steps inside another's step (no recursion), and
outputs within the group take no hop. A member told to terminate leaves the group (its keys
undeclared; a swap's new generation runs in a process of its own); the process exits when none
is left.

Before it runs a member's code the stepping thread marks that member in ``stepping`` (a 4-byte
file the orchestrator maps, :func:`read_mark`), so that a crash or hang of the process names the
component whose step failed.
"""
from __future__ import annotations

import mmap
import os
import queue
import struct
import sys
import threading
import time

from components import bus, protocol
from components.process import IDLE_FLUSH_S, ComponentProcess, Halt
from components.serving import ORPHANED, RELEASED, TERMINATED, beat_interval, open_component_session

_MARK = struct.Struct("<I")   # 1 + the index of the member whose code runs; 0: none
_IDLE = _MARK.pack(0)
_BEAT = protocol.Beat().encode()


def read_mark(path) -> int | None:
    """The index (in the runner's ``--member`` order) of the member whose code the group's
    process was running, from its stepping file; None when it was between members."""
    try:
        with open(path, "rb") as file:
            data = file.read(_MARK.size)
    except OSError:
        return None
    mark = _MARK.unpack(data)[0] if len(data) == _MARK.size else 0
    return mark - 1 if mark else None


class Member:
    """A component hosted in the group: its step logic and where its messages come."""

    def __init__(self, name: str, index: int, run_id: str, generation: int, process: ComponentProcess):
        self.name, self.process = name, process
        self.mark = _MARK.pack(index + 1)
        self.command = bus.command_key(run_id, name, generation)
        self.output_prefix = bus.output_prefix(run_id, name)


class Group:
    """The members' step logic and the routing between them; no Zenoh (``transport`` carries
    what leaves the group, so the routing is tested with a stand-in). ``inbox``: the queue the
    members' messages come on, as (member name, key, payload); (None, "", b"") says the
    orchestrator went away. ``stepping``: a writable 4-byte buffer (the mapped stepping file)."""

    def __init__(self, run_id: str, members: list[tuple[str, int]], transport, inbox: queue.SimpleQueue, stepping):
        self.run_id, self.transport, self.inbox, self.stepping = run_id, transport, inbox, stepping
        self.lock = threading.Lock()   # members leave while the watchdog goes over them
        self.members: dict[str, Member] = {}
        self.local_keys: dict[tuple[str, str], str] = {}   # (consumer, source) -> the output key
        for index, (name, generation) in enumerate(members):
            process = ComponentProcess(name, self._replies(name), self._outputs(name), self._batches(name))
            self.members[name] = Member(name, index, run_id, generation, process)

    def _replies(self, name: str):
        return lambda payload: self.transport.publish_reply(name, payload)

    def _batches(self, name: str):
        return lambda payload: self.transport.publish_batch(name, payload)

    def _outputs(self, source: str):
        def publish_output(consumers: list[str], payload: bytes) -> None:
            for consumer in consumers:
                if consumer in self.members:   # hosted here: on the queue, read after this step
                    key = self.local_keys.get((consumer, source))
                    if key is None:
                        key = self.local_keys[consumer, source] = bus.output_key(self.run_id, consumer, source)
                    self.inbox.put((consumer, key, payload))
                else:
                    self.transport.publish_output(consumer, source, payload)
        return publish_output

    def serve(self) -> str:
        """Apply the queue's messages until no member is left (TERMINATED, or RELEASED for a
        restart) or the orchestrator went away (ORPHANED)."""
        get, handle = self.inbox.get, self.handle
        while True:
            ended = handle(*get())
            if ended is not None:
                return ended

    def handle(self, name: str | None, key: str, payload: bytes) -> str | None:
        """Apply one message to the member it is for, and let the member step; how the group
        ended, or None while it goes on."""
        if name is None:
            print("the orchestrator went away: exiting", file=sys.stderr, flush=True)
            return ORPHANED
        member = self.members.get(name)
        if member is None:
            return None   # for a member that has left
        self.stepping[:_MARK.size] = member.mark
        try:
            return self._apply(member, key, payload)
        finally:
            self.stepping[:_MARK.size] = _IDLE

    def _apply(self, member: Member, key: str, payload: bytes) -> str | None:
        process = member.process
        try:
            if key.startswith(member.output_prefix):
                process.source_output(key[len(member.output_prefix):], payload)
            elif key == member.command:
                if not process.command(payload):
                    self._leave(member)
                    return None if self.members else (TERMINATED if process.final else RELEASED)
            else:
                return None   # for another generation of this component
        except bus.Malformed as e:   # whoever reaches the bus cannot stop a member
            process.dropped(key, str(e))
            return None
        try:
            process.advance()
        except Halt:
            pass
        return None

    def _leave(self, member: Member) -> None:
        with self.lock:
            del self.members[member.name]
            self.transport.leave(member.name)

    def tick(self, beat: bool) -> None:
        """From the watchdog thread: flush the batches that are due; with ``beat``, a heartbeat
        from every member."""
        with self.lock:
            for member in self.members.values():
                member.process.flush_if_due()
                if beat:
                    member.process.publish_reply(_BEAT)


class ZenohTransport:
    """The group's keys on its session: each member's inbox subscription (onto the group's
    queue), reply and batch publishers and liveliness token; publishers of outputs that leave."""

    def __init__(self, session, run_id: str, inbox: queue.SimpleQueue):
        self.session, self.run_id, self.inbox = session, run_id, inbox
        self.held: dict[str, list] = {}            # member -> what it declared
        self.replies: dict[str, object] = {}
        self.batches: dict[str, object] = {}
        self.outputs: dict[tuple[str, str], object] = {}   # (consumer, source) -> publisher
        self.views: dict[str, bus.LiveFrameSender] = {}   # member -> its frames for the live views

    def join(self, name: str, generation: int) -> None:
        session, run_id, put = self.session, self.run_id, self.inbox.put
        self.replies[name] = bus.publisher(session, bus.reply_key(run_id, name, generation))
        self.batches[name] = bus.publisher(session, bus.batch_key(run_id, name))
        self.held[name] = [
            session.declare_subscriber(bus.inbox_pattern(run_id, name),
                                       lambda sample: put((name, str(sample.key_expr), sample.payload.to_bytes()))),
            self.replies[name], self.batches[name],
            session.liveliness().declare_token(bus.alive_key(run_id, name, generation))]
        self.views[name] = bus.LiveFrameSender(session, run_id, name)
        self.held[name].append(self.views[name])

    def publish_reply(self, name: str, payload: bytes) -> None:
        self.replies[name].put(payload)

    def publish_batch(self, name: str, payload: bytes) -> None:
        self.batches[name].put(payload)

    def publish_output(self, consumer: str, source: str, payload: bytes) -> None:
        publisher = self.outputs.get((consumer, source))
        if publisher is None:
            publisher = self.outputs[consumer, source] = bus.publisher(
                self.session, bus.output_key(self.run_id, consumer, source))
            self.held[source].append(publisher)
        publisher.put(payload)

    def leave(self, name: str) -> None:
        self.views.pop(name, None)
        for held in self.held.pop(name, ()):
            _undeclare(held)
        self.outputs = {pair: p for pair, p in self.outputs.items() if pair[1] != name}

    def close(self) -> None:
        for name in list(self.held):
            self.leave(name)


def _undeclare(held) -> None:
    import zenoh
    try:
        held.undeclare()
    except (zenoh.ZError, RuntimeError):   # the session is gone, or its send is blocked on a cut link
        pass


def _watchdog(group: Group, stop: threading.Event, beat_s: float | None) -> None:
    import zenoh

    beat_at = time.monotonic()
    try:
        while not stop.wait(IDLE_FLUSH_S):
            beat = beat_s is not None and time.monotonic() >= beat_at
            if beat:
                beat_at = time.monotonic() + beat_s
            group.tick(beat)
    except zenoh.ZError:   # the session closed under it: the stepping thread ends too
        pass


def serve_group(connect: str, run_id: str, members: list[tuple[str, int]], listen: str | None, secret: str,
                cpu: int | None = None, settings: dict | None = None, orchestrator: str | None = None,
                stepping: str | None = None) -> str:
    """Run the components ``members`` ((name, generation) each) of run ``run_id`` in this process
    until none is left or the orchestrator goes away (as :func:`components.serving.serve` runs one);
    ``stepping``: the file to mark the member whose code runs in (none: marks go nowhere)."""
    import zenoh

    session = open_component_session(connect, listen, secret, settings)
    inbox: queue.SimpleQueue = queue.SimpleQueue()
    transport = ZenohTransport(session, run_id, inbox)
    mark_file = open(stepping, "r+b") if stepping else None
    mark = mmap.mmap(mark_file.fileno(), _MARK.size) if mark_file else bytearray(_MARK.size)
    group = Group(run_id, members, transport, inbox, mark)
    stop, keep = threading.Event(), []
    try:
        gone = lambda: inbox.put((None, "", b""))   # noqa: E731 - wakes the stepping thread
        if orchestrator in {str(t.zid) for t in session.info.transports()}:
            keep.append(session.info.declare_transport_events_listener(
                lambda e: gone() if e.kind == zenoh.SampleKind.DELETE and str(e.transport.zid) == orchestrator
                else None))
        else:
            keep.append(session.liveliness().declare_subscriber(
                bus.orchestrator_alive_key(run_id), lambda s: gone() if s.kind == zenoh.SampleKind.DELETE else None))
        for name, generation in members:
            transport.join(name, generation)
            group.members[name].process.view = transport.views[name]
        threading.Thread(target=_watchdog, args=(group, stop, beat_interval(settings)), daemon=True).start()
        if cpu is not None:
            os.sched_setaffinity(0, {cpu})   # this thread only
        return group.serve()
    finally:
        stop.set()
        with group.lock:
            transport.close()
        for held in keep:
            _undeclare(held)
        if mark_file is not None:
            mark.close()
            mark_file.close()
        bus.close_session(session)
