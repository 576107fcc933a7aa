"""The Sun seen from the Earth, and the Earth's shadow: plain functions, no I/O.

- :func:`sun_direction_eci`: the unit vector from the Earth's centre towards the Sun, GCRF axes
  (= ECI, = the dynamics' W axes), at a TT two-part Julian date: ERFA's ``epv00`` (the Earth's
  heliocentric position, ICRS axes, a few km; TT is taken for TDB, under 2 ms apart). Neither light
  time (8 min, 20 arcsec of motion) nor aberration is applied: both under 0.006 deg.
- :func:`in_earth_shadow`: a point is in the Earth's shadow when it is behind the Earth and within
  a cylinder of the Earth's equatorial radius along the Sun direction (no penumbra, no umbra cone:
  the cylinder errs by under 0.3 % of the shadow's radius in low orbit).
"""
from __future__ import annotations

import numpy as np

from components.constants import NS_PER_S
from components.orbit.timescales import SECONDS_PER_DAY, parse_utc, utc_to_tt

R_EARTH = 6378137.0   # m, WGS 84 equatorial radius


def sun_direction_eci(tt: tuple[float, float]) -> np.ndarray:
    """Unit vector Earth -> Sun, GCRF axes, at TT ``tt`` (two-part Julian date)."""
    import erfa

    heliocentric, _ = erfa.epv00(tt[0], tt[1])
    earth_to_sun = -np.asarray(heliocentric["p"], dtype=np.float64)   # au, ICRS axes
    return earth_to_sun / np.linalg.norm(earth_to_sun)


class SunClock:
    """The Sun direction at run time ``t_ns`` (ns since the run's UTC ``epoch``)."""

    def __init__(self, epoch: str):
        self.tt0 = utc_to_tt(parse_utc(epoch))

    def direction(self, t_ns: int) -> np.ndarray:
        return sun_direction_eci((self.tt0[0], self.tt0[1] + (t_ns / NS_PER_S) / SECONDS_PER_DAY))


def in_earth_shadow(r_eci: np.ndarray, sun_eci: np.ndarray) -> bool:
    """Whether the point ``r_eci`` (m, from the Earth's centre) is in the Earth's cylindrical shadow
    for the unit Sun direction ``sun_eci``. The origin (no orbit) is taken as lit."""
    r = np.asarray(r_eci, dtype=np.float64)
    along = float(r @ sun_eci)
    if not np.any(r) or along >= 0.0:
        return False
    return float(np.linalg.norm(r - along * sun_eci)) < R_EARTH
