"""Quintic Hermite spline: interpolation, C2 continuity, and agreement with scipy's BPoly."""

import numpy as np
import pytest
from scipy.interpolate import BPoly

from components.orbit.spline import QuinticHermiteSpline, SplineError


def _waypoints(n=6, seed=4):
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.5, 100.0, size=n)) - 3.0
    return t, rng.normal(size=(n, 3)) * 7e6, rng.normal(size=(n, 3)) * 7e3, rng.normal(size=(n, 3)) * 9.0


def test_passes_through_every_waypoint_position_velocity_acceleration():
    # relative tolerance 1e-12 of each quantity's scale (rounding of the polynomial evaluation)
    t, p, v, a = _waypoints()
    s = QuinticHermiteSpline(t, p, v, a)
    for k in range(len(t)):
        for seg in {max(k - 1, 0), min(k, len(t) - 2)}:  # from both neighbouring segments
            pk, vk, ak = s.evaluate(t[k], segment=seg)
            np.testing.assert_allclose(pk, p[k], rtol=0, atol=1e-12 * 7e6 * 10)
            np.testing.assert_allclose(vk, v[k], rtol=0, atol=1e-12 * 7e3 * 10)
            np.testing.assert_allclose(ak, a[k], rtol=0, atol=1e-12 * 9.0 * 1e4)


def test_c2_at_the_joints():
    # At each interior joint the left segment's polynomial and the right one's give the same
    # position, velocity and acceleration (relative 1e-12), and approaching the joint from both
    # sides the jumps vanish at least linearly (ratio >= ~10 for a 10x smaller offset): continuous up to the
    # second derivative. The third derivative is free to jump (C2, not C3).
    t, p, v, a = _waypoints()
    s = QuinticHermiteSpline(t, p, v, a)
    for k in range(1, len(t) - 1):
        left, right = s.evaluate(t[k], segment=k - 1), s.evaluate(t[k], segment=k)
        for m, scale in enumerate((7e6, 7e3, 9.0)):
            assert np.linalg.norm(left[m] - right[m]) < 1e-12 * scale * 1e3
        jumps = []
        for d in (1e-2, 1e-3):
            lo, hi = s.evaluate(t[k] - d), s.evaluate(t[k] + d)
            jumps.append([np.linalg.norm(lo[m] - hi[m]) for m in range(3)])
        ratio = np.array(jumps[0]) / np.array(jumps[1])
        assert np.all(ratio > 9.0), ratio


def test_matches_scipy_bpoly_from_derivatives():
    # Reference: scipy.interpolate.BPoly.from_derivatives builds the same piecewise quintic Hermite
    # interpolant in the Bernstein basis. Tolerance 1e-9 relative to each quantity's scale; measured ~1e-14.
    t, p, v, a = _waypoints(n=8, seed=11)
    s = QuinticHermiteSpline(t, p, v, a)
    ref = BPoly.from_derivatives(t, np.stack([p, v, a], axis=1))
    dref, ddref = ref.derivative(), ref.derivative(2)
    for x in np.linspace(t[0], t[-1], 503):
        pos, vel, acc = s.evaluate(x)
        np.testing.assert_allclose(pos, ref(x), rtol=0, atol=1e-9 * 7e6)
        np.testing.assert_allclose(vel, dref(x), rtol=0, atol=1e-9 * 7e3)
        np.testing.assert_allclose(acc, ddref(x), rtol=0, atol=1e-9 * 9.0 * 100)


def test_reproduces_a_quintic_exactly():
    # Waypoints sampled from one quintic polynomial: the spline must be that polynomial everywhere
    coef = np.array(
        [
            [1.0, -2.0, 0.5],
            [3.0, 1.0, -1.0],
            [0.2, 0.0, 0.1],
            [-0.03, 0.01, 0.02],
            [0.002, -0.001, 0.0],
            [-1e-4, 2e-5, 3e-5],
        ]
    )
    poly = [np.polynomial.Polynomial(coef[:, j]) for j in range(3)]
    t = np.array([0.0, 1.5, 4.0, 7.0, 10.0])

    def value(x, m):
        return np.array([pj.deriv(m)(x) if m else pj(x) for pj in poly])

    s = QuinticHermiteSpline(t, [value(x, 0) for x in t], [value(x, 1) for x in t], [value(x, 2) for x in t])
    for x in np.linspace(0, 10, 41):
        pos, vel, acc = s.evaluate(x)
        np.testing.assert_allclose(pos, value(x, 0), atol=1e-10)
        np.testing.assert_allclose(vel, value(x, 1), atol=1e-10)
        np.testing.assert_allclose(acc, value(x, 2), atol=1e-10)


def test_outside_span_is_an_error():
    t, p, v, a = _waypoints()
    s = QuinticHermiteSpline(t, p, v, a)
    with pytest.raises(ValueError, match="outside the waypoints' span"):
        s.evaluate(t[-1] + 1e-3)


@pytest.mark.parametrize(
    "times,match,index",
    [
        ([0.0], "at least 2 waypoints, got 1", None),
        ([0.0, 2.0, 1.0], r"strictly increasing times, got t\[1\] = 2.0 s then t\[2\] = 1.0 s", 2),
        ([0.0, 1.0, 1.0], r"strictly increasing times, got t\[1\] = 1.0 s then t\[2\] = 1.0 s", 2),
    ],
)
def test_bad_waypoints(times, match, index):
    n = len(times)
    with pytest.raises(SplineError, match=match) as info:
        QuinticHermiteSpline(times, np.ones((n, 3)), np.ones((n, 3)), np.ones((n, 3)))
    assert info.value.index == index


def test_mismatched_shapes_and_nan():
    with pytest.raises(SplineError, match=r"velocitys|velocities|shape"):
        QuinticHermiteSpline([0, 1], np.ones((2, 3)), np.ones((2, 2)), np.ones((2, 3)))
    with pytest.raises(SplineError, match="finite positions"):
        QuinticHermiteSpline([0, 1], [[0, 0, 0], [np.nan, 0, 0]], np.ones((2, 3)), np.ones((2, 3)))
