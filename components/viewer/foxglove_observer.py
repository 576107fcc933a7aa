"""The Foxglove observer process: signal rows from the bus, served live over the Foxglove WebSocket
protocol (``foxglove-sdk``) with the topics of the rosbag2 export.

    python -m components.viewer.foxglove_observer --connect tcp/127.0.0.1:7447 --run-id demo-1a2b3c4d --setup viewer.json

Started by the orchestrator for ``--view foxglove[:PORT]`` (setup JSON as for
components/viewer/observer.py, plus ``port`` and ``linger``: keep serving after the run until the
orchestrator goes, when it runs at a terminal). It listens on ws://127.0.0.1:PORT (localhost only)
from the first batch of rows on: every channel exists before a client can subscribe. The
orchestrator checks that the port is free before the run (exit 2 if not); should it be taken in
between, the observer says so and exits, and the run goes on without the view.

Each batch of rows becomes a small :class:`RecordedRun` and goes through the rosbag2 exporter's
builders (:func:`components.rosbag.run_topics`): the same topics, message types and CDR bytes as
``orchestrator export --rosbag2`` writes for those rows, on ``ros2msg`` schema / ``cdr`` channels
(Foxglove reads ROS 2 messages without a ROS install). Latched topics (``/tf_static``,
``robot_description``) are built from the first batch and sent again whenever a client subscribes
to them: the server keeps no history. The meshes the robots' ``robot_description`` names
(``package://`` URIs as written) are served to Foxglove's 3D panel on request (the protocol's
``fetchAsset``); no other file is. Camera frames come from the bus as the cameras send them
(:class:`components.ros_frames.LiveFrames`: the export's Image and CameraInfo, stamped when taken)
on channels advertised from the start. Like the Rerun observer it runs niced and reads a dropping
publisher: a slow client never holds up a step (the server drops its oldest messages for it).
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import sys
import threading
import time
from pathlib import Path

import numpy as np

from components import bus, bus_security
from components.ros_topics import LiveTopics
from components.viewer.observer import (LIVE_BATCH_S, MAX_BATCH_ROWS, NICENESS, POLL_S, RowBuffer, Stop,
                                        orchestrator_gone, raise_stop, take_rows)

HOST = "127.0.0.1"
DISTRO = "ros2_jazzy"   # message definitions, as the rosbag2 export writes them


class ServeError(Exception):
    """The WebSocket server could not start (its port taken since the orchestrator checked it)."""


def log(message: str) -> None:
    print(f"viewer foxglove: {message}", file=sys.stderr, flush=True)


def port_problem(port: int) -> str | None:
    """Why the server could not listen on ``port`` (in use, not allowed), or None."""
    probe = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)   # as the server binds: TIME_WAIT is no conflict
    try:
        probe.bind((HOST, port))
    except OSError as e:
        return f"cannot listen on port {port} ({e.strerror}); choose another with --view foxglove:PORT"
    finally:
        probe.close()
    return None


class RosChannels:
    """Rows to ROS 2 messages (the rosbag2 exporter's builders) on Foxglove channels, one per topic."""

    def __init__(self, columns: list[str], config: dict, config_dir: str | None, context):
        from rosbags.typesys import Stores, get_typestore
        self.columns = columns
        self.config = config
        self.config_dir = Path(config_dir) if config_dir else None
        self.context = context
        self.typestore = get_typestore(Stores(DISTRO))
        self.channels: dict[str, object] = {}
        self.latched: dict[str, bytes] = {}        # topic -> its one message (sent again on subscribe)
        self.latched_ns: dict[str, int] = {}
        self.warned: set[str] = set()
        self.rows_sent = 0
        self.live = LiveTopics(config, config_dir, columns, self.typestore, self.warn)
        self.assets = self._assets()               # URI -> file: what robot_description references
        self._resend: set[str] = set()             # latched topics subscribed to since the last batch
        self.subscriptions: dict[str, int] = {}    # topic -> clients subscribed to it
        self._lock = threading.Lock()

    def warn(self, message: str) -> None:
        if message not in self.warned:             # the builders run per batch: say each thing once
            self.warned.add(message)
            log(message)

    def subscribed(self, topic: str) -> None:
        """A client subscribed (server thread): a latched topic's message goes out again."""
        with self._lock:
            self._resend.add(topic)
            self.subscriptions[topic] = self.subscriptions.get(topic, 0) + 1

    def unsubscribed(self, topic: str) -> None:
        with self._lock:
            self.subscriptions[topic] = self.subscriptions.get(topic, 1) - 1

    def watched(self, topics) -> bool:
        """Whether a client subscribes to one of ``topics``."""
        with self._lock:
            return any(self.subscriptions.get(topic, 0) > 0 for topic in topics)

    def _channel(self, topic: str, msgtype: str):
        if topic not in self.channels:
            from foxglove import Channel, Schema
            definition, _ = self.typestore.generate_msgdef(msgtype, ros_version=2)
            self.channels[topic] = Channel(topic, message_encoding="cdr", context=self.context,
                                           schema=Schema(name=msgtype, encoding="ros2msg",
                                                         data=definition.encode()))
        return self.channels[topic]

    def build(self, times, rows) -> tuple[list, int]:
        """The messages of a batch of rows as (log time = ROS stamp, channel, CDR bytes), in time
        order, and the last row's stamp (ns). Creates the channels of topics not seen before."""
        batch, stamp = self.live.batch(times, rows)
        self.rows_sent += len(times)
        return self.queue(batch), stamp

    def queue(self, batch) -> list:
        """[(RosTopic, [(stamp ns, CDR bytes)])] (rows' or frames') as (log time, channel, CDR bytes), in time order."""
        queue = []
        for topic, messages in batch:
            channel = self._channel(topic.name, topic.msgtype)
            if topic.latched and messages:
                self.latched_ns[topic.name], self.latched[topic.name] = messages[0]
            queue += [(ns, channel, data) for ns, data in messages]
        queue.sort(key=lambda item: item[0])   # stable: topics in the exporter's order within a stamp
        return queue

    def _assets(self) -> dict[str, Path]:
        from components.plotting import RecordedRun
        from components.rosbag import RosContext
        from components.ros_topics import run_assets

        run = RecordedRun(self.config, {}, np.zeros(1), self.config_dir)
        return run_assets(RosContext(run, self.typestore, self.warn), self.warn)

    def asset(self, uri: str) -> bytes | None:
        """A mesh a robot_description names (server thread, Foxglove's fetchAsset); None (not
        found) for any other URI: only the robots' own files are served."""
        path = self.assets.get(uri)
        return path.read_bytes() if path is not None else None

    @staticmethod
    def log(queue) -> None:
        for ns, channel, data in queue:
            channel.log(data, log_time=int(ns))

    def resend_latched(self) -> None:
        with self._lock:
            topics, self._resend = self._resend & self.latched.keys(), self._resend - self.latched.keys()
        for topic in topics:
            self.channels[topic].log(self.latched[topic], log_time=self.latched_ns[topic])


def _listener(channels: RosChannels):
    from foxglove.websocket import ServerListener

    class Subscriptions(ServerListener):
        def on_subscribe(self, client, channel) -> None:
            channels.subscribed(channel.topic)

        def on_unsubscribe(self, client, channel) -> None:
            channels.unsubscribed(channel.topic)

    return Subscriptions()


def observe(connect: str, run_id: str, setup: dict) -> int:
    """Serve the run until END (then, with a terminal, until Ctrl-C) or the orchestrator is gone."""
    import foxglove
    import zenoh

    from components.ros_frames import LiveFrames

    columns = list(setup["columns"])
    config = setup.get("config") or {}
    port = int(setup.get("port") or 8765)
    settings = bus_security.from_env()
    session = bus.open_view_session(connect, os.environ.get(bus.SECRET_ENV), settings)   # frames come from the mesh
    token = watcher = signals = server = frames = None
    try:
        signals = session.declare_subscriber(bus.signals_key(run_id), zenoh.handlers.FifoChannel(16384))
        watcher = session.liveliness().declare_subscriber(bus.orchestrator_alive_key(run_id),
                                                          zenoh.handlers.FifoChannel(16))
        channels = RosChannels(columns, config, setup.get("config_dir"), foxglove.Context())
        # camera frames from the bus, on channels made now (before the server: see below)
        frames = LiveFrames(session, run_id, config, setup.get("config_dir"), channels.typestore, channels.warn)
        for topic in frames.topics.values():
            channels._channel(topic.name, topic.msgtype)
        if unlinked := frames.wait_linked():
            channels.warn(f"no mesh link yet to {', '.join(unlinked)}: their first frames may be missing from the view")
        token = session.liveliness().declare_token(bus.viewer_alive_key(run_id))
        buffer = RowBuffer(len(columns))
        last_log = time.monotonic()
        ended = gone = False
        while not ended and not gone:
            ended, empty = take_rows(signals, buffer)
            now = time.monotonic()
            if buffer and (ended or now - last_log >= LIVE_BATCH_S or len(buffer) >= MAX_BATCH_ROWS):
                steps, times, rows = buffer.take()
                queue, stamp = channels.build(times, rows)
                if server is None:
                    # only now: every channel exists before a client can subscribe (foxglove-sdk
                    # 0.30 may answer "unknown channel" to a subscription racing an advertisement)
                    server = serve(channels, name=(config.get("run") or {}).get("name") or run_id, port=port)
                channels.log(queue)
                server.broadcast_time(stamp)
                last_log = now
            if channels.watched(frames.topics):   # till then the frames wait (LiveFrames.BACKLOG)
                channels.log(channels.queue(frames.take()))
            channels.resend_latched()
            gone = orchestrator_gone(watcher)
            if empty and not ended:
                time.sleep(POLL_S)
        if buffer.bad:
            log(f"ignored {buffer.bad} signal rows of an unexpected size (expected {buffer.size} bytes)")
        if summary := frames.summary():
            log(summary)
        if ended and not gone and setup.get("linger"):   # a terminal: until Ctrl-C (ViewerLink.stop)
            log(f"run over ({channels.rows_sent} rows sent); still serving until Ctrl-C")
            while not orchestrator_gone(watcher):
                channels.resend_latched()
                time.sleep(0.1)
    except Stop:
        pass
    finally:
        for declared in (token, watcher, signals, frames):
            if declared is not None:
                try:
                    declared.undeclare()
                except Exception:
                    pass
        session.close()
        if server is not None:
            server.stop()
    return 0


def serve(channels: RosChannels, name: str, port: int):
    """Start the WebSocket server on the channels' context; raises ServeError naming the port."""
    import foxglove
    try:
        server = foxglove.start_server(name=name, host=HOST, port=port, context=channels.context,
                                       server_listener=_listener(channels), capabilities=[foxglove.Capability.Time],
                                       asset_handler=channels.asset)
    except RuntimeError as e:
        raise ServeError(f"cannot listen on port {port}: {e}") from None
    log(f"serving the run on ws://localhost:{server.port} (Foxglove: Open connection, Foxglove WebSocket)")
    return server


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m components.viewer.foxglove_observer",
                                     description=__doc__.splitlines()[0])
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
    except ServeError as e:   # the run goes on without the view
        log(str(e))
        return 2
    except Exception as e:  # one line, not a traceback; the run goes on without the viewer
        log(f"stopped: {type(e).__name__}: {e}")
        return 1


if __name__ == "__main__":
    sys.exit(main())
