"""Physical constants and unit factors shared by the components (one definition each). SI units.

Earth (one set, used by the orbit, dynamics and viewer components):

- ``MU_EARTH`` = 3.986004418e14 m^3/s^2: geocentric gravitational constant including the
  atmosphere, a defining parameter of WGS 84 (NIMA TR8350.2, 3rd ed.). (EGM96's own scaling
  value is 3.986004415e14, 8e-10 relative lower: immaterial here.)
- ``R_EARTH`` = 6378137.0 m: WGS 84 equatorial radius (semi-major axis of the ellipsoid); also
  the radius of the spherical Earth that altitudes (drag) and the viewer's globe refer to.
- ``J2_EARTH`` = 1.08262668e-3: EGM96 (Lemoine et al., NASA/TP-1998-206861), J2 = -sqrt(5) C̄20
  with the fully normalized C̄20 = -4.84165371736e-4. EGM96 refers it to a = 6378136.3 m; using
  it with R_EARTH changes J2 R^2 by 2e-7 relative, far below the first-order J2 model's error.
- ``EARTH_RATE`` = 7.292115e-5 rad/s: WGS 84 mean angular velocity of the Earth (about ECI z,
  for an atmosphere co-rotating with the Earth).

Time: ``NS_PER_S``; convert the integer nanoseconds of the clock with ``t_ns / NS_PER_S``
(a division, correctly rounded: 1.2e11 ns -> exactly 120.0 s; ``t_ns * 1e-9`` is not).
"""

from __future__ import annotations

MU_EARTH = 3.986004418e14
"""Earth's gravitational parameter GM, m^3/s^2 (WGS 84)."""
R_EARTH = 6378137.0
"""Earth's equatorial radius, m (WGS 84)."""
J2_EARTH = 1.08262668e-3
"""Earth's second zonal harmonic J2, unitless (EGM96, unnormalized)."""
EARTH_RATE = 7.292115e-5
"""Earth's rotation rate about ECI z, rad/s (WGS 84)."""

NS_PER_S = 1e9
"""Nanoseconds per second: seconds = t_ns / NS_PER_S."""

MAX_IMAGE_SIZE = 8192
"""The largest image width or height, pixels, a camera renders or an estimator takes."""
