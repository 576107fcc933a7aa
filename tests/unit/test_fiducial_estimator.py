"""estimator.fiducial's core (components/estimators/fiducial.py) against independent pictures of
the capture target's marker layout (tests/fiducial_scenes.py: a homography warp of OpenCV's own
marker drawings, and a ray caster on the committed meshes of the markers' cells) at known poses.

Bounds: position within 2 mm + 2 mm per metre of distance, attitude within 0.6 deg, with pixel
noise of 2 grey levels (measured: at most 1.1 mm and 0.24 deg from 0.1 to 1 m). A sign flip or
an axis swap anywhere in the chain (camera mount, marker poses, PnP) is centimetres and tens of
degrees off; a half-pixel shift of the principal point is about 0.3 mm at 0.3 m and is not caught
here (the camera's own tests hold its projection against cv2.projectPoints).
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest

from components.errors import ConfigError
from components.estimators import marker_meshes as fiducial_markers
from components.estimators.fiducial import FiducialEstimator
from components.estimators.marker_layout import Marker, read_layout
from components.rotations import exp_so3, log_so3, quat_to_matrix
from tests import fiducial_scenes as scenes  # skips this module without the extra [vision]
from tests import validation

cv2 = scenes.cv2

LAYOUT = read_layout(scenes.LAYOUT)
# the wrist camera's mount in E used throughout: off the tool's axis, tilted towards it
P_EE_CAMERA = np.array([0.0, 0.07, -0.05])
R_EE_CAMERA = exp_so3([0.12, 0.0, 0.02])
NO_DISTORTION = np.zeros(0)  # a pinhole lens
# (distance m, offset m, tilt rad, roll rad): no pose with a symmetry of the layout
POSES = [
    (0.10, (0.01, -0.02), (0.05, -0.08), 0.3),
    (0.20, (0.03, 0.01), (0.10, 0.05), 2.0),
    (0.30, (-0.02, 0.04), (-0.07, 0.11), -1.1),
    (0.50, (0.05, -0.03), (0.12, 0.02), 2.9),
    (0.75, (0.0, 0.02), (0.03, -0.06), -2.4),
    (1.00, (0.04, 0.0), (-0.05, 0.04), 0.7),
]


def position_bound(distance: float) -> float:
    return 0.002 + 0.002 * distance


ANGLE_BOUND = math.radians(0.6)


def in_view(R_C_G, p_C_G) -> list[int]:
    """The ids whose black squares project wholly inside the image (none of these poses puts one
    marker in front of another)."""
    rvec = cv2.Rodrigues(R_C_G)[0]
    ids = []
    for marker in LAYOUT.markers:
        corners, _ = cv2.projectPoints(marker.corners(), rvec, p_C_G, scenes.K, None)
        if np.all((corners.reshape(4, 2) >= 0) & (corners.reshape(4, 2) <= [scenes.WIDTH - 1, scenes.HEIGHT - 1])):
            ids.append(marker.id)
    return ids


def errors(estimate, R_C_G, p_C_G):
    """(position error m, attitude error rad) of an estimate of G in E against the truth in C."""
    p_true = R_EE_CAMERA @ p_C_G + P_EE_CAMERA
    R_true = R_EE_CAMERA @ R_C_G
    R = quat_to_matrix(estimate.q_ee_grasp)
    return float(np.linalg.norm(estimate.p_ee_grasp - p_true)), float(np.linalg.norm(log_so3(R_true.T @ R)))


def solve(image, estimator=None, K=scenes.K, distortion=NO_DISTORTION):
    estimator = estimator or FiducialEstimator(LAYOUT, 1, 1.5)
    return estimator.estimate(image, K, distortion, P_EE_CAMERA, R_EE_CAMERA)


@pytest.mark.parametrize("distance, offset, tilt, roll", POSES)
def test_pose_from_warped_marker_pictures(distance, offset, tilt, roll):
    R_C_G, p_C_G = scenes.camera_pose(distance, offset, tilt, roll)
    image = scenes.noisy(scenes.warp(LAYOUT, R_C_G, p_C_G), 2.0, seed=int(distance * 100))
    estimate = solve(image)
    assert estimate.valid, estimate.reason
    dp, da = errors(estimate, R_C_G, p_C_G)
    validation.check("fiducial_position", dp)  # the validation table's rows (m, deg)
    validation.check("fiducial_attitude", math.degrees(da))
    assert dp <= position_bound(distance) and da <= ANGLE_BOUND, (dp, math.degrees(da))
    assert estimate.reprojection_error < 1.0
    assert np.isclose(np.linalg.norm(estimate.q_ee_grasp), 1.0)


@pytest.mark.parametrize("distance, offset, tilt, roll", [POSES[1], POSES[3]])
def test_pose_from_the_committed_marker_meshes(distance, offset, tilt, roll):
    """The model's own assets (the white and black cells' OBJ files, read by trimesh) ray cast:
    each id shows where the layout puts it, the right way up."""
    R_C_G, p_C_G = scenes.camera_pose(distance, offset, tilt, roll)
    image = scenes.noisy(scenes.ray_cast(LAYOUT, R_C_G, p_C_G), 2.0, seed=7)
    estimator = FiducialEstimator(LAYOUT, 1, 1.5)
    assert sorted(estimator.detect(image)) == in_view(R_C_G, p_C_G)  # 3 at 0.2 m, all 5 at 0.5 m
    estimate = solve(image, estimator)
    assert estimate.valid, estimate.reason
    dp, da = errors(estimate, R_C_G, p_C_G)
    validation.check("fiducial_position", dp)  # the validation table's rows (m, deg)
    validation.check("fiducial_attitude", math.degrees(da))
    assert dp <= position_bound(distance) and da <= ANGLE_BOUND, (dp, math.degrees(da))


def test_a_distorted_lens_is_solved_with_its_distortion():
    """Barrel distortion ray cast exactly (rays through cv2.undistortPoints): solved with the
    coefficients it is within the bounds; taken for a pinhole it is refused or off."""
    distortion = np.array([-0.12, 0.03, 0.001, -0.0005, 0.0])
    R_C_G, p_C_G = scenes.camera_pose(0.4, (0.06, -0.05), (0.08, -0.1), 1.3)
    image = scenes.noisy(scenes.ray_cast(LAYOUT, R_C_G, p_C_G, distortion=distortion), 2.0, seed=3)
    estimate = solve(image, distortion=distortion)
    assert estimate.valid and estimate.markers >= 4, estimate.reason
    dp, da = errors(estimate, R_C_G, p_C_G)
    validation.check("fiducial_position", dp)  # the validation table's rows (m, deg)
    validation.check("fiducial_attitude", math.degrees(da))
    assert dp <= position_bound(0.4) and da <= ANGLE_BOUND, (dp, math.degrees(da))
    pinhole = solve(image)
    assert not pinhole.valid or errors(pinhole, R_C_G, p_C_G)[0] > 10 * dp


def test_markers_turned_and_tilted_in_their_link():
    """A layout whose markers are not all pi about x (that rotation is its own inverse): each turned
    about its normal and tilted, so a transposed marker rotation anywhere is caught."""
    turned = tuple(
        dataclasses.replace(m, R_link_marker=m.R_link_marker @ exp_so3([0.2 * i, -0.15 * i, 0.4 + 0.7 * i]))
        for i, m in enumerate(LAYOUT.markers)
    )
    layout = dataclasses.replace(LAYOUT, markers=turned)
    R_C_G, p_C_G = scenes.camera_pose(0.5, (0.05, -0.03), (0.12, 0.02), 2.9)
    estimate = FiducialEstimator(layout, 3, 1.5).estimate(
        scenes.noisy(scenes.warp(layout, R_C_G, p_C_G), 2.0, seed=2), scenes.K, NO_DISTORTION, P_EE_CAMERA, R_EE_CAMERA
    )
    assert estimate.valid and estimate.markers >= 4, estimate.reason
    dp, da = errors(estimate, R_C_G, p_C_G)
    assert dp <= position_bound(0.5) and da <= ANGLE_BOUND, (dp, math.degrees(da))
    # one of them alone: its own pose is all there is (no other marker's corners to pull it back)
    R_C_G, p_C_G = scenes.camera_pose(0.2, (0.02, 0.13), (0.1, 0.05), 0.6)
    alone = scenes.warp(dataclasses.replace(layout, markers=(turned[2],)), R_C_G, p_C_G)
    estimate = FiducialEstimator(layout, 1, 1.5).estimate(
        scenes.noisy(alone, 2.0, seed=4), scenes.K, NO_DISTORTION, P_EE_CAMERA, R_EE_CAMERA
    )
    assert estimate.valid and estimate.markers == 1, estimate.reason
    dp, da = errors(estimate, R_C_G, p_C_G)
    assert dp <= position_bound(0.2) and da <= ANGLE_BOUND, (dp, math.degrees(da))


def test_markers_out_of_view_give_no_pose():
    R_C_G, p_C_G = scenes.camera_pose(0.4, (0.0, 0.0), (1.2, 0.3), 0.0)  # looking away, past the face
    estimate = solve(scenes.warp(LAYOUT, R_C_G, p_C_G))
    assert not estimate.valid and estimate.markers == 0
    assert "0 marker(s) seen, 1 needed" in estimate.reason
    assert np.all(np.isnan(estimate.p_ee_grasp)) and np.all(np.isnan(estimate.q_ee_grasp))


def test_occluded_markers_are_not_used_and_too_few_give_no_pose():
    """Only the tip marker left in view at 0.3 m: a pose with min_markers 1 (a single 4 cm square
    is looser: 1.7 mm and 0.55 deg measured here, 6.7 deg at 0.5 m), none with 2."""
    R_C_G, p_C_G = scenes.camera_pose(0.3, (0.05, -0.03), (0.12, 0.02), 2.9)
    image = scenes.noisy(scenes.warp(LAYOUT, R_C_G, p_C_G), 2.0, seed=1)
    rvec = cv2.Rodrigues(R_C_G)[0]
    for marker in LAYOUT.markers[1:]:  # an arm in front of every root marker
        quad, _ = cv2.projectPoints(marker.corners(marker.size * 0.8), rvec, p_C_G, scenes.K, None)
        cv2.fillConvexPoly(image, np.rint(quad.reshape(4, 2)).astype(np.int32), (40, 40, 40))
    two = FiducialEstimator(LAYOUT, 2, 1.5).estimate(image, scenes.K, NO_DISTORTION, P_EE_CAMERA, R_EE_CAMERA)
    assert not two.valid and two.markers == 1 and "1 marker(s) seen, 2 needed" in two.reason
    one = solve(image)
    assert one.valid and one.markers == 1
    dp, da = errors(one, R_C_G, p_C_G)
    assert dp <= position_bound(0.3) and da <= 2 * ANGLE_BOUND, (dp, math.degrees(da))


def test_a_marker_away_from_its_place_fails_the_reprojection_check():
    """Marker 2 drawn 1.5 cm off where the layout puts it: no pose fits every corner."""
    R_C_G, p_C_G = scenes.camera_pose(0.5, (0.05, -0.03), (0.12, 0.02), 2.9)
    image = scenes.warp(LAYOUT, R_C_G, p_C_G, shift={2: np.array([0.015, 0.0, 0.0])})
    estimate = solve(image)
    assert not estimate.valid and estimate.markers == 5
    assert estimate.reprojection_error > 1.5 and "reprojection error" in estimate.reason
    assert FiducialEstimator(LAYOUT, 1, 50.0).estimate(image, scenes.K, NO_DISTORTION, P_EE_CAMERA, R_EE_CAMERA).valid


def test_ids_outside_the_layout_and_ids_seen_twice_are_dropped():
    R_C_G, p_C_G = scenes.camera_pose(0.5, (0.05, -0.03), (0.12, 0.02), 2.9)
    # a stranger (id 9) on the face, and a second marker 4 on the other side of the rod
    extra = (
        Marker(9, 0.06, np.array([0.1, 0.1, 0.1995]), LAYOUT.markers[1].R_link_marker),
        Marker(4, 0.06, np.array([-0.1, -0.12, 0.1995]), LAYOUT.markers[1].R_link_marker),
    )
    drawn = dataclasses.replace(LAYOUT, markers=LAYOUT.markers + extra)
    estimator = FiducialEstimator(LAYOUT, 1, 1.5)
    image = scenes.warp(drawn, R_C_G, p_C_G)
    assert sorted(estimator.detect(image)) == [0, 1, 2, 3]
    estimate = solve(image, estimator)
    assert estimate.valid and estimate.markers == 4
    dp, da = errors(estimate, R_C_G, p_C_G)
    assert dp <= position_bound(0.5) and da <= ANGLE_BOUND


def test_the_same_image_gives_the_same_bits():
    R_C_G, p_C_G = scenes.camera_pose(0.3, (-0.02, 0.04), (-0.07, 0.11), -1.1)
    image = scenes.noisy(scenes.warp(LAYOUT, R_C_G, p_C_G), 2.0, seed=5)
    a, b = solve(image), solve(image.copy())
    assert a.p_ee_grasp.tobytes() == b.p_ee_grasp.tobytes() and a.q_ee_grasp.tobytes() == b.q_ee_grasp.tobytes()


def test_an_image_that_is_not_rgb_uint8_is_refused():
    with pytest.raises(ValueError, match="H x W x 3 uint8"):
        solve(np.zeros((48, 64), dtype=np.uint8))


# --------------------------------------------------------------------------- the layout and its mesh


def test_the_committed_meshes_are_what_the_layout_gives_and_the_target_draws_them():
    from components.robots.urdf import read_urdf

    assert fiducial_markers.stale(LAYOUT, scenes.ROOT) == [], (
        "run orchestrator markers models/capture/grapple_markers.yaml"
    )
    urdf = read_urdf(scenes.ROOT / "models" / "capture" / "target.urdf")
    root = urdf.tree.getroot()
    colours = {m.get("name"): m.find("color").get("rgba") for m in root.findall("material")}
    drawn = {
        visual.find("geometry/mesh").get("filename"): colours[visual.find("material").get("name")]
        for visual in root.find(f"link[@name='{LAYOUT.link}']").findall("visual")
        if visual.find("geometry/mesh") is not None
    }
    assert drawn == {
        str(fiducial_markers.mesh_path(LAYOUT, "white")): "1 1 1 1",
        str(fiducial_markers.mesh_path(LAYOUT, "black")): "0 0 0 1",
    }


def test_the_meshes_cells_read_back_as_the_layouts_ids():
    """Each marker's black cells, put back on a grid from the black mesh's triangles, are the
    picture OpenCV's detector reads as that marker's id."""
    import trimesh

    mesh = trimesh.load(str(fiducial_markers.mesh_path(LAYOUT, "black")), force="mesh", process=False)
    centres = np.asarray(mesh.triangles_center)
    detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    n = LAYOUT.cells + 2 * LAYOUT.quiet_zone
    for marker in LAYOUT.markers:
        side = marker.size * LAYOUT.quad_scale
        local = (centres - marker.p_link_marker) @ marker.R_link_marker  # marker frame
        mine = np.all(np.abs(local[:, :2]) < 0.5 * side, axis=1) & (np.abs(local[:, 2]) < 1e-9)
        picture = np.full((n, n), 255, np.uint8)
        cols = np.floor((local[mine, 0] + 0.5 * side) / side * n).astype(int)
        rows = np.floor((0.5 * side - local[mine, 1]) / side * n).astype(int)
        picture[rows, cols] = 0
        big = np.pad(cv2.resize(picture, (n * 20, n * 20), interpolation=cv2.INTER_NEAREST), 40, constant_values=255)
        _, ids, _ = detector.detectMarkers(big)
        assert ids is not None and ids.ravel().tolist() == [marker.id]


@pytest.mark.parametrize(
    "edit, key",
    [
        (lambda d: d.update(dictionary="DICT_9X9_1"), "dictionary"),
        (lambda d: d["markers"][1].update(id=0), "listed twice"),
        (lambda d: d["markers"][0].update(id=50), "ids 0 to 49"),
        (lambda d: d["markers"][0].update(orientation=[1, 0, 0, 0.5]), "unit quaternion"),
        (lambda d: d["markers"][0].update(size="-4 cm"), "markers[0].size"),
        (lambda d: d["markers"][0].update(colour="red"), "markers[0].colour"),
        (lambda d: d.pop("link"), "link"),
    ],
)
def test_a_bad_layout_is_refused_naming_the_field(tmp_path, edit, key):
    import yaml

    data = yaml.safe_load(scenes.LAYOUT.read_text())
    edit(data)
    path = tmp_path / "layout.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=re.escape(key)) as raised:
        read_layout(path, "markers")
    assert raised.value.key == "markers" and str(path) in str(raised.value)


def test_the_camera_to_end_effector_transform_over_fixed_joints_against_pinocchio(tmp_path):
    """components.estimators.component.fixed_transform on a chain a - b - c - d of fixed joints
    with turns and offsets (and a branch), against Pinocchio's frame placements."""
    import pinocchio as pin

    from components.estimators.component import fixed_transform
    from components.robots.urdf import read_urdf

    links = "".join(
        f'<link name="{n}"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" '
        f'izz="1"/></inertial></link>'
        for n in "abcde"
    )
    joints = [
        ("a", "b", "0.1 0.2 0.3", "0.3 -0.2 1.1"),
        ("b", "c", "-0.4 0.05 0.2", "1.2 0.4 -0.7"),
        ("c", "d", "0.0 0.3 -0.1", "-0.5 0.9 0.2"),
        ("a", "e", "0.5 0 0", "0 0 1.5"),
    ]
    text = "".join(
        f'<joint name="{p}_{c}" type="fixed"><parent link="{p}"/><child link="{c}"/>'
        f'<origin xyz="{xyz}" rpy="{rpy}"/></joint>'
        for p, c, xyz, rpy in joints
    )
    path = tmp_path / "chain.urdf"
    path.write_text(f'<robot name="chain">{links}{text}</robot>')
    model = pin.buildModelFromUrdf(str(path))
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    placement = {n: data.oMf[model.getFrameId(n)].homogeneous for n in "abcde"}
    urdf = read_urdf(path)
    for a, b in (("a", "d"), ("d", "a"), ("b", "d"), ("e", "d"), ("c", "c")):
        expected = np.linalg.inv(placement[a]) @ placement[b]
        assert np.allclose(fixed_transform(urdf, a, b), expected, atol=1e-12), (a, b)
