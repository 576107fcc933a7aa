"""Serving components on the run's bus: the session (a peer of the run's mesh, or a client of its
router), the keys of each component served, and the loop that feeds their
:class:`components.group.Group` from the inbox, one generation at a time. One process serves one
component (``python -m components.runner --name``), or a process group (``--member`` repeated);
``orchestrator join`` serves one after another on one session (:mod:`orchestrator.hosts.joiner`).
"""

from __future__ import annotations

import mmap
import os
import queue
import threading
import time
from typing import TYPE_CHECKING, cast

from components import bus, protocol
from components.group import MARK_SIZE, Group
from components.live_frames import LiveFrameSender
from components.process import IDLE_FLUSH_S

if TYPE_CHECKING:
    import zenoh
    from zenoh.handlers import Handler

INBOX_CAPACITY = 4096  # messages waiting in a component's inbox FIFO (a full one holds the senders back)
_QUIT = protocol.Quit().encode()
_GONE = (None, "", b"")  # the orchestrator went away (Group.handle)


class FifoInbox:
    """One component's inbox: Zenoh's FIFO channel, read by the stepping thread (no Python runs on
    Zenoh's threads per message). The orchestrator gone: a quit message to itself, behind what
    came before. No ``put``: a component never feeds itself (wiring.py)."""

    def __init__(self, session, run_id: str):
        self.session, self.run_id = session, run_id
        self.fifo: zenoh.Subscriber[Handler[zenoh.Sample]] | None = None  # once subscribed
        self.name: str | None = None
        self.quit: str | None = None

    def subscribe(self, name: str, generation: int):
        import zenoh

        self.name, self.quit = name, bus.quit_key(self.run_id, name, generation)
        self.fifo = self.session.declare_subscriber(
            bus.inbox_pattern(self.run_id, name), zenoh.handlers.FifoChannel(INBOX_CAPACITY)
        )
        return self.fifo

    def get(self) -> tuple[str | None, str, bytes]:
        sample = cast("zenoh.Subscriber[Handler[zenoh.Sample]]", self.fifo).recv()  # get follows subscribe
        key = str(sample.key_expr)
        return _GONE if key == self.quit else (self.name, key, sample.payload.to_bytes())

    def wake(self) -> None:
        self.session.put(self.quit, _QUIT)


class QueueInbox:
    """A process group's inbox: every member's subscription and the outputs between members on
    one queue."""

    def __init__(self, session, run_id: str):
        self.session, self.run_id = session, run_id
        self.queue: queue.SimpleQueue = queue.SimpleQueue()
        self.get, self.put = self.queue.get, self.queue.put

    def subscribe(self, name: str, generation: int):
        put = self.put
        return self.session.declare_subscriber(
            bus.inbox_pattern(self.run_id, name),
            lambda sample: put((name, str(sample.key_expr), sample.payload.to_bytes())),
        )

    def wake(self) -> None:
        self.put(_GONE)


class ZenohTransport:
    """The served components' keys on the session: each one's inbox subscription, reply and batch
    publishers and liveliness token; publishers of outputs that leave the process."""

    def __init__(self, session, run_id: str, inbox):
        self.session, self.run_id, self.inbox = session, run_id, inbox
        self.held: dict[str, list] = {}  # member -> what it declared
        self.replies: dict[str, zenoh.Publisher] = {}
        self.batches: dict[str, zenoh.Publisher] = {}
        self.outputs: dict[tuple[str, str], zenoh.Publisher] = {}  # (consumer, source) -> publisher
        self.views: dict[str, LiveFrameSender] = {}  # member -> its frames for the live views

    def join(self, name: str, generation: int) -> None:
        session, run_id = self.session, self.run_id
        self.held[name] = [self.inbox.subscribe(name, generation)]
        self.replies[name] = bus.publisher(session, bus.reply_key(run_id, name, generation))
        self.batches[name] = bus.publisher(session, bus.batch_key(run_id, name))
        self.held[name] += [
            self.replies[name],
            self.batches[name],
            session.liveliness().declare_token(bus.alive_key(run_id, name, generation)),
        ]
        self.views[name] = LiveFrameSender(session, run_id, name)
        self.held[name].append(self.views[name])

    def publish_reply(self, name: str, payload: bytes) -> None:
        self.replies[name].put(payload)

    def publish_batch(self, name: str, payload: bytes) -> None:
        self.batches[name].put(payload)

    def publish_output(self, consumer: str, source: str, payload: bytes) -> None:
        publisher = self.outputs.get((consumer, source))
        if publisher is None:
            publisher = self.outputs[consumer, source] = bus.publisher(
                self.session, bus.output_key(self.run_id, consumer, source)
            )
            self.held[source].append(publisher)
        publisher.put(payload)

    def interrupt_on_terminate(self, name: str, command: str, component) -> None:
        """For a component whose steps may wait on the outside: a subscriber that interrupts it as
        soon as a terminate arrives, while the stepping thread, which reads it from the inbox, may
        be inside such a step."""

        def on_command(sample) -> None:
            payload = sample.payload.to_bytes()
            if payload[:1] != b"H":  # not a horizon grant, the frequent one
                try:
                    if type(protocol.decode_command(payload)) is protocol.Terminate:
                        component.interrupt()
                except protocol.Malformed:
                    pass

        self.held[name].append(self.session.declare_subscriber(command, on_command))

    def leave(self, name: str) -> None:
        self.views.pop(name, None)
        for held in self.held.pop(name, ()):
            _undeclare(held)
        self.outputs = {pair: p for pair, p in self.outputs.items() if pair[1] != name}

    def close(self) -> None:
        for name in list(self.held):
            self.leave(name)


def _watch_orchestrator(session, run_id: str, orchestrator: str | None, gone):
    """Call ``gone`` when the orchestrator goes away: the closing of this session's direct link to
    it (Zenoh id ``orchestrator``), else the deletion of its liveliness token. The listener or
    subscriber that watches, to undeclare."""
    import zenoh

    if orchestrator in {str(t.zid) for t in session.info.transports()}:
        return session.info.declare_transport_events_listener(
            lambda e: gone() if e.kind == zenoh.SampleKind.DELETE and str(e.transport.zid) == orchestrator else None
        )
    return session.liveliness().declare_subscriber(
        bus.orchestrator_alive_key(run_id), lambda s: gone() if s.kind == zenoh.SampleKind.DELETE else None
    )


def _undeclare(held) -> None:
    import zenoh

    try:
        held.undeclare()
    except (zenoh.ZError, RuntimeError):  # the session is gone, or (PyO3: "Already borrowed") the
        pass  # watchdog's send is blocked on a cut link: it goes with the session


def _watchdog(group: Group, stop: threading.Event, beat_s: float | None) -> None:
    """Flush batches when due; and every ``beat_s`` a heartbeat, so that the orchestrator tells a
    silent link (cut: Zenoh may take long to close a link it cannot send on) within bus.lease."""
    import zenoh

    beat_at = time.monotonic()
    try:
        while not stop.wait(IDLE_FLUSH_S):
            beat = False
            if beat_s is not None and time.monotonic() >= beat_at:
                beat, beat_at = True, time.monotonic() + beat_s
            group.tick(beat)
    except zenoh.ZError:  # the session closed under it (Ctrl-C, a cut link): the stepping thread ends too
        pass


def serve(
    connect: str,
    run_id: str,
    members: list[tuple[str, int]],
    listen: str | None,
    secret: str,
    cpu: int | None = None,
    settings: dict | None = None,
    orchestrator: str | None = None,
    stepping: str | None = None,
) -> str:
    """Run the components ``members`` ((name, generation) each: one, or a process group's) of run
    ``run_id`` until none is left or the orchestrator goes away; ``secret``: the run's (see
    :func:`bus.open_session`); ``settings``: the run's bus settings (TLS, access control, lease,
    mode: :mod:`components.bus_security`). How it ended (:func:`serve_session`)."""
    session = open_component_session(connect, listen, secret, settings)
    try:
        return serve_session(session, run_id, members, cpu, orchestrator, beat_interval(settings), stepping)
    finally:
        bus.close_session(session)


def open_component_session(
    connect: str | list[str],
    listen: str | None,
    secret: str,
    settings: dict | None,
    connect_timeout_s: float | None = None,
):
    """A component's session: a peer of the run's mesh listening on ``listen``, or (settings'
    mode ``client``) a client of the run's router, listening nowhere."""
    settings = settings or {}
    connect = [connect] if isinstance(connect, str) else list(connect)
    peer = settings.get("mode", "peer") == "peer"
    listen_on = [listen or bus.listen_beside(connect[0])] if peer else []
    return bus.open_session(
        listen_on, connect, mesh=peer, secret=secret, settings=settings, connect_timeout_s=connect_timeout_s
    )


def beat_interval(settings: dict | None) -> float | None:
    """A quarter of the run's lease (bus.lease), in seconds; None without one."""
    lease_ms = (settings or {}).get("lease_ms")
    return lease_ms / 4000 if lease_ms else None


def serve_session(
    session,
    run_id: str,
    members: list[tuple[str, int]],
    cpu: int | None = None,
    orchestrator: str | None = None,
    beat_s: float | None = None,
    stepping: str | None = None,
) -> str:
    """Serve one generation of the components ``members`` on an open session until it ends:
    TERMINATED (the run is over), RELEASED (terminated for a restart: the run may want them
    again, in a new generation) or ORPHANED (the orchestrator died, or the link to it was cut).
    ``cpu``: step on that CPU alone (the bus's threads, started before, keep the CPUs this process
    was given). ``orchestrator``: the Zenoh id of the orchestrator's session; when this session
    links to it directly, the closing of that link says the orchestrator is gone (its liveliness
    token may be dropped with another peer's link), else its liveliness token does. ``beat_s``:
    send a heartbeat that often. ``stepping``: the file to mark the member whose code runs in
    (none: marks go nowhere)."""
    inbox = (FifoInbox if len(members) == 1 else QueueInbox)(session, run_id)
    transport = ZenohTransport(session, run_id, inbox)
    mark_file = open(stepping, "r+b") if stepping else None  # noqa: SIM115 (closed in the finally below)
    mark = mmap.mmap(mark_file.fileno(), MARK_SIZE) if mark_file else None
    group = Group(run_id, members, transport, inbox, mark)
    stop, keep = threading.Event(), []
    try:

        def gone() -> None:
            group.interrupt()
            inbox.wake()

        keep.append(_watch_orchestrator(session, run_id, orchestrator, gone))
        for name, generation in members:
            transport.join(name, generation)
            group.members[name].process.view = transport.views[name]
        threading.Thread(target=_watchdog, args=(group, stop, beat_s), daemon=True).start()
        if cpu is not None:
            os.sched_setaffinity(0, {cpu})  # this thread only
        return group.serve()
    finally:
        stop.set()
        with group.lock:  # not while the watchdog goes over the members
            transport.close()
        for held in keep:
            _undeclare(held)
        if mark is not None:
            mark.close()
        if mark_file is not None:
            mark_file.close()
