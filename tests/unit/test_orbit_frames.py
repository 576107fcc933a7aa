"""LVLH frame and its angular velocity (references: scipy's Rotation, finite differences)."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from components.orbit.frames import lvlh_dcm, lvlh_state
from components.orbit.kepler import KeplerOrbit
from components.rotations import continuous

deg = math.radians


def _states():
    rng = np.random.default_rng(7)
    for _ in range(50):
        yield rng.normal(size=3) * 7e6, rng.normal(size=3) * 7e3


def test_lvlh_is_orthonormal_right_handed_x_along_r_z_along_h():
    # Tolerances 1e-14 (rounding only)
    for r, v in _states():
        c = lvlh_dcm(r, v)
        np.testing.assert_allclose(c.T @ c, np.eye(3), atol=1e-14)
        assert np.linalg.det(c) == pytest.approx(1.0, abs=1e-14)
        np.testing.assert_allclose(c[:, 0], r / np.linalg.norm(r), atol=1e-14)
        h = np.cross(r, v)
        np.testing.assert_allclose(c[:, 2], h / np.linalg.norm(h), atol=1e-14)
        np.testing.assert_allclose(c[:, 1], np.cross(c[:, 2], c[:, 0]), atol=1e-14)
        assert c[:, 1] @ v > 0  # y points along-track (prograde)


def test_lvlh_circular_equatorial_orbit_by_hand():
    # r along ECI x, v along ECI y: LVLH = ECI, so q_eci_lvlh = identity
    c = lvlh_dcm([7e6, 0, 0], [0, 7.5e3, 0])
    np.testing.assert_allclose(c, np.eye(3), atol=1e-15)
    # a quarter turn later: r along y, v along -x -> LVLH x = ECI y, y = -ECI x: 90° about z
    q, w = lvlh_state([0, 7e6, 0], [-7.5e3, 0, 0], [0, -8.0, 0])
    np.testing.assert_allclose(q, [0, 0, math.sqrt(0.5), math.sqrt(0.5)], atol=1e-15)
    np.testing.assert_allclose(w, [0, 0, 7.5e3 / 7e6], rtol=1e-15)


def test_lvlh_undefined_for_radial_motion():
    with pytest.raises(ValueError, match="not parallel"):
        lvlh_dcm([7e6, 0, 0], [10.0, 0, 0])
    with pytest.raises(ValueError):
        lvlh_dcm([0, 0, 0], [0, 7e3, 0])


def test_quaternion_rotates_lvlh_vectors_into_eci():
    # q_eci_lvlh applied to LVLH's x axis gives r̂ in ECI (the contract's q_A_B meaning)
    for r, v in list(_states())[:10]:
        q, _ = lvlh_state(r, v, np.zeros(3))
        np.testing.assert_allclose(Rotation.from_quat(q).apply([1, 0, 0]), r / np.linalg.norm(r), atol=1e-14)


def test_continuous_keeps_sign():
    q = np.array([0.0, 0.0, 0.6, 0.8])
    np.testing.assert_array_equal(continuous(-q, q), q)
    np.testing.assert_array_equal(continuous(q, q), q)
    np.testing.assert_array_equal(continuous(q, None), q)
    # several quaternions in one flat output (links): each keeps its own sign
    links = np.concatenate([q, [0.6, 0.0, 0.0, 0.8], [0.0, -0.8, 0.0, 0.6]])
    flipped = links * np.repeat([1.0, -1.0, -1.0], 4)
    np.testing.assert_array_equal(continuous(flipped, links), links)


def _rate_by_finite_difference(q_of_t, t, h):
    """Angular velocity (ECI axes) of q_eci_lvlh(t) by a central difference of rotations (scipy)."""
    qm, qp = Rotation.from_quat(q_of_t(t - h)), Rotation.from_quat(q_of_t(t + h))
    return (qp * qm.inv()).as_rotvec() / (2 * h)


@pytest.mark.parametrize(
    "j2,a,e", [(False, 6778e3, 0.0), (False, 26600e3, 0.7), (True, 6778e3, 0.0004), (True, 10000e3, 0.3)]
)
def test_w_lvlh_matches_finite_difference_of_q_eci_lvlh(j2, a, e):
    # Central difference of the quaternion series (h = 0.5 s, truncation O(h^2 w^3) ~ 1e-11 rad/s);
    # tolerance 1e-10 rad/s absolute. With J2 the out-of-plane (x) term is ~1e-6 rad/s, so the
    # test would fail without it.
    orbit = KeplerOrbit(a, e, deg(51.64), deg(10), deg(30), 0.2, j2=j2)

    def q_of_t(t):
        return lvlh_state(*orbit.state(t))[0]

    for t in (0.0, 700.0, 3000.0, 40000.0):
        r, v, acc = orbit.state(t)
        _, w = lvlh_state(r, v, acc)
        w_fd = _rate_by_finite_difference(q_of_t, t, 0.5)
        assert np.linalg.norm(w - w_fd) < 1e-10, (t, w, w_fd)
        x_rate = w @ lvlh_dcm(r, v)[:, 0]
        if j2:
            assert abs(x_rate) > 1e-8  # the out-of-plane term is exercised
        else:
            assert abs(x_rate) < 1e-15
