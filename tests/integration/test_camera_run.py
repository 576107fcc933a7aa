"""sensor.camera in a real run: the capture scenario (configs/capture_tumbling_target.yaml) with a
wrist camera on the servicer's end effector, `orchestrator run --record` (seven component
processes over Zenoh on loopback), and `orchestrator check` refusing bad cameras with exit 2.

The frames' depth at the grapple is checked against the dynamics' own record of where the
grapple is (``grasp.p_ee_grasp``, ``grasp.q_ee_grasp``, DART's kinematics): the ray through the
pixel nearest the grapple's projection meets the plane of the grapple's tip disc at a depth
computed here in float64 from those recorded values.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas
import pytest
import yaml
from scipy.spatial.transform import Rotation

from components.camera.render import EGL_PACKAGES, egl_problem
from tests.conftest import ROOT, component_processes, needs, orchestrator

pytestmark = [
    pytest.mark.integration,
    pytest.mark.skipif(egl_problem() is not None, reason=f"no EGL here: {egl_problem()}"),
]

CAPTURE = ROOT / "configs" / "capture_tumbling_target.yaml"
# where the camera sits on the end effector (beside the tool, which spans |y| < 0.05 m)
MOUNT = np.array([0.0, 0.07, -0.03])
# the grapple in the ee frame at the start (the capture config's initial arm pose): the camera
# looks at it, so that the frames hold it while the arm starts to move
GRAPPLE_AT_START = np.array([0.82793285, 0.29939321, -0.0460646])
DISC_RADIUS = 0.05 * np.cos(np.pi / 64)  # the tip disc's 64-gon's inradius (m)
WIDTH, HEIGHT, F, CX, CY = 640, 480, 500.0, 301.3, 251.7


def looking_at(direction) -> list[float]:
    """q_link_camera [x, y, z, w] whose z axis points along ``direction`` (link axes)."""
    z = np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x)
    R = np.column_stack([x, np.cross(z, x), z])
    return [float(v) for v in Rotation.from_matrix(R).as_quat()]


def camera_config(path: Path, duration: str = "1 s", step: str = "100 ms", **camera) -> Path:
    """The capture config with a camera added (URDF paths made absolute: the file is elsewhere)."""
    config = yaml.safe_load(CAPTURE.read_text())
    config["run"]["duration"] = duration
    bodies = config["components"]["dynamics"]["parameters"]["bodies"]
    for body in bodies.values():
        body["urdf"] = str((CAPTURE.parent / body["urdf"]).resolve())
    controller = config["components"]["controller"]["parameters"]
    controller["urdf"] = str((CAPTURE.parent / controller["urdf"]).resolve())
    parameters = {
        "bodies": {name: body["urdf"] for name, body in bodies.items()},
        "body": "servicer",
        "link": "ee",
        "position": MOUNT.tolist(),
        "orientation": looking_at(GRAPPLE_AT_START - MOUNT),
        "width": WIDTH,
        "height": HEIGHT,
        "fx": F,
        "fy": F,
        "cx": CX,
        "cy": CY,
        "near": 0.05,
        "far": 20.0,
        "ambient": 0.1,
        "seed": 3,
        "pixel_noise": 0.0,
        "depth_noise": 0.0,
        **camera,
    }
    config["components"]["camera"] = {"type": "sensor.camera", "step": step, "parameters": parameters}
    for body in bodies:
        for variable in ("position", "orientation", "q"):
            config["connections"][f"camera.{body}.{variable}"] = f"dynamics.{body}.{variable}"
    config["connections"]["camera.r_eci"] = "orbit.r_eci"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """The capture config with a wrist camera (1 s, 10 Hz), run and recorded: its directory."""
    base = tmp_path_factory.mktemp("camera")
    config = camera_config(base / "camera.yaml")
    done = orchestrator("run", config, "--record", base / "run", "--view", f"save:{base / 'live.rrd'}", timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert not component_processes("capture_tumbling_target"), "component processes left after the run"
    return base / "run"


def rrd_camera(rrd: Path, entity: str):
    """(the pinhole's K as logged, the colour images logged) of a camera entity in an .rrd."""
    from rerun.chunk import RrdReader

    pinhole, images = None, []
    for chunk in RrdReader(rrd).stream():
        batch = chunk.to_record_batch()
        if chunk.entity_path == entity and chunk.is_static and "Pinhole:image_from_camera" in batch.schema.names:
            pinhole = np.array(batch.column("Pinhole:image_from_camera").to_pylist()[0]).reshape(3, 3).T  # column-major
        if chunk.entity_path == f"{entity}/rgb" and "Image:buffer" in batch.schema.names:
            images += batch.column("Image:buffer").to_pylist()
    return pinhole, images


@needs("view", "the recording's live view")
def test_a_wrist_camera_records_frames_whose_depth_at_the_grapple_is_the_dynamics_truth(recorded):
    record = recorded
    signals = pandas.read_parquet(record / "signals.parquet")
    frames = sorted((record / "frames" / "camera").glob("*.npz"))
    assert [f.name for f in frames] == [f"{k:06d}.npz" for k in range(10)]  # 1 s at 10 Hz, none lost
    assert signals["camera.frame"].iloc[-1] == 10.0
    T_link_camera = np.eye(4)
    T_link_camera[:3, :3] = Rotation.from_quat(looking_at(GRAPPLE_AT_START - MOUNT)).as_matrix()
    T_link_camera[:3, 3] = MOUNT
    K = np.array([[F, 0.0, CX], [0.0, F, CY], [0.0, 0.0, 1.0]])
    checked = 0
    for path in frames:
        with np.load(path) as frame:
            rgb, depth, t = frame["rgb"], frame["depth"], float(frame["t"])
            assert rgb.shape == (HEIGHT, WIDTH, 3) and rgb.dtype == np.uint8
            assert depth.shape == (HEIGHT, WIDTH) and depth.dtype == np.float32
            assert np.array_equal(frame["K"], K) and np.allclose(frame["T_link_camera"], T_link_camera, atol=1e-15)
        row = signals.loc[np.isclose(signals["time"], t, atol=1e-9)].iloc[0]
        p_ee = np.array([row[f"dynamics.grasp.p_ee_grasp[{i}]"] for i in range(3)])
        R_ee_grasp = Rotation.from_quat([row[f"dynamics.grasp.q_ee_grasp[{i}]"] for i in range(4)]).as_matrix()
        # the grapple's origin and its tip disc's plane (normal: grapple z) in the camera frame
        R_c = T_link_camera[:3, :3].T
        origin = R_c @ (p_ee - MOUNT)
        normal = R_c @ R_ee_grasp[:, 2]
        assert origin[2] > 0.3 and normal @ origin > 0.0  # in front, and the disc's face turned to the camera
        u, v = (K @ origin)[:2] / origin[2]
        pixel = np.array([round(u), round(v)])
        ray = np.linalg.solve(K, [pixel[0], pixel[1], 1.0])
        hit = ray * (normal @ origin) / (normal @ ray)  # on the plane z_G = 0
        assert np.linalg.norm(hit - origin) < DISC_RADIUS - 0.005  # well inside the disc
        assert abs(depth[pixel[1], pixel[0]] - hit[2]) < 1e-4, (path.name, depth[pixel[1], pixel[0]], hit[2])
        checked += 1
    assert checked == 10
    assert signals["camera.lit"].iloc[-1] in (0.0, 1.0)


def assert_same_frames(first_run: Path, second_run: Path) -> None:
    """The camera's frames of two recordings: the same files, the same images bit for bit, something lit."""
    first = sorted((first_run / "frames" / "camera").glob("*.npz"))
    second = sorted((second_run / "frames" / "camera").glob("*.npz"))
    assert [f.name for f in first] == [f.name for f in second] and len(first) == 10
    for a, b in zip(first, second):
        with np.load(a) as x, np.load(b) as y:
            assert x["rgb"].tobytes() == y["rgb"].tobytes() and x["depth"].tobytes() == y["depth"].tobytes(), a.name
            assert x["rgb"].max() > 0  # something lit is in view


@needs("view", "the recording's live view")
def test_a_second_run_records_the_same_frames_bit_for_bit(recorded, tmp_path):
    done = orchestrator("run", recorded / "config.yaml", "--record", tmp_path / "again", timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert_same_frames(recorded, tmp_path / "again")


@needs("view", "the recording's live view")
def test_a_camera_without_bodies_sees_the_dynamics_bodies_in_the_same_frames(recorded, tmp_path):
    """``recorded``'s camera names the dynamics' bodies itself; left out, it takes them: the
    recording's config.yaml writes them out and the frames are the same bit for bit."""
    config = yaml.safe_load((recorded.parent / "camera.yaml").read_text())
    del config["components"]["camera"]["parameters"]["bodies"]
    (tmp_path / "scene.yaml").write_text(yaml.safe_dump(config, sort_keys=False))
    done = orchestrator("run", tmp_path / "scene.yaml", "--record", tmp_path / "run", timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    written = yaml.safe_load((tmp_path / "run" / "config.yaml").read_text())["components"]
    dynamics = written["dynamics"]["parameters"]["bodies"]
    assert written["camera"]["parameters"]["bodies"] == {name: body["urdf"] for name, body in dynamics.items()}
    assert_same_frames(recorded, tmp_path / "run")


@needs("view", "the recording's live view")
def test_the_view_draws_the_frustum_on_the_end_effector_and_the_frames(recorded, tmp_path):
    """`orchestrator view DIR` into an .rrd, read back with Rerun: the camera's pinhole (its K) and
    mount under the ee link's entity, its images on the timeline, each the recorded frame's pixels."""
    rrd = tmp_path / "view.rrd"
    done = orchestrator("view", recorded, "--view", f"save:{rrd}", "--rate", "100", timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    entity = "/world/dynamics/servicer/links/ee/camera"
    pinhole, images = rrd_camera(rrd, entity)
    assert np.allclose(pinhole, [[F, 0.0, CX], [0.0, F, CY], [0.0, 0.0, 1.0]])
    assert len(images) == 10
    with np.load(recorded / "frames" / "camera" / "000009.npz") as frame:
        assert bytes(np.asarray(images[-1][0], dtype=np.uint8)) == frame["rgb"].tobytes()
    # live (--view save: while the run recorded): the frames as their files appeared, at 30 rows/s
    # of sim time the latest of each row; one written after the run's last row may be missing
    pinhole, live = rrd_camera(recorded.parent / "live.rrd", entity)
    assert np.allclose(pinhole, [[F, 0.0, CX], [0.0, F, CY], [0.0, 0.0, 1.0]])
    recorded_frames = set()
    for path in sorted((recorded / "frames" / "camera").glob("*.npz")):
        with np.load(path) as frame:
            recorded_frames.add(frame["rgb"].tobytes())
    assert len(live) >= 5 and all(bytes(np.asarray(image[0], dtype=np.uint8)) in recorded_frames for image in live)


@needs("view", "the recording's live view")
def test_the_rosbag2_export_carries_the_frames_their_intrinsics_and_the_mount(recorded, tmp_path):
    """`orchestrator export DIR --rosbag2 OUT`, read back with the independent MCAP reader: every
    frame as sensor_msgs/Image (rgb8 and 32FC1, the recorded bytes), CameraInfo with K and a zero
    plumb_bob D, stamped when taken, and the camera's optical frame on the ee link in /tf_static."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    bag = tmp_path / "bag"
    done = orchestrator("export", recorded, "--rosbag2", bag, timeout=300)
    assert done.returncode == 0, done.stderr
    topics: dict[str, list] = {}
    with open(next(bag.glob("*.mcap")), "rb") as f:
        for _, channel, message, decoded in make_reader(
            f, decoder_factories=[DecoderFactory()]
        ).iter_decoded_messages():
            topics.setdefault(channel.topic, []).append((message.log_time, decoded))
    frames = sorted((recorded / "frames" / "camera").glob("*.npz"))
    images, depths, infos = (
        topics["/camera/image_raw"],
        topics["/camera/depth/image_raw"],
        topics["/camera/camera_info"],
    )
    assert len(images) == len(depths) == len(infos) == len(frames) == 10
    epoch_ns = 1663502400 * 10**9  # 2022-09-18T12:00:00Z
    for path, (ns, image), (_, depth), (_, info) in zip(frames, images, depths, infos):
        with np.load(path) as frame:
            assert ns == epoch_ns + round(float(frame["t"]) * 1e9)
            assert (image.encoding, image.height, image.width, image.step) == ("rgb8", HEIGHT, WIDTH, 3 * WIDTH)
            assert bytes(image.data) == frame["rgb"].tobytes() and image.header.frame_id == "camera"
            assert depth.encoding == "32FC1" and bytes(depth.data) == frame["depth"].astype("<f4").tobytes()
            assert np.array_equal(info.k, frame["K"].ravel()) and info.distortion_model == "plumb_bob"
            assert not np.any(info.d) and np.array_equal(np.reshape(info.p, (3, 4))[:, :3], frame["K"])
    mounts = [t for _, m in topics["/tf_static"] for t in m.transforms if t.child_frame_id == "camera"]
    assert len(mounts) == 1 and mounts[0].header.frame_id == "dynamics/servicer/ee"
    translation = mounts[0].transform.translation
    assert np.allclose([translation.x, translation.y, translation.z], MOUNT, atol=1e-15)
    rotation = mounts[0].transform.rotation
    R = Rotation.from_quat([rotation.x, rotation.y, rotation.z, rotation.w]).as_matrix()
    assert np.allclose(R, Rotation.from_quat(looking_at(GRAPPLE_AT_START - MOUNT)).as_matrix(), atol=1e-12)


def test_the_guides_camera_passes_check(tmp_path):
    """docs/guides/camera.md's YAML, added to the capture config as it says, is a valid camera (its
    scene: the dynamics' bodies)."""
    import re

    block = re.search(r"```yaml\n(.*?)```", (ROOT / "docs" / "guides" / "camera.md").read_text(), re.S).group(1)
    snippet = yaml.safe_load(block)
    config = yaml.safe_load(camera_config(tmp_path / "base.yaml").read_text())
    del config["components"]["camera"]
    config["components"].update(snippet["components"])
    config["connections"].update(snippet["connections"])
    (tmp_path / "guide.yaml").write_text(yaml.safe_dump(config, sort_keys=False))
    done = orchestrator("check", tmp_path / "guide.yaml", timeout=300)
    assert done.returncode == 0, done.stderr


@pytest.mark.parametrize(
    "setting, key, expected",
    [
        ("components.camera.parameters.link=hand", "components.camera.parameters.link", "expected a link of servicer"),
        ("components.camera.parameters.body=moon", "components.camera.parameters.body", "expected one of bodies"),
        ("components.camera.parameters.fx=0", "components.camera.parameters.fx", "expected a quantity > 0, got 0"),
        ("components.camera.parameters.cx=700", "components.camera.parameters.cx", "within the image (-0.5 to 639.5"),
        (
            "components.camera.parameters.width=0",
            "components.camera.parameters.width",
            "expected an integer >= 1, got 0",
        ),
        (
            "components.camera.parameters.height=9000",
            "components.camera.parameters.height",
            "expected 1 to 8192 pixels, got 9000",
        ),
        (
            "components.camera.step=15ms",
            "components.camera.step",
            "must be a positive integer multiple of run.step (10 ms)",
        ),
        ("components.camera.parameters.far=0.01", "components.camera.parameters.far", "expected more than near"),
        (
            "components.camera.parameters.distortion=[-3, 0, 0, 0, 0]",
            "components.camera.parameters.distortion",
            "the distortion does not invert over the image",
        ),
    ],
)
def test_a_bad_camera_is_refused_at_check_naming_the_key(tmp_path, setting, key, expected):
    config = camera_config(tmp_path / "camera.yaml")
    done = orchestrator("check", config, "--set", setting, timeout=300)
    assert done.returncode == 2, done.stdout + done.stderr
    assert f"{key}: " in done.stderr and expected in done.stderr, done.stderr


def test_no_egl_is_refused_at_check_naming_the_packages(tmp_path):
    """glvnd finding no EGL vendor is what a machine without Mesa's EGL looks like."""
    config = camera_config(tmp_path / "camera.yaml")
    done = orchestrator(
        "check", config, timeout=300, env={**os.environ, "__EGL_VENDOR_LIBRARY_FILENAMES": str(tmp_path / "none.json")}
    )
    assert done.returncode == 2, done.stdout + done.stderr
    assert "components.camera.parameters: sensor.camera renders with OpenGL on EGL" in done.stderr, done.stderr
    assert EGL_PACKAGES in done.stderr
