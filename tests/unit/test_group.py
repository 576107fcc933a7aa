"""A process group's routing without the bus (components/group.py Group): outputs to a member go
on the group's own queue, outputs to anyone else through the transport; a member that leaves is
reached through the transport from then on; the stepping mark names the member whose code runs."""

from __future__ import annotations

import queue

import numpy as np

from components import bus, protocol
from components.group import TERMINATED, Group, read_mark
from components.schedule import Route
from components.sdk import RunSettings

RUN = "loop-0"
STEP_NS = 1_000_000


class Transport:
    """What leaves the group: each member's replies and batches, outputs by (consumer, source)."""

    def __init__(self):
        self.replies: dict[str, list[bytes]] = {}
        self.batches: dict[str, list[bytes]] = {}
        self.outputs: list[tuple[str, str, bytes]] = []
        self.left: list[str] = []

    def publish_reply(self, name, payload):
        self.replies.setdefault(name, []).append(payload)

    def publish_batch(self, name, payload):
        self.batches.setdefault(name, []).append(payload)

    def publish_output(self, consumer, source, payload):
        self.outputs.append((consumer, source, payload))

    def leave(self, name):
        self.left.append(name)


class Marks(bytearray):
    """The stepping buffer, remembering every mark written to it."""

    def __init__(self):
        super().__init__(4)
        self.written: list[int] = []

    def __setitem__(self, index, value):
        super().__setitem__(index, value)
        self.written.append(int.from_bytes(bytes(value), "little"))


def command(inbox: queue.SimpleQueue, name: str, message: protocol.Message) -> None:
    inbox.put((name, bus.command_key(RUN, name, 0), message.encode()))


def drain(group: Group, inbox: queue.SimpleQueue) -> str | None:
    ended = None
    while not inbox.empty() and ended is None:
        ended = group.handle(*inbox.get())
    return ended


def started_group():
    """src (test.constant 2) -> int (test.integrator), src also feeding ``outside``, not hosted here."""
    inbox, transport, marks = queue.SimpleQueue(), Transport(), Marks()
    group = Group(RUN, [("src", 0), ("int", 0)], transport, inbox, marks)
    command(inbox, "src", protocol.Instantiate("test.constant", {"value": 2.0}, RunSettings().to_json()))
    command(inbox, "int", protocol.Instantiate("test.integrator", {"gain": 0.5}, RunSettings().to_json()))
    command(
        inbox,
        "src",
        protocol.Wire(
            generation=0,
            step_ns=STEP_NS,
            ratio=1,
            k=0,
            consumers=["int", "outside"],
            batch_consumers=[],
            routes=[],
            sources={},
            faults=[],
        ),
    )
    route = Route("src", np.array([0]), np.array([0]), 1, 0)
    command(
        inbox,
        "int",
        protocol.Wire(
            generation=0,
            step_ns=STEP_NS,
            ratio=1,
            k=0,
            consumers=[],
            batch_consumers=[],
            routes=[route],
            sources={"src": 0},
            faults=[],
        ),
    )
    for name, inputs in (("src", np.empty(0)), ("int", np.array([2.0]))):
        command(inbox, name, protocol.Initialize(0, {}, inputs))
    command(inbox, "src", protocol.Start([], 0, np.empty(0)))
    held, values = protocol.holding([("src", 0, np.array([2.0]))])
    command(inbox, "int", protocol.Start(held, 0, values))
    assert drain(group, inbox) is None
    return group, inbox, transport, marks


def recorded(transport: Transport, name: str) -> tuple[list[int], np.ndarray]:
    batches = [bus.decode_batch(b) for b in transport.batches.get(name, [])]
    return (
        [t for b in batches for t in b[1].tolist()],
        np.concatenate([b[3] for b in batches]) if batches else np.empty((0, 0)),
    )


def test_outputs_to_a_member_stay_in_the_group_and_the_others_go_through_the_transport():
    group, inbox, transport, marks = started_group()
    for name in ("src", "int"):
        command(inbox, name, protocol.Horizon(5))
    assert drain(group, inbox) is None
    assert [(c, s) for c, s, _ in transport.outputs] == [("outside", "src")] * 5  # none to int
    tags, rows = recorded(transport, "int")
    assert tags == [1, 2, 3, 4, 5]
    assert np.array_equal(rows[:, 0], 0.5 * 2.0 * np.arange(1, 6) * 1e-3)  # every step on src's y
    # each member's code ran under its own mark (1 + its index), cleared after
    assert set(marks.written) == {0, 1, 2} and read_mark_of(marks) is None


def read_mark_of(marks: Marks) -> int | None:
    mark = int.from_bytes(bytes(marks[:4]), "little")
    return mark - 1 if mark else None


def test_a_member_that_leaves_is_reached_through_the_transport_and_the_last_ends_the_group():
    group, inbox, transport, _ = started_group()
    command(inbox, "int", protocol.Terminate(False))
    assert drain(group, inbox) is None and transport.left == ["int"]
    command(inbox, "src", protocol.Horizon(2))
    inbox.put(("int", bus.output_key(RUN, "int", "src"), b"queued for int before it left"))
    assert drain(group, inbox) is None
    assert [(c, s) for c, s, _ in transport.outputs] == [("int", "src"), ("outside", "src")] * 2
    command(inbox, "src", protocol.Terminate(True))
    assert drain(group, inbox) == TERMINATED and transport.left == ["int", "src"]


def test_the_stepping_file_names_the_member_running(tmp_path):
    path = tmp_path / "group.stepping"
    path.write_bytes(bytes(4))
    assert read_mark(path) is None
    path.write_bytes((2).to_bytes(4, "little"))
    assert read_mark(path) == 1
    assert read_mark(tmp_path / "missing") is None
