"""What a dynamics component exports as ROS 2 messages (its type's ``rosbag``), per row of the recording.

| topic | type | content |
|---|---|---|
| ``/tf`` | tf2_msgs/TFMessage | ``eci`` -> ``<dyn>/world`` (W: at ``r_eci``, ECI axes); ``<dyn>/world`` -> ``<dyn>/<body>/<link>`` for every link (the base: ``position``, ``orientation``; the others: ``link_position``, ``link_orientation`` when recorded, else forward kinematics of the URDF) |
| ``/<dyn>/<body>/joint_states`` | sensor_msgs/JointState | the URDF's movable joints: ``q`` (rad, m), ``qd``, effort: the output feeding ``<body>.tau`` (N m, N; empty if not connected) |
| ``/<dyn>/<body>/pose`` | geometry_msgs/PoseStamped | the base in W (``position``, ``orientation``), frame ``<dyn>/world`` |
| ``/<dyn>/<body>/twist`` | geometry_msgs/TwistStamped | the base's ``twist`` (m/s, rad/s), W axes, frame ``<dyn>/world`` |
| ``/<dyn>/<body>/robot_description`` | std_msgs/String | the URDF as written (``package://`` mesh URIs kept; transient local), links unprefixed: prefix ``<dyn>/<body>/`` in RViz or Foxglove |

Base pose and twist are in W, not LVLH: they are what the dynamics records, so the bag is exact;
``/tf`` places W and LVLH in ECI, so tf gives the base in LVLH.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from components.errors import ConfigError
from components.robots.model import body_items, resolve_urdf
from components.rosbag import ROOT_FRAME, RosContext, RosExport, RosTopic, link_frame, source_of, world_frame

if TYPE_CHECKING:
    from components.robots.urdf import UrdfModel


def _packages(context: RosContext) -> dict:
    run = context.run
    packages = (run.config.get("run") or {}).get("packages") or {}
    base = Path(run.config_dir or ".")  # as the run resolved them: relative to the config's directory
    return {str(k): str(base / str(v)) for k, v in packages.items()} if isinstance(packages, dict) else {}


def _links_in_w(context: RosContext, dynamics: str, body: str, urdf, position, orientation, q):
    """Link origins (n, L, 3) and q_W_link (n, L, 4) [x, y, z, w]: recorded if the dynamics recorded
    them (link_outputs: true), else forward kinematics of the URDF; None if neither is possible."""
    from components.rotations import matrix_to_quat
    from components.viewer.robot import Kinematics, read_geometry

    run = context.run
    recorded_p = run.variable(f"{dynamics}.{body}.link_position")
    recorded_q = run.variable(f"{dynamics}.{body}.link_orientation")
    if recorded_p is not None and recorded_q is not None:
        n = len(run.time)
        return recorded_p.reshape(n, -1, 3), recorded_q.reshape(n, -1, 4)
    if q is None:
        return None
    try:
        kinematics = Kinematics(read_geometry(urdf, _packages(context)))
    except Exception as e:  # a URDF Pinocchio cannot load: the base still goes out
        context.warn(f"{dynamics}.{body}: no link frames (forward kinematics of {urdf}: {e})")
        return None
    translations, rotations = kinematics.link_poses(position, orientation, q)
    return translations, matrix_to_quat(rotations)


def _topics(context: RosContext, dynamics: str):
    run, stamps = context.run, context.stamps
    try:
        bodies = body_items(run.parameters(dynamics).get("bodies"))
    except ConfigError as e:
        context.warn(f"{dynamics}: {e}; no bodies exported")
        return []
    world = world_frame(dynamics)
    transforms: list[list] = [[] for _ in stamps]
    r_source = source_of(run, dynamics, "r_eci")
    r_eci = run.vector(".".join(r_source), 3) if r_source else None
    if r_eci is not None:
        for row, ns in enumerate(stamps):
            transforms[row].append(context.transform(ns, ROOT_FRAME, world, r_eci[row], (0.0, 0.0, 0.0, 1.0)))
    topics = []
    for body, spec in bodies:
        topics += _body_topics(context, dynamics, body, spec, world, transforms)
    topics.insert(
        0,
        RosTopic(
            "/tf", "tf2_msgs/msg/TFMessage", [(int(ns), context.tf(ts)) for ns, ts in zip(stamps, transforms) if ts]
        ),
    )
    return topics


def _body_topics(context: RosContext, dynamics: str, body: str, spec, world: str, transforms: list[list]):
    """One body's topics (robot_description, pose, twist, joint_states); its frames appended to
    ``transforms`` (one list per row)."""
    from components.robots.urdf import read_urdf, source_text

    run, stamps = context.run, context.stamps
    prefix = f"{dynamics}.{body}"
    position, orientation = run.vector(f"{prefix}.position", 3), run.vector(f"{prefix}.orientation", 4)
    twist, q, qd = run.vector(f"{prefix}.twist", 6), run.vector(f"{prefix}.q"), run.vector(f"{prefix}.qd")
    model: UrdfModel | None
    try:
        urdf = resolve_urdf(spec["urdf"], run.config_dir, f"bodies.{body}.urdf", _packages(context))
        model = read_urdf(urdf, _packages(context))
        description = source_text(urdf, _packages(context))
    except (ConfigError, ValueError, OSError) as e:
        context.warn(f"{prefix}: its URDF cannot be read ({e}); no joint names, links or robot_description")
        model = None
    topics = []
    if model is not None:
        topics.append(
            RosTopic(
                f"/{dynamics}/{body}/robot_description",
                "std_msgs/msg/String",
                [(int(stamps[0]), context.msg("std_msgs/msg/String")(data=description))],
                latched=True,
            )
        )
    if position is None or orientation is None:
        return topics
    base = link_frame(dynamics, body, model.root if model else "base")
    links = _links_in_w(context, dynamics, body, urdf, position, orientation, q) if model else None
    for row, ns in enumerate(stamps):
        transforms[row].append(context.transform(ns, world, base, position[row], orientation[row]))
        if links is not None and model is not None:  # (links only with a model)
            for j, link in enumerate(model.link_names):
                if link != model.root:
                    transforms[row].append(
                        context.transform(
                            ns, world, link_frame(dynamics, body, link), links[0][row, j], links[1][row, j]
                        )
                    )
    topics.append(_pose_topic(context, dynamics, body, world, position, orientation))
    if twist is not None:
        topics.append(_twist_topic(context, dynamics, body, world, twist))
    if q is not None:
        topics.append(_joint_states(context, dynamics, body, model, q, qd))
    return topics


def _pose_topic(context: RosContext, dynamics: str, body: str, world: str, position, orientation) -> RosTopic:
    Pose, PoseStamped = context.msg("geometry_msgs/msg/Pose"), context.msg("geometry_msgs/msg/PoseStamped")
    return RosTopic(
        f"/{dynamics}/{body}/pose",
        "geometry_msgs/msg/PoseStamped",
        [
            (
                int(ns),
                PoseStamped(
                    header=context.header(ns, world),
                    pose=Pose(position=context.point(position[row]), orientation=context.quaternion(orientation[row])),
                ),
            )
            for row, ns in enumerate(context.stamps)
        ],
    )


def _twist_topic(context: RosContext, dynamics: str, body: str, world: str, twist) -> RosTopic:
    Twist, TwistStamped = context.msg("geometry_msgs/msg/Twist"), context.msg("geometry_msgs/msg/TwistStamped")
    return RosTopic(
        f"/{dynamics}/{body}/twist",
        "geometry_msgs/msg/TwistStamped",
        [
            (
                int(ns),
                TwistStamped(
                    header=context.header(ns, world),
                    twist=Twist(linear=context.vector3(twist[row, :3]), angular=context.vector3(twist[row, 3:])),
                ),
            )
            for row, ns in enumerate(context.stamps)
        ],
    )


def _joint_states(context: RosContext, dynamics: str, body: str, model, q, qd) -> RosTopic:
    run = context.run
    names = (
        model.movable_joints
        if model is not None and len(model.movable_joints) == q.shape[1]
        else [f"q[{i}]" for i in range(q.shape[1])]
    )
    tau_source = source_of(run, dynamics, f"{body}.tau")
    effort = run.vector(".".join(tau_source)) if tau_source else None
    if effort is not None and effort.shape[1] != q.shape[1]:
        effort = None
    empty = np.empty(0)
    JointState = context.msg("sensor_msgs/msg/JointState")
    frame = link_frame(dynamics, body, model.root) if model is not None else ""
    return RosTopic(
        f"/{dynamics}/{body}/joint_states",
        "sensor_msgs/msg/JointState",
        [
            (
                int(ns),
                JointState(
                    header=context.header(ns, frame),
                    name=list(names),
                    position=np.ascontiguousarray(q[row]),
                    velocity=np.ascontiguousarray(qd[row]) if qd is not None else empty,
                    effort=np.ascontiguousarray(effort[row]) if effort is not None else empty,
                ),
            )
            for row, ns in enumerate(context.stamps)
        ],
    )


def _output_frames(context: RosContext, dynamics: str) -> dict[str, str]:
    """Where the outputs sensors read are measured: a body's IMU outputs at its base link, the
    grasp's at the chaser's end effector."""
    from components.robots.urdf import read_urdf

    frames: dict[str, str] = {}
    params = context.run.parameters(dynamics)
    try:
        bodies = dict(body_items(params.get("bodies")))
    except ConfigError:
        return frames
    for body, spec in bodies.items():
        try:
            root = read_urdf(
                resolve_urdf(spec["urdf"], context.run.config_dir, "urdf", _packages(context)), _packages(context)
            ).root
        except (ConfigError, ValueError, OSError):
            continue
        for variable in ("imu_rate", "specific_force", "position", "orientation", "twist"):
            frames[f"{body}.{variable}"] = link_frame(dynamics, body, root)
    grasp = params.get("grasp") or {}
    if grasp.get("chaser") and grasp.get("end_effector"):
        for variable in ("p_ee_grasp", "q_ee_grasp", "twist_ee_grasp", "wrench"):
            frames[f"grasp.{variable}"] = link_frame(dynamics, grasp["chaser"], grasp["end_effector"])
    return frames


def _assets(context: RosContext, dynamics: str) -> dict[str, Path]:
    """The mesh files the bodies' ``robot_description`` names, by the URI as written there
    (``package://...``, ``file://...`` or a path relative to the URDF), resolved as the run did."""
    import xml.etree.ElementTree as ET

    from components.robots.packages import PackageError, resolve_uri
    from components.robots.urdf import source_text

    assets: dict[str, Path] = {}
    try:
        bodies = body_items(context.run.parameters(dynamics).get("bodies"))
    except ConfigError:
        return assets
    packages = _packages(context)
    for body, spec in bodies:
        try:
            urdf = resolve_urdf(spec["urdf"], context.run.config_dir, f"bodies.{body}.urdf", packages)
            text = source_text(urdf, packages)
            meshes = ET.fromstring(text).iter("mesh")
        except (ConfigError, ValueError, OSError, ET.ParseError):
            continue  # the topics' builder says why the URDF cannot be read
        for mesh in meshes:
            uri = mesh.get("filename")
            if uri is None:
                continue  # read_urdf refuses it: the topics' builder says so
            try:
                assets.setdefault(uri, resolve_uri(uri, urdf.parent, packages))
            except PackageError as e:
                context.warn(f"{dynamics}.{body}: mesh not served ({e})")
    return assets


ROS_EXPORT = RosExport(
    "per body: joint_states, base pose and twist in W, robot_description; /tf: W in ECI, every link in W",
    _topics,
    _output_frames,
    _assets,
)
