"""The live views' camera frames: frame outputs from the bus (``v/<component>/<output>``, sent by
:class:`components.live_frames.LiveFrameSender` only while a view subscribes), as the ROS 2 messages of the
rosbag2 export (``RosExport.frames``: sensor.camera's Image and CameraInfo, CDR bytes).

A subscriber per frame output keeps the messages as they come (Zenoh's thread only stores them,
at most ``BACKLOG`` per output); :meth:`LiveFrames.take`, on the view's own thread, builds the
messages of what came since the last call. A view slower than the camera for long skips the
oldest frames (``skipped``); the run never waits for it (the cameras' publishers drop). A frame
no later than the last one taken of its output (seen once on a loaded machine: the same frame
twice) is not shown again (``repeated``).
"""

from __future__ import annotations

import collections
import threading
from collections.abc import Callable
from pathlib import Path

import numpy as np

from components import bus, protocol, registry
from components.errors import ConfigError
from components.rosbag import FrameTopics, RosContext, RosTopic

BACKLOG = 16  # frames kept per output until the view takes them (bursts pass; a view behind for long skips)
LINK_WAIT_S = 10.0  # at most this long before the run starts for the mesh links to the frames' components


def frame_topics(context: RosContext) -> dict[str, FrameTopics]:
    """{component: its FrameTopics} of the run's component types that declare ``rosbag.frames``."""
    found = {}
    for name, spec in (context.run.config.get("components") or {}).items():
        try:
            cls = registry.load((spec or {}).get("type"), context.run.config_dir)
        except ConfigError:
            continue  # the views' row topics say so
        if cls.rosbag is not None and cls.rosbag.frames is not None:
            topics = cls.rosbag.frames(context, name)
            if topics is not None:
                found[name] = topics
    return found


class LiveFrames:
    """The run's frame outputs as ROS 2 messages. ``topics``: only the outputs with a topic among
    them are subscribed to (None: all); ``topics_of`` lists every topic they go on."""

    def __init__(
        self,
        session,
        run_id: str,
        config: dict,
        config_dir,
        typestore,
        warn: Callable[[str], None],
        topics: list[str] | None = None,
    ):
        from components.plotting import RecordedRun

        self.typestore = typestore
        run = RecordedRun(config, {}, np.zeros(1), Path(config_dir) if config_dir else None)
        self.context = RosContext(run, typestore, warn)
        self.specs = frame_topics(self.context)
        wanted = set(topics) if topics is not None else None
        self.topics: dict[str, RosTopic] = {}
        self._waiting: dict[tuple[str, str], collections.deque] = {}  # (component, output) -> messages
        self._lock = threading.Lock()
        self.received = self.skipped = self.bad = self.published = self.repeated = 0
        self._last_ns: dict[tuple[str, str], int] = {}  # (component, output) -> the latest frame's time taken
        self._outputs: list[tuple[str, str]] = []  # (component, output) subscribed to
        self.subscribers = []
        self.session, self.run_id = session, run_id
        for component, spec in self.specs.items():
            for output, output_topics in spec.outputs.items():
                if wanted is not None and not wanted & {t.name for t in output_topics}:
                    continue  # nobody asked for it: not subscribed, so the camera sends nothing
                self.topics.update((t.name, t) for t in output_topics)
                self._outputs.append((component, output))
                self.subscribers.append(
                    session.declare_subscriber(bus.view_key(run_id, component, output), self._keeper(component, output))
                )

    def wait_linked(self, timeout_s: float = LINK_WAIT_S) -> list[str]:
        """Wait until the view is linked to every component whose frames it subscribes to; the
        components not linked by ``timeout_s`` (their first frames may be missing).

        Frames go straight from a component to the view (peers do not route for each other), over a
        link the mesh makes after the view joins; a frame sent before it reaches nobody. A
        component's liveliness token reaches the view over that same link (in client mode, over the
        router that also carries its frames), so seeing it means the frames can come. Called before
        the view's own token, which the orchestrator waits for before the first step."""
        import time

        import zenoh

        wanted = {component for component, _ in self._outputs}
        if not wanted:
            return []
        seen: set[str] = set()
        arrived = threading.Condition()

        def token(sample) -> None:
            fields = protocol.ALIVE.fields(str(sample.key_expr))
            if fields and sample.kind == zenoh.SampleKind.PUT:
                with arrived:
                    seen.add(fields["name"])
                    arrived.notify_all()

        subscriber = self.session.liveliness().declare_subscriber(
            protocol.ALIVE.pattern(self.run_id), token, history=True
        )
        try:
            deadline = time.monotonic() + timeout_s
            with arrived:
                while not wanted <= seen and (left := deadline - time.monotonic()) > 0:
                    arrived.wait(left)
                return sorted(wanted - seen)
        finally:
            subscriber.undeclare()

    def _keeper(self, component: str, output: str):
        def keep(sample) -> None:
            payload = sample.payload.to_bytes()
            with self._lock:
                self.received += 1
                waiting = self._waiting.setdefault((component, output), collections.deque(maxlen=BACKLOG))
                self.skipped += len(waiting) == BACKLOG  # the oldest goes: the view fell behind
                waiting.append(payload)

        return keep

    def take(self) -> list[tuple[RosTopic, list[tuple[int, bytes]]]]:
        """The frames come since the last call, as (topic, [(stamp ns, CDR bytes)]), topics in the
        order of ``outputs`` (an image before its camera_info)."""
        with self._lock:
            waiting, self._waiting = self._waiting, {}
        batch: dict[str, tuple[RosTopic, list]] = {}
        for (component, output), payload in ((key, p) for key, queue in waiting.items() for p in queue):
            try:
                taken_ns, _, _, name, frame = bus.decode_view_frame(payload)
            except bus.Malformed:
                self.bad += 1
                continue
            if name != output:
                self.bad += 1
                continue
            if taken_ns <= self._last_ns.get((component, output), -1):
                self.repeated += 1  # a frame again, or an older one after it: a view shows each once, in order
                continue
            self._last_ns[component, output] = taken_ns
            ns = self.context.epoch_ns + taken_ns
            for topic, message in self.specs[component].messages(output, ns, frame):
                data = bytes(self.typestore.serialize_cdr(message, topic.msgtype))
                batch.setdefault(topic.name, (topic, []))[1].append((ns, data))
                self.published += 1
        return list(batch.values())

    def summary(self) -> str | None:
        """A line on the frames the view did not show, or None when it showed every one it got."""
        if not (self.skipped or self.repeated or self.bad):
            return None
        return (
            f"camera frames: {self.received} received, {self.skipped} skipped (the view fell behind), "
            f"{self.repeated} repeated or late (not shown again), {self.bad} malformed"
        )

    def undeclare(self) -> None:
        for subscriber in self.subscribers:
            try:
                subscriber.undeclare()
            except Exception:  # the session is gone: so is it
                pass
        self.subscribers = []
