"""A recording as a rosbag2 folder with MCAP storage (``orchestrator export DIR --rosbag2 OUT``).

``export_rosbag2(record_dir, out)`` reads ``DIR/signals.parquet`` and ``DIR/config.yaml``
(docs/design.md §6) and writes ``OUT/metadata.yaml`` and ``OUT/<name>_0.mcap`` (rosbag2 format
version 9, ROS 2 Jazzy message definitions and their RIHS01 type hashes) with the `rosbags` library:

- ``/clock`` (rosgraph_msgs/Clock): the simulation time of each row, as ROS time ``run.epoch + t``;
- what each component's type declares (its ``rosbag``, :class:`components.rosbag.RosExport`): the
  components' ``/tf`` messages go out on one ``/tf`` topic, their ``/tf_static`` transforms as one
  message (a late subscriber gets only the last message of a transient-local topic);
- a component whose type declares nothing exports nothing (``warn`` names it), unless
  ``all_signals``: then each of its recorded variables goes out as std_msgs/Float64MultiArray on
  ``/<component>/<variable>`` per row (that message has no header: its time is the log time).

Every message's log time is its header's stamp (``/tf_static`` and ``robot_description``: the
first row's). Topics that are transient local (``latched``) say so in their offered QoS profile.
"""

from __future__ import annotations

import heapq
import shutil
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from components.ros_topics import run_topics
from components.rosbag import RosContext, RosTopic, TopicError

DISTRO = "ros2_jazzy"  # message definitions and type hashes (rosbags' typestore)
BAG_VERSION: Final = 9  # rosbag2's metadata.yaml version (Jazzy)


class ExportError(Exception):
    """A recording that cannot be exported, or an OUT that must not be written."""


@dataclass
class Exported:
    """What was written: the bag's folder, messages per topic, the bag's size (bytes)."""

    path: Path
    counts: dict[str, int]
    size: int


def _qos(latched: bool):
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    never = QosTime(sec=0x7FFFFFFF, nsec=0xFFFFFFFF)  # rclcpp's "infinite" duration
    return Qos(
        history=QosHistory.KEEP_LAST,
        depth=1 if latched else 10,
        reliability=QosReliability.RELIABLE,
        durability=QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE,
        deadline=never,
        lifespan=never,
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=never,
        avoid_ros_namespace_conventions=False,
    )


def _stream(topic: RosTopic, order: int, connection):
    """The topic's messages as (ns, order, k, connection, msgtype, message), in time order."""
    for k, (ns, message) in enumerate(topic.messages):
        yield ns, order, k, connection, topic.msgtype, message


def _write(path: Path, topics: list[RosTopic], typestore) -> None:
    """The topics' messages in (time, topic, index) order, merged as they are read: a topic of
    :class:`~components.rosbag.LazyMessages` has one message in memory at a time."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    with Writer(path, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP) as writer:
        streams = []
        for order, topic in enumerate(topics):
            connection = writer.add_connection(
                topic.name, topic.msgtype, typestore=typestore, offered_qos_profiles=[_qos(topic.latched)]
            )
            streams.append(_stream(topic, order, connection))
        for ns, _, _, connection, msgtype, message in heapq.merge(*streams, key=lambda item: item[:3]):
            writer.write(connection, ns, typestore.serialize_cdr(message, msgtype))
    _name_distro(path / "metadata.yaml", DISTRO.removeprefix("ros2_"))


def _name_distro(metadata: Path, distro: str) -> None:
    """rosbags writes ``ros_distro: rosbags``; rosbag2 writes the distro the bag's types are from."""
    text = metadata.read_text()
    written = "  ros_distro: rosbags\n"
    if written not in text:
        raise ExportError(f"{metadata}: expected rosbags' line {written.strip()!r} to name the distro, not found")
    metadata.write_text(text.replace(written, f"  ros_distro: {distro}\n"))


def export_rosbag2(
    record_dir, out, overwrite: bool = False, all_signals: bool = False, warn: Callable[[str], None] | None = None
) -> Exported:
    """Write the recording in ``record_dir`` as a rosbag2 folder ``out`` (see the module's docstring).

    ExportError when ``record_dir`` holds no recording, or ``out`` exists and ``overwrite`` is not
    set. With ``overwrite``, ``out`` is replaced only once the new bag is complete.
    """
    from rosbags.typesys import Stores, get_typestore

    from components.plotting import PlotError
    from orchestrator.plots.recording import load_run

    record_dir, out = Path(record_dir), Path(out)
    warn = warn or (lambda message: print(f"export: {message}", file=sys.stderr, flush=True))
    if out.exists() and not overwrite:
        raise ExportError(
            f"--rosbag2 {out}: expected a path that does not exist yet, got an existing "
            f"{'directory' if out.is_dir() else 'file'} (--overwrite replaces it)"
        )
    if out.exists() and not out.is_dir():
        raise ExportError(f"--rosbag2 {out}: expected a bag folder to replace, got a file")
    if out.exists() and not (out / "metadata.yaml").exists() and any(out.iterdir()):
        raise ExportError(
            f"--rosbag2 {out}: expected a rosbag2 folder (metadata.yaml) to replace, got a "
            "directory of other files; not touched"
        )
    try:
        run = load_run(record_dir)
    except PlotError as e:
        raise ExportError(str(e)) from None
    typestore = get_typestore(Stores(DISTRO))
    context = RosContext(run, typestore, warn)
    try:
        topics = run_topics(context, warn, all_signals)
    except TopicError as e:
        raise ExportError(str(e)) from None
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        bag = staging / out.name  # the bag's files are named after its folder
        _write(bag, topics, typestore)
        if out.exists():
            shutil.rmtree(out)
        bag.rename(out)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    size = sum(f.stat().st_size for f in out.iterdir())
    return Exported(out, {t.name: len(t.messages) for t in topics}, size)
