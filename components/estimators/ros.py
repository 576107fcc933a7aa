"""``estimator.fiducial``'s ROS 2 messages (``orchestrator export --rosbag2``, the Foxglove view):
``/<c>/pose``, a geometry_msgs/PoseStamped once per accepted frame, stamped when the frame was
taken, in the end effector's tf frame (``<dynamics>/<body>/<end_effector>``, the dynamics'
link frames; the component's own name when its camera's body is not connected to a dynamics)."""

from __future__ import annotations

from components.estimators.plots import chaser_dynamics
from components.rosbag import RosContext, RosExport, RosTopic, link_frame, measurement_rows


def _pose(context: RosContext, c: str) -> list[RosTopic]:
    run = context.run
    p, q = run.vector(f"{c}.p", 3), run.vector(f"{c}.q", 4)
    valid, t_measured = run.columns.get(f"{c}.valid"), run.columns.get(f"{c}.t_measured")
    if p is None or q is None or valid is None or t_measured is None:
        return []
    params = run.parameters(c)
    dynamics = chaser_dynamics(run, c)
    frame = link_frame(dynamics, str(params.get("body")), str(params.get("end_effector"))) if dynamics else c
    Pose, PoseStamped = context.msg("geometry_msgs/msg/Pose"), context.msg("geometry_msgs/msg/PoseStamped")
    return [
        RosTopic(
            f"/{c}/pose",
            "geometry_msgs/msg/PoseStamped",
            [
                (
                    int(context.stamps[row]),
                    PoseStamped(
                        header=context.header(context.stamp_of(float(t_measured[row])), frame),
                        pose=Pose(position=context.point(p[row]), orientation=context.quaternion(q[row])),
                    ),
                )
                for row in measurement_rows(valid, t_measured)
            ],
        )
    ]


POSE = RosExport("``/<c>/pose`` geometry_msgs/PoseStamped in the end effector's frame, once per accepted frame", _pose)
