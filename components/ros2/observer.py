"""The ROS 2 observer process: signal rows from the run's bus, published live to ROS 2 over
rmw_zenoh (``orchestrator run CFG --ros2 [ENDPOINT]`` or a ``ros2:`` config section).

    python -m components.ros2.observer --connect tcp/127.0.0.1:7447 --run-id demo-1a2b3c4d --setup ros2.json

Started by the orchestrator, it runs in the observer shell (components/observer_shell.py): it
subscribes to the run's signal rows (a dropping publisher, so it never holds up a step), runs
niced, declares its liveliness token ``alive/_ros2/0`` once its camera frames are subscribed, and
leaves at the run's END or when the orchestrator goes. The setup JSON: ``columns``, ``config``
(resolved), ``config_dir``, and ``ros2``: ``endpoint`` (the ROS side's router, rmw_zenohd),
``domain_id``, ``distro``, ``topics`` (None: all), ``node`` (the node's name).

The ROS side is a second Zenoh session, a client of that router (no secret, no TLS: the run's own
bus keeps both; no port opened here). On it a ROS 2 node (:class:`components.ros2.rmw_zenoh.Node`) publishes the
topics of the rosbag2 export (:class:`components.ros_topics.LiveTopics`: the same message
types and CDR bytes as ``orchestrator export --rosbag2`` for those rows), in time order per batch,
each sample with rmw_zenoh's attachment (the source timestamp is this process's system clock, as
rmw_zenoh's; the simulation time is in the messages' stamps and on ``/clock``). Latched topics
(``/tf_static``, ``robot_description``) are sent once, from a TRANSIENT_LOCAL publisher whose cache
answers late joiners. A router that cannot be reached within ``CONNECT_TIMEOUT_S``: a warning naming
it, the rows are dropped, and a thread tries again every ``RETRY_S``, so a router started later
still gets the rest of the run.
"""

from __future__ import annotations

import sys
import threading
import time
from typing import cast

from components import bus, observer_shell
from components.observer_shell import Stop, View
from components.ros2 import rmw_zenoh, router
from components.ros2.rclpy_transport import RCLPY, RclpyNode
from components.ros2.stream_report import FAILED, NO_LINK, StreamCounts

CONNECT_TIMEOUT_S = 3.0  # how long a link to the ROS router may take to come up
LINK_POLL_S = 0.1  # how often the link's state is looked at
RETRY_S = 2.0  # between tries when it did not
DISCOVER_S = 3.0  # rclpy: at most this long for DDS discovery before the run starts (rclpy_side.discover)
DISTROS = {"jazzy": "ros2_jazzy", "kilted": "ros2_kilted", "lyrical": "ros2_lyrical"}  # rmw_zenoh with type hashes


class RosLink:
    """The session to the ROS side's router at ``endpoint``: a Zenoh client of it (the router
    routes a client's samples, tokens and queries to the ROS nodes, its peers; this process listens
    on no port). Tried at once; if the router cannot be reached, ``warning`` says so and a thread
    tries again every ``RETRY_S`` until :meth:`close`."""

    def __init__(self, endpoint: str):
        self.endpoint = endpoint
        self.session = None
        self.warning: str | None = None
        self.up: bool | None = None  # None: not yet looked at
        self._polled = 0.0
        self._stop = threading.Event()
        self._thread = None
        try:
            self.session = self._open()
        except Exception as e:
            self.warning = (
                f"warning: cannot reach the ROS 2 router at {endpoint} ({str(e).split(' at ')[0]}): "
                f"{router.hint()}; the run goes on, and the ROS 2 view connects if a router comes up there"
            )
            self._thread = threading.Thread(target=self._retry, name="ros2-link", daemon=True)
            self._thread.start()

    def _open(self):
        return bus.open_session(
            connect=[self.endpoint], settings={"mode": "client"}, connect_timeout_s=CONNECT_TIMEOUT_S
        )

    def _retry(self) -> None:
        while not self._stop.wait(RETRY_S):
            try:
                session = self._open()
            except Exception:
                continue
            if self._stop.is_set():
                session.close()
            else:
                self.session = session
            return

    def poll(self) -> str | None:
        """ "lost" when the link to the router has gone down since the last call, "back" when it is
        up again (the client session reconnects by itself; declarations go to the new router)."""
        now = time.monotonic()
        if self.session is None or now - self._polled < LINK_POLL_S:
            return None
        self._polled = now
        up = bool(list(self.session.info.routers_zid()))
        if up == self.up:
            return None
        was, self.up = self.up, up
        return None if was is None else ("back" if up else "lost")

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=CONNECT_TIMEOUT_S + 1)
        if self.session is not None:
            self.session.close()


class RosPublishers:
    """The run's topics on a ROS 2 node (an rmw_zenoh.Node or an RclpyNode; None until there is
    one): a publisher per topic, made when the topic first has messages; the messages of a batch in
    time order. Every message counted in ``counts``: published, or dropped (no node or no link, a
    publish that raised). A latched topic's last message is kept to send again (:meth:`link_back`)."""

    def __init__(self, node, typestore, topics: list[str] | None, warn, counts: StreamCounts | None = None):
        self.node = node
        self.typestore = typestore
        self.wanted = set(topics) if topics is not None else None
        self.warn = warn
        self.counts = counts or StreamCounts()
        self.publishers: dict[str, object] = {}
        self.skipped: set[str] = set()
        self.latched: dict[str, tuple[object, bytes]] = {}  # topic name -> (RosTopic, its last message)
        self.resend: set[str] = set()  # latched topics to send again
        self.seen: set[str] = set()  # topics that had messages

    @property
    def sent(self) -> int:
        return sum(self.counts.published.values())

    def _wants(self, topic) -> bool:
        if topic.name in self.skipped:
            return False
        if topic.name not in self.publishers:
            if self.wanted is not None and topic.name not in self.wanted:
                self.skipped.add(topic.name)
                return False
            if problem := rmw_zenoh.check_topic_name(topic.name):
                self.warn(f"topic {topic.name} not published: ROS 2 rejects the name ({problem})")
                self.skipped.add(topic.name)
                return False
        return True

    def _publisher(self, topic):
        if topic.name not in self.publishers:
            # block: a batch's burst would overflow the link's queue and be dropped; waiting holds
            # up this process only, never the run (its rows come through a dropping publisher)
            self.publishers[topic.name] = self.node.publisher(
                topic.name, topic.msgtype, self.typestore, latched=topic.latched, block=True
            )
        return self.publishers[topic.name]

    def _put(self, topic, data: bytes) -> None:
        try:
            self._publisher(topic).put(data, time.time_ns())  # rmw_zenoh's source timestamp: the system clock
        except Stop:
            raise
        except Exception as e:  # a dead rclpy process, a closed session: this message is lost, the run goes on
            self.counts.drop(topic.name, FAILED)
            self.warn(f"publishing on {topic.name} failed ({type(e).__name__}); its messages are dropped (counted)")
        else:
            self.counts.sent(topic.name)

    def publish(self, batch, up: bool = True) -> None:
        """``batch``: [(RosTopic, [(stamp ns, CDR bytes)])] of :meth:`LiveTopics.batch`; ``up``:
        whether the link to the ROS side is (else the messages are dropped, counted)."""
        up = up and self.node is not None
        queue = []
        for topic, messages in batch:
            if not messages or not self._wants(topic):
                continue
            self.seen.add(topic.name)
            if topic.latched:
                self.latched[topic.name] = (topic, messages[-1][1])
                self.resend.discard(topic.name)
            if not up:
                self.counts.drop(topic.name, NO_LINK, len(messages))
                if topic.latched:
                    self.resend.add(topic.name)
                continue
            queue += [(ns, topic, data) for ns, data in messages]
        queue.sort(key=lambda item: item[0])  # stable: the exporter's topic order within a stamp
        for _, topic, data in queue:
            self._put(topic, data)

    def link_back(self) -> None:
        """The link came back: the volatile publishers are declared again, the latched topics go
        again (:meth:`resend_latched`)."""
        for publisher in self.publishers.values():
            redeclare = getattr(publisher, "declare_again", None)  # rmw_zenoh's; rclpy's child has its own link
            if redeclare is not None:
                redeclare()
        self.resend |= set(self.latched)

    def resend_latched(self) -> None:
        """Send each latched topic waiting for it once a subscription to it is known."""
        if self.node is None:
            return
        for name in sorted(self.resend):
            topic, data = self.latched[name]
            publisher = self._publisher(topic)
            if getattr(publisher, "has_subscribers", lambda: True)():
                self.resend.discard(name)
                self._put(topic, data)

    def missing(self) -> list[str]:
        """Topics asked for (``topics``) that the run has not had."""
        return sorted((self.wanted or set()) - self.seen)


class Ros2View(View):
    """The rows and frames as ROS 2 messages, published by a node on the ROS side (over rmw_zenoh's
    wire through its router, or with rclpy); every message counted in the report."""

    name = "ros2"

    def __init__(self, shell):
        super().__init__(shell)
        # the latched topics' AdvancedPublisher answers a late joiner from Zenoh's thread with congestion
        # control BLOCK: on bus.RUNTIME's one thread that wait stops the transmit that would end it
        bus.prefer_runtime(bus.RUNTIME_OWN_TX)
        self.counts = StreamCounts()
        self.link: RosLink | None = None
        self.node: RclpyNode | rmw_zenoh.Node | None = None
        self.publishers: RosPublishers | None = None  # made by prepare, before any step
        self.ros, self.report = shell.setup["ros2"], shell.setup.get("report")

    def alive_key(self, run_id: str) -> str:
        return bus.ros2_alive_key(run_id)

    def prepare(self) -> None:
        from rosbags.typesys import Stores, get_typestore

        from components.ros_topics import LiveTopics

        shell, ros = self.shell, self.ros
        typestore = get_typestore(Stores(DISTROS[ros["distro"]]))
        # camera frames from the bus (subscribed before the token: the run's first frames come)
        self.frames = shell.live_frames(typestore, ros.get("topics"))
        if ros.get("why"):
            self.log(ros["why"])
        if ros.get("transport") == RCLPY:  # up before the run starts: a node that cannot start stops it
            self.node = RclpyNode(ros["python"], ros["domain_id"], ros["node"], warn=shell.warn, discover_s=DISCOVER_S)
            self.log(
                f"publishing the run to ROS 2 (domain {ros['domain_id']}, {self.node.rmw}) with rclpy "
                f"as node /{ros['node']}"
            )
        else:
            self.link = RosLink(ros["endpoint"])
            if self.link.warning:
                self.log(self.link.warning)
        self.publishers = RosPublishers(self.node, typestore, ros.get("topics"), shell.warn, self.counts)
        self.live = LiveTopics(shell.config, shell.config_dir, shell.columns, typestore, shell.warn)

    def step(self, batch) -> None:
        ros, link, publishers, counts = self.ros, self.link, cast(RosPublishers, self.publishers), self.counts
        if self.node is None and link is not None and link.session is not None:
            self.node = publishers.node = rmw_zenoh.Node(link.session, ros["domain_id"], ros["node"])
            self.log(
                f"publishing the run to ROS 2 (domain {ros['domain_id']}) over rmw_zenoh's wire through "
                f"{ros['endpoint']} as node /{ros['node']}"
            )
        if link is not None and (change := link.poll()):
            if change == "lost":
                counts.links_lost += 1
                self.log(
                    f"the link to the ROS 2 router at {ros['endpoint']} is down: messages are dropped "
                    f"(counted) until it is back"
                )
            else:
                counts.links_back += 1
                self.log(f"the link to the ROS 2 router at {ros['endpoint']} is back: the stream resumes")
                publishers.link_back()
        up = link is None or link.up is not False
        if up:
            publishers.resend_latched()
        if batch is not None:
            _, times, rows = batch
            counts.rows += len(rows)
            publishers.publish(self.live.batch(times, rows)[0], up)  # without the router, dropped (counted)
        publishers.publish(self.frames.take(), up)

    def finish(self, ended: bool) -> None:
        publishers = cast(RosPublishers, self.publishers)
        if self.node is not None and (missing := publishers.missing()):
            self.log(
                f"ros2.topics: the run had no {', '.join(missing)} "
                f"(its topics: {', '.join(sorted(publishers.publishers)) or 'none'})"
            )
        if ended:
            self.log(f"run over: {publishers.sent} messages published on {len(publishers.publishers)} topics")

    def close(self, completed: bool) -> None:
        if self.report:  # what was delivered, for the orchestrator's summary
            try:
                self.counts.write(self.report)
            except OSError as e:
                self.log(f"cannot write {self.report}: {e}")
        if self.node is not None:
            self.node.close()
        if self.link is not None:
            self.link.close()


def main(argv: list[str] | None = None) -> int:
    return observer_shell.main(Ros2View, argv, "python -m components.ros2.observer", __doc__.splitlines()[0])


if __name__ == "__main__":
    sys.exit(main())
