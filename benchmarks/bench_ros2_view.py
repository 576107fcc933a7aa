"""The live ROS 2 view (``--ros2``): messages per second its publishing path sustains, and its cost
on a run.

    python benchmarks/bench_ros2_view.py throughput [--config configs/humanoid_tracking.yaml] [--duration 2s]
    python benchmarks/bench_ros2_view.py cost [--config configs/humanoid_tracking.yaml] [--duration 5s]
                                            [--rate 30] [--repeats 3]

``throughput``: records the config once, then feeds its rows, in the observer's batches (200 rows,
the most a 0.2 s batch holds at 1 kHz), through the observer's own path (LiveTopics: the export's
builders and CDR; RosPublishers: rmw_zenoh's keys and attachments) to a Zenoh router on loopback
with a subscriber counting what arrives; prints rows/s and messages/s, and the share of building
and serializing against putting. ``cost``: the run with and without ``--ros2`` (a router stand-in on
loopback, every ``--rate`` Hz of sim time; with ``--ros2-python`` the rclpy transport too), in
turn, comparing the lockstep loop time (``--profile``) and the CPU time of the whole process tree
(orchestrator, components, observer), which depends less on what else the machine does. Medians
over ``--repeats`` rounds.
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
PROFILE = re.compile(r"profile: (\d+) steps in ([0-9.]+) s wall")
ROUTER = """
import sys, zenoh
config = zenoh.Config()
config.insert_json5("mode", '"router"')
config.insert_json5("listen/endpoints", '["%s"]')
config.insert_json5("scouting/multicast/enabled", "false")
session = zenoh.open(config)
print("ready", flush=True)
sys.stdin.read()
session.close()
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Router:
    def __init__(self):
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.process = subprocess.Popen(
            [sys.executable, "-c", ROUTER % self.endpoint], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
        )
        assert self.process.stdout.readline().strip() == "ready"

    def close(self):
        self.process.stdin.close()
        self.process.wait(timeout=10)


def throughput(args) -> None:
    import pyarrow.parquet as pq
    import yaml
    import zenoh
    from rosbags.typesys import Stores, get_typestore

    from components import bus
    from components.ros2 import rmw_zenoh
    from components.ros2.observer import RosPublishers
    from components.ros_topics import LiveTopics

    with tempfile.TemporaryDirectory(prefix="zenorbit-bench-ros2-") as tmp:
        record = Path(tmp) / "rec"
        result = subprocess.run(
            [
                sys.executable,
                "-m",
                "orchestrator.cli",
                "run",
                args.config,
                "--set",
                f"run.duration={args.duration}",
                "--record",
                str(record),
            ],
            cwd=ROOT,
            capture_output=True,
            text=True,
        )
        if result.returncode:
            sys.exit(result.stderr[-2000:])
        table = pq.read_table(record / "signals.parquet")
        config = yaml.safe_load((record / "config.yaml").read_text())
    columns = [c for c in table.column_names if c not in ("step", "time")]
    times = table.column("time").to_numpy()
    rows = np.column_stack([table.column(c).to_numpy().astype(np.float64) for c in columns])
    router = Router()
    received = [0]
    ros_side = zenoh.open(bus.session_config(connect=[router.endpoint], mesh=True))
    counter = ros_side.declare_subscriber("0/**", lambda sample: received.__setitem__(0, received[0] + 1))
    session = bus.open_session(connect=[router.endpoint], settings={"mode": "client"})
    typestore = get_typestore(Stores.ROS2_JAZZY)
    node = rmw_zenoh.Node(session, 0, "bench")
    publishers = RosPublishers(node, typestore, None, print)
    live = LiveTopics(config, str(Path(args.config).resolve().parent), columns, typestore, lambda m: None)
    build = put = 0.0
    for start in range(0, len(times), 200):
        t0 = time.perf_counter()
        batch = live.batch(times[start : start + 200], rows[start : start + 200])[0]
        t1 = time.perf_counter()
        publishers.publish(batch)
        t2 = time.perf_counter()
        build, put = build + t1 - t0, put + t2 - t1
    time.sleep(3.0)  # let the last samples arrive before counting
    total = build + put
    print(
        f"{Path(args.config).name}: {len(times)} rows, {publishers.sent} messages on {len(publishers.publishers)} "
        f"topics in {total:.2f} s: {len(times) / total:.0f} rows/s, {publishers.sent / total:.0f} messages/s "
        f"(building and CDR {100 * build / total:.0f} %, put {100 * put / total:.0f} %); "
        f"{received[0]} received by a subscriber through the router"
    )
    node.close()
    session.close()
    counter.undeclare()
    ros_side.close()
    router.close()


def children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_once(config: str, duration: str, ros2: list[str], rate: str):
    """(loop s, wall s, steps, CPU s of the process tree); ``ros2``: the view's arguments, [] for none."""
    cmd = [sys.executable, "-m", "orchestrator.cli", "run", config, "--profile", "--set", f"run.duration={duration}"]
    if ros2:
        cmd += [*ros2, "--set", f"ros2.rate={rate} Hz"]
    started, cpu = time.perf_counter(), children_cpu()
    result = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=1800)
    wall, cpu = time.perf_counter() - started, children_cpu() - cpu
    if result.returncode:
        sys.exit(result.stderr[-2000:])
    match = PROFILE.search(result.stderr)
    return float(match[2]), wall, int(match[1]), cpu


def cost(args) -> None:
    router = Router()
    views = {"none": [], "zenoh": ["--ros2", router.endpoint]}
    if args.ros2_python:
        views["rclpy"] = ["--ros2", "rclpy", "--set", f"ros2.python={args.ros2_python}", "--set", "ros2.domain_id=96"]
    try:
        run_once(args.config, "0.2s", [], args.rate)
        results: dict[str, list] = {view: [] for view in views}
        for i in range(args.repeats):
            for view, extra in views.items():
                results[view].append(run_once(args.config, args.duration, extra, args.rate))
            print(
                f"  round {i + 1}: "
                + "; ".join(f"{view} loop {r[-1][0]:.3f} s, CPU {r[-1][3]:.2f} s" for view, r in results.items()),
                flush=True,
            )
    finally:
        router.close()
    loop0 = np.median([r[0] for r in results["none"]])
    cpu0 = np.median([r[3] for r in results["none"]])
    print(
        f"{Path(args.config).name}, {results['none'][0][2]} steps, ros2 at {args.rate} Hz of sim time, medians of "
        f"{args.repeats} ({os.cpu_count()} CPUs); without a view: loop {loop0:.3f} s, CPU of all processes {cpu0:.2f} s"
    )
    for view in list(views)[1:]:
        loop, cpu = np.median([r[0] for r in results[view]]), np.median([r[3] for r in results[view]])
        print(
            f"  {view}: loop {loop:.3f} s ({100 * (loop / loop0 - 1):+.1f} %), CPU {cpu:.2f} s "
            f"({100 * (cpu / cpu0 - 1):+.1f} %)"
        )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("what", choices=("throughput", "cost"))
    parser.add_argument("--config", default=str(ROOT / "configs" / "humanoid_tracking.yaml"))
    parser.add_argument("--duration", default=None, help="sim time (default: 2s throughput, 5s cost)")
    parser.add_argument("--rate", default="30", help="cost: ros2.rate, Hz of sim time")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument(
        "--ros2-python",
        default=None,
        help="cost: also the rclpy transport, with this Python (python -m tests.ros2_rclpy.environment)",
    )
    args = parser.parse_args()
    args.duration = args.duration or ("2s" if args.what == "throughput" else "5s")
    (throughput if args.what == "throughput" else cost)(args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
