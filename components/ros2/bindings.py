"""The variables of a ``ros2.bridge`` bound to ROS 2 topic fields: each output and input's topic,
message type, field, length, unit, joint names and start read from the bridge's parameters and
checked, one by one and across variables (a name used twice, a topic both ways, one topic's
variables disagreeing); every problem a ConfigError naming its key.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from components.errors import ConfigError
from components.ros2 import messages
from components.ros2.rmw_zenoh import check_topic_name
from components.schema import Problems

CLOCK_TOPIC = "/clock"  # the bridge's own (the run's time): no variable's


@dataclass(frozen=True)
class Binding:
    """A variable of the bridge and the field of the ROS 2 topic it is."""

    variable: str
    causality: str
    topic: str
    message: messages.MessageMap
    field: messages.Field
    shape: tuple[int, ...]
    unit: str
    names: tuple[str, ...] | None
    start: np.ndarray
    frame_id: str


def bindings(params: Mapping) -> list[Binding]:
    """Every variable's binding, outputs first; Problems (each naming its key) for what is wrong."""
    found, problems = [], []
    for causality, group in (("output", "outputs"), ("input", "inputs")):
        for name, spec in params[group].items():
            try:
                found.append(_binding(causality, f"{group}.{name}", name, spec))
            except ConfigError as e:
                problems.append(e)
    if problems:
        raise Problems(problems)
    problems += _across(params, found)
    if problems:
        raise Problems(problems)
    return found


def _binding(causality: str, key: str, name: str, spec: Mapping) -> Binding:
    topic = spec["topic"]
    wrong = check_topic_name(topic)
    if wrong:
        raise ConfigError(f"{key}.topic", f"{topic!r} is not a ROS 2 topic name: {wrong}")
    if topic == CLOCK_TOPIC:
        raise ConfigError(f"{key}.topic", f"{CLOCK_TOPIC} is the bridge's own (the run's time); choose another topic")
    message, field = _message_field(key, topic, spec)
    size = _size(key, topic, message, field, spec)
    unit = spec["unit"] or field.unit
    if unit is None:
        raise ConfigError(
            f"{key}.unit",
            f"topic {topic}: {message.msgtype}.{field.name} has no unit of its own: "
            f"give the variable's (e.g. rad, N*m)",
        )
    shape = () if message.msgtype == "std_msgs/msg/Float64" else (size,)
    start = spec.get("start")
    if start is None:
        start = np.asarray(field.neutral if field.neutral else np.zeros(size), dtype=np.float64)
    start = np.asarray(start, dtype=np.float64)
    if start.size not in (1, size):
        raise ConfigError(f"{key}.start", f"expected one value or {size}, got {start.size}")
    return Binding(
        name,
        causality,
        topic,
        message,
        field,
        shape,
        unit,
        tuple(spec["names"]) if spec["names"] else None,
        np.broadcast_to(start, (size,)).reshape(shape).copy(),
        spec.get("frame_id", ""),
    )


def _message_field(key: str, topic: str, spec: Mapping) -> tuple[messages.MessageMap, messages.Field]:
    """The message type's map and the field the variable is (the type's one field when none is given)."""
    message = messages.MAPS.get(spec["type"])
    if message is None:
        raise ConfigError(
            f"{key}.type",
            f"topic {topic}: the bridge cannot map message type {spec['type']!r}; "
            f"supported types (fields): {messages.supported()}",
        )
    field_name = spec["field"]
    if field_name is None:
        if len(message.fields) > 1:
            raise ConfigError(
                f"{key}.field",
                f"topic {topic}: {message.msgtype} has several fields: give one of {', '.join(message.fields)}",
            )
        field_name = next(iter(message.fields))
    field = message.fields.get(field_name)
    if field is None:
        raise ConfigError(
            f"{key}.field",
            f"topic {topic}: expected a field of {message.msgtype} ({', '.join(message.fields)}), got {field_name!r}",
        )
    return message, field


def _size(key: str, topic: str, message: messages.MessageMap, field: messages.Field, spec: Mapping) -> int:
    """The variable's length: the field's own, else the given size or number of joint names; the
    joint names checked against the message type and the length."""
    size = spec["size"]
    if field.size is None:
        if size is None:
            size = len(spec["names"]) if spec["names"] else None
        if size is None:
            raise ConfigError(
                f"{key}.size",
                f"topic {topic}: {message.msgtype}.{field.name} is a sequence: give the "
                f"variable's length (size, or names)",
            )
    elif size is not None and size != field.size:
        raise ConfigError(f"{key}.size", f"{message.msgtype}.{field.name} holds {field.size} values, got size {size}")
    else:
        size = field.size
    if spec["names"] is not None:
        if not message.named:
            raise ConfigError(
                f"{key}.names",
                f"{message.msgtype} carries no joint names (only "
                f"{', '.join(t for t, m in messages.MAPS.items() if m.named)} do)",
            )
        if len(spec["names"]) != size:
            raise ConfigError(f"{key}.names", f"expected {size} joint names (size), got {len(spec['names'])}")
    return size


def _across(params: Mapping, found: list[Binding]) -> list[ConfigError]:
    """What is wrong between variables: a name used twice, a topic both ways, variables of one
    topic disagreeing on its type, its joint names or frame, or sharing a part of its messages."""
    problems = []
    both = set(params["outputs"]) & set(params["inputs"])
    problems += [ConfigError(f"inputs.{n}", "is an output too: a variable name must be unique") for n in sorted(both)]
    direction: dict[str, str] = {}  # topic -> "outputs" or "inputs"
    for b in found:
        side = f"{b.causality}s"
        other = direction.setdefault(b.topic, side)
        if other != side:
            problems.append(
                ConfigError(f"{side}.{b.variable}.topic", f"{b.topic} is also among the {other}: a topic goes one way")
            )
    by_topic: dict[tuple[str, str], list[Binding]] = {}
    for b in found:
        by_topic.setdefault((b.causality, b.topic), []).append(b)
    for (causality, topic), group in by_topic.items():
        first = group[0]
        for b in group[1:]:
            key = f"{causality}s.{b.variable}"
            if b.message is not first.message:
                problems.append(
                    ConfigError(
                        f"{key}.type",
                        f"topic {topic} is {first.message.msgtype} (for {first.variable}), got {b.message.msgtype}",
                    )
                )
                continue
            if b.names and first.names and b.names != first.names and causality == "input":
                problems.append(ConfigError(f"{key}.names", f"topic {topic}: {first.variable} gives other joint names"))
            if b.frame_id != first.frame_id:
                problems.append(
                    ConfigError(
                        f"{key}.frame_id",
                        f"topic {topic}: {first.variable} gives frame_id {first.frame_id!r}, got {b.frame_id!r}",
                    )
                )
        covered: dict[str, str] = {}
        for b in group:
            for part in b.field.parts:
                if part in covered and covered[part] != b.variable:
                    problems.append(
                        ConfigError(
                            f"{causality}s.{b.variable}.field", f"topic {topic}: {covered[part]} is its {part} already"
                        )
                    )
                covered[part] = b.variable
    return problems
