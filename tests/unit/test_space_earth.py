"""components/space/earth.py: WGS 84 geodetic coordinates against ERFA's gc2gd/gd2gc, the GCRF -> ITRF
rotation against ERFA's IAU 2006/2000A chain, the run clock across a leap second."""

from __future__ import annotations

import math

import erfa
import numpy as np

from components import timescales
from components.space import earth
from tests import validation


def random_points(n: int, seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True) * rng.uniform(6.2e6, 4.3e7, size=(n, 1))


def test_geodetic_from_ecef_matches_erfa_gc2gd():
    """Points from 6200 km (below the equator's surface) to beyond GEO, every direction."""
    worst_height, worst_angle = 0.0, 0.0
    for r in random_points(5000):
        longitude, latitude, height = erfa.gc2gd(1, r)  # 1: WGS 84
        phi, lam, h = earth.geodetic_from_ecef(r)
        worst_height = max(worst_height, abs(h - height))
        worst_angle = max(worst_angle, abs(phi - latitude), abs(math.remainder(lam - longitude, 2 * math.pi)))
    print(f"geodetic vs gc2gd: height {worst_height:.1e} m, angles {worst_angle:.1e} rad")
    assert worst_angle < 1e-10
    validation.check("geodetic_wgs84", worst_height)


def test_ecef_from_geodetic_matches_erfa_gd2gc_and_inverts():
    rng = np.random.default_rng(4)
    for _ in range(500):
        phi, lam, h = rng.uniform(-1.5, 1.5), rng.uniform(-math.pi, math.pi), rng.uniform(0.0, 2e6)
        r = earth.ecef_from_geodetic(phi, lam, h)
        assert np.abs(r - erfa.gd2gc(1, lam, phi, h)).max() < 1e-8
        back = earth.geodetic_from_ecef(r)
        assert abs(back[0] - phi) < 1e-12 and abs(back[1] - lam) < 1e-12 and abs(back[2] - h) < 1e-7


def test_gcrf_to_itrf_is_iau_2006_2000a():
    """R3(ERA) C_cirs_gcrf against ERFA's own chain c2t06a (IAU 2006/2000A, no polar motion) over
    2000-2050, and IAU 2000B's c2t00b within its 4e-9 rad; the Earth's rotation angle in it (a
    point on the equator turns with the ERA)."""
    for year_days in np.linspace(0.0, 50 * 365.25, 7):
        utc = (2451545.0, year_days + 0.123)
        tt = timescales.utc_to_tt(utc)
        M = earth.gcrf_to_itrf(tt, utc)
        assert np.abs(M @ M.T - np.eye(3)).max() < 1e-15
        # c2t06a keeps the TIO locator s' (-47 uas a century) in W: left out here, the only difference
        assert np.abs(M - erfa.c2t06a(*tt, *utc, 0.0, 0.0)).max() < abs(erfa.sp00(*tt)) + 1e-13
        assert 1e-10 < np.abs(M - erfa.c2t00b(*tt, *utc, 0.0, 0.0)).max() < 4e-9
    utc = (2461120.5, 0.25)
    tt = timescales.utc_to_tt(utc)
    M = earth.gcrf_to_itrf(tt, utc)
    later = earth.gcrf_to_itrf((tt[0], tt[1] + 1.0 / 86400), (utc[0], utc[1] + 1.0 / 86400))
    x = M.T @ np.array([1.0, 0.0, 0.0])  # the ITRF x axis in GCRF, then a second later
    turned = math.atan2(np.linalg.norm(np.cross(x, later.T @ [1.0, 0.0, 0.0])), x @ (later.T @ [1.0, 0.0, 0.0]))
    assert abs(turned - 7.292115e-5) < 1e-9  # rad in one second: the Earth's rate (+ precession)


def test_earth_clock_counts_the_leap_second():
    """Run time 1 s after 2016-12-31T23:59:59 is 23:59:60 (UTC), 2 s after is 2017-01-01T00:00:00."""
    clock = earth.EarthRotation("2016-12-31T23:59:59Z")
    after = erfa.d2dtf("UTC", 0, *clock.utc_tt(2.0)[0])
    assert (int(after[0]), int(after[1]), int(after[2])) == (2017, 1, 1) and tuple(after[3])[:3] == (0, 0, 0)
    tt = clock.utc_tt(0.0)[1]
    assert abs(((tt[0] - 2457753.5) + tt[1]) * 86400 - (86399 + 68.184)) < 1e-4  # TT - UTC = 68.184 s
