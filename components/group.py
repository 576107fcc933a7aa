"""The components one process serves, and the routing between them: one component, or the
members of a process group (the config's ``components.<name>.process``), on one stepping thread
(:mod:`components.serving` puts them on the bus).

Each member has everything a component process has: its own keys (inbox, commands, replies,
batches, liveliness token) and its own :class:`components.process.ComponentProcess`. Their inbox
messages come on one queue, read by the stepping thread; an output for a consumer hosted here is
put on that same queue (the encoded bytes, as the bus would carry them: the consumer decodes
exactly what it would have received), and one for any other consumer goes over Zenoh. So a member
never steps inside another's step (no recursion), and outputs within the group take no hop. A
member told to terminate leaves the group (its keys undeclared; a swap's new generation runs in a
process of its own); the process exits when none is left.

Before it runs a member's code the stepping thread marks that member in ``stepping`` (a 4-byte
file the orchestrator maps, :func:`read_mark`), so that a crash or hang of the process names the
component whose step failed.
"""

from __future__ import annotations

import struct
import sys
import threading
from typing import TYPE_CHECKING

from components import bus, protocol
from components.process import ComponentProcess, Halt

if TYPE_CHECKING:
    from components.sdk import Component

TERMINATED, RELEASED, ORPHANED = "terminated", "released", "orphaned"  # how serving a generation ended

_MARK = struct.Struct("<I")  # 1 + the index of the member whose code runs; 0: none
MARK_SIZE = _MARK.size
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
        self.interruptible = False  # its type's steps may wait on the outside (Component.interrupt)
        self.command = bus.command_key(run_id, name, generation)
        self.output_prefix = bus.output_prefix(run_id, name)


class Group:
    """The members' step logic and the routing between them; no Zenoh (``transport`` carries
    what leaves the group, so the routing is tested with a stand-in). ``inbox``: the queue the
    members' messages come on, as (member name, key, payload) (``get`` and ``put``); (None, "", b"")
    says the orchestrator went away. ``stepping``: a writable 4-byte buffer (the mapped stepping file), or
    None where no one reads the marks (a component alone in its process)."""

    def __init__(self, run_id: str, members: list[tuple[str, int]], transport, inbox, stepping):
        self.run_id, self.transport, self.inbox, self.stepping = run_id, transport, inbox, stepping
        self.lock = threading.Lock()  # members leave while the watchdog goes over them
        self.members: dict[str, Member] = {}
        self.local_keys: dict[tuple[str, str], str] = {}  # (consumer, source) -> the output key
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
                if consumer in self.members:  # hosted here: on the queue, read after this step
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
            return None  # for a member that has left
        stepping = self.stepping
        if stepping is None:  # one component: its process names it
            return self._apply(member, key, payload)
        stepping[: _MARK.size] = member.mark
        try:
            return self._apply(member, key, payload)
        finally:
            stepping[: _MARK.size] = _IDLE

    def _apply(self, member: Member, key: str, payload: bytes) -> str | None:
        process = member.process
        try:
            if key.startswith(member.output_prefix):
                process.source_output(key[len(member.output_prefix) :], payload)
            elif key == member.command:
                if not process.command(payload):
                    self._leave(member)
                    return None if self.members else (TERMINATED if process.final else RELEASED)
                if not member.interruptible and process.component is not None and process.component.interruptible():
                    member.interruptible = True
                    self.transport.interrupt_on_terminate(member.name, member.command, process.component)
            else:
                return None  # for another generation of this component
        except bus.Malformed as e:  # whoever reaches the bus cannot stop a member
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

    def interrupt(self) -> None:
        """From another thread, the run ending (the orchestrator gone): a step that waits on the
        outside ends that wait now."""
        for member in list(self.members.values()):  # a copy: members leave on the stepping thread
            if member.interruptible:
                component: Component | None = member.process.component
                assert component is not None, "a member is interruptible once its component is built"
                component.interrupt()

    def tick(self, beat: bool) -> None:
        """From the watchdog thread: flush the batches that are due; with ``beat``, a heartbeat
        from every member."""
        with self.lock:
            for member in self.members.values():
                member.process.flush_if_due()
                if beat:
                    member.process.publish_reply(_BEAT)
