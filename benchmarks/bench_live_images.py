"""The cost of camera frames in the live views (``--ros2``, ``--view foxglove``), at 640x480.

    python -m benchmarks.bench_live_images [--frames 100]

- in the camera's process, per step: ``live_frames.LiveFrameSender.send`` while nobody watches (a dict
  look-up: nothing encoded), and the encoding of the view messages when a view watches
  (``bus.encode_view_frame``, RGB uint8 and depth float32);
- in the view, per frame: :meth:`components.ros_frames.LiveFrames.take` for one RGB + depth frame
  (decode, build Image, Image and CameraInfo as the export does, serialize to CDR), the messages
  handed to it as its subscriber would.

Prints the medians and the CDR sizes. Timings on a shared machine are upper bounds: state the load
beside them. A benchmark, never run by the tests.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np
import yaml


class _Sample:
    """A message as the view's subscriber gets it (``sample.payload.to_bytes()``)."""

    def __init__(self, payload: bytes):
        self.payload, self._bytes = self, payload

    def to_bytes(self) -> bytes:
        return self._bytes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=100)
    args = parser.parse_args()

    import tempfile
    from pathlib import Path

    from rosbags.typesys import Stores, get_typestore

    from components import bus
    from components.live_frames import LiveFrameSender
    from components.ros_frames import LiveFrames
    from tests.integration.test_camera_run import camera_config

    with tempfile.TemporaryDirectory() as tmp:
        config = yaml.safe_load(camera_config(Path(tmp) / "camera.yaml").read_text())
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (480, 640, 3), dtype=np.uint8)
    depth = rng.random((480, 640), dtype=np.float32)

    session = bus.open_session()
    try:
        sender = LiveFrameSender(session, "bench", "camera")
        sender.declare(["rgb", "depth"])
        idle = []
        for _ in range(args.frames):
            started = time.perf_counter()
            sender.send("rgb", 0, 0, 1, rgb)
            sender.send("depth", 0, 0, 1, depth)
            idle.append(time.perf_counter() - started)
        encode, payloads = [], []
        for k in range(args.frames):
            started = time.perf_counter()
            pair = (
                bus.encode_view_frame(k * 100_000_000, 0, k, "rgb", rgb),
                bus.encode_view_frame(k * 100_000_000, 0, k, "depth", depth),
            )
            encode.append(time.perf_counter() - started)
            payloads.append(pair)
        frames = LiveFrames(session, "bench", config, None, get_typestore(Stores.ROS2_JAZZY), print)
        keep_rgb, keep_depth = frames._keeper("camera", "rgb"), frames._keeper("camera", "depth")
        view, sizes = [], {}
        for image, depth_message in payloads:
            keep_rgb(_Sample(image))
            keep_depth(_Sample(depth_message))
            started = time.perf_counter()
            batch = frames.take()
            view.append(time.perf_counter() - started)
            sizes = {topic.name: len(messages[0][1]) for topic, messages in batch}
        frames.undeclare()
        sender.undeclare()
    finally:
        session.close()
    ms = lambda values: 1e3 * statistics.median(values)  # noqa: E731
    print(f"640x480 RGB + depth, {args.frames} frames")
    print(f"camera, nobody watching: {1e6 * statistics.median(idle):.2f} us a step (nothing encoded)")
    print(f"camera, a view watching: encode {ms(encode):.2f} ms a frame (RGB + depth view messages)")
    print(f"view: {ms(view):.2f} ms a frame (decode, Image + Image + CameraInfo, CDR)")
    for topic, size in sorted(sizes.items()):
        print(f"  {topic}: {size:,} B")
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")


if __name__ == "__main__":
    main()
