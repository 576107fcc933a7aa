"""The Earth's magnetic field at a point: the World Magnetic Model or a centered tilted dipole;
plain functions and classes, no I/O.

| quantity | formula | unit, frame |
|---|---|---|
| r_ecef | C_ecef_eci(t) r_eci (:class:`components.space.earth.EarthRotation`: IAU 2006/2000A, UT1 = UTC, no polar motion) | m, ECEF |
| dipole | B = (a / r)^3 (3 r_hat (r_hat . d) - d), d = (g11, h11, g10) | T, ECEF |
| WMM | B = -grad V, V = a sum_n=1..12 (a/r)^(n+1) sum_m=0..n (g_nm(t) cos m lon + h_nm(t) sin m lon) P_n^m(sin lat_c) | T, local N-E-D |
| WMM, in time | g_nm(t) = g_nm + (t - 2025.0) dg_nm, t in decimal years | nT, nT/yr |
| B_eci | C_ecef_eci^T B_ecef | T, ECI (GCRF) |

- ``a``: the model's reference radius, 6371.2 km for both (the WMM's, and Basilisk's for its
  dipole); ``r = |r_ecef|``; ``lat_c`` geocentric latitude, ``lon`` longitude; ``P_n^m`` Schmidt
  semi-normalized associated Legendre functions.
- **WMM2025** (NOAA NCEI / BGS, valid 2025.0-2030.0, degree and order 12) as evaluated by
  pygeomag (``WMM_2025.COF``, byte for byte the coefficient file Basilisk's ``magneticFieldWMM``
  reads; its md5 a1b6402dd23658d15affb0f31babccc7). pygeomag takes geodetic latitude and height
  above the WGS 84 ellipsoid and gives the field in the local geodetic north, east, down axes:
  the position goes ECEF -> geodetic by ERFA ``gc2gd`` (WGS 84, exact to well under a mm), and
  the field comes back to ECEF by the geodetic N-E-D axes at that latitude
  (N = (-sin lat cos lon, -sin lat sin lon, cos lat), E = (-sin lon, cos lon, 0),
  D = (-cos lat cos lon, -cos lat sin lon, -sin lat)). The two conversions undo each other
  (pygeomag turns geodetic back into the geocentric spherical coordinates the series is written
  in), so the result is the field at the ECEF point whatever the ellipsoid: Basilisk evaluates
  the same series directly in geocentric coordinates. Outside 2025.0-2030.0 the model is refused.
- **Decimal year** (the WMM's time): ``year + (day_of_year - 1 + seconds_of_day / 86400) /
  days_in_year`` of the UTC date, as the WMM's own ``MAG_DateToYear`` and Basilisk count it.
- **Dipole** (Basilisk's ``magneticFieldCenteredDipole``, its Eq. from Markley and Crassidis,
  p. 405): the IGRF degree-1 terms only. Defaults are Basilisk's for the Earth
  (``simSetPlanetEnvironment.centeredDipoleMagField``): g10 = -30926 nT, g11 = -2318 nT,
  h11 = 5817 nT, a = 6371.2 km (|B| about 30 uT at the equator's surface, the dipole tilted
  about 11.5 deg from the spin axis). At the dipole's own pole the field is twice the field at
  its equator at the same radius (a closed form the tests use).
"""

from __future__ import annotations

import datetime as _dt
import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np

WMM_RADIUS = 6371200.0  # m, the WMM's (and the IGRF's) reference radius a
WMM_EPOCH = 2025.0  # decimal years: WMM2025's epoch; valid for 5 years
WMM_LIFESPAN = 5.0
NT = 1e-9  # T per nT
# Basilisk's centered dipole of the Earth (simSetPlanetEnvironment.centeredDipoleMagField), T and m
BASILISK_DIPOLE = {"g10": -30926.0e-9, "g11": -2318.0e-9, "h11": 5817.0e-9, "radius": 6371.2e3}
MODELS = ("wmm", "dipole")


def decimal_year(utc: tuple[float, float]) -> float:
    """The WMM's decimal year of a UTC two-part Julian date: year + (day_of_year - 1 +
    seconds_of_day / 86400) / days_in_year."""
    import erfa

    year, month, day, fraction = erfa.jd2cal(utc[0], utc[1])  # (no leap-second table: no warning past it)
    year, month, day = int(year), int(month), int(day)
    doy = (_dt.date(year, month, day) - _dt.date(year, 1, 1)).days
    days = 366 if (year % 4 == 0 and year % 100 != 0) or year % 400 == 0 else 365
    return year + (doy + float(fraction)) / days


def dipole_field_ecef(r_ecef: np.ndarray, g10: float, g11: float, h11: float, radius: float) -> np.ndarray:
    """Centered tilted dipole, T, ECEF: (a/r)^3 (3 r_hat (r_hat . d) - d), d = (g11, h11, g10)
    (T), a = ``radius`` (m), at ``r_ecef`` (m; (3,) or (n, 3))."""
    r = np.asarray(r_ecef, dtype=float)
    d = np.array([g11, h11, g10], dtype=float)
    norm = np.linalg.norm(r, axis=-1, keepdims=True)
    r_hat = r / norm
    return (radius / norm) ** 3 * (3.0 * r_hat * (r_hat @ d)[..., None] - d)


def geodetic_ned_axes(lat: float, lon: float) -> np.ndarray:
    """Rows: the local geodetic north, east and down unit vectors in ECEF at geodetic latitude
    ``lat`` and longitude ``lon`` (rad)."""
    sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    return np.array([[-sl * co, -sl * so, cl], [-so, co, 0.0], [-cl * co, -cl * so, -sl]])


class WorldMagneticModel:
    """WMM2025 by pygeomag: ``field_ecef(r_ecef, year)`` (m, decimal years) -> T, ECEF."""

    def __init__(self):
        from pygeomag import GeoMag

        self.geomag = GeoMag(coefficients_file=str(wmm_coefficients()))

    def field_ecef(self, r_ecef: np.ndarray, year: float) -> np.ndarray:
        import erfa

        if not WMM_EPOCH <= year <= WMM_EPOCH + WMM_LIFESPAN:
            raise ValueError(
                f"the WMM2025 is valid from {WMM_EPOCH:g} to {WMM_EPOCH + WMM_LIFESPAN:g}: expected a "
                f"time within it, got the decimal year {year:.4f} (use the dipole model outside it)"
            )
        lon, lat, height = erfa.gc2gd(1, np.asarray(r_ecef, dtype=float))  # 1: WGS 84
        lon, lat, height = float(lon), float(lat), float(height)
        result = self.geomag.calculate(
            math.degrees(lat), math.degrees(lon), height / 1e3, year, allow_date_outside_lifespan=True
        )
        ned = np.array([result.x, result.y, result.z]) * NT
        return ned @ geodetic_ned_axes(lat, lon)


def wmm_coefficients() -> Path:
    """pygeomag's WMM2025 coefficient file (the one Basilisk's magneticFieldWMM reads)."""
    import pygeomag

    return Path(pygeomag.__file__).resolve().parent / "wmm" / "WMM_2025.COF"


class GeomagneticField:
    """The field at run time: ``b_eci(r_eci, t_ns)`` (m, ECI; integer ns since the UTC ``epoch``)
    -> T, ECI. ``model``: ``wmm`` or ``dipole`` (``dipole``: g10, g11, h11 in T and radius in
    m, Basilisk's by default)."""

    def __init__(self, model: str, epoch, dipole: Mapping[str, float] | None = None):
        from components.space.earth import EarthRotation

        if model not in MODELS:
            raise ValueError(f"model: expected one of {', '.join(MODELS)}, got {model!r}")
        self.model = model
        self.rotation = EarthRotation(epoch)
        self.dipole = dict(BASILISK_DIPOLE if dipole is None else dipole)
        self.wmm = WorldMagneticModel() if model == "wmm" else None

    def b_ecef(self, r_ecef: np.ndarray, utc: tuple[float, float]) -> np.ndarray:
        """The field (T, ECEF) at ``r_ecef`` (m, (3,) or (n, 3)) at the UTC date ``utc``."""
        if self.wmm is None:
            return dipole_field_ecef(r_ecef, **self.dipole)
        year = decimal_year(utc)
        r = np.asarray(r_ecef, dtype=float)
        if r.ndim == 1:
            return self.wmm.field_ecef(r, year)
        return np.array([self.wmm.field_ecef(x, year) for x in r])

    def b_eci(self, r_eci: np.ndarray, t_ns: int) -> np.ndarray:
        """The field (T, ECI) at ``r_eci`` (m, ECI; (3,) or (n, 3)) at run time ``t_ns``."""
        utc, _ = self.rotation.dates(t_ns)
        C = self.rotation.ecef_from_eci(t_ns)
        return self.b_ecef(np.asarray(r_eci, dtype=float) @ C.T, utc) @ C
