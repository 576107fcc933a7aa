"""What a component type exports as ROS 2 messages (its ``rosbag``): the :class:`RosExport` a type
declares, the :class:`RosTopic` it fills, and the :class:`RosContext` it builds messages with.
``orchestrator export DIR --rosbag2 OUT`` (orchestrator/export/rosbag2.py) writes the topics of the
types in the recording; a type without ``rosbag`` exports nothing (the exporter names it).

Conventions every builder follows (docs/guides/ros2.md):

- stamps: ``run.epoch + t`` as ROS time (UTC, sec + nanosec since 1970, leap seconds not counted),
  t rounded to the nanosecond; a message's log time in the bag is its row's stamp;
- frames: ``eci`` (the root), ``<orbit>/lvlh``, ``<dynamics>/world`` (W), ``<dynamics>/<body>/<link>``,
  ``<sensor>`` (a sensor component's frame); see :func:`link_frame`;
- values: copied from the recording (float64 to float64), quaternions [x, y, z, w] as recorded.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from components.plotting import RecordedRun

ROOT_FRAME = "eci"


def link_frame(dynamics: str, body: str, link: str) -> str:
    """The tf frame of a body's link: ``<dynamics>/<body>/<link>``."""
    return f"{dynamics}/{body}/{link}"


def world_frame(dynamics: str) -> str:
    """The tf frame of a dynamics component's world frame W: ``<dynamics>/world``."""
    return f"{dynamics}/world"


def lvlh_frame(orbit: str) -> str:
    """The tf frame of an orbit component's LVLH frame: ``<orbit>/lvlh``."""
    return f"{orbit}/lvlh"


class LazyMessages(Sequence):
    """A topic's messages built one at a time when read: ``length`` of them, the k-th from
    ``build(k)`` -> (log time ns, message), in time order. The export writes each and drops it, so
    a recording's camera frames (2 MB each uncompressed) are never all in memory at once."""

    def __init__(self, length: int, build: Callable[[int], tuple[int, object]]):
        self.length, self.build = length, build

    def __len__(self) -> int:
        return self.length

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self.build(i) for i in range(*k.indices(self.length))]
        if not -self.length <= k < self.length:
            raise IndexError(f"message {k} of {self.length}")
        return self.build(k % self.length)

    def __iter__(self) -> Iterator[tuple[int, object]]:
        return (self.build(k) for k in range(self.length))


@dataclass
class RosTopic:
    """One topic of the bag: ``name`` (``/dynamics/humanoid/joint_states``), ``msgtype``
    (``sensor_msgs/msg/JointState``), ``messages`` as (log time ns, message), a list or, for
    messages too big to hold together, :class:`LazyMessages` (already in time order); ``latched``:
    offered with transient-local durability, depth 1 (``/tf_static``, ``robot_description``)."""

    name: str
    msgtype: str
    messages: list[tuple[int, object]] | LazyMessages = field(default_factory=list)
    latched: bool = False


@dataclass(frozen=True)
class RosExport:
    """The ROS 2 messages a component type exports from a recording.

    ``description``: one line for the docs' table. ``topics(context, c)``: the :class:`RosTopic` s of
    component ``c``; transforms for ``/tf`` and ``/tf_static`` are topics of those names (the
    exporter merges the components' into one topic each). Empty when the recording holds nothing
    it exports. ``output_frames(context, c)``: {output variable: tf frame it is measured in}, for
    the sensors that read it (their frame is mounted there, see :meth:`RosContext.mount_of`).
    ``assets(context, c)``: {URI as its messages name it: the file}, the files a viewer fetches to
    draw them (the meshes a ``robot_description`` references); served by the live Foxglove view.
    ``frames(context, c)``: the :class:`FrameTopics` of component ``c``'s frame outputs, which the
    live views (``--ros2``, ``--view foxglove``) publish from the bus as they come (None: none).
    """

    description: str
    topics: Callable[[RosContext, str], Iterable[RosTopic]]
    output_frames: Callable[[RosContext, str], dict[str, str]] | None = None
    assets: Callable[[RosContext, str], dict[str, Path]] | None = None
    frames: Callable[[RosContext, str], FrameTopics | None] | None = None


@dataclass
class FrameTopics:
    """A component's frame outputs as live ROS 2 topics: ``outputs`` {frame output: the topics
    (no messages) its frames go on}; ``messages(output, stamp ns, frame)`` -> [(RosTopic, message)],
    the messages of one frame, as the export builds them from the recorded frame."""

    outputs: dict[str, list[RosTopic]]
    messages: Callable[[str, int, np.ndarray], list[tuple[RosTopic, object]]]


class TopicError(Exception):
    """Two component types put different message types on one topic."""


class RosContext:
    """A recording as the builders see it: ``run`` (:class:`RecordedRun`), ``stamps`` (ns per row,
    ROS time), the message classes (``msg("sensor_msgs/msg/Imu")``) and helpers for common parts."""

    def __init__(self, run: RecordedRun, typestore, warn: Callable[[str], None]):
        self.run = run
        self.typestore = typestore
        self.warn = warn
        self.epoch_ns = epoch_ns((run.config.get("run") or {}).get("epoch"))
        self.stamps = self.epoch_ns + np.rint(run.time * 1e9).astype(np.int64)
        self.output_frames: dict[str, str] = {}  # "<component>.<variable>" -> frame (RosExport.output_frames)

    def mount_of(self, component: str, variable: str) -> str | None:
        """The frame the output feeding ``component.variable`` is measured in, if a type said so."""
        source = self.run.source(component, variable)
        return self.output_frames.get(source) if source else None

    def msg(self, msgtype: str):
        return self.typestore.types[msgtype]

    def stamp_of(self, t: float) -> int:
        """ROS time (ns) of simulation time ``t`` (s)."""
        return self.epoch_ns + int(np.rint(t * 1e9))

    def time(self, ns: int):
        return self.msg("builtin_interfaces/msg/Time")(sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000))

    def header(self, ns: int, frame_id: str):
        return self.msg("std_msgs/msg/Header")(stamp=self.time(ns), frame_id=frame_id)

    def vector3(self, xyz):
        return self.msg("geometry_msgs/msg/Vector3")(x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2]))

    def point(self, xyz):
        return self.msg("geometry_msgs/msg/Point")(x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2]))

    def quaternion(self, xyzw):
        return self.msg("geometry_msgs/msg/Quaternion")(
            x=float(xyzw[0]), y=float(xyzw[1]), z=float(xyzw[2]), w=float(xyzw[3])
        )

    def transform(self, ns: int, parent: str, child: str, translation, rotation_xyzw):
        """geometry_msgs/TransformStamped: ``child`` in ``parent`` (m; quaternion [x, y, z, w])."""
        return self.msg("geometry_msgs/msg/TransformStamped")(
            header=self.header(ns, parent),
            child_frame_id=child,
            transform=self.msg("geometry_msgs/msg/Transform")(
                translation=self.vector3(translation), rotation=self.quaternion(rotation_xyzw)
            ),
        )

    def tf(self, transforms: list):
        return self.msg("tf2_msgs/msg/TFMessage")(transforms=transforms)


def epoch_ns(epoch) -> int:
    """``run.epoch`` (ISO 8601 UTC, e.g. 2022-09-18T12:00:00Z) as ns since 1970-01-01 UTC; 0 when absent."""
    if epoch in (None, ""):
        return 0
    moment = datetime.fromisoformat(str(epoch).replace("Z", "+00:00"))
    if moment.tzinfo is None:
        moment = moment.replace(tzinfo=UTC)
    delta = moment - datetime(1970, 1, 1, tzinfo=UTC)
    return (delta.days * 86_400 + delta.seconds) * 1_000_000_000 + delta.microseconds * 1_000


def source_of(run: RecordedRun, component: str, variable: str) -> tuple[str, str] | None:
    """The output feeding ``component.variable`` as (component, variable), if connected."""
    source = run.source(component, variable)
    if not source or "." not in source:
        return None
    owner, _, name = source.partition(".")
    return owner, name


def measurement_rows(valid: np.ndarray, t_measured: np.ndarray) -> list[int]:
    """Rows where a new measurement comes out: valid, and t_measured unlike the previous one's."""
    rows, last = [], None
    for row, (ok, t) in enumerate(zip(valid, t_measured)):
        if ok and t != last:
            rows.append(row)
            last = t
    return rows
