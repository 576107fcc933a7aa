"""Serving a component on the run's bus: its session (a peer of the run's mesh, or a client of its
router), its keys, and the loop that feeds :class:`components.process.ComponentProcess` from its
inbox, one generation at a time (``python -m components.runner`` serves one; ``orchestrator
join`` serves one after another, see :mod:`orchestrator.hosts.joiner`)."""
from __future__ import annotations

import os
import sys
import threading
import time

from components import bus, protocol
from components.process import IDLE_FLUSH_S, ComponentProcess, Halt

INBOX_CAPACITY = 4096   # messages waiting in the inbox FIFO (a full one holds the senders back)
_BEAT = protocol.Beat().encode()   # the same bytes every time
_QUIT = protocol.Quit().encode()


def _watchdog(process: ComponentProcess, stop: threading.Event, beat_s: float | None) -> None:
    """Flush batches when due; and every ``beat_s`` a heartbeat, so that the orchestrator tells a
    silent link (cut: Zenoh may take long to close a link it cannot send on) within bus.lease."""
    import zenoh

    beat_at = time.monotonic()
    try:
        while not stop.wait(IDLE_FLUSH_S):
            process.flush_if_due()
            if beat_s is not None and time.monotonic() >= beat_at:
                beat_at = time.monotonic() + beat_s
                process.publish_reply(_BEAT)
    except zenoh.ZError:   # the session closed under it (Ctrl-C, a cut link): the main loop ends too
        pass


def _interrupter(session, component, command: str, quit_key: str) -> list:
    """For a component whose steps may wait on the outside (``Component.interrupt``): subscribers
    that interrupt it as soon as a terminate or a quit arrives, while the main thread, which reads
    them from the inbox, may be inside such a step."""
    def on_command(sample) -> None:
        payload = sample.payload.to_bytes()
        if payload[:1] != b"H":   # not a horizon grant, the frequent one
            try:
                if type(protocol.decode_command(payload)) is protocol.Terminate:
                    component.interrupt()
            except protocol.Malformed:
                pass
    return [session.declare_subscriber(command, on_command),
            session.declare_subscriber(quit_key, lambda sample: component.interrupt())]


TERMINATED, RELEASED, ORPHANED = "terminated", "released", "orphaned"   # how serving a generation ended


def serve(connect: str, run_id: str, name: str, generation: int, listen: str | None, secret: str,
          cpu: int | None = None, settings: dict | None = None, orchestrator: str | None = None) -> str:
    """Run component ``name`` of run ``run_id`` until told to exit; ``secret``: the run's (see
    :func:`bus.open_session`); ``settings``: the run's bus settings (TLS, access control, lease,
    mode: :mod:`components.bus_security`); ``cpu``: step on that CPU alone (the bus's threads,
    started before, keep the CPUs this process was given). How it ended (:func:`serve_session`)."""
    session = open_component_session(connect, listen, secret, settings)
    try:
        return serve_session(session, run_id, name, generation, cpu, orchestrator, beat_interval(settings))
    finally:
        bus.close_session(session)


def open_component_session(connect: str | list[str], listen: str | None, secret: str, settings: dict | None,
                           connect_timeout_s: float | None = None):
    """A component's session: a peer of the run's mesh listening on ``listen``, or (settings'
    mode ``client``) a client of the run's router, listening nowhere."""
    settings = settings or {}
    connect = [connect] if isinstance(connect, str) else list(connect)
    peer = settings.get("mode", "peer") == "peer"
    listen_on = [listen or bus.listen_beside(connect[0])] if peer else []
    return bus.open_session(listen_on, connect, mesh=peer, secret=secret, settings=settings,
                            connect_timeout_s=connect_timeout_s)


def beat_interval(settings: dict | None) -> float | None:
    """A quarter of the run's lease (bus.lease), in seconds; None without one."""
    lease_ms = (settings or {}).get("lease_ms")
    return lease_ms / 4000 if lease_ms else None


def serve_session(session, run_id: str, name: str, generation: int, cpu: int | None = None,
                  orchestrator: str | None = None, beat_s: float | None = None) -> str:
    """Serve one generation of component ``name`` on an open session until it ends:
    TERMINATED (the run is over), RELEASED (terminated for a restart: the run may want this
    component again, in a new generation) or ORPHANED (the orchestrator died, or the link to it
    was cut). ``orchestrator``: the Zenoh id of the orchestrator's session; when this session
    links to it directly, the closing of that link says the orchestrator is gone (its liveliness
    token may be dropped with another peer's link), else its liveliness token does. ``beat_s``:
    send a heartbeat that often."""
    import zenoh

    keep = []   # subscribers and publishers live as long as this generation
    stop_watchdog = threading.Event()
    try:
        inbox = session.declare_subscriber(bus.inbox_pattern(run_id, name), zenoh.handlers.FifoChannel(INBOX_CAPACITY))
        keep.append(inbox)
        command = bus.command_key(run_id, name, generation)
        quit_key = bus.quit_key(run_id, name, generation)
        output_prefix = bus.output_prefix(run_id, name)
        replies = bus.publisher(session, bus.reply_key(run_id, name, generation))
        batches = bus.publisher(session, bus.batch_key(run_id, name))
        keep += [replies, batches]
        outputs: dict[str, object] = {}

        def publish_output(consumers: list[str], payload: bytes) -> None:
            for consumer in consumers:
                publisher = outputs.get(consumer)
                if publisher is None:
                    publisher = outputs[consumer] = bus.publisher(session, bus.output_key(run_id, consumer, name))
                    keep.append(publisher)
                publisher.put(payload)

        # the orchestrator gone (killed, machine lost): wake the main loop with a quit message
        if orchestrator in {str(t.zid) for t in session.info.transports()}:
            keep.append(session.info.declare_transport_events_listener(
                lambda e: session.put(quit_key, _QUIT)
                if e.kind == zenoh.SampleKind.DELETE and str(e.transport.zid) == orchestrator else None))
        else:
            keep.append(session.liveliness().declare_subscriber(
                bus.orchestrator_alive_key(run_id),
                lambda s: session.put(quit_key, _QUIT) if s.kind == zenoh.SampleKind.DELETE else None))
        keep.append(session.liveliness().declare_token(bus.alive_key(run_id, name, generation)))
        process = ComponentProcess(name, replies.put, publish_output, batches.put)
        process.view = bus.LiveFrameSender(session, run_id, name)
        keep.append(process.view)
        threading.Thread(target=_watchdog, args=(process, stop_watchdog, beat_s), daemon=True).start()
        if cpu is not None:
            os.sched_setaffinity(0, {cpu})   # this thread only
        interrupter = []
        while True:
            sample = inbox.recv()
            key = str(sample.key_expr)
            if key == quit_key:
                print("the orchestrator went away: exiting", file=sys.stderr, flush=True)
                return ORPHANED
            try:
                if key.startswith(output_prefix):
                    process.source_output(key[len(output_prefix):], sample.payload.to_bytes())
                elif key == command:
                    if not process.command(sample.payload.to_bytes()):
                        return TERMINATED if process.final else RELEASED
                    if not interrupter and process.component is not None and process.component.interruptible():
                        interrupter = _interrupter(session, process.component, command, quit_key)
                        keep += interrupter
                else:
                    continue   # for another generation of this component
            except bus.Malformed as e:   # whoever reaches the bus cannot stop this component
                process.dropped(key, str(e))
                continue
            try:
                process.advance()
            except Halt:
                pass
    finally:
        stop_watchdog.set()
        for held in keep:
            try:
                held.undeclare()
            except (zenoh.ZError, RuntimeError):   # the session is gone, or (PyO3: "Already borrowed") the
                pass                               # watchdog's send is blocked on a cut link: it goes with the session


