"""The cost of a camera frame on the bus against the cost of rendering it; on disk, its bytes and
write/read time as recorded (deflated) against the uncompressed files recorded before.

    python -m benchmarks.bench_frames [--frames 60]
    python -m benchmarks.bench_frames --disk RUN_DIR/frames/wrist   # the frames of a recorded run

A 640x480 frame of the capture scene (``sensor.camera``: RGB uint8 and depth float32, 2.15 MB a
step) is rendered by the camera in this process; then the same two frame messages
(``components.bus.encode_frame``) go from one Zenoh session to another over loopback TCP, each
step waiting until the receiver has decoded both (one frame in flight, as in lockstep), with the
run's secret on the link. Prints the median and 90th percentile of each, per frame, and their
ratio. Timings on a shared machine are upper bounds: state the load beside them.

``--disk DIR``: each frame file in DIR (e.g. ``orchestrator run configs/capture_vision.yaml
--record runs/vision --set run.duration=6s``, then ``runs/vision/frames/wrist``) is read and
written again in both formats as the camera's writer does (a hidden file, renamed into place)
into a temporary directory beside DIR, then read back whole (the page cache warm: the cost of
decoding, not of the disk); prints bytes, write (wall and the thread's CPU: the load does not
inflate the latter) and read ms per frame, and checks that every
array reads back bit for bit.
"""

from __future__ import annotations

import argparse
import os
import shutil
import socket
import statistics
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import yaml


def render_times(n: int) -> tuple[list[float], dict]:
    from components.testing.harness import Harness
    from tests.conftest import ROOT

    capture = yaml.safe_load((ROOT / "configs" / "capture_vision.yaml").read_text())
    run = capture["run"]
    orbit = Harness(
        "orbit.kepler", capture["components"]["orbit"]["parameters"], epoch=run["epoch"], config_dir=ROOT / "configs"
    )
    dynamics = Harness(
        "dynamics.dart",
        capture["components"]["dynamics"]["parameters"],
        epoch=run["epoch"],
        config_dir=ROOT / "configs",
    )
    o = orbit.initialize()
    for key in ("r_eci", "v_eci", "q_eci_lvlh", "w_lvlh"):
        dynamics.inputs[key] = o[key]
    d = dynamics.initialize()
    camera = Harness(
        "sensor.camera", capture["components"]["wrist"]["parameters"], epoch=run["epoch"], config_dir=ROOT / "configs"
    )
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
    with socket.socket() as probe:  # a free port on loopback
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
    time.sleep(0.5)  # the subscription reaches the sender (a benchmark, not a test)
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


def disk(directory: Path) -> None:
    from components.camera.frames import frame_files, read_frame, write_frame

    frames = [read_frame(path) for path in frame_files(directory)]
    if not frames:
        raise SystemExit(f"--disk {directory}: expected the frame files of a recorded camera (NNNNNN.npz), got none")
    raw = statistics.mean(sum(a.nbytes for a in f.values()) for f in frames)
    print(
        f"{len(frames)} frames of {directory}, {frames[0]['rgb'].shape[1]}x{frames[0]['rgb'].shape[0]}, "
        f"{raw / 1e6:.2f} MB of arrays each"
    )
    formats = {
        "uncompressed (numpy.savez, before)": lambda f, arrays: np.savez(f, **arrays),
        "deflated (write_frame, level 1, now)": write_frame,
    }
    for label, write in formats.items():
        out = Path(tempfile.mkdtemp(prefix=".bench_frames.", dir=directory.parent))
        try:
            writes, cpu, reads, sizes = [], [], [], []
            for k, arrays in enumerate(frames):
                path, hidden = out / f"{k:06d}.npz", out / f".{k:06d}.npz.part"
                started, started_cpu = time.perf_counter(), time.thread_time()
                with open(hidden, "wb") as f:
                    write(f, arrays)
                os.replace(hidden, path)
                writes.append(time.perf_counter() - started)
                cpu.append(time.thread_time() - started_cpu)
                sizes.append(path.stat().st_size)
            for k, arrays in enumerate(frames):
                started = time.perf_counter()
                back = read_frame(out / f"{k:06d}.npz")
                reads.append(time.perf_counter() - started)
                if any(
                    back[key].tobytes() != value.tobytes() or back[key].dtype != value.dtype
                    for key, value in arrays.items()
                ):
                    raise SystemExit(f"{label}: frame {k} does not read back bit for bit")
        finally:
            shutil.rmtree(out, ignore_errors=True)
        print(
            f"{label}: {statistics.mean(sizes) / 1e6:.3f} MB a frame (min {min(sizes) / 1e6:.3f}, "
            f"max {max(sizes) / 1e6:.3f}); write {summary(writes)} (CPU {summary(cpu)}); read {summary(reads)}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument(
        "--disk",
        type=Path,
        metavar="DIR",
        help="a recorded camera's frames: bytes and write/read time per frame, uncompressed against deflated",
    )
    args = parser.parse_args()
    if args.disk is not None:
        print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
        disk(args.disk)
        return
    render, frames = render_times(args.frames)
    size = sum(f.nbytes for f in frames.values())
    transport = transport_times(frames, args.frames)
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    print(f"render (sensor.camera step, 640x480, pixel noise as configured): {summary(render)}")
    print(
        f"bus (rgb + depth, {size / 1e6:.2f} MB, loopback TCP, encode + send + receive + decode): {summary(transport)}"
    )
    print(f"ratio bus / render (medians): {statistics.median(transport) / statistics.median(render):.2f}")


if __name__ == "__main__":
    main()
