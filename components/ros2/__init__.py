"""ROS 2 over Zenoh: rmw_zenoh's conventions (:mod:`components.ros2.rmw_zenoh`) and the live ROS 2
view of a run (:mod:`components.ros2.observer`)."""
