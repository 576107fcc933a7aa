"""A ROS 2 user's node for the ``ros2.bridge`` tests, on rclpy (run by the Python that has it, not
the project's): a PD law on a spring. It subscribes to ``/spring/joint_states`` and answers each
with the effort ``-kp * position - kd * velocity`` on ``/spring/effort`` (trajectory_msgs/
JointTrajectory, points[0].effort, stamped with the state's stamp) and ``/spring/effort_array``
(std_msgs/Float64MultiArray, no header). It runs with ``use_sim_time``: it answers a state once its
own clock (from ``/clock``) has reached the state's stamp, and writes, per answer, its clock's time
then (``--log``, one ``stamp now`` line per answer, written as it goes). ``--exit-after N`` ends the
process after N answers (a node that dies). ``--ready`` is created once its subscriptions are up.
Imports only the standard library and ROS 2's packages.
"""

import argparse
import queue
import sys
import threading
from pathlib import Path

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

CLOCK_WAIT_S = 30.0


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--domain", type=int, required=True)
    parser.add_argument("--kp", type=float, required=True)
    parser.add_argument("--kd", type=float, required=True)
    parser.add_argument("--ready", type=Path, required=True)
    parser.add_argument("--log", type=Path, required=True)
    parser.add_argument("--exit-after", type=int, default=None)
    args = parser.parse_args()
    rclpy.init(domain_id=args.domain)
    node = rclpy.create_node("spring_pd", parameter_overrides=[Parameter("use_sim_time", Parameter.Type.BOOL, True)])
    states: queue.SimpleQueue = queue.SimpleQueue()  # callbacks only enqueue; the main thread answers
    effort_pub = node.create_publisher(JointTrajectory, "/spring/effort", 10)
    array_pub = node.create_publisher(Float64MultiArray, "/spring/effort_array", 10)
    node.create_subscription(JointState, "/spring/joint_states", states.put, 10)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    threading.Thread(target=executor.spin, daemon=True).start()
    args.ready.write_text("ready")
    answered = 0
    with args.log.open("w") as log:
        while args.exit_after is None or answered < args.exit_after:
            state = states.get()
            stamp = state.header.stamp.sec * 1_000_000_000 + state.header.stamp.nanosec
            waited = 0.0
            while node.get_clock().now().nanoseconds < stamp and waited < CLOCK_WAIT_S:
                threading.Event().wait(0.001)
                waited += 0.001
            now = node.get_clock().now().nanoseconds
            effort = [-args.kp * p - args.kd * v for p, v in zip(state.position, state.velocity)]
            effort_pub.publish(
                JointTrajectory(
                    header=state.header, joint_names=list(state.name), points=[JointTrajectoryPoint(effort=effort)]
                )
            )
            array_pub.publish(Float64MultiArray(data=effort))
            log.write(f"{stamp} {now}\n")
            log.flush()
            answered += 1
    executor.shutdown(timeout_sec=1.0)
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
