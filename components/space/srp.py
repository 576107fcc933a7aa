"""Solar radiation pressure on a body or on a link's facets: plain functions, no I/O.

The pressure at distance abs(d) from the Sun is P = Phi / c (AU / abs(d))^2, Phi the solar flux at
1 AU, c the speed of light; s_hat = d / abs(d) is the unit vector from the point to the Sun, nu the
illumination factor (:mod:`components.space.eclipse`).

| model | force | torque | source |
|---|---|---|---|
| cannonball | F = -nu P Cr A s_hat | none (at the CoM) | Basilisk ``radiationPressure`` (cannonball) |
| facet k (area A_k, unit normal n_k, specular rho_s, diffuse rho_d), cos_k = n_k . s_hat > 0 | F_k = -nu P A_k cos_k [(1 - rho_s) s_hat + 2 (rho_d / 3 + rho_s cos_k) n_k] | r_k x F_k | Basilisk ``facetSRPDynamicEffector`` |
| facet, cos_k <= 0 (facing away) | 0 | 0 | |

Cr = 1 + rho_s (a sphere absorbing and reflecting diffusely has Cr = 1 + 4 rho_d / 9). r_k is the
facet's centre of pressure from the point the torque is about (the link's CoM in the dynamics). A
flat plate facing the Sun (cos = 1) takes F = -nu P A (1 + rho_s + 2 rho_d / 3) n: twice the
absorbed push for a mirror, the closed form of tests/unit/test_space_srp.py. Facets do not shade
each other.

Units and axes: m, m^2, N, N m; any one set of axes for s (and the normals, centres): the result
is in those axes. Constants: ``SOLAR_FLUX`` 1361 W/m^2 (IAU 2015 Resolution B3 nominal total
solar irradiance), ``SPEED_OF_LIGHT`` 299 792 458 m/s, ``AU`` 149 597 870 700 m (exact).
Basilisk uses 1372.5398 W/m^2 in ``radiationPressure`` and 1368 W/m^2 in ``facetSRPDynamicEffector``
(its AU 149 597 870 693 m in the first): its cross-check passes its own.

Facet arrays: one row per facet, ``FACET_COLUMNS`` = area, normal (3), centre (3), specular, diffuse.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from components.space.ephemeris import AU

SOLAR_FLUX = 1361.0  # W/m^2 at 1 AU (IAU 2015 Resolution B3, nominal total solar irradiance)
SPEED_OF_LIGHT = 299_792_458.0  # m/s (exact)
FACET_COLUMNS = ("area", "nx", "ny", "nz", "cx", "cy", "cz", "specular", "diffuse")


def pressure_1au(flux: float = SOLAR_FLUX) -> float:
    """Radiation pressure at 1 AU on an absorbing surface facing the Sun, N/m^2 (flux in W/m^2)."""
    return flux / SPEED_OF_LIGHT


@numba.njit(cache=True)
def cannonball_nb(s, cr_area, p_1au, au, nu, f):
    """Adds to ``f`` the cannonball force (N) for ``s`` the point -> Sun (m), Cr A (m^2),
    ``p_1au`` Phi / c (N/m^2), ``au`` (m) and the illumination factor ``nu``."""
    d2 = s[0] * s[0] + s[1] * s[1] + s[2] * s[2]
    d = math.sqrt(d2)
    k = -nu * cr_area * p_1au * (au * au / d2) / d
    for i in range(3):
        f[i] += k * s[i]


@numba.njit(cache=True)
def facets_nb(s, facets, p_1au, au, nu, f, t):
    """Adds to ``f`` (N) and ``t`` (N m, about the centres' origin) the facets' forces and
    torques (rows: ``FACET_COLUMNS``) for ``s`` the point -> Sun (m), in the facets' axes."""
    d2 = s[0] * s[0] + s[1] * s[1] + s[2] * s[2]
    d = math.sqrt(d2)
    s0, s1, s2 = s[0] / d, s[1] / d, s[2] / d
    pressure = nu * p_1au * (au * au / d2)
    for k in range(facets.shape[0]):
        row = facets[k]
        n0, n1, n2 = row[1], row[2], row[3]
        cos = n0 * s0 + n1 * s1 + n2 * s2
        if row[0] * cos <= 0.0:
            continue
        specular, diffuse = row[7], row[8]
        scale = -pressure * row[0] * cos
        along_s = scale * (1.0 - specular)
        along_n = scale * 2.0 * (diffuse / 3.0 + specular * cos)
        g0, g1, g2 = along_s * s0 + along_n * n0, along_s * s1 + along_n * n1, along_s * s2 + along_n * n2
        f[0] += g0
        f[1] += g1
        f[2] += g2
        c0, c1, c2 = row[4], row[5], row[6]
        t[0] += c1 * g2 - c2 * g1
        t[1] += c2 * g0 - c0 * g2
        t[2] += c0 * g1 - c1 * g0


def cannonball_force(s, cr_area: float, nu: float = 1.0, *, flux: float = SOLAR_FLUX, au: float = AU) -> np.ndarray:
    """The cannonball force (N) for ``s`` the point -> Sun (m), Cr A (m^2), illumination ``nu``,
    ``flux`` (W/m^2 at 1 AU)."""
    f = np.zeros(3)
    cannonball_nb(np.asarray(s, dtype=np.float64), float(cr_area), pressure_1au(flux), float(au), float(nu), f)
    return f


def facet_wrench(
    s, facets, nu: float = 1.0, *, flux: float = SOLAR_FLUX, au: float = AU
) -> tuple[np.ndarray, np.ndarray]:
    """(force N, torque N m about the origin of the facets' centres) of ``facets`` (rows:
    ``FACET_COLUMNS``) for ``s`` the point -> Sun (m), in the facets' axes."""
    f, t = np.zeros(3), np.zeros(3)
    facets_nb(
        np.asarray(s, dtype=np.float64),
        np.ascontiguousarray(facets, dtype=np.float64).reshape(-1, 9),
        pressure_1au(flux),
        float(au),
        float(nu),
        f,
        t,
    )
    return f, t


def facet_rows(facets, *, where: str = "facets") -> np.ndarray:
    """Facet rows from mappings {area, normal, centre, specular, diffuse} (m^2, any nonzero
    length normalized, m); ValueError naming ``where[i]`` for a facet that cannot be."""
    rows = []
    for i, facet in enumerate(facets):
        normal = np.asarray(facet["normal"], dtype=np.float64)
        norm = float(np.linalg.norm(normal))
        if not norm > 0.0 or not math.isfinite(norm):
            raise ValueError(
                f"{where}[{i}].normal: expected a direction (a vector that is not zero), got {list(facet['normal'])}"
            )
        specular, diffuse = float(facet["specular"]), float(facet["diffuse"])
        if specular + diffuse > 1.0:
            raise ValueError(
                f"{where}[{i}]: expected specular + diffuse <= 1 (the rest is absorbed), got {specular} + {diffuse}"
            )
        rows.append(
            [float(facet["area"]), *(normal / norm), *np.asarray(facet["centre"], dtype=np.float64), specular, diffuse]
        )
    return np.array(rows, dtype=np.float64).reshape(-1, 9)
