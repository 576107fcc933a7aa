"""The Earth's gravity field in spherical harmonics, and the Sun's and the Moon's pull: plain models, no I/O.

| quantity | formula | frame | unit |
|---|---|---|---|
| potential | U = mu/r sum_{n=0}^{N} (R/r)^n sum_{m=0}^{min(n, M)} Pbar_nm(sin phi) (Cbar_nm cos m lam + Sbar_nm sin m lam) | ITRF | m^2/s^2 |
| field | g = grad U, by Pines' singularity-free recursion (below) | ITRF | m/s^2 |
| harmonic perturbation | a_harm = g - (-mu r/r^3): the sum from degree 1 | ITRF, then ECI = C_itrf_gcrf^T a | m/s^2 |
| J2 closed form | a = -3/2 J2 mu R^2/r^5 (x (1 - 5 z^2/r^2), y (1 - 5 z^2/r^2), z (3 - 5 z^2/r^2)), J2 = -sqrt(5) Cbar_20 | ITRF | m/s^2 |
| third body | a_3 = mu_3 ((s - r)/abs(s - r)^3 - s/abs(s)^3) = -mu_3/abs(d)^3 (r + f(q) s) | ECI | m/s^2 |
| third body on a link | a_3(R + d) - a_3(R) = g_3(R - s + d) - g_3(R - s), g_3(x) = -mu_3 x/abs(x)^3 | ECI (W) | m/s^2 |

Symbols: r the point from the Earth's centre (m), s the third body from the Earth's centre (m),
d = r - s, q = r.(r - 2 s)/s.s, f(q) = ((1 + q)^(3/2) - 1) = q (3 + 3 q + q^2)/(1 + (1 + q)^(3/2))
(Battin, *An Introduction to the Mathematics and Methods of Astrodynamics*, sec. 8.4: the
difference of two nearly equal vectors written without the cancellation). mu, R: the field's
GM and reference radius (from its coefficient file); Cbar, Sbar fully normalized (4 pi)
coefficients; N, M the degree and order kept.

Pines' recursion (S. Pines, AIAA J. 11(11), 1973; normalized form: Lundberg & Schutz, J. Guid.
Control Dyn. 11(1), 1988; Eckman, Brown & Adamo, NASA/TP-2011-216155) is free of the poles'
singularity and stable to degree ~100 in double precision. With direction cosines s = x/r,
t = y/r, u = z/r, rho_n = mu/r^2 (R/r)^n, (s + i t)^m = r_m + i i_m, k_0 = 1, k_m = 2 (m >= 1):

    Abar_00 = 1, Abar_nn = sqrt((2n+1) k_n / (2n k_{n-1})) Abar_{n-1,n-1},
    Abar_{n,n-1} = sqrt(2n k_{n-1}/k_n) u Abar_nn,
    Abar_nm = u sqrt((2n+1)(2n-1)/((n-m)(n+m))) Abar_{n-1,m}
              - sqrt((2n+1)(n-m-1)(n+m-1)/((2n-3)(n+m)(n-m))) Abar_{n-2,m},
    D_nm = Cbar r_m + Sbar i_m, E_nm = Cbar r_{m-1} + Sbar i_{m-1}, F_nm = Sbar r_{m-1} - Cbar i_{m-1},
    a1 = sum rho_n sum_m m Abar_nm E_nm,  a2 = sum rho_n sum_m m Abar_nm F_nm,
    a3 = sum rho_n sum_m sqrt((n-m)(n+m+1) k_m/k_{m+1}) Abar_{n,m+1} D_nm,
    a4 = -sum rho_n sum_m sqrt((n+m+1)(n+m+2)(2n+1) k_m/((2n+3) k_{m+1})) Abar_{n+1,m+1} D_nm,
    g = (a1 + s a4, a2 + t a4, a3 + u a4).

The coefficient file (``data/GGM03S_20.txt``, see ``data/README.md``) is GGM03S to degree and
order 20 in the format Basilisk's ``loadGravFromFile`` reads, so both sides of the cross-check
read the same numbers. The field is compiled with numba (no fastmath: IEEE arithmetic).
"""

from __future__ import annotations

import math
from pathlib import Path

import numba
import numpy as np

DATA = Path(__file__).resolve().parent / "data"
GGM03S_20 = DATA / "GGM03S_20.txt"
"""GGM03S (CSR, Tapley et al. 2007) to degree and order 20: mu = 3.986004415e14 m^3/s^2, R = 6378136.3 m."""

# GM of the Sun and the Moon, m^3/s^2: JPL DE440 (Park et al., AJ 161:105, 2021, table 8)
MU_SUN = 1.32712440041279419e20
MU_MOON = 4.902800118457551e12


class GravityFileError(ValueError):
    """A coefficient file that cannot be read, or a degree/order it does not hold."""


def read_coefficients(path: str | Path, degree: int):
    """(mu m^3/s^2, R m, Cbar, Sbar (degree+1, degree+1)) from a coefficient file in the JPL/Basilisk
    format: a first row ``R, mu, sigma_mu, max_degree, max_order, normalized(1), ref_lon(0), ref_lat(0)``,
    then rows ``n, m, Cbar_nm, Sbar_nm[, sigmas]``."""
    path = Path(path)
    try:
        rows = path.read_text().splitlines()
    except OSError as e:
        raise GravityFileError(f"cannot read the gravity field {path}: {e.strerror or e}") from None
    try:
        head = [float(x) for x in rows[0].split(",")[:8]]
        radius, mu, max_degree, max_order, normalized = head[0], head[1], int(head[3]), int(head[4]), head[5]
    except (IndexError, ValueError):
        raise GravityFileError(
            f"{path}: expected a first row 'R, mu, sigma, max_degree, max_order, 1, 0, 0', got {rows[0][:80]!r}"
            if rows
            else f"{path}: empty"
        ) from None
    if normalized != 1:
        raise GravityFileError(f"{path}: expected fully normalized coefficients (6th field 1), got {normalized:g}")
    if degree > min(max_degree, max_order):
        raise GravityFileError(
            f"degree and order {degree} asked of {path}, which holds degree {max_degree}, order {max_order}"
        )
    c = np.zeros((degree + 1, degree + 1))
    s = np.zeros((degree + 1, degree + 1))
    for k, row in enumerate(rows[1:], start=2):
        if not row.strip():
            continue
        fields = row.split(",")
        try:
            n, m = int(fields[0]), int(fields[1])
            cnm, snm = float(fields[2]), float(fields[3])
        except (IndexError, ValueError):
            raise GravityFileError(f"{path}, line {k}: expected 'n, m, C, S', got {row[:80]!r}") from None
        if n <= degree and m <= n:
            c[n, m], s[n, m] = cnm, snm
    return mu, radius, c, s


def _factors(degree: int, order: int):
    """The recursion's constant factors (see the module docstring), arrays indexed [n, m]."""
    size = degree + 2
    k = np.array([1.0] + [2.0] * (size + 1))
    diagonal = np.zeros(size + 1)
    diagonal[0] = 1.0
    below = np.zeros(size + 1)
    alpha = np.zeros((size + 1, size + 1))
    beta = np.zeros((size + 1, size + 1))
    for n in range(1, size + 1):
        diagonal[n] = math.sqrt((2 * n + 1) * k[n] / (2 * n * k[n - 1])) * diagonal[n - 1]
        below[n] = math.sqrt(2 * n * k[n - 1] / k[n])
        for m in range(0, n - 1):
            alpha[n, m] = math.sqrt((2 * n + 1) * (2 * n - 1) / ((n - m) * (n + m)))
            beta[n, m] = math.sqrt((2 * n + 1) * (n - m - 1) * (n + m - 1) / ((2 * n - 3) * (n + m) * (n - m)))
    q1 = np.zeros((degree + 1, order + 1))
    q2 = np.zeros((degree + 1, order + 1))
    for n in range(degree + 1):
        for m in range(min(n, order) + 1):
            q1[n, m] = math.sqrt((n - m) * (n + m + 1) * k[m] / k[m + 1])
            q2[n, m] = math.sqrt((n + m + 1) * (n + m + 2) * (2 * n + 1) * k[m] / ((2 * n + 3) * k[m + 1]))
    return diagonal, below, alpha, beta, q1, q2


@numba.njit(cache=True)
def pines_field(x, y, z, mu, radius, c, s, degree, order, first, diagonal, below, alpha, beta, q1, q2, a_bar, out):
    """The field g (m/s^2, the point's axes: ITRF) of the degrees ``first``..``degree`` (orders up to
    ``order``) at (x, y, z) (m) into ``out``; ``a_bar`` (degree+2, order+2) scratch."""
    r = math.sqrt(x * x + y * y + z * z)
    su, tu, u = x / r, y / r, z / r
    top = order + 1  # orders of Abar needed: 0..order+1
    for n in range(degree + 2):
        for m in range(min(n, top) + 1):
            a_bar[n, m] = 0.0
    for m in range(min(degree + 1, top) + 1):  # each column's seeds: Abar_mm, Abar_{m+1,m}
        a_bar[m, m] = diagonal[m]
        if m + 1 <= degree + 1:
            a_bar[m + 1, m] = below[m + 1] * u * diagonal[m + 1]
    for m in range(top + 1):
        for n in range(m + 2, degree + 2):
            a_bar[n, m] = u * alpha[n, m] * a_bar[n - 1, m] - beta[n, m] * a_bar[n - 2, m]
    re = np.empty(order + 1)
    im = np.empty(order + 1)
    re[0], im[0] = 1.0, 0.0
    for m in range(1, order + 1):
        re[m] = su * re[m - 1] - tu * im[m - 1]
        im[m] = su * im[m - 1] + tu * re[m - 1]
    ratio = radius / r
    rho = mu / (r * r)
    for _ in range(first):
        rho *= ratio
    a1 = a2 = a3 = a4 = 0.0
    for n in range(first, degree + 1):
        s1 = s2 = s3 = s4 = 0.0
        for m in range(min(n, order) + 1):
            cnm, snm = c[n, m], s[n, m]
            d = cnm * re[m] + snm * im[m]
            if m > 0:
                e = cnm * re[m - 1] + snm * im[m - 1]
                f = snm * re[m - 1] - cnm * im[m - 1]
                s1 += m * a_bar[n, m] * e
                s2 += m * a_bar[n, m] * f
            if m < n:
                s3 += q1[n, m] * a_bar[n, m + 1] * d
            s4 += q2[n, m] * a_bar[n + 1, m + 1] * d
        a1 += rho * s1
        a2 += rho * s2
        a3 += rho * s3
        a4 -= rho * s4
        rho *= ratio
    out[0] = a1 + su * a4
    out[1] = a2 + tu * a4
    out[2] = a3 + u * a4


class GravityField:
    """A spherical-harmonic field kept to ``degree`` and ``order`` (order <= degree), from ``path``.

    ``perturbation(r)`` is the sum from degree 1 (what the harmonics add to -mu r/r^3);
    ``field(r)`` the whole field; both in the axes of r (ITRF), m and m/s^2.
    """

    def __init__(self, degree: int, order: int, path: str | Path = GGM03S_20):
        if not 0 <= order <= degree:
            raise GravityFileError(f"expected 0 <= order <= degree, got degree {degree}, order {order}")
        self.degree, self.order, self.path = int(degree), int(order), Path(path)
        self.mu, self.radius, self.c, self.s = read_coefficients(path, self.degree)
        self._factors = _factors(self.degree, self.order)
        self._a_bar = np.zeros((self.degree + 2, self.order + 2))

    @property
    def j2(self) -> float:
        """Unnormalized J2 = -sqrt(5) Cbar_20 (0 below degree 2)."""
        return -math.sqrt(5.0) * self.c[2, 0] if self.degree >= 2 else 0.0

    def _evaluate(self, r, first: int) -> np.ndarray:
        out = np.empty(3)
        pines_field(
            float(r[0]),
            float(r[1]),
            float(r[2]),
            self.mu,
            self.radius,
            self.c,
            self.s,
            self.degree,
            self.order,
            first,
            *self._factors,
            self._a_bar,
            out,
        )
        return out

    def field(self, r_itrf) -> np.ndarray:
        """The whole field (degrees 0..N), m/s^2, ITRF."""
        return self._evaluate(r_itrf, 0)

    def perturbation(self, r_itrf) -> np.ndarray:
        """The field less the point mass (degrees 1..N), m/s^2, ITRF."""
        return self._evaluate(r_itrf, 1)


def j2_acceleration(r, mu: float, radius: float, j2: float) -> np.ndarray:
    """The J2 term in closed form (textbook; e.g. Vallado, eq. 8-30), m/s^2, in the axes of r (Earth-fixed z)."""
    x, y, z = (float(v) for v in r)
    r2 = x * x + y * y + z * z
    k = -1.5 * j2 * mu * radius * radius / (r2 * r2 * math.sqrt(r2))
    w = 5.0 * z * z / r2
    return np.array([k * x * (1.0 - w), k * y * (1.0 - w), k * z * (3.0 - w)])


def third_body_acceleration(r, s, mu3: float) -> np.ndarray:
    """mu3 ((s - r)/|s - r|^3 - s/|s|^3) (m/s^2) on a point at r from the Earth's centre, by a body
    of GM ``mu3`` (m^3/s^2) at s (m), in Battin's form without cancellation (module docstring)."""
    rx, ry, rz = float(r[0]), float(r[1]), float(r[2])
    sx, sy, sz = float(s[0]), float(s[1]), float(s[2])
    s2 = sx * sx + sy * sy + sz * sz
    q = (rx * (rx - 2.0 * sx) + ry * (ry - 2.0 * sy) + rz * (rz - 2.0 * sz)) / s2
    p = (1.0 + q) ** 1.5
    f = q * (3.0 + q * (3.0 + q)) / (1.0 + p)
    dx, dy, dz = rx - sx, ry - sy, rz - sz
    d2 = dx * dx + dy * dy + dz * dz
    k = -mu3 / (d2 * math.sqrt(d2))
    return np.array([k * (rx + f * sx), k * (ry + f * sy), k * (rz + f * sz)])
