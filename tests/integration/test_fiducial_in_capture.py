"""The capture scenario with a wrist sensor.camera and estimator.fiducial, which reads the camera's
images over the bus, in place of the relative-pose oracle:

- ``orchestrator run --record`` (real processes, Zenoh on loopback): its measurements against the
  dynamics' own ``grasp.p_ee_grasp``, ``grasp.q_ee_grasp`` at each frame's time, while the arm
  holds its posture and the camera looks at the grapple 0.88 m away (the markers' face lit by
  ``ambient`` alone: white cells at ~25 of 255); a second run gives the same columns bit for bit;
  ``orchestrator plot`` draws those errors, ``orchestrator export --rosbag2`` writes them as
  PoseStamped in the end effector's frame; the Rerun view of the recording shows the camera's
  frustum on the end effector and its frames;
- ``orchestrator check``: accepted as it is, refused with exit 2 naming the key (and the field of
  the layout file) for bad parameters."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas
import pytest
import yaml

from components.camera.render import egl_problem
from components.rotations import log_so3, matrix_to_quat, quat_to_matrix
from orchestrator.plots.recording import figures
from tests.conftest import ROOT, component_processes, needs, orchestrator

pytestmark = [
    pytest.mark.integration,
    needs("vision", "estimator.fiducial"),
    pytest.mark.skipif(egl_problem() is not None, reason=f"no EGL here: {egl_problem()}"),
]
CAPTURE = ROOT / "configs" / "capture_tumbling_target.yaml"
KEY = "components.pose_sensor.parameters"


# the grapple in the end-effector frame at the start (the config's arm pose): the camera looks at it
GRAPPLE_AT_START = np.array([0.82793285, 0.29939321, -0.0460646])
MOUNT = np.array([0.0, 0.07, -0.03])
EPOCH_NS = 1663502400 * 1_000_000_000  # the capture config's epoch, 2022-09-18T12:00:00Z


def looking_at(direction) -> list[float]:
    """q_link_camera [x, y, z, w] whose z axis points along ``direction`` (link axes)."""
    z = np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x)
    return matrix_to_quat(np.column_stack([x, np.cross(z, x), z])).tolist()


def vision_config(path: Path, duration: str = "40 s") -> Path:
    """The shipped capture with the estimator as its pose sensor (URDF paths made absolute)."""
    data = yaml.safe_load(CAPTURE.read_text())
    data["run"]["duration"] = duration
    for body in data["components"]["dynamics"]["parameters"]["bodies"].values():
        body["urdf"] = str((CAPTURE.parent / body["urdf"]).resolve())
    controller = data["components"]["controller"]["parameters"]
    controller["urdf"] = str((CAPTURE.parent / controller["urdf"]).resolve())
    bodies = {name: body["urdf"] for name, body in data["components"]["dynamics"]["parameters"]["bodies"].items()}
    camera = {
        "bodies": bodies,
        "body": "servicer",
        "link": "ee",
        "position": MOUNT.tolist(),
        "orientation": looking_at(GRAPPLE_AT_START - MOUNT),
        "width": 640,
        "height": 480,
        "fx": 500,
        "fy": 500,
        "cx": 319.5,
        "cy": 239.5,
        "near": 0.02,
        "far": 20,
        "ambient": 0.1,
        "seed": 5,
        "pixel_noise": 2,
        "depth_noise": 0,
    }
    data["components"]["wrist"] = {"type": "sensor.camera", "step": "100 ms", "parameters": camera}
    data["components"]["pose_sensor"] = {
        "type": "estimator.fiducial",
        "step": "100 ms",
        "parameters": {
            "body": "servicer",
            "urdf": bodies["servicer"],
            "link": "ee",
            "end_effector": "ee",
            "width": 640,
            "height": 480,
            "markers": str(ROOT / "models" / "capture" / "grapple_markers.yaml"),
            "min_markers": 2,
            "max_reprojection_error": 1.5,
        },
    }
    connections = data["connections"]
    del connections["pose_sensor.p_true"], connections["pose_sensor.q_true"]
    for body in bodies:
        for variable in ("position", "orientation", "q"):
            connections[f"wrist.{body}.{variable}"] = f"dynamics.{body}.{variable}"
    connections["wrist.r_eci"] = "orbit.r_eci"
    for variable in ("rgb", "K", "D", "T_link_camera", "t_frame", "frame"):
        connections[f"pose_sensor.{variable}"] = f"wrist.{variable}"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


@pytest.fixture
def config(tmp_path):
    return vision_config(tmp_path / "vision.yaml")


@needs("view", "orchestrator view")
def test_the_estimator_over_a_run_against_the_dynamics_and_again_bit_for_bit(tmp_path):
    """1.2 s, 12 frames, the arm still: every frame the estimator reads gives a pose within 5 mm
    and 0.6 deg of the dynamics' (measured: 0.2-3.1 mm, 0.1-0.4 deg, 4 markers each, 0.88 m away)."""
    config = vision_config(tmp_path / "vision.yaml", duration="1200 ms")
    runs = []
    for name in ("a", "b"):
        done = orchestrator("run", config, "--record", tmp_path / name, timeout=600)
        assert done.returncode == 0, done.stderr[-3000:]
        assert not component_processes("capture_tumbling_target"), "component processes left after the run"
        runs.append(pandas.read_parquet(tmp_path / name / "signals.parquet"))
    signals = runs[0]
    columns = [c for c in signals.columns if c.startswith("pose_sensor.")]
    assert runs[1][columns].to_numpy().tobytes() == signals[columns].to_numpy().tobytes()
    # frame k, taken at k * 100 ms, is the camera's output from (k + 1) * 100 ms on, which the
    # estimator's step then reads: its solve is out from (k + 2) * 100 ms on; before, no frame
    assert (signals.loc[signals["step"] < 20, "pose_sensor.valid"] == 0.0).all()
    frames = signals[(signals["step"] % 10 == 0) & (signals["step"] >= 20)]
    assert np.array_equal(
        frames["pose_sensor.t_measured"].to_numpy(), (frames["step"].to_numpy() // 10 - 2) * 1e8 / 1e9
    )
    assert (
        len(frames) == 11 and (frames["pose_sensor.valid"] == 1.0).all() and (frames["pose_sensor.markers"] >= 3).all()
    )
    position_errors, attitude_errors = [], []
    for _, row in frames.iterrows():
        truth = signals.loc[np.isclose(signals["time"], row["pose_sensor.t_measured"], atol=1e-9)].iloc[0]
        p = np.array([row[f"pose_sensor.p[{i}]"] for i in range(3)])
        p_true = np.array([truth[f"dynamics.grasp.p_ee_grasp[{i}]"] for i in range(3)])
        R = quat_to_matrix([row[f"pose_sensor.q[{i}]"] for i in range(4)])
        R_true = quat_to_matrix([truth[f"dynamics.grasp.q_ee_grasp[{i}]"] for i in range(4)])
        position_errors.append(np.linalg.norm(p - p_true))
        attitude_errors.append(np.linalg.norm(log_so3(R_true.T @ R)))
    assert max(position_errors) <= 0.005 and max(attitude_errors) <= math.radians(0.6), (
        position_errors,
        attitude_errors,
    )
    # orchestrator plot draws those errors at the frames' times
    done = orchestrator("plot", tmp_path / "a")
    assert done.returncode == 0, done.stderr
    assert str(tmp_path / "a" / "plots" / "pose_sensor_pose.png") in done.stdout.split()
    figure = dict(figures(tmp_path / "a"))["pose_sensor_pose.png"]
    t, position = line(figure, "error against dynamics.grasp", "position")
    assert np.array_equal(t, frames["pose_sensor.t_measured"].to_numpy())
    assert np.allclose(position, 1e3 * np.array(position_errors), rtol=1e-12, atol=0.0)
    assert np.allclose(line(figure, "attitude error", "attitude")[1], np.degrees(attitude_errors), rtol=1e-12, atol=0.0)
    assert len(list((tmp_path / "a" / "frames" / "wrist").glob("*.npz"))) == 12  # the last one too
    assert frames["wrist.frame"].tolist() == list(range(2, 13)) and frames["pose_sensor.frame_solved"].tolist() == list(
        range(1, 12)
    )
    # orchestrator export --rosbag2: a PoseStamped per frame in the end effector's tf frame, read back
    # with the independent MCAP reader
    bag = tmp_path / "bag"
    done = orchestrator("export", tmp_path / "a", "--rosbag2", bag)
    assert done.returncode == 0, done.stderr
    poses = read_bag(bag)["/pose_sensor/pose"]
    assert len(poses) == 11
    for (_, message), (_, row) in zip(poses, frames.iterrows()):
        assert message.header.frame_id == "dynamics/servicer/ee"
        stamp = message.header.stamp.sec * 1_000_000_000 + message.header.stamp.nanosec
        assert stamp == EPOCH_NS + round(row["pose_sensor.t_measured"] * 1e9)
        position = message.pose.position
        assert [position.x, position.y, position.z] == [row[f"pose_sensor.p[{i}]"] for i in range(3)]
    # the Rerun view of the recording: the camera's pinhole on the end effector, and its frames
    rrd = tmp_path / "view.rrd"
    done = orchestrator("view", tmp_path / "a", "--view", f"save:{rrd}", "--rate", "100", timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    pinhole, images = rrd_camera(rrd, "/world/dynamics/servicer/links/ee/wrist")
    assert np.allclose(pinhole, [[500.0, 0.0, 319.5], [0.0, 500.0, 239.5], [0.0, 0.0, 1.0]])
    assert len(images) == 12
    with np.load(tmp_path / "a" / "frames" / "wrist" / "000011.npz") as frame:
        assert bytes(np.asarray(images[-1][0], dtype=np.uint8)) == frame["rgb"].tobytes()


def read_bag(bag: Path) -> dict[str, list]:
    """{topic: [(log time ns, decoded message)]} with the MCAP reader (not the exporter's rosbags)."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    (path,) = bag.glob("*.mcap")
    topics: dict[str, list] = {}
    with open(path, "rb") as f:
        for _, channel, message, decoded in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
            log_time_order=True
        ):
            topics.setdefault(channel.topic, []).append((message.log_time, decoded))
    return topics


def line(fig, title_part: str, label: str):
    ax = next(a for a in fig.axes if title_part in a.get_title())
    drawn = next(ln for ln in ax.get_lines() if ln.get_label() == label)
    return np.asarray(drawn.get_xdata(), dtype=float), np.asarray(drawn.get_ydata(), dtype=float)


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


def test_the_estimator_in_place_of_the_oracle_checks(config):
    done = orchestrator("check", config)
    assert done.returncode == 0, done.stderr
    assert "7 components" in done.stdout


@pytest.mark.parametrize(
    "setting, key, expected",
    [
        ("min_markers=9", "min_markers", "expected at most the layout's 5 markers, got 9"),
        ("markers=nowhere.yaml", "markers", "marker layout 'nowhere.yaml' not found"),
        ("end_effector=arm_5_link", "end_effector", "joint arm_6_joint between them is revolute, not fixed"),
        ("link=hand", "link", "expected a link of"),
        ("max_reprojection_error=-1", "max_reprojection_error", "expected a quantity > 0, got -1"),
    ],
)
def test_bad_parameters_exit_2_naming_the_key(config, setting, key, expected):
    done = orchestrator("check", config, "--set", f"{KEY}.{setting}")
    assert done.returncode == 2, done.stdout + done.stderr
    assert f"{KEY}.{key}: " in done.stderr and expected in done.stderr, done.stderr


def test_an_estimator_of_another_image_size_than_its_camera_exits_2_naming_both(config):
    done = orchestrator("check", config, "--set", f"{KEY}.width=641")
    assert done.returncode == 2, done.stdout + done.stderr
    assert (
        "connections.pose_sensor.rgb: frame mismatch: input pose_sensor.rgb is uint8 (480, 641, 3), "
        "output wrist.rgb is uint8 (480, 640, 3)"
    ) in done.stderr, done.stderr


def test_a_bad_layout_file_exits_2_naming_the_field_in_it(config, tmp_path):
    layout = yaml.safe_load((ROOT / "models" / "capture" / "grapple_markers.yaml").read_text())
    layout["markers"][2]["id"] = 1
    path = tmp_path / "layout.yaml"
    path.write_text(yaml.safe_dump(layout))
    done = orchestrator("check", config, "--set", f"{KEY}.markers={path}")
    assert done.returncode == 2, done.stdout + done.stderr
    assert f"{KEY}.markers: {path}: marker id 1 listed twice" in done.stderr, done.stderr
