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

import shutil
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from components.rosbag import RosContext, RosTopic

DISTRO = "ros2_jazzy"      # message definitions and type hashes (rosbags' typestore)
BAG_VERSION = 9            # rosbag2's metadata.yaml version (Jazzy)


class ExportError(Exception):
    """A recording that cannot be exported, or an OUT that must not be written."""


@dataclass
class Exported:
    """What was written: the bag's folder, messages per topic, the bag's size (bytes)."""
    path: Path
    counts: dict[str, int]
    size: int


def _qos(latched: bool):
    from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness, QosReliability,
                                    QosTime)
    never = QosTime(sec=0x7FFFFFFF, nsec=0xFFFFFFFF)   # rclcpp's "infinite" duration
    return Qos(history=QosHistory.KEEP_LAST, depth=1 if latched else 10, reliability=QosReliability.RELIABLE,
               durability=QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE,
               deadline=never, lifespan=never, liveliness=QosLiveliness.AUTOMATIC,
               liveliness_lease_duration=never, avoid_ros_namespace_conventions=False)


def _signal_topics(context: RosContext, component: str) -> list[RosTopic]:
    """Each recorded variable of ``component`` as std_msgs/Float64MultiArray, one per row."""
    run = context.run
    Array = context.msg("std_msgs/msg/Float64MultiArray")
    Layout = context.msg("std_msgs/msg/MultiArrayLayout")
    names = sorted({c.split("[")[0] for c in run.columns if c.startswith(f"{component}.")})
    topics = []
    for name in names:
        values = run.variable(name)
        if values is None:
            continue
        values = np.ascontiguousarray(values, dtype=np.float64)
        topic = "/" + name.replace(".", "/")
        topics.append(RosTopic(topic, "std_msgs/msg/Float64MultiArray", [
            (int(ns), Array(layout=Layout(dim=[], data_offset=0), data=values[row]))
            for row, ns in enumerate(context.stamps)]))
    return topics


def _component_topics(context: RosContext, warn: Callable[[str], None], all_signals: bool = False) -> list[RosTopic]:
    """The topics the run's component types declare, in config order (with ``all_signals``, the
    other components' variables as arrays)."""
    from components import registry
    from components.errors import ConfigError

    run = context.run
    exports, generic = [], []
    for name, spec in (run.config.get("components") or {}).items():
        type_name = (spec or {}).get("type")
        try:
            cls = registry.load(type_name, run.config_dir)
        except ConfigError as e:
            warn(f"{name}: not exported ({e.message})")
            continue
        if cls.rosbag is None:
            if all_signals:
                generic.append(name)
            else:
                warn(f"{name}: its type {type_name} declares no ROS messages (rosbag); not exported "
                     "(--all-signals: its variables as Float64MultiArray)")
            continue
        exports.append((name, cls.rosbag))
    for name, export in exports:   # first: where outputs are measured, for the sensors reading them
        if export.output_frames is not None:
            context.output_frames.update({f"{name}.{v}": f for v, f in export.output_frames(context, name).items()})
    return ([topic for name, export in exports for topic in export.topics(context, name)]
            + [topic for name in generic for topic in _signal_topics(context, name)])


def _merged(context: RosContext, topics: list[RosTopic]) -> list[RosTopic]:
    """One topic per name: messages in time order; ``/tf_static``'s transforms in one message."""
    by_name: dict[str, RosTopic] = {}
    for topic in topics:
        if topic.name not in by_name:
            by_name[topic.name] = RosTopic(topic.name, topic.msgtype, [], topic.latched)
        known = by_name[topic.name]
        if known.msgtype != topic.msgtype:
            raise ExportError(f"topic {topic.name}: two message types ({known.msgtype}, {topic.msgtype})")
        known.messages += topic.messages
    static = by_name.get("/tf_static")
    if static is not None and static.messages:
        transforms = [t for _, message in static.messages for t in message.transforms]
        static.messages = [(min(ns for ns, _ in static.messages), context.tf(transforms))]
    for topic in by_name.values():
        topic.messages.sort(key=lambda item: item[0])   # stable: components' order within a stamp
    return list(by_name.values())


def _write(path: Path, topics: list[RosTopic], typestore) -> None:
    from rosbags.rosbag2 import StoragePlugin, Writer

    queue = []
    with Writer(path, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP) as writer:
        for order, topic in enumerate(topics):
            connection = writer.add_connection(topic.name, topic.msgtype, typestore=typestore,
                                               offered_qos_profiles=[_qos(topic.latched)])
            queue += [(ns, order, k, connection, topic.msgtype, message)
                      for k, (ns, message) in enumerate(topic.messages)]
        queue.sort(key=lambda item: item[:3])
        for ns, _, _, connection, msgtype, message in queue:
            writer.write(connection, ns, typestore.serialize_cdr(message, msgtype))


def export_rosbag2(record_dir, out, overwrite: bool = False, all_signals: bool = False,
                   warn: Callable[[str], None] | None = None) -> Exported:
    """Write the recording in ``record_dir`` as a rosbag2 folder ``out`` (see the module's docstring).

    ExportError when ``record_dir`` holds no recording, or ``out`` exists and ``overwrite`` is not
    set. With ``overwrite``, ``out`` is replaced only once the new bag is complete.
    """
    from components.plotting import PlotError
    from orchestrator.plots.recording import load_run
    from rosbags.typesys import Stores, get_typestore

    record_dir, out = Path(record_dir), Path(out)
    warn = warn or (lambda message: print(f"export: {message}", file=sys.stderr, flush=True))
    if out.exists() and not overwrite:
        raise ExportError(f"--rosbag2 {out}: expected a path that does not exist yet, got an existing "
                          f"{'directory' if out.is_dir() else 'file'} (--overwrite replaces it)")
    if out.exists() and not out.is_dir():
        raise ExportError(f"--rosbag2 {out}: expected a bag folder to replace, got a file")
    if out.exists() and not (out / "metadata.yaml").exists() and any(out.iterdir()):
        raise ExportError(f"--rosbag2 {out}: expected a rosbag2 folder (metadata.yaml) to replace, got a "
                          "directory of other files; not touched")
    try:
        run = load_run(record_dir)
    except PlotError as e:
        raise ExportError(str(e)) from None
    typestore = get_typestore(Stores(DISTRO))
    context = RosContext(run, typestore, warn)
    Clock = context.msg("rosgraph_msgs/msg/Clock")
    clock = RosTopic("/clock", "rosgraph_msgs/msg/Clock", [(int(ns), Clock(clock=context.time(ns)))
                                                          for ns in context.stamps])
    topics = [clock] + _merged(context, _component_topics(context, warn, all_signals))
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        bag = staging / out.name    # the bag's files are named after its folder
        _write(bag, topics, typestore)
        if out.exists():
            shutil.rmtree(out)
        bag.rename(out)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    size = sum(f.stat().st_size for f in out.iterdir())
    return Exported(out, {t.name: len(t.messages) for t in topics}, size)
