"""estimator.fiducial through the in-process harness, fed a camera's outputs as the bus would
(its frame input ``rgb`` and K, D, T_link_camera, t_frame, frame):

- the real thing: sensor.camera (OpenGL on EGL) renders the capture servicer and target at known
  relative poses, its frame goes to the estimator, whose pose is checked against the end
  effector's pose by Pinocchio's forward kinematics of the servicer URDF (not the camera's own
  kinematics) and the grapple's fixed joint;
- the step logic on drawn frames (tests/fiducial_scenes.py): a grapple turning frame by frame
  (q sign-continuous where the solve's w >= 0 quaternion flips), a frame without markers (valid
  0, the pose held), the frame's time, no frame yet;
- the state handed to a fresh instance, bit for bit;
- bad parameters refused naming the key.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from components.camera.render import egl_problem
from components.errors import ConfigError
from components.estimators.fiducial import FiducialEstimator
from components.estimators.marker_layout import read_layout
from components.rotations import exp_so3, log_so3, matrix_to_quat, quat_to_matrix, rpy_to_matrix
from components.testing.harness import Harness
from tests import fiducial_scenes as scenes

pytestmark = pytest.mark.skipif(egl_problem() is not None, reason=f"no EGL here: {egl_problem()}")

ROOT = Path(__file__).resolve().parents[2]
CONFIGS = ROOT / "configs"
EPOCH = "2022-09-18T12:00:00Z"
STEP = 100_000_000
LAYOUT = read_layout(scenes.LAYOUT)
CAMERA = {
    "bodies": {"servicer": "../models/capture/servicer.urdf", "target": "../models/capture/target.urdf"},
    "body": "servicer",
    "link": "ee",
    "position": [0.0, 0.07, -0.03],
    "orientation": [0.1305, 0.0, 0.0, 0.9914],
    "width": 640,
    "height": 480,
    "fx": 500.0,
    "fy": 500.0,
    "cx": 321.3,
    "cy": 236.8,
    "near": 0.02,
    "far": 20.0,
    "ambient": 0.1,
    "seed": 3,
    "pixel_noise": 2.0,
    "depth_noise": 0.0,
}
PARAMS = {
    "body": "servicer",
    "urdf": "../models/capture/servicer.urdf",
    "link": "ee",
    "end_effector": "ee",
    "width": 640,
    "height": 480,
    "markers": "../models/capture/grapple_markers.yaml",
    "min_markers": 2,
    "max_reprojection_error": 1.5,
}
ARM = yaml.safe_load((CONFIGS / "capture_tumbling_target.yaml").read_text())["components"]["dynamics"]["parameters"][
    "bodies"
]["servicer"]["q"]
JOINTS = [
    "arm_1_joint",
    "arm_2_joint",
    "arm_3_joint",
    "arm_4_joint",
    "arm_5_joint",
    "arm_6_joint",
    "wheel_x_joint",
    "wheel_y_joint",
    "wheel_z_joint",
]  # the URDF's order


def harness(**params) -> Harness:
    return Harness("estimator.fiducial", {**PARAMS, **params}, epoch=EPOCH, config_dir=CONFIGS)


def camera(**changes) -> Harness:
    return Harness("sensor.camera", {**CAMERA, **changes}, epoch=EPOCH, config_dir=CONFIGS)


def seen(estimator: Harness, camera: Harness, T_E_G: np.ndarray) -> dict:
    """The camera takes a frame of the grapple at T_E_G; the estimator's step on it."""
    camera.inputs.update(scene_inputs(T_E_G))
    out = camera.step(STEP)
    estimator.inputs.update(
        rgb=camera.frames["rgb"], **{k: out[k] for k in ("K", "D", "T_link_camera", "t_frame", "frame")}
    )
    return estimator.step(STEP)


def ee_in_base() -> np.ndarray:
    """T_base_ee (4x4) of the servicer in the capture config's arm pose, by Pinocchio."""
    import pinocchio as pin

    model = pin.buildModelFromUrdf(str(ROOT / "models" / "capture" / "servicer.urdf"), pin.JointModelFreeFlyer())
    data = model.createData()
    q = pin.neutral(model)
    for name, value in ARM.items():
        q[model.joints[model.getJointId(name)].idx_q] = value
    pin.framesForwardKinematics(model, data, q)
    placement = data.oMf[model.getFrameId("ee")]
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = placement.rotation, placement.translation
    return T


def scene_inputs(T_E_G: np.ndarray) -> dict:
    """The camera's inputs that put the grapple at T_E_G in the end effector, the markers' face
    turned 30 deg off the Sun (lit), the servicer's base at W's origin."""
    from components.camera.sun import SunClock

    T_base_E = ee_in_base()
    sun = SunClock(EPOCH).direction(0)
    normal = (T_base_E @ T_E_G)[:3, :3] @ [0.0, 0.0, -1.0]  # the markers face -z of G
    side = np.cross(sun, [0.3, 0.2, 0.9])
    wanted = exp_so3(side / np.linalg.norm(side) * math.radians(30.0)) @ sun
    axis = np.cross(normal, wanted)
    R_W_base = exp_so3(axis / np.linalg.norm(axis) * math.acos(np.clip(normal @ wanted, -1.0, 1.0)))
    T_W_base = np.eye(4)
    T_W_base[:3, :3] = R_W_base
    T_target_G = np.eye(4)  # target.urdf's grapple_joint
    T_target_G[:3, :3], T_target_G[:3, 3] = rpy_to_matrix((math.pi, 0.0, 0.0)), (0.0, 0.0, 0.65)
    T_W_target = T_W_base @ T_base_E @ T_E_G @ np.linalg.inv(T_target_G)
    return {
        "r_eci": np.zeros(3),
        "servicer.position": np.zeros(3),
        "servicer.orientation": matrix_to_quat(R_W_base),
        "servicer.q": np.array([ARM.get(j, 0.0) for j in JOINTS]),
        "target.position": T_W_target[:3, 3],
        "target.orientation": matrix_to_quat(T_W_target[:3, :3]),
    }


def grapple(distance: float, tilt, roll: float, offset=(0.01, -0.03)) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = exp_so3([tilt[0], 0.0, 0.0]) @ exp_so3([0.0, tilt[1], 0.0]) @ exp_so3([0.0, 0.0, roll])
    T[:3, 3] = (*offset, distance)
    return T


@pytest.mark.parametrize(
    "distance, tilt, roll", [(0.15, (0.05, -0.08), 0.4), (0.3, (0.1, 0.05), 2.0), (0.5, (-0.07, 0.1), -1.2)]
)
def test_the_rendered_target_gives_the_pose_the_kinematics_put_it_at(distance, tilt, roll):
    """Measured: 0.3-0.6 mm and 0.03-0.16 deg, 3 to 5 markers."""
    T_E_G = grapple(distance, tilt, roll)
    eye = camera()
    out = seen(harness(), eye, T_E_G)
    assert out["valid"] == 1.0 and out["markers"] >= 3 and out["reprojection_error"] < 1.0
    assert np.linalg.norm(out["p"] - T_E_G[:3, 3]) <= 0.002 + 0.002 * distance
    assert np.linalg.norm(log_so3(T_E_G[:3, :3].T @ quat_to_matrix(out["q"]))) <= math.radians(0.6)
    assert out["t_measured"] == 0.0
    eye.component.terminate()


def test_a_distorted_lens_rendered_by_the_camera_is_solved_with_its_distortion():
    """The camera's plumb_bob lens (its frames carry D): the same bounds as a pinhole."""
    T_E_G = grapple(0.3, (0.1, 0.05), 2.0)
    eye = camera(distortion=[-0.15, 0.05, 0.001, -0.0008, 0.0])
    out = seen(harness(), eye, T_E_G)
    assert out["valid"] == 1.0 and out["markers"] >= 3 and out["reprojection_error"] < 1.0
    assert np.linalg.norm(out["p"] - T_E_G[:3, 3]) <= 0.002 + 0.002 * 0.3
    assert np.linalg.norm(log_so3(T_E_G[:3, :3].T @ quat_to_matrix(out["q"]))) <= math.radians(0.6)
    eye.component.terminate()


def test_the_state_continues_in_a_fresh_instance_bit_for_bit():
    frames = [drawn(roll) for roll in ROLLS[:5]]
    a = harness()
    for k in range(3):
        feed(a, frames[k][2], k)
        a.step(STEP)
    b = Harness("estimator.fiducial", PARAMS, epoch=EPOCH, config_dir=CONFIGS, t0_ns=a.t_ns)
    b.set_state(a.get_state())
    for k in range(3, 5):
        feed(a, frames[k][2], k)
        feed(b, frames[k][2], k)
        out_a, out_b = a.step(STEP), b.step(STEP)
        assert out_a["valid"] == 1.0
        for name in out_a:
            assert out_a[name].tobytes() == out_b[name].tobytes(), (k, name)


# --------------------------------------------------------------------------- the step on drawn frames

ROLLS = np.linspace(0.0, 2.8 * math.pi, 12)  # 1.4 turns about the optical axis in 12 frames
K = scenes.K
R_E_C = quat_to_matrix(CAMERA["orientation"])
P_E_C = np.array(CAMERA["position"])


def drawn(roll: float):
    """(R_C_G, p_C_G, frame) of a drawn picture of the markers at 0.3 m with this roll."""
    R_C_G, p_C_G = scenes.camera_pose(0.3, (0.02, -0.01), (0.06, -0.09), roll)
    rgb = scenes.noisy(scenes.warp(LAYOUT, R_C_G, p_C_G), 2.0, seed=int(roll * 100) % 1000)
    return R_C_G, p_C_G, {"rgb": rgb, "K": K.copy(), "D": np.zeros(5)}


def feed(h: Harness, frame: dict, k: int) -> None:
    """Frame k of a camera stepping every STEP, as its outputs would give it."""
    from components.camera.model import mount_transform

    h.inputs.update(
        rgb=frame["rgb"],
        K=frame["K"],
        D=frame["D"],
        t_frame=k * STEP / 1e9,
        frame=k + 1.0,
        T_link_camera=mount_transform(CAMERA["position"], CAMERA["orientation"]),
    )


def test_a_turning_grapple_frame_by_frame_with_q_sign_continuous():
    h = harness()
    frames = [drawn(roll) for roll in ROLLS]
    core = FiducialEstimator(LAYOUT, 2, 1.5)
    previous = raw_previous = None
    raw_flips = 0
    for k, (R_C_G, p_C_G, frame) in enumerate(frames):
        feed(h, frame, k)
        out = h.step(STEP)
        assert out["valid"] == 1.0 and out["markers"] >= 2 and 0.0 < out["reprojection_error"] < 1.0
        assert out["t_measured"] == k * STEP / 1e9
        assert np.linalg.norm(out["p"] - (R_E_C @ p_C_G + P_E_C)) <= 0.0026
        assert np.linalg.norm(log_so3((R_E_C @ R_C_G).T @ quat_to_matrix(out["q"]))) <= math.radians(0.6)
        if previous is not None:
            assert float(out["q"] @ previous) > 0.0, f"q jumps sign at frame {k}"
        previous = out["q"].copy()
        raw = core.estimate(frame["rgb"], K, np.zeros(0), P_E_C, R_E_C).q_ee_grasp
        raw_flips += raw_previous is not None and float(raw @ raw_previous) < 0.0
        raw_previous = raw
    assert raw_flips >= 1, "the sequence never crosses w = 0: it does not test the sign continuity"


def test_a_frame_without_markers_is_not_valid_and_holds_the_pose():
    h = harness()
    blank = {"rgb": np.full((480, 640, 3), scenes.BACKGROUND, np.uint8), "K": K.copy(), "D": np.zeros(5)}
    frames = [drawn(r)[2] for r in ROLLS[:3]] + [blank, drawn(ROLLS[4])[2]]
    nothing = h.step(STEP)  # the camera's start values: no frame yet
    assert nothing["valid"] == 0.0 and nothing["t_measured"] == 0.0 and np.array_equal(nothing["q"], [0, 0, 0, 1])
    for k in range(3):
        feed(h, frames[k], k)
        good = h.step(STEP)
    feed(h, frames[3], 3)
    h.inputs["t_frame"] = 0.29  # taken 10 ms before its step
    held = h.step(STEP)
    assert held["valid"] == 0.0 and held["markers"] == 0.0 and held["reprojection_error"] == 0.0
    assert held["t_measured"] == 0.29  # the frame's time
    assert np.array_equal(held["p"], good["p"]) and np.array_equal(held["q"], good["q"])
    feed(h, frames[4], 4)
    after = h.step(STEP)
    assert after["valid"] == 1.0 and float(after["q"] @ good["q"]) > 0.0


@pytest.mark.parametrize(
    "change, key, expected",
    [
        ({"markers": "none.yaml"}, "markers", "marker layout 'none.yaml' not found"),
        ({"min_markers": 6}, "min_markers", "at most the layout's 5 markers, got 6"),
        ({"end_effector": "hand"}, "end_effector", "expected a link of ../models/capture/servicer.urdf"),
        ({"end_effector": "arm_5_link"}, "end_effector", "joint arm_6_joint between them is revolute, not fixed"),
        ({"link": "hand"}, "link", "expected a link of ../models/capture/servicer.urdf"),
        ({"width": 9000}, "width", "expected 1 to 8192 pixels, got 9000"),
        ({"max_reprojection_error": 0}, "max_reprojection_error", "expected a quantity > 0"),
        ({"fx": 500}, "fx", "unknown parameter"),
    ],
)
def test_bad_parameters_are_refused_naming_the_key(change, key, expected):
    with pytest.raises(ConfigError, match=expected) as raised:
        harness(**change)
    assert raised.value.key == key


def test_a_camera_on_a_link_fixed_to_the_end_effector():
    """The same camera mounted on arm_6_link (ee is 0.14 m beyond it on a fixed joint): the same
    pose in E."""
    T_E_G = grapple(0.3, (0.1, 0.05), 2.0)
    eye, wrist = camera(), camera(link="arm_6_link", position=[0.0, 0.07, 0.11])
    a, b = seen(harness(), eye, T_E_G), seen(harness(link="arm_6_link"), wrist, T_E_G)
    assert b["valid"] == 1.0
    assert np.linalg.norm(a["p"] - b["p"]) < 1e-9 and abs(abs(float(a["q"] @ b["q"])) - 1.0) < 1e-12
    eye.component.terminate()
    wrist.component.terminate()
