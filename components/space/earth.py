"""The Earth's orientation and shape: GCRF -> ITRF rotation and WGS 84 geodetic coordinates; plain functions.

| function | returns | unit, frames | model |
|---|---|---|---|
| :func:`gcrf_to_itrf` | M with r_itrf = M r_gcrf | 1, GCRF -> ITRF | ERFA ``c2t00b``: IAU 2000B precession-nutation, ERA, no polar motion, UT1 = UTC |
| :func:`geodetic_from_ecef` | latitude, longitude, height | rad, rad, m (WGS 84) | Bowring's iteration, three rounds |
| :func:`ecef_from_geodetic` | r_itrf | m, ITRF | closed form |
| :class:`EarthClock` | UTC and TT at run time t | two-part Julian dates | ERFA leap seconds (TAI in between) |

ECI is GCRF (the project's ECI and the dynamics' W axes); ECEF is ITRF. The rotation is
``M = W R3(ERA) NPB`` (ERFA's CIO-based chain), here with ``W = I``: polar motion (~0.3" ~ 10 m on
the ground) and UT1 - UTC (|dUT1| < 0.9 s: < 0.004 deg of longitude, < 420 m at the equator) are
left out, since no Earth orientation parameters are available offline. IAU 2000B agrees with
IAU 2000A (``c2t06a``) to 3e-9 rad (2 cm on the ground) over 2000-2050 at a tenth of the cost (7 us
against 73 us).

WGS 84: a = 6378137 m, 1/f = 298.257223563 (NIMA TR8350.2). With p = hypot(x, y), e^2 = f (2 - f),
b = a (1 - f), e'^2 = e^2 / (1 - e^2), Bowring's iteration from beta = atan2(z, (1 - f) p):

    phi = atan2(z + e'^2 b sin^3 beta, p - e^2 a cos^3 beta),   beta = atan2((1 - f) sin phi, cos phi)
    h = p cos phi + z sin phi - a sqrt(1 - e^2 sin^2 phi),         lambda = atan2(y, x)

converges in two rounds (three are taken) for any point from the surface to beyond GEO: it agrees with
ERFA's ``gc2gd`` to 3e-11 rad and 3e-8 m (tests/unit/test_space_earth.py).
"""
from __future__ import annotations

import math

import numpy as np

from components.orbit import timescales

WGS84_A = 6378137.0                  # m, semi-major axis
WGS84_F = 1.0 / 298.257223563        # flattening
_E2 = WGS84_F * (2.0 - WGS84_F)
_B = WGS84_A * (1.0 - WGS84_F)
_EP2 = _E2 / (1.0 - _E2)


def gcrf_to_itrf(tt: tuple[float, float], ut1: tuple[float, float]) -> np.ndarray:
    """The rotation M (3, 3) with r_itrf = M r_gcrf at TT ``tt`` and UT1 ``ut1`` (two-part Julian
    dates; pass UTC for UT1 without EOP): IAU 2000B, no polar motion."""
    import erfa

    return np.asarray(erfa.c2t00b(tt[0], tt[1], ut1[0], ut1[1], 0.0, 0.0), dtype=np.float64)


def geodetic_from_ecef(r_ecef) -> tuple[float, float, float]:
    """WGS 84 geodetic latitude (rad), longitude (rad, -pi..pi) and height (m) of r_ecef (m, ITRF)."""
    x, y, z = (float(c) for c in r_ecef)
    p = math.hypot(x, y)
    beta = math.atan2(z, (1.0 - WGS84_F) * p)
    for _ in range(3):
        s, c = math.sin(beta), math.cos(beta)
        phi = math.atan2(z + _EP2 * _B * s * s * s, p - _E2 * WGS84_A * c * c * c)
        beta = math.atan2((1.0 - WGS84_F) * math.sin(phi), math.cos(phi))
    s = math.sin(phi)
    height = p * math.cos(phi) + z * s - WGS84_A * math.sqrt(1.0 - _E2 * s * s)
    return phi, math.atan2(y, x), height


def ecef_from_geodetic(latitude: float, longitude: float, height: float) -> np.ndarray:
    """r_ecef (m, ITRF) of a WGS 84 geodetic latitude, longitude (rad) and height (m)."""
    s, c = math.sin(latitude), math.cos(latitude)
    n = WGS84_A / math.sqrt(1.0 - _E2 * s * s)          # prime vertical radius of curvature
    return np.array([(n + height) * c * math.cos(longitude), (n + height) * c * math.sin(longitude),
                     (n * (1.0 - _E2) + height) * s])


class EarthClock:
    """UTC and TT at run time t (SI seconds since the run's UTC ``epoch``, leap seconds counted:
    the seconds are added in TAI), and the Earth's orientation then."""

    def __init__(self, epoch):
        self.epoch_tai = timescales.utc_to_tai(timescales.parse_utc(epoch))

    def utc_tt(self, t_s: float) -> tuple[tuple[float, float], tuple[float, float]]:
        """(UTC, TT) two-part Julian dates at run time ``t_s``."""
        tai = (self.epoch_tai[0], self.epoch_tai[1] + t_s / timescales.SECONDS_PER_DAY)
        return timescales.tai_to_utc(tai), timescales.tai_to_tt(tai)

    def gcrf_to_itrf(self, t_s: float) -> np.ndarray:
        """M with r_itrf = M r_gcrf at run time ``t_s`` (UT1 = UTC)."""
        utc, tt = self.utc_tt(t_s)
        return gcrf_to_itrf(tt, utc)
