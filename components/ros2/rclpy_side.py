"""The ROS 2 side of the ``rclpy`` transport: one rclpy node, in a process of its own, run by the
Python that has the user's ROS 2 (a sourced /opt/ros, or a venv with the Jazzy wheels), on
whatever middleware that environment selects (``RMW_IMPLEMENTATION``: Fast DDS by default).

    python rclpy_side.py --domain 0 --node zenorbit_demo [--namespace /]

This file imports only the standard library and rclpy (and, per topic, the message's package), so
that any Python with rclpy runs it: the project's packages need not be installed there. Its parent
(:mod:`components.ros2.rclpy_transport`) speaks to it over its stdin and stdout in frames: a
little-endian uint32 length, one byte of kind, then the payload.

parent -> this side:
  ``P`` {id, topic, type, latched, depth}   declare a publisher (CDR bytes in, ``raw``; depth null: KEEP_ALL)
  ``S`` {id, topic, type, latched, depth}   declare a subscription (its messages go back as ``M``)
  ``M`` uint32 id + CDR                       publish on publisher ``id``
  ``G`` {request, topics}                     ask the graph: each entity's matched count, and who
                                              else publishes and subscribes ``topics``
  ``Q`` {}                                    finish: publish what came before, then exit 0
this side -> parent:
  ``R`` {rmw, domain, python, node}           the node is up
  ``M`` uint32 id + CDR                       a message on subscription ``id``
  ``W`` {id, text}                            entity ``id`` could not be made (its messages are dropped)
  ``G`` {request, matched, graph}             the graph answer

A closed stdin (the parent gone) ends the process too. Nothing else may write to stdout: it is
moved to a private descriptor at once, and fd 1 points at stderr for the libraries' own prints.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import struct
import sys
import threading
import time
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the checker's only: this file imports nothing but the standard library and rclpy
    from rclpy.publisher import Publisher
    from rclpy.subscription import Subscription

HEADER = struct.Struct("<IB")
ENTITY_ID = struct.Struct("<I")
FLUSH_S = 2.0  # at the end, how long the subscribers may take to acknowledge the last messages
MATCH_WAIT_S = 2.0  # how long a new publisher waits to be matched by subscriptions the graph knows of
SETTLED_S = 0.5  # discovery: a graph unchanged this long, once another node is known, is taken as whole


def read_exact(fd: int, size: int) -> bytes | None:
    chunks, remaining = [], size
    while remaining:
        chunk = os.read(fd, remaining)
        if not chunk:
            return None
        chunks.append(chunk)
        remaining -= len(chunk)
    return b"".join(chunks)


class Channel:
    """Frames to the parent, from any thread."""

    def __init__(self, fd: int):
        self.fd = fd
        self.lock = threading.Lock()

    def send(self, kind: bytes, payload: bytes) -> None:
        frame = HEADER.pack(len(payload), kind[0]) + payload
        with self.lock:
            view = memoryview(frame)
            while view:
                view = view[os.write(self.fd, view) :]

    def send_json(self, kind: bytes, value: dict) -> None:
        self.send(kind, json.dumps(value).encode())


def message_class(msgtype: str):
    package, kind, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), name)


def discover(node, limit_s: float) -> None:
    """Wait, at most ``limit_s``, until the middleware's discovery has shown this node the others
    on its domain: DDS learns of a participant some 0.1 s to seconds after it starts (seen here: 0.2
    to 2.6 s on a loaded machine), and a message published before a subscription is matched is lost
    to it. Done when another node is known and the graph has not changed for ``SETTLED_S``."""
    started = changed = time.monotonic()
    seen: tuple = ()
    own = (node.get_name(), node.get_namespace())
    while (now := time.monotonic()) - started < limit_s:
        others = frozenset(n for n in node.get_node_names_and_namespaces() if tuple(n) != own)
        topics = frozenset((topic, tuple(types)) for topic, types in node.get_topic_names_and_types())
        if (others, topics) != seen:
            seen, changed = (others, topics), now
        elif others and now - changed >= SETTLED_S:
            return
        time.sleep(0.02)


class SideNode:
    """The rclpy node and what the parent declared on it: publishers and subscriptions by id,
    each answering the parent's frames."""

    def __init__(self, channel: Channel, domain: int, name: str, namespace: str):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.channel = channel
        rclpy.init(domain_id=domain)
        self.node = rclpy.create_node(name, namespace=namespace)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.spinner = threading.Thread(target=self.executor.spin, name="rclpy-spin", daemon=True)
        self.spinner.start()
        self.publishers: dict[int, Publisher] = {}
        self.subscriptions: dict[int, Subscription] = {}
        self.unpublished: set[str] = set()  # topics a publish failed on (said once each)

    @staticmethod
    def qos(spec: dict):
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        if spec["depth"] is None:  # KEEP_ALL: reliable delivery of every sample to the readers it matched
            return QoSProfile(
                history=HistoryPolicy.KEEP_ALL,
                reliability=ReliabilityPolicy.RELIABLE,
                durability=DurabilityPolicy.VOLATILE,
            )
        return QoSProfile(
            history=HistoryPolicy.KEEP_LAST,
            depth=int(spec["depth"]),
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if spec["latched"] else DurabilityPolicy.VOLATILE,
        )

    def declare(self, kind: bytes, spec: dict) -> None:
        try:
            cls = message_class(spec["type"])
        except (ImportError, AttributeError, ValueError) as e:
            self.channel.send_json(
                b"W",
                {
                    "id": spec["id"],
                    "text": f"{spec['topic']}: no message type {spec['type']} in "
                    f"this ROS 2 environment ({type(e).__name__}: {e}); install its package",
                },
            )
            return
        if kind == b"P":
            publisher = self.node.create_publisher(cls, spec["topic"], self.qos(spec))
            self.publishers[spec["id"]] = publisher
            self.await_matches(publisher, spec["topic"])
        else:
            header, channel = ENTITY_ID.pack(spec["id"]), self.channel
            self.subscriptions[spec["id"]] = self.node.create_subscription(
                cls, spec["topic"], lambda data: channel.send(b"M", header + data), self.qos(spec), raw=True
            )

    def await_matches(self, publisher, topic: str) -> None:
        # a message published before DDS matched a subscription the graph already knows is lost to it
        deadline = time.monotonic() + MATCH_WAIT_S
        while publisher.get_subscription_count() < self.node.count_subscribers(topic) and time.monotonic() < deadline:
            time.sleep(0.005)

    def graph(self, request: dict) -> dict:
        node = self.node
        matched = {str(i): p.get_subscription_count() for i, p in self.publishers.items()}
        matched |= {str(i): s.get_publisher_count() for i, s in self.subscriptions.items()}
        others = []
        own = (node.get_name(), node.get_namespace())
        for topic in request["topics"]:
            for role, infos in (
                ("publisher", node.get_publishers_info_by_topic(topic)),
                ("subscription", node.get_subscriptions_info_by_topic(topic)),
            ):
                others += [
                    [role, topic, info.topic_type, info.node_namespace.rstrip("/") + "/" + info.node_name]
                    for info in infos
                    if (info.node_name, info.node_namespace) != own
                ]
        return {"request": request["request"], "matched": matched, "graph": others}

    def publish(self, payload: bytes) -> None:
        (entity,) = ENTITY_ID.unpack_from(payload)
        publisher = self.publishers.get(entity)
        if publisher is None:
            return
        try:
            publisher.publish(payload[ENTITY_ID.size :])
        except Exception as e:  # rclpy's RCLError: the writer's history full past its wait
            if publisher.topic_name not in self.unpublished:
                self.unpublished.add(publisher.topic_name)
                self.channel.send_json(
                    b"W",
                    {
                        "id": None,
                        "text": f"{publisher.topic_name}: a message could not be published ({type(e).__name__}: {e})",
                    },
                )

    def serve(self) -> None:
        """Answer the parent's frames until it says finish or goes away."""
        while True:
            header = read_exact(0, HEADER.size)
            if header is None:
                break
            size, kind = HEADER.unpack(header)
            payload = read_exact(0, size)
            if payload is None:
                break
            kind = bytes([kind])
            if kind == b"M":
                self.publish(payload)
            elif kind in (b"P", b"S"):
                self.declare(kind, json.loads(payload))
            elif kind == b"G":
                self.channel.send_json(b"G", self.graph(json.loads(payload)))
            elif kind == b"Q":
                break

    def close(self) -> None:
        """Give the subscribers up to FLUSH_S to acknowledge what was published, then end rclpy."""
        import rclpy
        import rclpy.duration

        deadline = time.monotonic() + FLUSH_S  # reliable: what was published reaches who matched
        for publisher in self.publishers.values():
            publisher.wait_for_all_acked(
                rclpy.duration.Duration(nanoseconds=max(0, int((deadline - time.monotonic()) * 1e9)))
            )
        self.executor.shutdown(timeout_sec=1.0)
        rclpy.try_shutdown()  # wakes the spinning thread, which must end before the process does
        self.spinner.join(timeout=2.0)
        self.node.destroy_node()


def main() -> int:
    out = os.dup(1)  # the protocol's descriptor; fd 1 becomes stderr for everything else
    os.dup2(2, 1)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--domain", type=int, required=True)
    parser.add_argument("--node", required=True)
    parser.add_argument("--namespace", default="/")
    parser.add_argument(
        "--discover", type=float, default=0.0, help="at most this long (s), learn the graph before saying ready"
    )
    args = parser.parse_args()

    import rclpy

    side = SideNode(Channel(out), args.domain, args.node, args.namespace)
    discover(side.node, args.discover)
    side.channel.send_json(
        b"R",
        {
            "rmw": rclpy.get_rmw_implementation_identifier(),
            "domain": args.domain,
            "python": sys.executable,
            "node": side.node.get_fully_qualified_name(),
        },
    )
    try:
        side.serve()
    except KeyboardInterrupt:
        pass
    finally:
        side.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
