"""The cost of a camera frame on the bus against the cost of rendering it.

    python -m benchmarks.bench_frames [--frames 60]

A 640x480 frame of the capture scene (``sensor.camera``: RGB uint8 and depth float32, 2.15 MB a
step) is rendered by the camera in this process; then the same two frame messages
(``components.bus.encode_frame``) go from one Zenoh session to another over loopback TCP, each
step waiting until the receiver has decoded both (one frame in flight, as in lockstep), with the
run's secret on the link. Prints the median and 90th percentile of each, per frame, and their
ratio. Timings on a shared machine are upper bounds: state the load beside them.
"""
from __future__ import annotations

import argparse
import os
import socket
import statistics
import threading
import time

import numpy as np
import yaml


def render_times(n: int) -> tuple[list[float], dict]:
    from components.testing.harness import Harness
    from tests.conftest import ROOT
    capture = yaml.safe_load((ROOT / "configs" / "capture_vision.yaml").read_text())
    run = capture["run"]
    orbit = Harness("orbit.kepler", capture["components"]["orbit"]["parameters"], epoch=run["epoch"],
                    config_dir=ROOT / "configs")
    dynamics = Harness("dynamics.dart", capture["components"]["dynamics"]["parameters"], epoch=run["epoch"],
                       config_dir=ROOT / "configs")
    o = orbit.initialize()
    for key in ("r_eci", "v_eci", "q_eci_lvlh", "w_lvlh"):
        dynamics.inputs[key] = o[key]
    d = dynamics.initialize()
    camera = Harness("sensor.camera", capture["components"]["wrist"]["parameters"], epoch=run["epoch"],
                     config_dir=ROOT / "configs")
    for name in camera.inputs:
        camera.inputs[name] = o["r_eci"] if name == "r_eci" else d[name]
    times = []
    for _ in range(n):
        started = time.perf_counter()
        camera.step(50_000_000)
        times.append(time.perf_counter() - started)
    frames = dict(camera.frames)
    camera.component.terminate()
    return times, frames


def transport_times(frames: dict, n: int) -> list[float]:
    from components import bus
    secret = "bench"
    with socket.socket() as probe:      # a free port on loopback
        probe.bind(("127.0.0.1", 0))
        endpoint = f"tcp/127.0.0.1:{probe.getsockname()[1]}"
    receiver = bus.open_session([endpoint], secret=secret)
    sender = bus.open_session(connect=[endpoint], secret=secret)
    got = threading.Event()
    seen = []

    def on_frame(sample) -> None:
        seen.append(bus.decode_frame(sample.payload.to_bytes())[2])
        if len(seen) % 2 == 0:
            got.set()

    sub = receiver.declare_subscriber("bench/frame", on_frame)
    pub = bus.publisher(sender, "bench/frame")
    time.sleep(0.5)   # the subscription reaches the sender (a benchmark, not a test)
    times = []
    for k in range(n):
        got.clear()
        started = time.perf_counter()
        for name, frame in frames.items():
            pub.put(bus.encode_frame(0, k, name, frame))
        if not got.wait(10.0):
            raise RuntimeError("a frame did not arrive")
        times.append(time.perf_counter() - started)
    sub.undeclare()
    pub.undeclare()
    sender.close()
    receiver.close()
    return times


def summary(times: list[float]) -> str:
    ms = sorted(1e3 * t for t in times)
    return f"median {statistics.median(ms):.2f} ms, p90 {ms[int(0.9 * (len(ms) - 1))]:.2f} ms"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=60)
    args = parser.parse_args()
    render, frames = render_times(args.frames)
    size = sum(f.nbytes for f in frames.values())
    transport = transport_times(frames, args.frames)
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    print(f"render (sensor.camera step, 640x480, pixel noise as configured): {summary(render)}")
    print(f"bus (rgb + depth, {size / 1e6:.2f} MB, loopback TCP, encode + send + receive + decode): {summary(transport)}")
    print(f"ratio bus / render (medians): {statistics.median(transport) / statistics.median(render):.2f}")


if __name__ == "__main__":
    main()
