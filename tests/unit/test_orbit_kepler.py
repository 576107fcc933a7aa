"""Kepler orbits against independent references: Vallado's textbook example, the closed-form
period, scipy's DOP853 two-body and J2 integrations, and a bracketing root finder."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from components.constants import EARTH_RATE, J2_EARTH, MU_EARTH, R_EARTH
from components.orbit.kepler import (
    ElementError,
    KeplerOrbit,
    check_elements,
    coe_to_rv,
    j2_secular_rates,
    solve_kepler,
    true_from_eccentric,
)
from tests import validation

deg = math.radians


def test_constants_are_the_published_values():
    assert MU_EARTH == 3.986004418e14  # WGS 84 GM
    assert R_EARTH == 6378137.0  # WGS 84 a
    assert pytest.approx(math.sqrt(5) * 4.84165371736e-4, rel=1e-8) == J2_EARTH  # EGM96 -sqrt(5) C20
    assert EARTH_RATE == 7.292115e-5  # WGS 84 omega


def test_vallado_example_2_6_coe2rv():
    # Vallado, Fundamentals of Astrodynamics and Applications (4th ed.), Example 2-6 (COE2RV):
    # p = 11067.790 km, e = 0.83285, i = 87.87°, Ω = 227.89°, ω = 53.38°, ν = 92.335°, with Vallado's
    # mu = 398600.4418 km^3/s^2 ->
    # r = 6525.368 I + 6861.532 J + 6449.119 K km, v = 4.902279 I + 5.533140 J - 1.975710 K km/s.
    # The book prints 3 decimals in km and 6 in km/s: tolerance half a unit of the last digit.
    r, v = coe_to_rv(11067.790e3, 0.83285, deg(87.87), deg(227.89), deg(53.38), deg(92.335), 398600.4418e9)
    validation.check("kepler_vallado", np.abs(r - [6525.368e3, 6861.532e3, 6449.119e3]).max())  # m
    np.testing.assert_allclose(v, [4902.279, 5533.140, -1975.710], rtol=0, atol=0.5e-3)  # m/s


def test_kepler_orbit_reproduces_vallado_example_at_true_anomaly():
    # Same example through KeplerOrbit: mean anomaly from ν (E, then M = E - e sin E) must give
    # back Vallado's r and v (same tolerance as above).
    e, p = 0.83285, 11067.790e3
    a = p / (1 - e * e)
    nu = deg(92.335)
    ecc = 2 * math.atan(math.sqrt((1 - e) / (1 + e)) * math.tan(nu / 2))
    m = ecc - e * math.sin(ecc)
    orbit = KeplerOrbit(a, e, deg(87.87), deg(227.89), deg(53.38), m, mu=398600.4418e9)
    r, v, _ = orbit.state(0.0)
    validation.check("kepler_vallado", np.abs(r - [6525.368e3, 6861.532e3, 6449.119e3]).max())
    np.testing.assert_allclose(v, [4902.279, 5533.140, -1975.710], rtol=0, atol=0.5e-3)


@pytest.mark.parametrize("e", [0.0, 1e-6, 0.1, 0.5, 0.7, 0.9, 0.97, 0.99, 0.999])
def test_kepler_solver_converges_to_1e_12_rad(e):
    # Reference: scipy's brentq on the same equation with xtol 1e-15 (a bracketing method,
    # independent of our Newton iteration). Tolerance 1e-12 rad (the solver's contract), over
    # 2001 mean anomalies in [-4 pi, 4 pi] including 0, ±pi and values near them.
    ms = np.concatenate([np.linspace(-4 * math.pi, 4 * math.pi, 2001), [1e-12, math.pi - 1e-12, math.pi + 1e-9]])
    worst = 0.0
    for m in ms:
        ecc = solve_kepler(m, e)
        m0 = m - 2 * math.pi * math.floor(m / (2 * math.pi))
        ref = brentq(lambda x, m0=m0: x - e * math.sin(x) - m0, 0.0, 2 * math.pi, xtol=1e-15)
        ref += m - m0
        worst = max(worst, abs(ecc - ref))
        assert abs(ecc - e * math.sin(ecc) - m) < 1e-12 * max(1.0, abs(m))
    assert worst < 1e-12, worst


def test_true_from_eccentric_matches_the_half_angle_formula():
    for e in (0.0, 0.3, 0.9):
        for ecc in np.linspace(-3, 3, 13):
            nu = true_from_eccentric(ecc, e)
            assert math.cos(nu) == pytest.approx((math.cos(ecc) - e) / (1 - e * math.cos(ecc)), abs=1e-14)
            assert math.copysign(1, nu) == math.copysign(1, ecc) or ecc == 0


@pytest.mark.parametrize("a,e", [(6778e3, 0.0), (7000e3, 0.01), (26600e3, 0.7)])
def test_one_period_returns_to_start_without_j2(a, e):
    # Closed form: a two-body orbit is periodic with T = 2 pi sqrt(a^3/mu). Tolerance 1 mm, 1 µm/s.
    orbit = KeplerOrbit(a, e, deg(51.6), deg(30), deg(40), deg(10))
    assert orbit.period == pytest.approx(2 * math.pi * math.sqrt(a**3 / MU_EARTH), rel=1e-15)
    r0, v0, _ = orbit.state(0.0)
    r1, v1, _ = orbit.state(orbit.period)
    assert np.linalg.norm(r1 - r0) < 1e-3
    assert np.linalg.norm(v1 - v0) < 1e-6
    # half a period later it is somewhere else (guards against a trivially constant orbit)
    assert np.linalg.norm(orbit.state(orbit.period / 2)[0] - r0) > a


def _two_body(t, y):
    r = y[:3]
    return np.concatenate([y[3:], -MU_EARTH * r / np.linalg.norm(r) ** 3])


@pytest.mark.parametrize("a,e,i", [(6778e3, 0.0004, 51.64), (26600e3, 0.7, 63.4), (42164e3, 0.0, 0.0)])
def test_kepler_matches_dop853_two_body_over_one_day(a, e, i):
    # Reference: scipy DOP853 integration of r'' = -mu r/|r|^3 (rtol 1e-12, atol 1e-6 m) from the
    # orbit's own state at t = 0, over one day. Tolerance: 1 m in position, 1 mm/s in velocity.
    # Measured: 8e-5 m (ISS), 9e-3 m (e = 0.7), dominated by the integrator.
    orbit = KeplerOrbit(a, e, deg(i), deg(30), deg(40), deg(10))
    r0, v0, acc0 = orbit.state(0.0)
    np.testing.assert_allclose(acc0, -MU_EARTH * r0 / np.linalg.norm(r0) ** 3, rtol=1e-12)
    ts = np.linspace(0.0, 86400.0, 97)
    sol = solve_ivp(
        _two_body, (0.0, 86400.0), np.concatenate([r0, v0]), method="DOP853", rtol=1e-12, atol=1e-6, t_eval=ts
    )
    assert sol.success
    worst = 0.0
    for k, t in enumerate(ts):
        r, v, _ = orbit.state(t)
        worst = max(worst, np.linalg.norm(r - sol.y[:3, k]))
        assert np.linalg.norm(v - sol.y[3:, k]) < 1e-3
    validation.check("kepler_two_body", worst)


def _raan(r, v):
    h = np.cross(r, v)
    return math.atan2(h[0], -h[1])


def _j2_accel(r):
    x, y, z = r
    rn = np.linalg.norm(r)
    k = 1.5 * J2_EARTH * MU_EARTH * R_EARTH**2 / rn**5
    f = 5.0 * z * z / rn**2
    return -MU_EARTH * r / rn**3 + k * np.array([x * (f - 1.0), y * (f - 1.0), z * (f - 3.0)])


def test_j2_raan_drift_of_iss_matches_closed_form_and_numerical_j2_integration():
    a, e, i = 6778e3, 0.0004, deg(51.64)
    orbit = KeplerOrbit(a, e, i, deg(10), deg(30), 0.0, j2=True)
    # closed form -3/2 n J2 (R/p)^2 cos i, evaluated independently here
    n = math.sqrt(MU_EARTH / a**3)
    closed = -1.5 * n * J2_EARTH * (R_EARTH / (a * (1 - e * e))) ** 2 * math.cos(i)
    assert orbit.raan_rate == pytest.approx(closed, rel=1e-14)
    assert math.degrees(closed) * 86400 == pytest.approx(-5.0, abs=0.01)  # ISS: about -5 deg/day

    # the node of the published r, v drifts at that rate: fit over one day, tolerance 1e-4 relative
    # (v includes the frame drift, so the osculating node wobbles slightly; measured 2e-5)
    ts = np.linspace(0.0, 86400.0, 401)
    nodes = np.unwrap([_raan(*orbit.state(t)[:2]) for t in ts])
    assert np.polyfit(ts, nodes, 1)[0] == pytest.approx(closed, rel=1e-4)

    # independent physics: integrate the J2 force model (DOP853, rtol 1e-10) from the same initial
    # state; the secular node rate must agree with first-order theory to 1 % (second-order J2 and
    # mean-vs-osculating elements; measured 4e-4)
    r0, v0, _ = orbit.state(0.0)
    sol = solve_ivp(
        lambda t, y: np.concatenate([y[3:], _j2_accel(y[:3])]),
        (0.0, 86400.0),
        np.concatenate([r0, v0]),
        method="DOP853",
        rtol=1e-10,
        atol=1e-4,
        t_eval=ts,
    )
    assert sol.success
    nodes_num = np.unwrap([_raan(sol.y[:3, k], sol.y[3:, k]) for k in range(len(ts))])
    validation.check("kepler_j2_raan", abs(np.polyfit(ts, nodes_num, 1)[0] / closed - 1))


def test_j2_rates_vanish_where_theory_says():
    # critical inclination 63.43°: dω/dt = 0; polar orbit: dΩ/dt = 0
    _, argp_rate, _ = j2_secular_rates(7000e3, 0.01, math.asin(math.sqrt(0.8)))
    raan_rate, _, _ = j2_secular_rates(7000e3, 0.01, math.pi / 2)
    assert abs(argp_rate) < 1e-20 and abs(raan_rate) < 1e-20


def test_j2_velocity_and_acceleration_are_time_derivatives_of_position():
    # Five-point central differences (h = 1 s: truncation h^4 n^4 |v| / 30 ~ 4e-10 m/s) of the
    # position and velocity. Tolerance 1e-6 m/s and 1e-9 m/s^2: after one day the mean anomaly
    # (~100 rad) carries ~1e-14 rad of rounding, i.e. ~1e-7 m of position noise.
    orbit = KeplerOrbit(6778e3, 0.05, deg(51.64), deg(10), deg(30), 0.3, j2=True)

    def derivative(f, t, h=1.0):
        return (f(t - 2 * h) - 8 * f(t - h) + 8 * f(t + h) - f(t + 2 * h)) / (12 * h)

    for t in (0.0, 1234.5, 86400.0):
        r, v, acc = orbit.state(t)
        assert np.linalg.norm(derivative(lambda s: orbit.state(s)[0], t) - v) < 1e-6
        assert np.linalg.norm(derivative(lambda s: orbit.state(s)[1], t) - acc) < 1e-9
        # the J2 drift adds an out-of-plane acceleration (nodal precession): not two-body
        assert np.linalg.norm(acc + MU_EARTH * r / np.linalg.norm(r) ** 3) > 1e-4


@pytest.mark.parametrize(
    "args,key",
    [
        ((6778e3, 1.0, 0.5), "eccentricity"),
        ((6778e3, 1.5, 0.5), "eccentricity"),
        ((6778e3, -0.1, 0.5), "eccentricity"),
        ((-6778e3, 0.0, 0.5), "semi_major_axis"),
        ((0.0, 0.0, 0.5), "semi_major_axis"),
        ((6778e3, 0.0, -0.1), "inclination"),
        ((6778e3, 0.0, math.pi + 1e-9), "inclination"),
        ((6778.0, 0.0, 0.5), "semi_major_axis"),  # km given as m: below the surface
        ((7000e3, 0.2, 0.5), "semi_major_axis"),  # perigee 5600 km
    ],
)
def test_bad_elements_name_the_element(args, key):
    with pytest.raises(ElementError) as info:
        check_elements(*args)
    assert info.value.key == key
    assert "got" in str(info.value)


def test_km_given_as_m_gets_a_hint():
    with pytest.raises(ElementError, match="did you mean '6778 km'"):
        check_elements(6778.0, 0.0, 0.5)
