"""A stock ROS 2 subscriber for the tests, run by the Python that has rclpy (not the project's): it
subscribes to each ``--topic NAME=pkg/msg/Type`` as a ROS 2 user's node would (reliable; a latched
topic TRANSIENT_LOCAL, depth 1), keeps every message's CDR bytes in arrival order, and writes them
as JSON lines ``{"topic", "cdr" (hex)}`` to ``--out`` when its stdin closes. ``--ready`` is created
once every subscription is up; ``--first`` when the first message arrives; ``--until-all`` ends it
once every topic has had a message. Imports only the standard library and rclpy.

    python listener.py --topic /clock=rosgraph_msgs/msg/Clock --latched /x --ready R --out O
"""

import argparse
import importlib
import json
import sys
import threading
from pathlib import Path

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy


def message_class(msgtype: str):
    package, kind, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), name)


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--topic", action="append", default=[], help="NAME=pkg/msg/Type")
    parser.add_argument("--latched", action="append", default=[], help="a topic subscribed TRANSIENT_LOCAL")
    parser.add_argument("--domain", type=int, required=True)
    parser.add_argument("--ready", type=Path, required=True)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--first", type=Path, help="created when the first message arrives")
    parser.add_argument(
        "--until-all", action="store_true", help="end once every topic has had a message (else when stdin closes)"
    )
    args = parser.parse_args()
    rclpy.init(domain_id=args.domain)
    node = rclpy.create_node("test_listener")
    received, lock = [], threading.Lock()
    every_topic = threading.Event()
    topics = {spec.split("=")[0] for spec in args.topic}

    def keep(topic):
        def on_message(data: bytes) -> None:
            with lock:
                if not received and args.first is not None:
                    args.first.write_text("first")
                received.append((topic, data))
                if {t for t, _ in received} == topics:
                    every_topic.set()

        return on_message

    for spec in args.topic:
        topic, msgtype = spec.split("=")
        latched = topic in args.latched
        qos = QoSProfile(
            history=HistoryPolicy.KEEP_LAST,
            depth=1 if latched else 1000,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
        )
        node.create_subscription(message_class(msgtype), topic, keep(topic), qos, raw=True)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    args.ready.write_text("ready")
    if args.until_all:
        every_topic.wait()
    else:
        sys.stdin.read()  # until the test closes it
    executor.shutdown(timeout_sec=1.0)
    rclpy.try_shutdown()
    spinner.join(timeout=2.0)
    with lock:
        lines = [json.dumps({"topic": t, "cdr": d.hex()}) for t, d in received]
    args.out.write_text("\n".join(lines) + ("\n" if lines else ""))
    node.destroy_node()
    return 0


if __name__ == "__main__":
    sys.exit(main())
