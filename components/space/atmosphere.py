"""The Earth's neutral atmosphere: mass density for drag; plain classes, no I/O.

| model | density | inputs | unit |
|---|---|---|---|
| :class:`ExponentialAtmosphere` | rho(h) = rho0_k exp(-(h - h0_k) / H_k), band k holding h | h = abs(r) - R_E (sphere, R_E = 6378.137 km) | kg/m^3, m |
| :class:`Nrlmsise00` | NRLMSISE-00 total mass density, anomalous oxygen included (``gtd7d``) | WGS 84 geodetic latitude, longitude, height; UTC; F10.7, F10.7a, Ap | kg/m^3 |
| :class:`LocalExponential` | rho(h) = rho_ref exp(-(h - h_ref) / H_ref): NRLMSISE-00 at a reference point and its local scale height | r_gcrf of the point, run time | kg/m^3, m |

Exponential: the 28-band table is Vallado's (Fundamentals of Astrodynamics and Applications,
Table 8-4; CIRA-72 below 1000 km), or one layer (h0, rho0, H) given.

NRLMSISE-00 (Picone, Hedin, Drob, Aikin 2002, J. Geophys. Res. 107(A12), 1468) through ``pymsis``
(its ``msis00``: NRL's Fortran, built single precision: density to ~1e-6 relative, UT to whole
seconds). The space-weather indices are given, never looked up (nothing is downloaded):

| parameter | meaning | unit |
|---|---|---|
| f107 | F10.7 solar radio flux of the previous day (observed, at the Sun-Earth distance) | sfu (1e-22 W m^-2 Hz^-1) |
| f107a | its 81-day average centred on the day | sfu |
| ap | daily planetary geomagnetic index Ap (daily-Ap mode, switch 9 = 1; the 3-hour ap history of storm-time mode is not supported) | 2 nT |

From r_gcrf at run time t: r_itrf = M(t) r_gcrf (:func:`components.space.earth.gcrf_to_itrf`, IAU
2006/2000A, UT1 = UTC, no polar motion), then WGS 84 geodetic latitude, longitude and height
(:func:`components.space.earth.geodetic_from_ecef`), then the model at day of year and UT seconds.

For drag on a multibody (:class:`LocalExponential`), NRLMSISE-00 is evaluated once per integration
step at the reference orbit point at the step's midpoint, at the heights h and h +- dh (one call,
three points, dh = 1 km): rho_ref = rho(h), 1/H_ref = ln(rho(h - dh) / rho(h + dh)) / (2 dh). Within
the step every link at every Runge-Kutta stage gets rho_ref exp(-(abs(x) - abs(R_mid)) / H_ref),
abs(x) its CoM's distance from the Earth's centre (the dynamics' compiled kernels evaluate this as a
one-band exponential). docs/environment/atmosphere.md states its error against evaluating the model
per link per stage.
"""

from __future__ import annotations

import math

import numpy as np

from components.constants import R_EARTH
from components.space import earth

# Piecewise exponential atmosphere (Vallado, "Fundamentals of Astrodynamics and Applications",
# Table 8-4; Wertz): base altitude km, density kg/m^3 at the base, scale height km.
_EXPONENTIAL_TABLE = np.array(
    [
        (0, 1.225, 7.249),
        (25, 3.899e-2, 6.349),
        (30, 1.774e-2, 6.682),
        (40, 3.972e-3, 7.554),
        (50, 1.057e-3, 8.382),
        (60, 3.206e-4, 7.714),
        (70, 8.770e-5, 6.549),
        (80, 1.905e-5, 5.799),
        (90, 3.396e-6, 5.382),
        (100, 5.297e-7, 5.877),
        (110, 9.661e-8, 7.263),
        (120, 2.438e-8, 9.473),
        (130, 8.484e-9, 12.636),
        (140, 3.845e-9, 16.149),
        (150, 2.070e-9, 22.523),
        (180, 5.464e-10, 29.740),
        (200, 2.789e-10, 37.105),
        (250, 7.248e-11, 45.546),
        (300, 2.418e-11, 53.628),
        (350, 9.518e-12, 53.298),
        (400, 3.725e-12, 58.515),
        (450, 1.585e-12, 60.828),
        (500, 6.967e-13, 63.822),
        (600, 1.454e-13, 71.835),
        (700, 3.614e-14, 88.667),
        (800, 1.170e-14, 124.64),
        (900, 5.245e-15, 181.05),
        (1000, 3.019e-15, 268.00),
    ]
)


class ExponentialAtmosphere:
    """Density by altitude, rho(h) = rho0_k exp(-(h - h0_k) / H_k) in the band k holding h.

    Default: the 28-band table above (0-1000 km; the last band extends upwards, below 0 km the
    first band is used). ``single=(h0, rho0, H)`` (m, kg/m^3, m) gives one exponential instead.
    """

    def __init__(self, single: tuple[float, float, float] | None = None):
        if single is None:
            self.h0 = _EXPONENTIAL_TABLE[:, 0] * 1e3
            self.rho0 = _EXPONENTIAL_TABLE[:, 1].copy()
            self.scale = _EXPONENTIAL_TABLE[:, 2] * 1e3
        else:
            h0, rho0, scale = single
            self.h0, self.rho0, self.scale = np.array([h0]), np.array([rho0]), np.array([scale])

    def density(self, altitude):
        """Density in kg/m^3 at altitude(s) in m."""
        h = np.asarray(altitude, dtype=float)
        k = np.clip(np.searchsorted(self.h0, h, side="right") - 1, 0, len(self.h0) - 1)
        return self.rho0[k] * np.exp(-(h - self.h0[k]) / self.scale[k])


ANOMALOUS_OXYGEN_MASS = 16 * 1.66e-27  # kg: the mass NRLMSISE-00 gives an anomalous oxygen atom (16 x 1.66e-24 g)
SPACE_WEATHER = {"f107": (0.0, 1000.0), "f107a": (0.0, 1000.0), "ap": (0.0, 400.0)}  # accepted ranges
VERSIONS = {"nrlmsise00": 0, "msis21": 2.1}


_UNIX_EPOCH_JD = 2440587.5  # 1970-01-01T00:00 UTC as a Julian date


def utc_datetime64(utc: tuple[float, float]) -> np.datetime64:
    """A UTC two-part Julian date as numpy datetime64, to the ms (ERFA's UTC dates stretch a
    leap-second day to 86401 s: on such a day the result runs up to 1 s early)."""
    return np.datetime64(round(((utc[0] - _UNIX_EPOCH_JD) + utc[1]) * 86_400_000.0), "ms")


class Nrlmsise00:
    """NRLMSISE-00 total mass density (kg/m^3) for given space weather (see the module docstring).

    ``model``: ``nrlmsise00`` (default) or ``msis21`` (NRLMSIS 2.1, the same inputs). Raises
    ValueError naming the range for an index out of it.
    """

    def __init__(self, f107: float, f107a: float, ap: float, model: str = "nrlmsise00"):
        for key, value in (("f107", f107), ("f107a", f107a), ("ap", ap)):
            low, high = SPACE_WEATHER[key]
            if not (low < value <= high if key != "ap" else low <= value <= high) or not math.isfinite(value):
                raise ValueError(
                    f"{key}: expected a value in {'[' if key == 'ap' else '('}{low:g}, {high:g}], got {value!r}"
                )
        if model not in VERSIONS:
            raise ValueError(f"model: expected one of {', '.join(VERSIONS)}, got {model!r}")
        self.f107, self.f107a, self.ap, self.model = float(f107), float(f107a), float(ap), model
        self.version = VERSIONS[model]
        self._indices: dict[int, tuple[np.ndarray, ...]] = {}  # the indices as pymsis takes them, per point count

    def density_geodetic(self, utc: tuple[float, float], latitude, longitude, height) -> np.ndarray:
        """Density (kg/m^3) at WGS 84 geodetic latitude(s), longitude(s) (rad) and height(s) (m), all
        at UTC ``utc`` (two-part Julian date); arrays broadcast together."""
        return self.outputs_geodetic(utc, latitude, longitude, height)[..., 0]

    def outputs_geodetic(self, utc: tuple[float, float], latitude, longitude, height) -> np.ndarray:
        """The model's outputs (..., 11) there (pymsis' order: mass density kg/m^3; N2, O2, O, He, H,
        Ar, N, anomalous O, NO number densities m^-3; temperature K), float64."""
        lat, lon, h = np.broadcast_arrays(np.degrees(latitude), np.degrees(longitude), np.asarray(height) / 1e3)
        return self._calculate(utc, lon.ravel(), lat.ravel(), h.ravel()).reshape(lat.shape + (11,))

    def _calculate(self, utc, lon_deg: np.ndarray, lat_deg: np.ndarray, height_km: np.ndarray) -> np.ndarray:
        """pymsis at n points (1-D arrays, deg, deg, km), the indices given: (n, 11) float64."""
        import pymsis

        n = len(lon_deg)
        indices = self._indices.get(n)
        if indices is None:
            indices = self._indices[n] = (np.full(n, self.f107), np.full(n, self.f107a), np.full((n, 7), self.ap))
        return pymsis.calculate(
            np.full(n, utc_datetime64(utc)), lon_deg, lat_deg, height_km, *indices, version=self.version
        ).astype(np.float64)

    def geodetic(self, r_gcrf, utc: tuple[float, float], tt: tuple[float, float]) -> tuple[float, float, float]:
        """WGS 84 latitude, longitude (rad) and height (m) of r_gcrf (m) at UTC/TT ``utc``, ``tt``."""
        return earth.geodetic_from_ecef(earth.gcrf_to_itrf(tt, utc) @ np.asarray(r_gcrf, dtype=float))

    def density(self, r_gcrf, utc: tuple[float, float], tt: tuple[float, float]) -> float:
        """Density (kg/m^3) at r_gcrf (m, GCRF) at UTC/TT ``utc``, ``tt`` (two-part Julian dates)."""
        return float(self.density_geodetic(utc, *self.geodetic(r_gcrf, utc, tt)))

    def local_exponential(self, r_gcrf, utc, tt, dh: float = 1e3) -> tuple[float, float]:
        """(rho, H): the density (kg/m^3) at r_gcrf and its local scale height (m),
        1/H = ln(rho(h - dh) / rho(h + dh)) / (2 dh), from one call at the three heights."""
        latitude, longitude, height = self.geodetic(r_gcrf, utc, tt)
        heights = (height + np.array([-dh, 0.0, dh])) / 1e3
        below, at, above = self._calculate(
            utc, np.full(3, math.degrees(longitude)), np.full(3, math.degrees(latitude)), heights
        )[:, 0]
        return float(at), 2.0 * dh / math.log(below / above)


class LocalExponential(ExponentialAtmosphere):
    """A one-band exponential that follows NRLMSISE-00 (the drag's model for a multibody): ``update``
    sets the band to the model's density and scale height at a point and run time; the band's
    base altitude is the point's altitude above the sphere of radius R_E, as the dynamics' kernels
    measure it (the arrays h0, rho0, scale change in place)."""

    varies = True

    def __init__(self, model: Nrlmsise00, epoch):
        super().__init__(single=(0.0, 0.0, 1.0))
        self.model, self.clock = model, earth.EarthRotation(epoch)

    def update(self, r_gcrf, t_s: float) -> None:
        """The band at r_gcrf (m) at run time t_s (s since run.epoch)."""
        utc, tt = self.clock.utc_tt(t_s)
        rho, scale = self.model.local_exponential(r_gcrf, utc, tt)
        self.h0[0] = math.sqrt(float(np.dot(r_gcrf, r_gcrf))) - R_EARTH
        self.rho0[0], self.scale[0] = rho, scale
