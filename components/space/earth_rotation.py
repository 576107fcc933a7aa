"""The Earth's orientation: the rotation from ECI (GCRF) to ECEF (ITRF), plain functions, no I/O.

| quantity | formula | unit |
|---|---|---|
| C_ecef_eci | W R3(ERA(UT1)) Q(TT), ERFA ``c2t06a``: Q the celestial-to-intermediate matrix (IAU 2006/2000A precession-nutation, CIO based), ERA the Earth rotation angle | 1 |
| at run time | R3(ERA(UT1(t))) Q(TT(t_m)), t_m = t rounded down to the whole minute (``EarthRotation``) | 1 |
| r_ecef | C_ecef_eci r_eci | m |
| ERA | 2 pi (0.7790572732640 + 1.00273781191135448 (JD_UT1 - 2451545.0)) | rad |

Polar motion W is the identity (x_p = y_p = 0) and UT1 is taken for UTC: there is no Earth
orientation data offline. |UT1 - UTC| < 0.9 s turns the Earth by at most 6.6e-5 rad (about
0.4 km of longitude at the surface); polar motion is under 1.5e-6 rad. The ERA and
precession-nutation are ERFA's, as elsewhere in the project (TEME -> GCRF in
:mod:`components.orbit.tle`, the ground track of :mod:`components.orbit.plots`). Cross-checks
against Basilisk feed Basilisk this same matrix (its ``J20002Pfix``), so both sides share one
Earth orientation.

At run time (:class:`EarthRotation`) the celestial-to-intermediate matrix Q (ERFA ``c2i06a``,
~70 us) is taken at the start of the minute and the Earth rotation angle (``era00``, 1 us) at t
itself: Q moves by under 1e-9 rad in a minute (nutation's fastest terms), about 4e-5 nT of field in
LEO. Both depend on t alone (no state), so a run stays deterministic and restarts bit-exactly.
"""
from __future__ import annotations

import math

import numpy as np

from components.constants import NS_PER_S
from components.orbit.timescales import SECONDS_PER_DAY, parse_utc, tai_to_tt, tai_to_utc, utc_to_tai

Q_PERIOD_NS = 60 * 10**9      # the celestial-to-intermediate matrix is taken once a minute


def ecef_from_eci(utc: tuple[float, float], tt: tuple[float, float]) -> np.ndarray:
    """C_ecef_eci (3x3) at UTC (= UT1 here) and TT two-part Julian dates; r_ecef = C @ r_eci."""
    import erfa

    return np.asarray(erfa.c2t06a(tt[0], tt[1], utc[0], utc[1], 0.0, 0.0), dtype=np.float64)


class EarthRotation:
    """C_ecef_eci and the dates at run time ``t_ns`` (integer ns since the run's UTC ``epoch``)."""

    def __init__(self, epoch):
        self.tai0 = utc_to_tai(parse_utc(epoch))
        self.q_minute, self.q_c2i = None, None      # Q of the minute last asked (a cache: t alone decides)

    def dates(self, t_ns: int) -> tuple[tuple[float, float], tuple[float, float]]:
        """(UTC, TT) two-part Julian dates of run time ``t_ns`` (leap seconds counted, through TAI)."""
        tai = (self.tai0[0], self.tai0[1] + (t_ns / NS_PER_S) / SECONDS_PER_DAY)
        return tai_to_utc(tai), tai_to_tt(tai)

    def ecef_from_eci(self, t_ns: int) -> np.ndarray:
        """C_ecef_eci at run time ``t_ns``: R3(ERA) at t, Q at the start of its minute."""
        import erfa

        minute = t_ns // Q_PERIOD_NS
        if minute != self.q_minute:
            _, tt = self.dates(minute * Q_PERIOD_NS)
            self.q_c2i, self.q_minute = np.asarray(erfa.c2i06a(tt[0], tt[1]), dtype=np.float64), minute
        utc, _ = self.dates(t_ns)
        angle = erfa.era00(utc[0], utc[1])
        c, s = math.cos(angle), math.sin(angle)
        return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]) @ self.q_c2i
