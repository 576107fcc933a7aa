"""The ROS 2 observer process: signal rows from the run's bus, published live to ROS 2 over
rmw_zenoh (``orchestrator run CFG --ros2 [ENDPOINT]`` or a ``ros2:`` config section).

    python -m components.ros2.observer --connect tcp/127.0.0.1:7447 --run-id demo-1a2b3c4d --setup ros2.json

Started by the orchestrator, like the live viewers (components/viewer/observer.py): it subscribes
to the run's signal rows (a dropping publisher, so it never holds up a step), runs niced, declares
its liveliness token ``alive/_ros2/0`` at once, and leaves at the run's END or when the
orchestrator goes. The setup JSON: ``columns``, ``config`` (resolved), ``config_dir``, and
``ros2``: ``endpoint`` (the ROS side's router, rmw_zenohd), ``domain_id``, ``distro``, ``topics``
(None: all), ``node`` (the node's name).

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

import argparse
import json
import os
import signal
import sys
import threading
import time
from pathlib import Path

from components import bus, bus_security
from components.ros2 import rmw_zenoh, router
from components.ros2.stream_report import FAILED, NO_LINK, StreamCounts
from components.ros2.rclpy_transport import RCLPY, RclpyNode
from components.viewer.observer import (LIVE_BATCH_S, MAX_BATCH_ROWS, NICENESS, POLL_S, RowBuffer, Stop,
                                        orchestrator_gone, raise_stop, take_rows)

CONNECT_TIMEOUT_S = 3.0   # how long a link to the ROS router may take to come up
LINK_POLL_S = 0.1         # how often the link's state is looked at
RETRY_S = 2.0             # between tries when it did not
DISCOVER_S = 3.0          # rclpy: at most this long for DDS discovery before the run starts (rclpy_side.discover)
DISTROS = {"jazzy": "ros2_jazzy", "kilted": "ros2_kilted", "lyrical": "ros2_lyrical"}   # rmw_zenoh with type hashes


def log(message: str) -> None:
    print(f"ros2: {message}", file=sys.stderr, flush=True)


class RosLink:
    """The session to the ROS side's router at ``endpoint``: a Zenoh client of it (the router
    routes a client's samples, tokens and queries to the ROS nodes, its peers; this process listens
    on no port). Tried at once; if the router cannot be reached, ``warning`` says so and a thread
    tries again every ``RETRY_S`` until :meth:`close`."""

    def __init__(self, endpoint: str):
        self.endpoint = endpoint
        self.session = None
        self.warning: str | None = None
        self.up: bool | None = None   # None: not yet looked at
        self._polled = 0.0
        self._stop = threading.Event()
        self._thread = None
        try:
            self.session = self._open()
        except Exception as e:
            self.warning = (f"warning: cannot reach the ROS 2 router at {endpoint} ({str(e).split(' at ')[0]}): "
                            f"{router.hint()}; the run goes on, and the ROS 2 view connects if a router comes up there")
            self._thread = threading.Thread(target=self._retry, name="ros2-link", daemon=True)
            self._thread.start()

    def _open(self):
        return bus.open_session(connect=[self.endpoint], settings={"mode": "client"},
                                connect_timeout_s=CONNECT_TIMEOUT_S)

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
        """"lost" when the link to the router has gone down since the last call, "back" when it is
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
        self.latched: dict[str, tuple[object, bytes]] = {}   # topic name -> (RosTopic, its last message)
        self.resend: set[str] = set()                        # latched topics to send again
        self.seen: set[str] = set()                          # topics that had messages

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
            self.publishers[topic.name] = self.node.publisher(topic.name, topic.msgtype, self.typestore,
                                                              latched=topic.latched, block=True)
        return self.publishers[topic.name]

    def _put(self, topic, data: bytes) -> None:
        try:
            self._publisher(topic).put(data, time.time_ns())   # rmw_zenoh's source timestamp: the system clock
        except Stop:
            raise
        except Exception as e:   # a dead rclpy process, a closed session: this message is lost, the run goes on
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
        queue.sort(key=lambda item: item[0])   # stable: the exporter's topic order within a stamp
        for _, topic, data in queue:
            self._put(topic, data)

    def link_back(self) -> None:
        """The link came back: the latched topics go again (:meth:`resend_latched`)."""
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


def observe(connect: str, run_id: str, setup: dict) -> int:
    """Publish the run to ROS 2 until END or the orchestrator is gone."""
    import zenoh
    from rosbags.typesys import Stores, get_typestore

    from components.ros_frames import LiveFrames
    from components.ros_topics import LiveTopics

    columns = list(setup["columns"])
    config = setup.get("config") or {}
    ros = setup["ros2"]
    warned: set[str] = set()

    def warn(message: str) -> None:
        if message not in warned:   # the builders run per batch: say each thing once
            warned.add(message)
            log(message)

    # the latched topics' AdvancedPublisher answers a late joiner from Zenoh's thread with congestion
    # control BLOCK: on bus.RUNTIME's one thread that wait stops the transmit that would end it
    bus.prefer_runtime(bus.RUNTIME_OWN_TX)
    counts = StreamCounts()
    session = bus.open_view_session(connect, os.environ.get(bus.SECRET_ENV), bus_security.from_env())   # frames: from the mesh
    token = watcher = signals = link = node = publishers = frames = None
    try:
        signals = session.declare_subscriber(bus.signals_key(run_id), zenoh.handlers.FifoChannel(16384))
        watcher = session.liveliness().declare_subscriber(bus.orchestrator_alive_key(run_id),
                                                          zenoh.handlers.FifoChannel(16))
        typestore = get_typestore(Stores(DISTROS[ros["distro"]]))
        # camera frames from the bus (subscribed before the token: the run's first frames come)
        frames = LiveFrames(session, run_id, config, setup.get("config_dir"), typestore, warn, ros.get("topics"))
        if ros.get("why"):
            log(ros["why"])
        if ros.get("transport") == RCLPY:   # up before the run starts: a node that cannot start stops it
            node = RclpyNode(ros["python"], ros["domain_id"], ros["node"], warn=warn, discover_s=DISCOVER_S)
            log(f"publishing the run to ROS 2 (domain {ros['domain_id']}, {node.rmw}) with rclpy as node /{ros['node']}")
        else:
            link = RosLink(ros["endpoint"])
            if link.warning:
                log(link.warning)
        publishers = RosPublishers(node, typestore, ros.get("topics"), warn, counts)
        live = LiveTopics(config, setup.get("config_dir"), columns, typestore, warn)
        if unlinked := frames.wait_linked():
            warn(f"no mesh link yet to {', '.join(unlinked)}: their first frames may be missing from the view")
        token = session.liveliness().declare_token(bus.ros2_alive_key(run_id))   # rows wait in the FIFO from here
        buffer = RowBuffer(len(columns))
        last = time.monotonic()
        ended = gone = False
        while not ended and not gone:
            ended, empty = take_rows(signals, buffer)
            if node is None and link is not None and link.session is not None:
                node = rmw_zenoh.Node(link.session, ros["domain_id"], ros["node"])
                log(f"publishing the run to ROS 2 (domain {ros['domain_id']}) over rmw_zenoh's wire through "
                    f"{ros['endpoint']} as node /{ros['node']}")
                publishers.node = node
            if link is not None and (change := link.poll()):
                if change == "lost":
                    counts.links_lost += 1
                    log(f"the link to the ROS 2 router at {ros['endpoint']} is down: messages are dropped "
                        f"(counted) until it is back")
                else:
                    counts.links_back += 1
                    log(f"the link to the ROS 2 router at {ros['endpoint']} is back: the stream resumes")
                    publishers.link_back()
            up = link is None or link.up is not False
            if up:
                publishers.resend_latched()
            now = time.monotonic()
            if buffer and (ended or now - last >= LIVE_BATCH_S or len(buffer) >= MAX_BATCH_ROWS):
                _, times, rows = buffer.take()
                counts.rows += len(rows)
                publishers.publish(live.batch(times, rows)[0], up)   # without the router, dropped (counted)
                last = now
            publishers.publish(frames.take(), up)
            gone = orchestrator_gone(watcher)
            if empty and not ended:
                time.sleep(POLL_S)
        if buffer.bad:
            log(f"ignored {buffer.bad} signal rows of an unexpected size (expected {buffer.size} bytes)")
        if summary := frames.summary():
            log(summary)
        if node is not None and (missing := publishers.missing()):
            log(f"ros2.topics: the run had no {', '.join(missing)} "
                f"(its topics: {', '.join(sorted(publishers.publishers)) or 'none'})")
        if ended:
            log(f"run over: {publishers.sent} messages published on {len(publishers.publishers)} topics")
    except Stop:
        pass
    finally:
        if setup.get("report"):   # what was delivered, for the orchestrator's summary
            try:
                counts.write(setup["report"])
            except OSError as e:
                log(f"cannot write {setup['report']}: {e}")
        if node is not None:
            node.close()
        if link is not None:
            link.close()
        for declared in (token, watcher, signals, frames):
            if declared is not None:
                try:
                    declared.undeclare()
                except Exception:
                    pass
        session.close()
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m components.ros2.observer", description=__doc__.splitlines()[0])
    parser.add_argument("--connect", required=True, help="the orchestrator's Zenoh endpoint, e.g. tcp/127.0.0.1:7447")
    parser.add_argument("--run-id", required=True)
    parser.add_argument("--setup", required=True, help="the JSON file the orchestrator wrote")
    args = parser.parse_args(argv)
    signal.signal(signal.SIGTERM, raise_stop)
    signal.signal(signal.SIGINT, raise_stop)
    try:
        os.nice(NICENESS)   # best effort: on a busy machine the lockstep processes go first
    except (AttributeError, OSError):
        pass
    try:
        setup = json.loads(Path(args.setup).read_text())
    except (OSError, ValueError) as e:
        log(f"cannot read the setup file {args.setup}: {e}")
        return 2
    try:
        return observe(args.connect, args.run_id, setup)
    except Stop:
        return 0
    except Exception as e:  # one line, not a traceback; the run goes on without the ROS 2 view
        log(f"stopped: {type(e).__name__}: {e}")
        return 1


if __name__ == "__main__":
    sys.exit(main())
