"""The Earth's orientation and shape: GCRF (the project's ECI) -> ITRF (Earth-fixed, ECEF) and WGS 84
geodetic coordinates; plain functions, no I/O. One Earth-rotation model for every model that needs one
(gravity harmonics, the atmosphere, the geomagnetic field) and for their cross-checks with Basilisk.

The CIO-based transformation of IERS Conventions 2010 (ch. 5) without polar motion and with
UT1 = UTC (no Earth-orientation data is read: none ships offline):

| quantity | formula | unit | source |
|---|---|---|---|
| celestial-to-intermediate matrix | C_cirs_gcrf = Q(X, Y, s)^T | 1 | ERFA ``c2i06a`` (IAU 2006/2000A precession-nutation), at TT |
| Earth rotation angle | ERA = 2 pi (0.7790572732640 + 1.00273781191135448 D_UT1) | rad | ERFA ``era00`` (IAU 2000), D_UT1 = days since J2000 UT1 |
| GCRF -> ITRF | C_itrf_gcrf = R3(ERA) C_cirs_gcrf | 1 | (polar motion W = I) |
| Earth's rotation rate | dERA/dt = 2 pi 1.00273781191135448 / 86400 | rad/s | |

R3(a) is the frame rotation about z: [[cos a, sin a, 0], [-sin a, cos a, 0], [0, 0, 1]].
``r_itrf = C_itrf_gcrf @ r_gcrf``. Neglected: polar motion (~0.3", ~10 m on the surface) and
UT1 - UTC (< 0.9 s, ~400 m of rotation on the equator): the frame is the ITRF to those amounts,
which matters for comparing positions with a ground truth, not for the physics of a run (the
same model is used on both sides of every cross-check: Basilisk is given these matrices).

C_cirs_gcrf moves by ~1e-11 rad/s (precession-nutation); :class:`EarthRotation` evaluates it
at given times (``matrix``, ``gcrf_to_itrf``) or once a minute (``ecef_from_eci``, for per-step
models) and R3(ERA) at every call, from the epoch's ERA and the elapsed SI seconds (UT1 runs on
through a leap second; UTC, for the models that take a date, comes from ``utc_tt`` through TAI).

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

from components import timescales
from components.constants import NS_PER_S
from components.timescales import SECONDS_PER_DAY, parse_utc, utc_to_tt

WGS84_A = 6378137.0  # m, semi-major axis
WGS84_F = 1.0 / 298.257223563  # flattening
_E2 = WGS84_F * (2.0 - WGS84_F)
_B = WGS84_A * (1.0 - WGS84_F)
_EP2 = _E2 / (1.0 - _E2)

C2I_PERIOD_NS = 60 * 10**9  # EarthRotation.ecef_from_eci: C_cirs_gcrf once a minute
ERA_RATE = 2.0 * math.pi * 1.00273781191135448 / SECONDS_PER_DAY
"""d ERA / dt, rad/s of UT1 (IAU 2000: the Earth's rotation in the ERA model)."""


def celestial_to_intermediate(tt: tuple[float, float]) -> np.ndarray:
    """C_cirs_gcrf (3x3) at TT ``tt`` (two-part Julian date): IAU 2006/2000A, ERFA ``c2i06a``."""
    import erfa

    return np.asarray(erfa.c2i06a(tt[0], tt[1]), dtype=np.float64)


def earth_rotation_angle(ut1: tuple[float, float]) -> float:
    """ERA (rad, [0, 2 pi)) at UT1 ``ut1`` (two-part Julian date): ERFA ``era00``."""
    import erfa

    return float(erfa.era00(ut1[0], ut1[1]))


def r3(angle: float) -> np.ndarray:
    """The frame rotation R3(angle) about z (rad)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])


def gcrf_to_itrf(tt: tuple[float, float], ut1: tuple[float, float]) -> np.ndarray:
    """C_itrf_gcrf = R3(ERA(ut1)) C_cirs_gcrf(tt): r_itrf = C @ r_gcrf (no polar motion)."""
    return r3(earth_rotation_angle(ut1)) @ celestial_to_intermediate(tt)


class EarthRotation:
    """C_itrf_gcrf at run time (s since the run's UTC ``epoch``), UT1 = UTC.

    ``matrix(t_s)`` evaluates both factors at t_s; ``matrix(t_s, c2i)`` takes a C_cirs_gcrf
    already evaluated (the propagator holds it over a step: it moves ~1e-10 rad in 10 s) and
    evaluates only R3(ERA), in closed form from the epoch's ERA (no ERFA call).
    """

    def __init__(self, epoch):
        self.utc0 = parse_utc(epoch)
        self.tt0 = utc_to_tt(self.utc0)
        self.era0 = earth_rotation_angle(self.utc0)
        self.tai0 = timescales.utc_to_tai(self.utc0)
        self._minute, self._c2i = None, None  # C_cirs_gcrf of the minute last asked (t alone decides)

    def utc_tt(self, t_s: float) -> tuple[tuple[float, float], tuple[float, float]]:
        """(UTC, TT) two-part Julian dates t_s SI seconds after the epoch (leap seconds counted:
        the seconds are added in TAI)."""
        tai = (self.tai0[0], self.tai0[1] + t_s / SECONDS_PER_DAY)
        return timescales.tai_to_utc(tai), timescales.tai_to_tt(tai)

    def dates(self, t_ns: int) -> tuple[tuple[float, float], tuple[float, float]]:
        """(UTC, TT) of run time ``t_ns`` (integer ns since the epoch)."""
        return self.utc_tt(t_ns / NS_PER_S)

    def tt(self, t_s: float) -> tuple[float, float]:
        """TT two-part Julian date t_s seconds after the epoch."""
        return self.tt0[0], self.tt0[1] + t_s / SECONDS_PER_DAY

    def tt_ns(self, t_ns: int) -> tuple[float, float]:
        """TT two-part Julian date of run time ``t_ns`` (integer ns)."""
        return self.tt(t_ns / NS_PER_S)

    def era(self, t_s: float) -> float:
        """ERA (rad, not reduced) t_s seconds after the epoch (UT1 = UTC, no leap second inside a run)."""
        return self.era0 + ERA_RATE * t_s

    def intermediate(self, t_s: float) -> np.ndarray:
        """C_cirs_gcrf at t_s."""
        return celestial_to_intermediate(self.tt(t_s))

    def matrix(self, t_s: float, c2i: np.ndarray | None = None) -> np.ndarray:
        """C_itrf_gcrf t_s seconds after the epoch."""
        if c2i is None:
            c2i = self.intermediate(t_s)
        return r3(self.era(t_s)) @ c2i

    def gcrf_to_itrf(self, t_s: float) -> np.ndarray:
        """C_itrf_gcrf t_s seconds after the epoch, both factors at t_s (as :meth:`matrix`)."""
        return self.matrix(t_s)

    def ecef_from_eci(self, t_ns: int) -> np.ndarray:
        """C_itrf_gcrf at run time ``t_ns`` with C_cirs_gcrf taken at the start of its minute
        (``C2I_PERIOD_NS``; it moves under 1e-9 rad in a minute) and R3(ERA) at t_ns: per step,
        one ERFA call a minute instead of one a step (c2i06a: ~70 us)."""
        minute = t_ns // C2I_PERIOD_NS
        if minute != self._minute:
            self._c2i, self._minute = self.intermediate(minute * C2I_PERIOD_NS / NS_PER_S), minute
        return self.matrix(t_ns / NS_PER_S, self._c2i)

    def matrix_rate(self, t_s: float, c2i: np.ndarray | None = None) -> np.ndarray:
        """d C_itrf_gcrf / dt (1/s), the Earth's rotation only (C_cirs_gcrf's drift, 1e-11 rad/s, left out)."""
        if c2i is None:
            c2i = self.intermediate(t_s)
        a = self.era(t_s)
        c, s = math.cos(a), math.sin(a)
        d = np.array([[-s, c, 0.0], [-c, -s, 0.0], [0.0, 0.0, 0.0]]) * ERA_RATE
        return d @ c2i


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
    n = WGS84_A / math.sqrt(1.0 - _E2 * s * s)  # prime vertical radius of curvature
    return np.array(
        [(n + height) * c * math.cos(longitude), (n + height) * c * math.sin(longitude), (n * (1.0 - _E2) + height) * s]
    )
