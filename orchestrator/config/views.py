"""The run's live views in a config: ``viewer:`` (Rerun or Foxglove, or ``--view``) and ``ros2:``
(or ``--ros2``), checked into ViewerSpec and Ros2Spec."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from components.extras import missing
from orchestrator.config.schema import ROS2, VIEWER
from orchestrator.config.specs import ComponentSpec, Ros2Spec, ViewerSpec


def viewer_spec(raw: Any, where: str, errors: list[str], base: Path) -> ViewerSpec | None:
    """Parse a ``viewer:`` section or a ``--view`` value (``spawn``, ``web``, ``save:FILE.rrd``,
    ``foxglove[:PORT]``)."""
    if isinstance(raw, str):
        mode, _, rest = raw.partition(":")
        if mode == "foxglove" and rest:
            if not rest.isdigit():
                errors.append(f"{where}: foxglove:PORT needs a port number, got {rest!r}")
                return None
            raw = {"mode": mode, "port": int(rest)}
        else:
            raw = {"mode": mode, **({"file": rest} if rest else {})}
    section, problems = VIEWER.resolve(raw, where)
    if problems:
        errors += [str(e) for e in problems]
        return None
    return _viewer(section, where, errors, base)


def _viewer(section: dict, where: str, errors: list[str], base: Path) -> ViewerSpec | None:
    if section["mode"] == "off":
        return None
    if section["mode"] == "save" and section["file"] is None:
        errors.append(f"{where}.file: save needs a file name ending in .rrd (e.g. save:run.rrd), got none")
        return None
    if section["mode"] != "foxglove" and (problem := missing("view", f"the Rerun viewer ({section['mode']})")):
        errors.append(f"{where}: {problem}")
        return None
    file = section["file"]
    if section["port"] > 65535:
        errors.append(f"{where}.port: expected a port number 1..65535, got {section['port']}")
        return None
    return ViewerSpec(
        mode=section["mode"],
        file=(base / file) if file else None,
        rate_hz=section["rate"],
        open_browser=section["open_browser"],
        port=section["port"],
    )


def clock_clash(components: dict[str, ComponentSpec], ros2: Ros2Spec | None, where: str) -> str | None:
    """Why the live ROS 2 view cannot publish ``/clock`` beside a ``ros2.bridge`` that does, in one
    domain, or None: a node with use_sim_time would hear two clocks, the view's lagging the bridge's."""
    if ros2 is None or (ros2.topics is not None and "/clock" not in ros2.topics):
        return None
    for name, spec in components.items():
        if spec.type == "ros2.bridge" and spec.resolved["clock"] and spec.resolved["domain_id"] == ros2.domain_id:
            return (
                f"{where}: the live ROS 2 view would publish /clock in domain {ros2.domain_id}, where the bridge "
                f"{name!r} publishes the run's /clock in lockstep (a node with use_sim_time would hear both): "
                f"give ros2.topics without /clock, or components.{name}.parameters.clock: false"
            )
    return None


def ros2_spec(raw: Any, where: str, errors: list[str], endpoint: str | None = None) -> Ros2Spec | None:
    """Parse a ``ros2:`` section (None: the defaults); ``endpoint``: ``--ros2 TRANSPORT|ENDPOINT``,
    which wins (an endpoint means transport zenoh). The domain id, if not given, is the
    environment's ROS_DOMAIN_ID, else 0. The transport is chosen here (auto: rclpy if a Python
    imports it). A topic name ROS 2 rejects, or rclpy asked for and not found: an error naming it."""
    import os

    from components.errors import ComponentError
    from components.ros2.rclpy_transport import TRANSPORTS, ZENOH, choose
    from components.ros2.rmw_zenoh import check_topic_name

    if raw is None or isinstance(raw, dict):
        if endpoint in TRANSPORTS:
            given = {"transport": endpoint}
        elif endpoint is not None:
            given = {"endpoint": endpoint, "transport": ZENOH}
        else:
            given = {}
        raw = {**(raw or {}), **given}
    section, problems = ROS2.resolve(raw, where)
    if problems:
        errors += [str(e) for e in problems]
        return None
    domain_id = section["domain_id"]
    if domain_id is None:
        text = os.environ.get("ROS_DOMAIN_ID", "").strip()
        if text and not text.isdigit():
            errors.append(f"{where}.domain_id: from ROS_DOMAIN_ID, expected an integer >= 0, got {text!r}")
            return None
        domain_id = int(text) if text else 0
    rejected = [
        f"{where}.topics[{i}]: ROS 2 rejects the topic name {topic!r}: {problem}"
        for i, topic in enumerate(section["topics"] or [])
        if (problem := check_topic_name(topic))
    ]
    if rejected:
        errors += rejected
        return None
    try:
        transport, python, why = choose(section["transport"], section["python"])
    except ComponentError as e:
        errors.append(f"{where}.transport: {e}")
        return None
    return Ros2Spec(
        endpoint=section["endpoint"],
        domain_id=domain_id,
        distro=section["distro"],
        topics=section["topics"],
        rate_hz=section["rate"],
        transport=transport,
        python=python,
        why=why,
    )


def live_views(
    config: dict, path: Path, components: dict[str, ComponentSpec], errors: list[str]
) -> tuple[ViewerSpec | None, Ros2Spec | None]:
    """The ``viewer:`` and ``ros2:`` sections, checked (a ROS 2 view's /clock against a bridge's)."""
    viewer = ros2 = None
    problems: list[str] = []
    if config.get("viewer") is not None:
        viewer = _viewer(config["viewer"], "viewer", problems, path.parent)
    if config.get("ros2") is not None:
        ros2 = ros2_spec(config["ros2"], "ros2", problems)
        if clash := clock_clash(components, ros2, "ros2"):
            problems.append(clash)
    errors += [f"{path}: {m}" for m in problems]
    return viewer, ros2
