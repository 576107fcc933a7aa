"""estimator.fiducial through the in-process harness, frames handed over by its frame source as a
camera records them (``rgb``, ``K``): a grapple turning in front of the camera frame by frame
(pose within the bounds of tests/unit/test_fiducial_estimator.py, q sign-continuous where the
core's w >= 0 quaternion flips), a frame without markers (valid 0, the pose held), steps without
a new frame, the state handed to a fresh instance, and bad parameters refused naming the key."""
from __future__ import annotations

import math

import numpy as np
import pytest

from components.errors import ComponentError, ConfigError
from components.estimators.fiducial import FiducialEstimator
from components.estimators.marker_layout import read_layout
from components.rotations import log_so3, quat_to_matrix
from components.testing.harness import Harness
from tests import fiducial_scenes as scenes

MS = 1_000_000
STEP = 50 * MS
LAYOUT = read_layout(scenes.LAYOUT)
MOUNT_P = np.array([0.0, 0.07, -0.05])
MOUNT_Q = np.array([0.06, 0.0, 0.01, 0.998])      # q_E_C, normalized by the component
PARAMS = {"markers": "models/capture/grapple_markers.yaml", "camera_position": MOUNT_P.tolist(),
          "camera_orientation": MOUNT_Q.tolist(), "min_markers": 2, "max_reprojection_error": 1.5}
# the grapple turning about the optical axis (1.4 turns over 12 frames) at 0.3 m, tilted
ROLLS = np.linspace(0.0, 2.8 * math.pi, 12)


def truth(roll: float):
    """(R_C_G, p_C_G) of the frame with this roll."""
    return scenes.camera_pose(0.3, (0.02, -0.01), (0.06, -0.09), roll)


def frames(blank: tuple[int, ...] = ()) -> list[dict]:
    out = []
    for k, roll in enumerate(ROLLS):
        rgb = np.full((scenes.HEIGHT, scenes.WIDTH, 3), scenes.BACKGROUND, np.uint8) if k in blank \
            else scenes.noisy(scenes.warp(LAYOUT, *truth(roll)), 2.0, seed=k)
        out.append({"rgb": rgb, "K": scenes.K.copy()})
    return out


def harness(frame_list, **params) -> Harness:
    h = Harness("estimator.fiducial", {**PARAMS, **params})
    h.component.frame_source = frame_list.__getitem__
    return h


def take(h: Harness, k: int) -> dict:
    """Frame k (taken at k * 50 ms) reaches the estimator at its step."""
    h.inputs.update({"frame": float(k + 1), "t_frame": k * STEP / 1e9})
    return h.step(STEP)


def test_a_turning_grapple_frame_by_frame_with_q_sign_continuous():
    R_E_C = quat_to_matrix(MOUNT_Q)
    frame_list = frames()
    h = harness(frame_list)
    core = FiducialEstimator(LAYOUT, 2, 1.5)
    previous, raw_flips, raw_previous = None, 0, None
    for k, roll in enumerate(ROLLS):
        out = take(h, k)
        R_C_G, p_C_G = truth(roll)
        assert out["valid"] == 1.0 and out["markers"] >= 2 and 0.0 < out["reprojection_error"] < 1.0
        assert out["t_measured"] == k * STEP / 1e9
        assert np.linalg.norm(out["p"] - (R_E_C @ p_C_G + MOUNT_P)) <= 0.0026
        assert np.linalg.norm(log_so3((R_E_C @ R_C_G).T @ quat_to_matrix(out["q"]))) <= math.radians(0.6)
        if previous is not None:
            assert float(out["q"] @ previous) > 0.0, f"q jumps sign at frame {k}"
        previous = out["q"].copy()
        raw = core.estimate(frame_list[k]["rgb"], scenes.K, np.zeros(0), MOUNT_P, R_E_C).q_ee_grasp
        raw_flips += raw_previous is not None and float(raw @ raw_previous) < 0.0
        raw_previous = raw
    assert raw_flips >= 1, "the sequence never crosses w = 0: it does not test the sign continuity"


def test_a_frame_without_markers_is_not_valid_and_holds_the_pose_and_no_new_frame_holds_everything():
    h = harness(frames(blank=(3,)))
    for k in range(3):
        good = take(h, k)
    held = take(h, 3)
    assert held["valid"] == 0.0 and held["markers"] == 0.0 and held["reprojection_error"] == 0.0
    assert held["t_measured"] == 3 * STEP / 1e9
    assert np.array_equal(held["p"], good["p"]) and np.array_equal(held["q"], good["q"])
    again = h.step(STEP)                      # frame still 4: nothing new to look at
    assert all(np.array_equal(again[name], held[name]) for name in held)
    after = take(h, 4)
    assert after["valid"] == 1.0 and float(after["q"] @ good["q"]) > 0.0


def test_the_state_continues_in_a_fresh_instance_bit_for_bit():
    frame_list = frames()
    a = harness(frame_list)
    for k in range(5):
        take(a, k)
    b = Harness("estimator.fiducial", PARAMS, t0_ns=a.t_ns)
    b.component.frame_source = frame_list.__getitem__
    b.set_state(a.get_state())
    for k in range(5, 9):
        out_a, out_b = take(a, k), take(b, k)
        for name in out_a:
            assert out_a[name].tobytes() == out_b[name].tobytes(), (k, name)


def test_without_a_frame_source_a_new_frame_is_an_error():
    h = Harness("estimator.fiducial", PARAMS)
    h.inputs["frame"] = 1.0
    with pytest.raises(ComponentError, match="no frame source"):
        h.step(STEP)


@pytest.mark.parametrize("change, key, expected", [
    ({"markers": "models/capture/none.yaml"}, "markers", "not found"),
    ({"min_markers": 6}, "min_markers", "at most the layout's 5 markers, got 6"),
    ({"min_markers": 0}, "min_markers", "expected an integer >= 1"),
    ({"camera_orientation": [0, 0, 0, 0]}, "camera_orientation", "is not a rotation"),
    ({"distortion": [0.1, 0.0, 0.0]}, "distortion", "expected 4, 5, 8, 12, 14 values"),
    ({"max_reprojection_error": 0}, "max_reprojection_error", "expected a quantity > 0"),
    ({"fx": 500}, "fx", "unknown parameter"),
])
def test_bad_parameters_are_refused_naming_the_key(change, key, expected):
    with pytest.raises(ConfigError, match=expected) as raised:
        Harness("estimator.fiducial", {**PARAMS, **change})
    assert raised.value.key == key
