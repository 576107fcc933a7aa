"""Camera frames in the live views: one real run of the capture scenario with a wrist camera
(sensor.camera, 10 Hz, 640x480 RGB + depth), recorded, paced at real time, with both live views
on: ``--ros2`` through ``orchestrator router --ros2`` (rmw_zenohd's configuration) to a subscriber
on rmw_zenoh's data keys, and ``--view foxglove`` to a Foxglove WebSocket client. Every
Image and CameraInfo either view delivers is, byte for byte, the rosbag2 export's message of that
topic and stamp, which the export builds from the recorded frame files (``frames/camera/*.npz``),
not from the bus; the stamps are the frames' run times (epoch + t), one per camera step. A view
waits for its mesh link to the camera before the run starts; frames may still drop on the way
(the cameras' publishers drop rather than hold up a step) on a loaded machine, never arrive
twice or out of order.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading

import numpy as np
import pytest

from components.camera.render import egl_problem
from tests.conftest import ROOT, component_processes, orchestrator
from tests.integration.test_camera_run import camera_config
from tests.integration.test_foxglove_view import DEADLINE_S, Client, _bag, _free_port
from tests.integration.test_ros2_router import Router

pytestmark = [
    pytest.mark.integration,
    pytest.mark.skipif(egl_problem() is not None, reason=f"no EGL here: {egl_problem()}"),
]

DOMAIN = 9
TOPICS = ("/camera/image_raw", "/camera/depth/image_raw", "/camera/camera_info")
EPOCH_NS = 1663502400 * 10**9  # the capture scenario's run.epoch, 2022-09-18T12:00:00Z
FRAMES = 10  # 1 s at 10 Hz


class RosSubscriber:
    """A peer of the stand-in router subscribed to the camera's topics on rmw_zenoh's data keys
    (``<domain>/<topic>/<DDS type>/<hash>``): (topic, payload) of each sample."""

    def __init__(self, endpoint: str):
        import zenoh

        from components import bus

        self.session = zenoh.open(bus.session_config(connect=[endpoint], mesh=True))
        self.samples: list[tuple[str, bytes]] = []
        self.lock = threading.Lock()
        self.subscriber = self.session.declare_subscriber(f"{DOMAIN}/camera/**", self._sample)

    def _sample(self, sample) -> None:
        _, *topic, _, _ = str(sample.key_expr).split("/")
        with self.lock:
            self.samples.append(("/" + "/".join(topic), sample.payload.to_bytes()))

    def close(self) -> None:
        self.subscriber.undeclare()
        self.session.close()


def _stamp(cdr: bytes) -> int:
    """The header stamp of an Image or CameraInfo (CDR: 4-byte encapsulation, then sec, nanosec)."""
    sec, nanosec = np.frombuffer(cdr, dtype="<i4", count=2, offset=4)
    return int(sec) * 10**9 + int(nanosec)


@pytest.fixture(scope="module")
def live(tmp_path_factory):
    base = tmp_path_factory.mktemp("live_images")
    config = camera_config(base / "camera.yaml")
    router, port = Router(_free_port()), _free_port()
    endpoint = router.endpoint
    ros = run = client = None
    try:
        ros = RosSubscriber(endpoint)
        run = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "orchestrator.cli",
                "run",
                str(config),
                "--set",
                "run.realtime=1",
                "--record",
                str(base / "rec"),
                "--ros2",
                endpoint,
                "--view",
                f"foxglove:{port}",
            ],
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env={**os.environ, "ROS_DOMAIN_ID": str(DOMAIN)},
        )
        client = Client(port, run)
        _, err = run.communicate(timeout=DEADLINE_S)
        client.thread.join(timeout=30)
    finally:
        if run is not None and run.poll() is None:
            run.kill()
            run.wait()
        if ros is not None:
            ros.close()
        router.stop()
    assert run.returncode == 0, err[-3000:]
    assert not component_processes("capture_tumbling_target"), "component processes left after the run"
    assert client.error is None, repr(client.error)
    exported = orchestrator("export", base / "rec", "--rosbag2", base / "bag")
    assert exported.returncode == 0, exported.stderr
    bag, _ = _bag(base / "bag")
    return ros.samples, [(t, data) for t, _, data in client.messages if t in TOPICS], bag, base / "rec", err


def _check(messages, bag, record, err):
    """Every message equals the export's of its topic and stamp; each topic has the frames in order,
    none twice, most of them (a loaded machine may drop a few: the views never hold up a step)."""
    frames = sorted((record / "frames" / "camera").glob("*.npz"))
    assert len(frames) == FRAMES
    stamps = []
    for path in frames:
        with np.load(path) as frame:
            stamps.append(EPOCH_NS + round(float(frame["t"]) * 1e9))
    assert stamps == [EPOCH_NS + k * 100_000_000 for k in range(FRAMES)]  # the camera's rate, in run time
    by_topic: dict[str, list[int]] = {}
    for topic, data in messages:
        ns = _stamp(data)
        assert data in bag[topic, ns], f"{topic} at {ns}: not the export's message"
        by_topic.setdefault(topic, []).append(ns)
    assert set(by_topic) == set(TOPICS), err[-3000:]
    for topic, received in by_topic.items():
        assert received == [ns for ns in stamps if ns in received], f"{topic}: {received}\n{err[-3000:]}"
        assert len(received) >= FRAMES // 2, f"{topic}\n{err[-3000:]}"


def test_the_ros2_view_carries_every_frame_as_the_export_does(live):
    samples, _, bag, record, err = live
    _check(samples, bag, record, err)


def test_the_foxglove_view_carries_every_frame_as_the_export_does(live):
    _, messages, bag, record, err = live
    _check(messages, bag, record, err)


def test_the_image_is_the_recorded_frame(live):
    """Independently of the export's builders: the Image's data is the recorded array's bytes (the
    last frame both images of which the ROS 2 view delivered)."""
    samples, _, _, record, err = live
    both = {_stamp(d) for t, d in samples if t == "/camera/image_raw"} & {
        _stamp(d) for t, d in samples if t == "/camera/depth/image_raw"
    }
    assert both, err[-3000:]
    k = (max(both) - EPOCH_NS) // 100_000_000  # the frame file of that stamp (the camera's 10 Hz)
    with np.load(record / "frames" / "camera" / f"{k:06d}.npz") as frame:
        rgb, depth = frame["rgb"], frame["depth"]
        assert EPOCH_NS + round(float(frame["t"]) * 1e9) == max(both)
    image = [d for t, d in samples if t == "/camera/image_raw" and _stamp(d) == max(both)]
    depth_image = [d for t, d in samples if t == "/camera/depth/image_raw" and _stamp(d) == max(both)]
    assert len(image) == len(depth_image) == 1, err[-3000:]
    assert len(image[0]) == 921_652 and len(depth_image[0]) == 1_228_852
    assert image[0][-rgb.nbytes :] == rgb.tobytes() and depth_image[0][-depth.nbytes :] == depth.astype("<f4").tobytes()
    assert np.any(rgb) and np.any(depth)  # the grapple is in view: not a blank frame
