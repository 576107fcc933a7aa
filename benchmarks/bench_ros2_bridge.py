"""``ros2.bridge`` in lockstep: the cost of a step over each transport, in one run.

    python benchmarks/bench_ros2_bridge.py [--steps 2000] [--repeats 3]

The spring of tests/integration/test_ros2_bridge.py under a PD law in a ROS 2 node, ``wait_for:
stamped``, two answer topics. ``zenoh``: the bridge on rmw_zenoh's wire to the stand-in node
(tests/integration/ros2_standin.py, Python, rosbags' CDR), which is also the router. ``rclpy``: the
bridge's rclpy child to a real rclpy node on Fast DDS (tests/ros2_rclpy/spring_node.py, in the ROS 2
Jazzy venv of tests/ros2_rclpy). Both nodes are Python, so the figures are transport plus node, a
round trip per step. Prints the stepping time per step (the orchestrator's own count of the loop)
and the run's wall time, medians over ``--repeats`` alternated pairs.
"""

from __future__ import annotations

import argparse
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.integration.test_ros2_bridge import KD, KP, STANDIN, _free_port, config  # noqa: E402
from tests.integration.test_ros2_rclpy import BOTH_OUTPUTS, bridge_config  # noqa: E402
from tests.ros2_rclpy.environment import ensure  # noqa: E402

SUMMARY = re.compile(r"completed: (\d+) steps.*?; ([0-9.]+) s wall \(([0-9.]+) s stepping")
SPRING_NODE = ROOT / "tests" / "ros2_rclpy" / "spring_node.py"
DOMAIN = 97


def wait_for(path: Path, process: subprocess.Popen, what: str) -> None:
    deadline = time.monotonic() + 60
    while not path.exists():
        if process.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"{what} did not come up")
        time.sleep(0.05)


def stop(process: subprocess.Popen) -> None:
    process.terminate()
    try:
        process.wait(30)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()


def run(text: str, tmp: Path) -> tuple[int, float, float]:
    path = tmp / "config.yaml"
    path.write_text(text)
    done = subprocess.run(
        [sys.executable, "-m", "orchestrator.cli", "run", str(path), "--record", str(tmp / "rec")],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    match = SUMMARY.search(done.stderr)
    if done.returncode != 0 or match is None:
        raise RuntimeError(done.stdout + done.stderr)
    return int(match[1]), float(match[2]), float(match[3])


def zenoh_once(steps: int, tmp: Path) -> tuple[int, float, float]:
    port = _free_port()
    node = subprocess.Popen(
        [
            sys.executable,
            str(STANDIN),
            "--listen",
            f"tcp/127.0.0.1:{port}",
            "--kp",
            str(KP),
            "--kd",
            str(KD),
            "--ready",
            str(tmp / "ready"),
            "--clock-log",
            str(tmp / "clock.log"),
        ],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        wait_for(tmp / "ready", node, "the stand-in node")
        return run(config("bench_zenoh", port, steps=steps), tmp)
    finally:
        stop(node)


def rclpy_once(steps: int, tmp: Path, python: str) -> tuple[int, float, float]:
    node = subprocess.Popen(
        [
            python,
            str(SPRING_NODE),
            "--domain",
            str(DOMAIN),
            "--kp",
            str(KP),
            "--kd",
            str(KD),
            "--ready",
            str(tmp / "ready"),
            "--log",
            str(tmp / "answers.log"),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        wait_for(tmp / "ready", node, "the rclpy node")
        return run(bridge_config("bench_rclpy", python, DOMAIN, BOTH_OUTPUTS, steps=steps), tmp)
    finally:
        stop(node)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    python = str(ensure())
    results: dict[str, list[tuple[int, float, float]]] = {"zenoh": [], "rclpy": []}
    for _ in range(args.repeats):
        with tempfile.TemporaryDirectory() as a, tempfile.TemporaryDirectory() as b:
            results["zenoh"].append(zenoh_once(args.steps, Path(a)))
            results["rclpy"].append(rclpy_once(args.steps, Path(b), python))
    per_step = {}
    for transport, rows in results.items():
        steps = rows[0][0]
        assert all(r[0] == steps == args.steps for r in rows), rows
        per_step[transport] = statistics.median(r[2] for r in rows) / steps * 1e3
        wall = statistics.median(r[1] for r in rows)
        print(f"{transport:6s} {steps} steps: {per_step[transport]:.3f} ms a step (stepping), run {wall:.1f} s wall")
    print(f"rclpy / zenoh per step: {per_step['rclpy'] / per_step['zenoh']:.2f}")


if __name__ == "__main__":
    main()
