"""How much of the Sun a point sees past the Earth and the Moon: the illumination (shadow) factor nu.

nu = 1 in full sun, 0 in umbra, between in penumbra (the fraction of the Sun's disk visible). Plain
functions, no I/O; the ``*_nb`` ones are compiled (numba) for the dynamics' per-link kernels, the
others wrap them for numpy callers (the camera, the sun sensor, the tests).

| model | nu | source |
|---|---|---|
| ``none`` | 1 | - |
| ``cylindrical`` | 0 if the point is behind the occulter (s . u < 0) and within its radius of the line through it along u, else 1 | Montenbruck & Gill (2000) 3.4.1 |
| ``conical`` | 1 - A / (pi a^2), the visible fraction of the Sun's disk (below) | Montenbruck & Gill (2000) 3.4.2; Basilisk ``eclipse`` |

Conical, for a point r, an occulting body at r_B of radius R_B and the Sun at r_S of radius R_S (one
origin and one set of axes; GCRF in the project, m):

| symbol | formula | meaning |
|---|---|---|
| s | r - r_B | occulter -> point |
| d | r_S - r | point -> Sun |
| a | asin(R_S / abs(d)) | apparent radius of the Sun, rad |
| b | asin(R_B / abs(s)) | apparent radius of the occulter, rad |
| c | acos(-s . d / (abs(s) abs(d))) | angle between their centres, rad |
| nu | 1 if c >= a + b; 0 if c <= b - a (umbra); 1 - b^2/a^2 if c <= a - b (annular) | |
| nu (partial) | 1 - (a^2 acos(x/a) + b^2 acos((c - x)/b) - c y) / (pi a^2), x = (c^2 + a^2 - b^2)/(2c), y = sqrt(a^2 - x^2) | two overlapping disks |

Cylindrical: u = (r_S - r_B) / abs(r_S - r_B), the Sun direction from the occulter.

Occulters: the Earth (at the origin) and, if given, the Moon. As Basilisk's ``eclipse`` does, one
body shades a point: of those not farther from the Sun than the point (abs(r_S - r) >= abs(r_S -
r_B)), the nearest to it (a point in the Earth's and the Moon's shadows at once, which takes a
solar eclipse seen from the point, counts the nearer only).

Radii (m): ``R_SUN`` 695 700 km (IAU 2015 Resolution B3 nominal solar radius), ``R_EARTH`` WGS 84
equatorial 6378.137 km (:mod:`components.constants`), ``R_MOON`` 1737.4 km (IAU mean radius).
Basilisk's (2.12) are 695 000, 6378.1366 and 1737.4 km: its cross-check passes its own.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from components.constants import R_EARTH

R_SUN = 695_700_000.0  # m, IAU 2015 Resolution B3 nominal solar radius
R_MOON = 1_737_400.0  # m, IAU mean lunar radius
NONE, CYLINDRICAL, CONICAL = 0, 1, 2
MODELS = {"none": NONE, "cylindrical": CYLINDRICAL, "conical": CONICAL}


@numba.njit(cache=True)
def disk_fraction(a, b, c):
    """The visible fraction of a disk of apparent radius ``a`` (the Sun) behind one of radius
    ``b`` whose centre is ``c`` away (all rad)."""
    if c >= a + b:
        return 1.0
    if c <= b - a:  # umbra: the occulter covers the Sun
        return 0.0
    if c <= a - b:  # annular: the occulter inside the Sun's disk
        return 1.0 - (b * b) / (a * a)
    x = (c * c + a * a - b * b) / (2.0 * c)
    y = math.sqrt(max(a * a - x * x, 0.0))
    area = a * a * math.acos(min(max(x / a, -1.0), 1.0)) + b * b * math.acos(min(max((c - x) / b, -1.0), 1.0)) - c * y
    return 1.0 - area / (math.pi * a * a)


@numba.njit(cache=True)
def body_factor(r, body, sun, radius, r_sun, model):
    """nu of the point ``r`` for one occulter at ``body`` of ``radius``, the Sun at ``sun`` of
    radius ``r_sun`` (m, one origin and axes); ``model``: NONE, CYLINDRICAL, CONICAL."""
    s0, s1, s2 = r[0] - body[0], r[1] - body[1], r[2] - body[2]
    if model == CYLINDRICAL:
        u0, u1, u2 = sun[0] - body[0], sun[1] - body[1], sun[2] - body[2]
        n = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
        u0, u1, u2 = u0 / n, u1 / n, u2 / n
        along = s0 * u0 + s1 * u1 + s2 * u2
        if along >= 0.0 or (s0 == 0.0 and s1 == 0.0 and s2 == 0.0):
            return 1.0
        p0, p1, p2 = s0 - along * u0, s1 - along * u1, s2 - along * u2
        return 0.0 if math.sqrt(p0 * p0 + p1 * p1 + p2 * p2) < radius else 1.0
    if model == CONICAL:
        d0, d1, d2 = sun[0] - r[0], sun[1] - r[1], sun[2] - r[2]
        ns = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
        nd = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        if ns <= radius:  # inside the occulter: no light
            return 0.0
        a = math.asin(min(r_sun / nd, 1.0))
        b = math.asin(radius / ns)
        c = math.acos(min(max(-(s0 * d0 + s1 * d1 + s2 * d2) / (ns * nd), -1.0), 1.0))
        return disk_fraction(a, b, c)
    return 1.0


@numba.njit(cache=True)
def illumination_nb(r, sun, moon, with_moon, model, r_sun, r_earth, r_moon):
    """nu of the point ``r`` (m from the Earth's centre) with the Sun at ``sun`` and the Moon at
    ``moon`` (same origin and axes; the Moon only ``with_moon``): the nearer occulter not beyond
    the point from the Sun (see the module docstring)."""
    if model == NONE:
        return 1.0
    d0, d1, d2 = sun[0] - r[0], sun[1] - r[1], sun[2] - r[2]
    to_sun = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    earth_to_sun = math.sqrt(sun[0] * sun[0] + sun[1] * sun[1] + sun[2] * sun[2])
    best = -1
    best_distance = 0.0
    if to_sun >= earth_to_sun:
        best, best_distance = 0, math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
    if with_moon:
        m0, m1, m2 = sun[0] - moon[0], sun[1] - moon[1], sun[2] - moon[2]
        if to_sun >= math.sqrt(m0 * m0 + m1 * m1 + m2 * m2):
            e0, e1, e2 = r[0] - moon[0], r[1] - moon[1], r[2] - moon[2]
            distance = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
            if best < 0 or distance < best_distance:
                best = 1
    if best == 0:
        return body_factor(r, np.zeros(3), sun, r_earth, r_sun, model)
    if best == 1:
        return body_factor(r, moon, sun, r_moon, r_sun, model)
    return 1.0


def illumination(
    r_eci,
    sun_eci,
    moon_eci=None,
    model: str = "conical",
    *,
    r_sun: float = R_SUN,
    r_earth: float = R_EARTH,
    r_moon: float = R_MOON,
) -> float:
    """The illumination factor nu in [0, 1] of the point ``r_eci`` (m, from the Earth's centre),
    the Sun at ``sun_eci`` and (unless None) the Moon at ``moon_eci`` (m, same axes; GCRF in the
    project), by ``model`` (``none``, ``cylindrical``, ``conical``); radii in m."""
    if model not in MODELS:
        raise ValueError(f"eclipse model: expected one of {', '.join(MODELS)}, got {model!r}")
    moon = np.zeros(3) if moon_eci is None else np.asarray(moon_eci, dtype=np.float64)
    return float(
        illumination_nb(
            np.asarray(r_eci, dtype=np.float64),
            np.asarray(sun_eci, dtype=np.float64),
            moon,
            moon_eci is not None,
            MODELS[model],
            r_sun,
            r_earth,
            r_moon,
        )
    )
