"""The Sun seen from the Earth, and the Earth's shadow: plain functions, no I/O.

- :class:`SunClock`: the unit vector from the Earth's centre towards the Sun, GCRF axes (= ECI, =
  the dynamics' W axes), at run time: :mod:`components.space.ephemeris` (ERFA's ``epv00``). Neither
  light time (8 min, 20 arcsec of motion) nor aberration is applied: both under 0.006 deg.
- :func:`in_earth_shadow`: a point is in the Earth's shadow when it is behind the Earth and within
  a cylinder of the Earth's equatorial radius along the Sun direction (no penumbra, no umbra cone:
  the cylinder errs by under 0.3 % of the shadow's radius in low orbit); the camera's default, its
  ``eclipse: cylindrical``. The models: :mod:`components.space.eclipse`.
"""

from __future__ import annotations

import numpy as np

from components.constants import R_EARTH  # noqa: F401 (the shadow's radius)
from components.space.eclipse import illumination
from components.space.ephemeris import Ephemeris, sun_direction_eci  # noqa: F401 (the camera's Sun)


class SunClock(Ephemeris):
    """The Sun direction at run time ``t_ns`` (ns since the run's UTC ``epoch``)."""

    def direction(self, t_ns: int) -> np.ndarray:
        return self.sun_direction(t_ns)


def in_earth_shadow(r_eci: np.ndarray, sun_eci: np.ndarray) -> bool:
    """Whether the point ``r_eci`` (m, from the Earth's centre) is in the Earth's cylindrical shadow
    for the Sun direction ``sun_eci`` (:func:`components.space.eclipse.illumination`, ``cylindrical``).
    The origin (no orbit) is taken as lit."""
    return illumination(r_eci, sun_eci, None, "cylindrical") == 0.0
