"""A recording's ROS 2 topics: ``/clock``, then what each of the run's component types declares
(``Component.rosbag``, found through the registry), merged by topic name. The rosbag2 export
(orchestrator/export/rosbag2.py) writes them; the live Foxglove view
(components/viewer/foxglove_observer.py) sends them."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from components import registry
from components.errors import ConfigError
from components.rosbag import LazyMessages, RosContext, RosTopic, TopicError


def signal_topics(context: RosContext, component: str) -> list[RosTopic]:
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
        topics.append(
            RosTopic(
                topic,
                "std_msgs/msg/Float64MultiArray",
                [
                    (int(ns), Array(layout=Layout(dim=[], data_offset=0), data=values[row]))
                    for row, ns in enumerate(context.stamps)
                ],
            )
        )
    return topics


def component_topics(context: RosContext, warn: Callable[[str], None], all_signals: bool = False) -> list[RosTopic]:
    """The topics the run's component types declare, in config order (with ``all_signals``, the
    other components' variables as arrays)."""
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
                warn(
                    f"{name}: its type {type_name} declares no ROS messages (rosbag); not exported "
                    "(--all-signals: its variables as Float64MultiArray)"
                )
            continue
        exports.append((name, cls.rosbag))
    for name, export in exports:  # first: where outputs are measured, for the sensors reading them
        if export.output_frames is not None:
            context.output_frames.update({f"{name}.{v}": f for v, f in export.output_frames(context, name).items()})
    return [topic for name, export in exports for topic in export.topics(context, name)] + [
        topic for name in generic for topic in signal_topics(context, name)
    ]


def merged(context: RosContext, topics: list[RosTopic]) -> list[RosTopic]:
    """One topic per name: messages in time order; ``/tf_static``'s transforms in one message. A
    topic of :class:`LazyMessages` alone on its name stays lazy (in time order already)."""
    groups: dict[str, list[RosTopic]] = {}
    for topic in topics:
        group = groups.setdefault(topic.name, [])
        if group and group[0].msgtype != topic.msgtype:
            raise TopicError(f"topic {topic.name}: two message types ({group[0].msgtype}, {topic.msgtype})")
        group.append(topic)
    by_name: dict[str, RosTopic] = {}
    for name, group in groups.items():
        first = group[0]
        if len(group) == 1 and isinstance(first.messages, LazyMessages):
            by_name[name] = RosTopic(name, first.msgtype, first.messages, first.latched)
            continue
        messages = [message for topic in group for message in topic.messages]
        messages.sort(key=lambda item: item[0])  # stable: components' order within a stamp
        by_name[name] = RosTopic(name, first.msgtype, messages, first.latched)
    static = by_name.get("/tf_static")
    if static is not None and static.messages:
        tf_messages: Sequence[tuple[int, Any]] = static.messages  # tf2_msgs/msg/TFMessage
        transforms = [t for _, message in tf_messages for t in message.transforms]
        static.messages = [(min(ns for ns, _ in static.messages), context.tf(transforms))]
    return list(by_name.values())


def run_topics(context: RosContext, warn: Callable[[str], None], all_signals: bool = False) -> list[RosTopic]:
    """Every topic of the recording in ``context``: ``/clock`` (one message per row), then the
    component types' topics merged by name (the rosbag2 export and the live Foxglove view)."""
    Clock = context.msg("rosgraph_msgs/msg/Clock")
    clock = RosTopic(
        "/clock", "rosgraph_msgs/msg/Clock", [(int(ns), Clock(clock=context.time(ns))) for ns in context.stamps]
    )
    return [clock] + merged(context, component_topics(context, warn, all_signals))


def run_assets(context: RosContext, warn: Callable[[str], None]) -> dict[str, Path]:
    """{URI: file} of every file the run's topics reference (meshes of ``robot_description``),
    from the component types that declare them (``RosExport.assets``)."""
    assets: dict[str, Path] = {}
    for name, spec in (context.run.config.get("components") or {}).items():
        try:
            cls = registry.load((spec or {}).get("type"), context.run.config_dir)
        except ConfigError:
            continue  # component_topics has said so
        if cls.rosbag is not None and cls.rosbag.assets is not None:
            for uri, path in cls.rosbag.assets(context, name).items():
                assets.setdefault(uri, path)
    return assets


class LiveTopics:
    """The live views' signal rows, batch by batch, as the export's topics with CDR messages.

    The previous batch's last row leads each batch, so that what a builder derives from consecutive
    rows (a relative pose's new measurement) comes out as in the export; what that row gave was
    sent with the previous batch and is left out. A latched topic has its first message only, once.
    """

    def __init__(self, config: dict, config_dir, columns: list[str], typestore, warn: Callable[[str], None]):
        self.config, self.columns, self.typestore, self.warn = config, columns, typestore, warn
        self.config_dir = Path(config_dir) if config_dir else None
        self.latched_sent: set[str] = set()
        self._lead: tuple[float, np.ndarray] | None = None  # (time s, row) of the previous batch's last row

    def batch(self, times, rows) -> tuple[list[tuple[RosTopic, list[tuple[int, bytes]]]], int]:
        """``times`` (s) and ``rows`` (one column per name of ``columns``): each topic with its
        messages as (stamp ns, CDR bytes), and the last row's stamp."""
        from components.plotting import RecordedRun

        times, rows = np.asarray(times, dtype=np.float64), np.asarray(rows, dtype=np.float64)
        if self._lead is not None:
            times, rows = np.concatenate([[self._lead[0]], times]), np.vstack([self._lead[1], rows])
        run = RecordedRun(
            self.config, {name: rows[:, i] for i, name in enumerate(self.columns)}, times, self.config_dir
        )
        context = RosContext(run, self.typestore, self.warn)
        sent_until = int(context.stamps[0]) if self._lead is not None else None
        batch = []
        for topic in run_topics(context, self.warn):
            if topic.latched:
                messages = [] if topic.name in self.latched_sent else topic.messages[:1]
                if messages:
                    self.latched_sent.add(topic.name)
            else:
                messages = [(ns, m) for ns, m in topic.messages if sent_until is None or ns > sent_until]
            batch.append(
                (
                    topic,
                    [
                        (int(ns), bytes(self.typestore.serialize_cdr(message, topic.msgtype)))
                        for ns, message in messages
                    ],
                )
            )
        self._lead = (times[-1], rows[-1].copy())
        return batch, int(context.stamps[-1])
