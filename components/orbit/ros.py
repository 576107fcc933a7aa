"""What an orbit component exports as ROS 2 messages (its type's ``rosbag``): ``/tf`` ``eci`` ->
``<orbit>/lvlh`` per row, the LVLH frame at the orbit point (``r_eci``, m) with ``q_eci_lvlh``."""

from __future__ import annotations

from components.rosbag import ROOT_FRAME, RosContext, RosExport, RosTopic, lvlh_frame


def _topics(context: RosContext, orbit: str):
    r_eci, q_eci_lvlh = context.run.vector(f"{orbit}.r_eci", 3), context.run.vector(f"{orbit}.q_eci_lvlh", 4)
    if r_eci is None or q_eci_lvlh is None:
        return []
    frame = lvlh_frame(orbit)
    return [
        RosTopic(
            "/tf",
            "tf2_msgs/msg/TFMessage",
            [
                (int(ns), context.tf([context.transform(ns, ROOT_FRAME, frame, r_eci[row], q_eci_lvlh[row])]))
                for row, ns in enumerate(context.stamps)
            ],
        )
    ]


ROS_EXPORT = RosExport("/tf: LVLH in ECI (r_eci, q_eci_lvlh)", _topics)
