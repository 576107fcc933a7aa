"""What the sensor types export as ROS 2 messages (their ``rosbag``): the measurement in the
sensor's frame ``<sensor>`` (the component's name), which ``/tf_static`` mounts, identity, on the
frame the measured output is taken in (a body's base for an IMU, the end effector for the grasp's
wrench and relative pose) when the dynamics says where that is.

| type | topic | message |
|---|---|---|
| sensor.imu | ``/<sensor>/imu`` | sensor_msgs/Imu: ``rate`` (rad/s), ``specific_force`` (m/s^2) as linear_acceleration, every row; no orientation (orientation_covariance[0] = -1, REP 145), covariances unknown (0) |
| sensor.force_torque | ``/<sensor>/wrench`` | geometry_msgs/WrenchStamped: ``wrench`` force (N), torque (N m), every row |
| sensor.relative_pose | ``/<sensor>/pose`` | geometry_msgs/PoseStamped: ``p`` (m), ``q`` [x, y, z, w] of the target in the sensor frame, once per measurement (``valid``, a new ``t_measured``), stamped ``t_measured`` |
"""

from __future__ import annotations

import numpy as np

from components.rosbag import RosContext, RosExport, RosTopic, measurement_rows


def _static_mount(context: RosContext, sensor: str, true_input: str) -> list[RosTopic]:
    mount = context.mount_of(sensor, true_input)
    if mount is None:
        return []
    ns = int(context.stamps[0])
    return [
        RosTopic(
            "/tf_static",
            "tf2_msgs/msg/TFMessage",
            [(ns, context.tf([context.transform(ns, mount, sensor, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))]))],
            latched=True,
        )
    ]


def _imu(context: RosContext, sensor: str):
    rate, force = context.run.vector(f"{sensor}.rate", 3), context.run.vector(f"{sensor}.specific_force", 3)
    if rate is None or force is None:
        return []
    Imu = context.msg("sensor_msgs/msg/Imu")
    unknown = np.zeros(9)
    no_orientation = np.array([-1.0] + [0.0] * 8)
    return _static_mount(context, sensor, "rate_true") + [
        RosTopic(
            f"/{sensor}/imu",
            "sensor_msgs/msg/Imu",
            [
                (
                    int(ns),
                    Imu(
                        header=context.header(ns, sensor),
                        orientation=context.quaternion((0.0, 0.0, 0.0, 1.0)),
                        orientation_covariance=no_orientation,
                        angular_velocity=context.vector3(rate[row]),
                        angular_velocity_covariance=unknown,
                        linear_acceleration=context.vector3(force[row]),
                        linear_acceleration_covariance=unknown,
                    ),
                )
                for row, ns in enumerate(context.stamps)
            ],
        )
    ]


def _wrench(context: RosContext, sensor: str):
    wrench = context.run.vector(f"{sensor}.wrench", 6)
    if wrench is None:
        return []
    Wrench, WrenchStamped = context.msg("geometry_msgs/msg/Wrench"), context.msg("geometry_msgs/msg/WrenchStamped")
    return _static_mount(context, sensor, "wrench_true") + [
        RosTopic(
            f"/{sensor}/wrench",
            "geometry_msgs/msg/WrenchStamped",
            [
                (
                    int(ns),
                    WrenchStamped(
                        header=context.header(ns, sensor),
                        wrench=Wrench(force=context.vector3(wrench[row, :3]), torque=context.vector3(wrench[row, 3:])),
                    ),
                )
                for row, ns in enumerate(context.stamps)
            ],
        )
    ]


def _relative_pose(context: RosContext, sensor: str):
    run = context.run
    p, q = run.vector(f"{sensor}.p", 3), run.vector(f"{sensor}.q", 4)
    valid, t_measured = run.columns.get(f"{sensor}.valid"), run.columns.get(f"{sensor}.t_measured")
    if p is None or q is None or valid is None or t_measured is None:
        return []
    Pose, PoseStamped = context.msg("geometry_msgs/msg/Pose"), context.msg("geometry_msgs/msg/PoseStamped")
    return _static_mount(context, sensor, "p_true") + [
        RosTopic(
            f"/{sensor}/pose",
            "geometry_msgs/msg/PoseStamped",
            [
                (
                    int(context.stamps[row]),
                    PoseStamped(
                        header=context.header(context.stamp_of(float(t_measured[row])), sensor),
                        pose=Pose(position=context.point(p[row]), orientation=context.quaternion(q[row])),
                    ),
                )
                for row in measurement_rows(valid, t_measured)
            ],
        )
    ]


IMU = RosExport("``/<c>/imu`` sensor_msgs/Imu (rate, specific_force)", _imu)
FORCE_TORQUE = RosExport("``/<c>/wrench`` geometry_msgs/WrenchStamped", _wrench)
RELATIVE_POSE = RosExport("``/<c>/pose`` geometry_msgs/PoseStamped, once per measurement", _relative_pose)
