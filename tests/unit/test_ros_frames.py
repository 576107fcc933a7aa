"""Frames for the live views (components/live_frames.py ``LiveFrameSender``, components/ros_frames.py,
components/camera/ros.py ``frame_topics``): the view message round trip; a component's process
hands each step's frames to its sender stamped when taken; the live Image/CameraInfo of a frame is
byte for byte what the rosbag2 export builds from the same frame recorded to a file; and over real
Zenoh sessions in this process, nothing is sent until a view subscribes, then every frame arrives."""

from __future__ import annotations

import socket
import time

import numpy as np
import pytest
import yaml
from rosbags.typesys import Stores, get_typestore

from components import bus, protocol
from components.camera.ros import _camera, frame_topics
from components.live_frames import LiveFrameSender
from components.plotting import RecordedRun
from components.process import ComponentProcess
from components.ros_frames import LiveFrames
from components.rosbag import RosContext
from components.sdk import RunSettings
from tests.integration.test_camera_run import camera_config

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
EPOCH_NS = 1663502400 * 10**9  # the capture scenario's epoch


def test_a_view_frame_survives_encoding_and_a_cut_one_is_malformed():
    depth = np.random.default_rng(3).standard_normal((6, 8)).astype(np.float32)
    payload = bus.encode_view_frame(123_456_789, 2, 40, "depth", depth)
    taken, generation, tag, output, back = bus.decode_view_frame(payload)
    assert (taken, generation, tag, output) == (123_456_789, 2, 40, "depth")
    assert back.dtype == np.float32 and back.tobytes() == depth.tobytes()
    for bad in (payload[:-1], payload[:5], b"F" + payload[1:]):
        with pytest.raises(protocol.Malformed):
            bus.decode_view_frame(bad)


class Sent(list):
    """The process's view sender, as a list of what it was handed."""

    def declare(self, outputs):
        self.declared = list(outputs)

    def send(self, output, taken_ns, generation, tag, frame):
        self.append((output, taken_ns, tag, frame.copy()))
        return True


def test_the_process_hands_each_steps_frames_to_the_view_stamped_at_the_step():
    p = ComponentProcess("camera", lambda payload: None, lambda consumers, payload: None, lambda payload: None)
    p.view = Sent()
    p.command(protocol.Instantiate("test.imager", {"width": 8, "height": 6}, RunSettings().to_json()).encode())
    p.command(
        protocol.Wire(
            generation=0,
            step_ns=1_000_000,
            ratio=2,
            k=0,
            batch_consumers=[],
            faults=[],
            consumers=[],
            routes=[],
            sources={},
        ).encode()
    )  # no consumer of its frames
    p.command(protocol.Initialize(0, {}, np.zeros(p.inputs.size)).encode())
    p.command(protocol.Sync().encode())
    assert p.view == [] and p.view.declared == ["rgb", "depth"]  # initialize's frames are not a step's
    p.command(protocol.Start([], 6, np.empty(0)).encode())
    p.advance()
    assert [(o, t, tag) for o, t, tag, _ in p.view] == [
        ("rgb", 0, 2),
        ("depth", 0, 2),
        ("rgb", 2_000_000, 4),
        ("depth", 2_000_000, 4),
        ("rgb", 4_000_000, 6),
        ("depth", 4_000_000, 6),
    ]
    assert p.view[2][3].tobytes() != p.view[0][3].tobytes()  # each step its own frame


@pytest.fixture(scope="module")
def camera_run(tmp_path_factory):
    """The capture scenario's config with a 640x480 camera (as test_camera_run builds it)."""
    base = tmp_path_factory.mktemp("ros_frames")
    config = yaml.safe_load(camera_config(base / "camera.yaml").read_text())
    return config, base


def _frame(seed: int):
    rng = np.random.default_rng(seed)
    return rng.integers(0, 256, (480, 640, 3), dtype=np.uint8), rng.random((480, 640), dtype=np.float32)


def test_the_live_messages_of_a_frame_are_the_exports_of_it_recorded(camera_run):
    config, base = camera_run
    rgb, depth = _frame(1)
    t = 0.3
    K = np.array([[500.0, 0.0, 301.3], [0.0, 500.0, 251.7], [0.0, 0.0, 1.0]])  # the config's fx, fy, cx, cy
    (base / "rec" / "frames" / "camera").mkdir(parents=True)
    np.savez(
        base / "rec" / "frames" / "camera" / "000003.npz",
        rgb=rgb,
        depth=depth,
        K=K,
        D=np.zeros(5),
        T_link_camera=np.eye(4),
        t=np.float64(t),
    )
    recorded = RosContext(RecordedRun(config, {}, np.zeros(1), None, base / "rec"), TYPESTORE, print)
    exported = {topic.name: topic for topic in _camera(recorded, "camera") if topic.name != "/tf_static"}
    live = frame_topics(RosContext(RecordedRun(config, {}, np.zeros(1), None), TYPESTORE, print), "camera")
    assert {o: [t.name for t in topics] for o, topics in live.outputs.items()} == {
        "rgb": ["/camera/image_raw", "/camera/camera_info"],
        "depth": ["/camera/depth/image_raw"],
    }
    ns = EPOCH_NS + 300_000_000
    messages = live.messages("rgb", ns, rgb) + live.messages("depth", ns, depth)
    assert (
        sorted(topic.name for topic, _ in messages)
        == sorted(exported)
        == ["/camera/camera_info", "/camera/depth/image_raw", "/camera/image_raw"]
    )
    for topic, message in messages:
        ((stamp, reference),) = exported[topic.name].messages
        assert stamp == ns
        assert bytes(TYPESTORE.serialize_cdr(message, topic.msgtype)) == bytes(
            TYPESTORE.serialize_cdr(reference, topic.msgtype)
        )


def _until(condition, timeout_s: float = 30.0) -> bool:
    """Poll ``condition`` (Zenoh delivers on its own thread) until true or the time is up."""
    deadline = time.monotonic() + timeout_s
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.005)
    return condition()


def test_frames_go_only_while_a_view_subscribes_and_then_all_arrive(camera_run):
    config, _ = camera_run
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        endpoint = f"tcp/127.0.0.1:{probe.getsockname()[1]}"
    camera = bus.open_session([endpoint], [], mesh=True)
    view = frames = sender = None
    try:
        sender = LiveFrameSender(camera, "r1", "camera")
        sender.declare(["rgb", "depth"])
        rgb, _depth = _frame(2)
        assert not sender.send("rgb", 0, 0, 10, rgb)  # nobody watches: nothing encoded, nothing sent
        view = bus.open_session([], [endpoint], mesh=True)
        frames = LiveFrames(view, "r1", config, None, TYPESTORE, print, topics=["/camera/image_raw"])
        assert _until(lambda: sender.watched.get("rgb"))
        assert not sender.watched.get("depth")  # its topic was not asked for
        for k in range(3):  # one at a time: a frame the link cannot take at once is dropped, by design
            assert sender.send("rgb", k * 100_000_000, 0, 10 * (k + 1), np.roll(rgb, k))
            assert _until(lambda k=k: frames.received == k + 1)
        batch = {topic.name: messages for topic, messages in frames.take()}
        assert sorted(batch) == ["/camera/camera_info", "/camera/image_raw"]
        assert [ns for ns, _ in batch["/camera/image_raw"]] == [EPOCH_NS + k * 100_000_000 for k in range(3)]
        for k, (_, cdr) in enumerate(batch["/camera/image_raw"]):
            assert len(cdr) == 921_652 and cdr[-rgb.nbytes :] == np.roll(rgb, k).tobytes()
        assert frames.skipped == 0 and frames.take() == []
        frames.undeclare()
        assert _until(lambda: not sender.watched.get("rgb"))  # the view left: sending stops
    finally:
        for closing in (sender, frames):
            if closing is not None:
                closing.undeclare()
        for session in (view, camera):
            if session is not None:
                session.close()
