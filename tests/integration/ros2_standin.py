"""A stand-in for a user's ROS 2 node, for the ``ros2.bridge`` tests: a plain Zenoh program that
follows rmw_zenoh's wire conventions on its own (key expressions, CDR, the 33-byte attachment,
liveliness tokens),
written here from rmw_zenoh's design rather than with components.ros2.rmw_zenoh, so the bridge is
checked against a second reading of them.

It listens where a ROS router (rmw_zenohd) would, subscribes to a sensor_msgs/JointState topic and
to /clock, and answers each JointState with a PD effort ``-kp * position - kd * velocity`` on two
topics: a trajectory_msgs/JointTrajectory (points[0].effort) stamped with the JointState's stamp,
and a std_msgs/Float64MultiArray (no header: one answer per message received). With
``--answer-until NS`` it stops answering messages stamped later (the node "hangs"). It writes
every /clock stamp it received to ``--clock-log`` when it is stopped (SIGTERM), and creates
``--ready`` once its subscriptions are declared, ``--waiting`` once it has let a message go
unanswered.

    python tests/integration/ros2_standin.py --listen tcp/127.0.0.1:7447 --kp 3 --kd 0.5 ...
"""

from __future__ import annotations

import argparse
import queue
import signal
import struct
import sys
from pathlib import Path

import numpy as np

ATTACHMENT = struct.Struct("<qqB16s")  # sequence, source timestamp (ns), LEB128 length 16, GID


def key(domain: int, topic: str, msgtype: str, typestore) -> str:
    """``<domain>/<topic without leading '/'>/<pkg>::msg::dds_::<Name>_/RIHS01_<hash>``."""
    package, _, name = msgtype.split("/")
    return f"{domain}/{topic.strip('/')}/{package}::msg::dds_::{name}_/{typestore.hash_rihs01(msgtype)}"


def token(
    domain: int, zid: str, entity: int, kind: str, topic: str | None = None, msgtype: str | None = None, typestore=None
) -> str:
    """A liveliness token of node ``standin`` (id 0) in namespace and enclave ``/``: ``@ros2_lv/<domain>/<zid>/
    <node id>/<entity id>/<NN|MP|MS>/<enclave>/<namespace>/<name>[/<topic>/<type>/<hash>/<qos>]``, '/' in
    names as '%', the QoS (reliable, volatile, keep last 10) with rmw_zenoh's defaults left empty."""
    parts = ["@ros2_lv", str(domain), zid, "0", str(entity), kind, "%", "%", "standin"]
    if topic is not None:
        package, _, name = msgtype.split("/")
        parts += [
            topic.replace("/", "%"),
            f"{package}::msg::dds_::{name}_",
            typestore.hash_rihs01(msgtype),
            "::,10:,:,:,,",
        ]
    return "/".join(parts)


def main() -> int:
    import zenoh
    from rosbags.typesys import Stores, get_typestore

    parser = argparse.ArgumentParser()
    parser.add_argument("--listen", required=True)
    parser.add_argument("--domain", type=int, default=0)
    parser.add_argument("--state", default="/spring/joint_states")
    parser.add_argument("--effort", default="/spring/effort")
    parser.add_argument("--effort-array", default="/spring/effort_array")
    parser.add_argument("--kp", type=float, required=True)
    parser.add_argument("--kd", type=float, required=True)
    parser.add_argument("--answer-until", type=int, default=None, help="answer messages stamped up to this (ns)")
    parser.add_argument("--ready", type=Path, required=True)
    parser.add_argument("--waiting", type=Path)
    parser.add_argument("--clock-log", type=Path, required=True)
    args = parser.parse_args()

    store = get_typestore(Stores.ROS2_JAZZY)
    types = store.types
    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("listen/endpoints", f'["{args.listen}"]')
    config.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(config)
    gid = bytes(range(16))
    sequence = {"n": 0}
    effort_key = key(args.domain, args.effort, "trajectory_msgs/msg/JointTrajectory", store)
    array_key = key(args.domain, args.effort_array, "std_msgs/msg/Float64MultiArray", store)
    received: queue.SimpleQueue = queue.SimpleQueue()  # callbacks only enqueue; the main thread answers
    clocks: list[int] = []

    def put(k: str, message, msgtype: str, stamp: int) -> None:
        sequence["n"] += 1
        session.put(
            k, bytes(store.serialize_cdr(message, msgtype)), attachment=ATTACHMENT.pack(sequence["n"], stamp, 16, gid)
        )

    def on_state(sample) -> None:
        seq, _, length, _ = ATTACHMENT.unpack(sample.attachment.to_bytes())  # an rmw_zenoh sample has one
        assert length == 16 and seq >= 1
        received.put(("state", sample.payload.to_bytes()))

    def on_clock(sample) -> None:
        ATTACHMENT.unpack(sample.attachment.to_bytes())
        received.put(("clock", sample.payload.to_bytes()))

    subscribers = [
        session.declare_subscriber(key(args.domain, args.state, "sensor_msgs/msg/JointState", store), on_state),
        session.declare_subscriber(key(args.domain, "/clock", "rosgraph_msgs/msg/Clock", store), on_clock),
    ]
    zid = str(session.info.zid())
    tokens = [
        session.liveliness().declare_token(t)
        for t in (
            token(args.domain, zid, 0, "NN"),
            token(args.domain, zid, 1, "MS", args.state, "sensor_msgs/msg/JointState", store),
            token(args.domain, zid, 2, "MS", "/clock", "rosgraph_msgs/msg/Clock", store),
            token(args.domain, zid, 3, "MP", args.effort, "trajectory_msgs/msg/JointTrajectory", store),
            token(args.domain, zid, 4, "MP", args.effort_array, "std_msgs/msg/Float64MultiArray", store),
        )
    ]
    signal.signal(signal.SIGTERM, lambda *_: received.put(("stop", b"")))
    args.ready.touch()
    try:
        while True:
            kind, payload = received.get()
            if kind == "stop":
                break
            if kind == "clock":
                clock = store.deserialize_cdr(payload, "rosgraph_msgs/msg/Clock").clock
                clocks.append(clock.sec * 1_000_000_000 + clock.nanosec)
                continue
            state = store.deserialize_cdr(payload, "sensor_msgs/msg/JointState")
            stamp = state.header.stamp.sec * 1_000_000_000 + state.header.stamp.nanosec
            if args.answer_until is not None and stamp > args.answer_until:
                if args.waiting is not None:
                    args.waiting.touch()
                continue
            effort = -args.kp * state.position - args.kd * state.velocity
            point = types["trajectory_msgs/msg/JointTrajectoryPoint"](
                positions=np.empty(0),
                velocities=np.empty(0),
                accelerations=np.empty(0),
                effort=effort,
                time_from_start=types["builtin_interfaces/msg/Duration"](sec=0, nanosec=0),
            )
            put(
                effort_key,
                types["trajectory_msgs/msg/JointTrajectory"](
                    header=state.header, joint_names=list(state.name), points=[point]
                ),
                "trajectory_msgs/msg/JointTrajectory",
                stamp,
            )
            layout = types["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=0)
            put(
                array_key,
                types["std_msgs/msg/Float64MultiArray"](layout=layout, data=effort),
                "std_msgs/msg/Float64MultiArray",
                stamp,
            )
    finally:
        args.clock_log.write_text("".join(f"{c}\n" for c in clocks))
        for declared in subscribers + tokens:
            declared.undeclare()
        session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
