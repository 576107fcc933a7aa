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
on channels advertised from the start. It runs in the observer shell (components/observer_shell.py),
niced, reading a dropping publisher: a slow client never holds up a step (the server drops its
oldest messages for it).
"""

from __future__ import annotations

import socket
import sys
import threading
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from components import observer_shell
from components.observer_shell import View, ViewError, logger, once
from components.ros_topics import LiveTopics

if TYPE_CHECKING:
    from foxglove import Channel

HOST = "127.0.0.1"
DISTRO = "ros2_jazzy"  # message definitions, as the rosbag2 export writes them

log = logger("viewer foxglove")


def port_problem(port: int) -> str | None:
    """Why the server could not listen on ``port`` (in use, not allowed), or None."""
    probe = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the server binds: TIME_WAIT is no conflict
    try:
        probe.bind((HOST, port))
    except OSError as e:
        return f"cannot listen on port {port} ({e.strerror}); choose another with --view foxglove:PORT"
    finally:
        probe.close()
    return None


class RosChannels:
    """Rows to ROS 2 messages (the rosbag2 exporter's builders) on Foxglove channels, one per topic."""

    def __init__(self, columns: list[str], config: dict, config_dir: str | None, context, warn=None):
        from rosbags.typesys import Stores, get_typestore

        self.columns = columns
        self.config = config
        self.config_dir = Path(config_dir) if config_dir else None
        self.context = context
        self.typestore = get_typestore(Stores(DISTRO))
        self.channels: dict[str, Channel] = {}
        self.latched: dict[str, bytes] = {}  # topic -> its one message (sent again on subscribe)
        self.latched_ns: dict[str, int] = {}
        self.warn = warn or once(log)  # the builders run per batch: say each thing once
        self.rows_sent = 0
        self.live = LiveTopics(config, config_dir, columns, self.typestore, self.warn)
        self.assets = self._assets()  # URI -> file: what robot_description references
        self._resend: set[str] = set()  # latched topics subscribed to since the last batch
        self.subscriptions: dict[str, int] = {}  # topic -> clients subscribed to it
        self._lock = threading.Lock()

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
            self.channels[topic] = Channel(
                topic,
                message_encoding="cdr",
                context=self.context,
                schema=Schema(name=msgtype, encoding="ros2msg", data=definition.encode()),
            )
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
        queue.sort(key=lambda item: item[0])  # stable: topics in the exporter's order within a stamp
        return queue

    def _assets(self) -> dict[str, Path]:
        from components.plotting import RecordedRun
        from components.ros_topics import run_assets
        from components.rosbag import RosContext

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


class FoxgloveView(View):
    """The rows and frames as ROS 2 messages on a Foxglove WebSocket server, from the first batch on."""

    name = "viewer foxglove"

    def __init__(self, shell):
        super().__init__(shell)
        self.server = None

    def prepare(self) -> None:
        import foxglove

        shell = self.shell
        self.port = int(shell.setup.get("port") or 8765)
        self.lingers = shell.setup.get("linger")
        self.run_name = (shell.config.get("run") or {}).get("name") or shell.run_id
        self.channels = RosChannels(shell.columns, shell.config, shell.config_dir, foxglove.Context(), shell.warn)
        # camera frames from the bus, on channels made now (before the server: see step)
        self.frames = shell.live_frames(self.channels.typestore)
        for topic in self.frames.topics.values():
            self.channels._channel(topic.name, topic.msgtype)

    def step(self, batch) -> None:
        channels = self.channels
        if batch is not None:
            _, times, rows = batch
            queue, stamp = channels.build(times, rows)
            if self.server is None:
                # only now: every channel exists before a client can subscribe (foxglove-sdk
                # 0.30 may answer "unknown channel" to a subscription racing an advertisement)
                self.server = serve(channels, name=self.run_name, port=self.port)
            channels.log(queue)
            self.server.broadcast_time(stamp)
        if channels.watched(self.frames.topics):  # till then the frames wait (LiveFrames.BACKLOG)
            channels.log(channels.queue(self.frames.take()))
        channels.resend_latched()

    def linger(self) -> str | None:  # a terminal: until Ctrl-C (ViewerLink.stop)
        return f"run over ({self.channels.rows_sent} rows sent); still serving until Ctrl-C" if self.lingers else None

    def close(self, completed: bool) -> None:
        if self.server is not None:
            self.server.stop()


def serve(channels: RosChannels, name: str, port: int):
    """Start the WebSocket server on the channels' context; raises ViewError naming the port (its
    port taken since the orchestrator checked it: exit 2, the run goes on without the view)."""
    import foxglove

    try:
        server = foxglove.start_server(
            name=name,
            host=HOST,
            port=port,
            context=channels.context,
            server_listener=_listener(channels),
            capabilities=[foxglove.Capability.Time],
            asset_handler=channels.asset,
        )
    except RuntimeError as e:
        raise ViewError(f"cannot listen on port {port}: {e}", 2) from None
    log(f"serving the run on ws://localhost:{server.port} (Foxglove: Open connection, Foxglove WebSocket)")
    return server


def main(argv: list[str] | None = None) -> int:
    return observer_shell.main(
        FoxgloveView, argv, "python -m components.viewer.foxglove_observer", __doc__.splitlines()[0]
    )


if __name__ == "__main__":
    sys.exit(main())
