"""components/rotations.py against an independent reference: scipy.spatial.transform.Rotation
(quaternions [x, y, z, w] too; as_matrix, as_quat, from_rotvec, from_euler) and np.cross.

Tolerances: 1e-14 absolute where only rounding separates the two (unit-size entries), stated
otherwise per test."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from components.rotations import (
    cross,
    cross3,
    exp_so3,
    log_so3,
    matrix_to_quat,
    matrix_to_rpy,
    quat_to_matrix,
    rpy_to_matrix,
    skew,
)


def _rotations():
    """Random rotations plus the hard cases for Shepperd's branches: identity, half turns about
    the axes and a diagonal, and angles just below pi."""
    return Rotation.concatenate(
        [
            Rotation.random(300, random_state=3),
            Rotation.identity(),
            *(Rotation.from_rotvec(math.pi * a) for a in np.eye(3)),
            Rotation.from_rotvec([math.pi / math.sqrt(2), math.pi / math.sqrt(2), 0]),
            Rotation.from_rotvec([0, math.pi - 1e-9, 0]),
            Rotation.from_rotvec([1e-12, 0, 0]),
        ]
    )


def _w_nonnegative(q):
    return q * np.where(q[..., 3:4] < 0, -1.0, 1.0)


def test_cross_products_match_numpy():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(2, 50, 3))
    for x, y in zip(a, b):
        np.testing.assert_allclose(cross3(x, y), np.cross(x, y), rtol=0, atol=1e-14)
        np.testing.assert_allclose(cross3(list(x), tuple(y)), np.cross(x, y), rtol=0, atol=1e-14)
        np.testing.assert_allclose(skew(x) @ y, np.cross(x, y), rtol=0, atol=1e-14)
    np.testing.assert_allclose(cross(a, b), np.cross(a, b), rtol=0, atol=1e-14)
    np.testing.assert_allclose(cross(a[0], b), np.cross(a[0], b), rtol=0, atol=1e-14)  # broadcasting


def test_quat_to_matrix_matches_scipy_single_and_batched():
    rotations = _rotations()
    quats, matrices = rotations.as_quat(), rotations.as_matrix()
    for q, R in zip(quats, matrices):
        np.testing.assert_allclose(quat_to_matrix(q), R, rtol=0, atol=1e-14)
        np.testing.assert_allclose(quat_to_matrix(-3.0 * q), R, rtol=0, atol=1e-14)  # normalized first, sign-free
    np.testing.assert_allclose(quat_to_matrix(quats), matrices, rtol=0, atol=1e-14)
    batch = quat_to_matrix(2.0 * quats[:300].reshape(3, 100, 4))
    assert batch.shape == (3, 100, 3, 3)
    np.testing.assert_allclose(batch, matrices[:300].reshape(3, 100, 3, 3), rtol=0, atol=1e-14)


def test_q_A_B_rotates_B_vectors_into_A():
    # 90 deg about z: B's x axis is A's y axis
    q = [0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5)]
    np.testing.assert_allclose(quat_to_matrix(q) @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-15)


def test_matrix_to_quat_matches_scipy_with_w_nonnegative_single_and_batched():
    rotations = _rotations()
    reference = _w_nonnegative(rotations.as_quat())
    batched = matrix_to_quat(rotations.as_matrix())
    single = np.array([matrix_to_quat(R) for R in rotations.as_matrix()])
    for q in (batched, single):
        assert np.all(q[:, 3] >= 0.0)
        # for a half turn (w = 0) q and -q both have w >= 0: either is right
        same = np.minimum(np.abs(q - reference).max(axis=1), np.abs(q + reference).max(axis=1))
        assert same.max() < 1e-14
        np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, rtol=0, atol=1e-15)
    np.testing.assert_allclose(single, batched, rtol=0, atol=1e-15)  # both paths agree
    shaped = matrix_to_quat(rotations.as_matrix()[:300].reshape(3, 100, 3, 3))
    assert shaped.shape == (3, 100, 4)
    np.testing.assert_allclose(shaped.reshape(-1, 4), batched[:300], rtol=0, atol=0)


def test_matrix_to_quat_normalizes_a_slightly_scaled_matrix():
    R = Rotation.from_rotvec([0.3, -0.2, 1.0]).as_matrix()
    for q in (matrix_to_quat(R * (1 + 1e-6)), matrix_to_quat(np.array([R * (1 - 1e-6)]))[0]):
        assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-15)
        np.testing.assert_allclose(q, _w_nonnegative(Rotation.from_matrix(R).as_quat()), atol=1e-6)


def test_quaternion_round_trips():
    rng = np.random.default_rng(0)
    for _ in range(50):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        q = q if q[3] >= 0 else -q
        np.testing.assert_allclose(matrix_to_quat(quat_to_matrix(q)), q, rtol=0, atol=1e-14)


def test_exp_so3_matches_scipy():
    rng = np.random.default_rng(2)
    axes = rng.normal(size=(40, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    for axis, angle in zip(axes, np.concatenate([[0.0, 1e-12, 1e-9, 1e-7, 1e-4], rng.uniform(-7, 7, size=35)])):
        phi = angle * axis
        np.testing.assert_allclose(exp_so3(phi), Rotation.from_rotvec(phi).as_matrix(), rtol=0, atol=1e-14)
    np.testing.assert_allclose(exp_so3([0.0, 0.0, 0.0]), np.eye(3), rtol=0, atol=0)


@pytest.mark.parametrize(
    "angle",
    [0.0, 1e-12, 1e-6, 1e-3, 0.5, 1.5, 2.0, 3.0, math.pi - 1e-2, math.pi - 1e-4, math.pi - 1e-6, math.pi - 1e-9],
)
def test_log_so3_matches_the_rotation_vector_at_every_angle(angle):
    # R from scipy's from_rotvec; tolerance 1e-14 rad absolute (plus 1e-12 relative) including
    # angles a hair below pi, where sin(angle) -> 0 and the axis must come from the symmetric part
    # (the earlier controller log_so3 was off by ~sin(angle), 2e-4 rad at pi - 1e-4)
    rng = np.random.default_rng(5)
    for _ in range(20):
        axis = rng.normal(size=3)
        phi = axis / np.linalg.norm(axis) * angle
        np.testing.assert_allclose(log_so3(Rotation.from_rotvec(phi).as_matrix()), phi, rtol=1e-12, atol=1e-14)


def test_log_so3_at_a_half_turn_and_round_trip():
    rng = np.random.default_rng(4)
    for axis in list(np.eye(3)) + list(rng.normal(size=(10, 3))):
        phi = math.pi * axis / np.linalg.norm(axis)
        got = log_so3(Rotation.from_rotvec(phi).as_matrix())
        assert min(np.abs(got - phi).max(), np.abs(got + phi).max()) < 1e-14  # +-: the same rotation
    for phi in list(rng.normal(size=(20, 3))) + [np.array([np.pi - 1e-7, 0, 0]), np.array([0, 1e-9, 0])]:
        R = exp_so3(phi)
        angle = np.linalg.norm(phi) % (2 * np.pi)
        np.testing.assert_allclose(exp_so3(log_so3(R)), R, rtol=0, atol=1e-14)
        assert np.linalg.norm(log_so3(R)) == pytest.approx(min(angle, 2 * np.pi - angle), abs=1e-14)


def test_rpy_matches_scipy_extrinsic_xyz_and_round_trips():
    # URDF rpy: R = Rz(yaw) Ry(pitch) Rx(roll) = scipy's extrinsic "xyz" Euler angles
    rng = np.random.default_rng(1)
    for rpy in list(rng.uniform(-3, 3, size=(20, 3))) + [np.array([0.3, np.pi / 2, -0.2])]:
        R = rpy_to_matrix(rpy)
        np.testing.assert_allclose(R, Rotation.from_euler("xyz", rpy).as_matrix(), rtol=0, atol=1e-14)
        np.testing.assert_allclose(rpy_to_matrix(matrix_to_rpy(R)), R, rtol=0, atol=1e-12)
