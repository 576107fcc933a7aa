"""Kepler's equation and Keplerian orbits with J2 secular drift.

Plain functions and one plain class; no bus, no I/O, no wall clock. SI units: m, s, rad.
Positions and velocities are in ECI (GCRF axes); the classical elements are referred to the
ECI equator and x axis.

Earth constants (``MU_EARTH``, ``R_EARTH``, ``J2_EARTH``, WGS 84 / EGM96): :mod:`components.constants`,
which names their sources.
"""

from __future__ import annotations

import math

import numpy as np

from components.constants import J2_EARTH, MU_EARTH, R_EARTH

TWO_PI = 2.0 * math.pi

Vector3 = tuple[float, float, float]


def cross_tuples(a: Vector3, b: Vector3) -> Vector3:
    """a × b of two 3-vectors given as tuples of floats."""
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


class ElementError(ValueError):
    """Invalid orbital elements; ``key`` names the offending element."""

    def __init__(self, key: str, message: str):
        super().__init__(f"{key}: {message}")
        self.key = key
        self.message = message


def check_elements(
    semi_major_axis: float, eccentricity: float, inclination: float, min_perigee: float | None = R_EARTH
) -> None:
    """Raise :class:`ElementError` unless the elements describe an elliptic orbit above the surface.

    semi_major_axis in m (> 0), eccentricity unitless (0 <= e < 1), inclination in rad ([0, pi]);
    unless ``min_perigee`` is None, the perigee radius a(1 - e) must exceed it (m; default
    Earth's equatorial radius, which also catches "6778" meant as km).
    """
    a, e, i = float(semi_major_axis), float(eccentricity), float(inclination)
    if not math.isfinite(a) or a <= 0.0:
        raise ElementError("semi_major_axis", f"expected a positive length (m), got {a!r}")
    if not math.isfinite(e) or not 0.0 <= e < 1.0:
        raise ElementError("eccentricity", f"expected 0 <= e < 1 (an elliptic orbit), got {e!r}")
    if not math.isfinite(i) or not 0.0 <= i <= math.pi:
        raise ElementError(
            "inclination", f"expected 0 <= i <= pi rad (0 to 180 deg), got {i!r} rad ({math.degrees(i):.6g} deg)"
        )
    if min_perigee is None:
        return
    perigee = a * (1.0 - e)
    if perigee <= min_perigee:
        if a * 1e3 * (1.0 - e) > min_perigee and a < 1e5:  # a bare number in km: 6778 for 6778 km
            hint = f"; did you mean '{a:g} km'?"
        elif a > 0.5 * min_perigee:  # an altitude where the radius belongs: 6000 km for 6000 km up
            hint = (
                f"; a is measured from Earth's centre, not its surface: for an altitude of "
                f"{a / 1e3:g} km, a = '{(a + min_perigee) / 1e3:g} km'"
            )
        else:
            hint = ""
        raise ElementError(
            "semi_major_axis",
            f"expected a perigee radius a(1-e) above Earth's surface ({min_perigee:.0f} m), "
            f"got a = {a:.9g} m, e = {e:g} -> {perigee:.9g} m{hint}",
        )


def solve_kepler(mean_anomaly: float, eccentricity: float, tol: float = 1e-12, max_iter: int = 100) -> float:
    """Eccentric anomaly E (rad) solving Kepler's equation M = E - e sin E, for 0 <= e < 1.

    mean_anomaly M in rad (any real); the result lies in the same 2*pi period as M.
    Newton's method safeguarded by bisection: for M reduced to [0, pi] the root lies in
    [M, min(M + e, pi)], and f(E) = E - e sin E - M is increasing there, so every iterate stays
    in a shrinking bracket and the method converges for every e < 1 (quadratically near the
    root). Stops when the Newton correction is below ``tol`` (rad); with Newton's quadratic
    convergence the remaining error is far below ``tol``.
    """
    e = float(eccentricity)
    if not 0.0 <= e < 1.0:
        raise ValueError(f"eccentricity: expected 0 <= e < 1, got {e!r}")
    m_full = float(mean_anomaly)
    if not math.isfinite(m_full):
        raise ValueError(f"mean_anomaly: expected a finite angle (rad), got {m_full!r}")
    turns = math.floor(m_full / TWO_PI)
    m = m_full - turns * TWO_PI  # [0, 2 pi)
    flip = m > math.pi
    if flip:
        m = TWO_PI - m  # [0, pi]; E(2 pi - M) = 2 pi - E(M)
    if e == 0.0 or m == 0.0 or m == math.pi:
        ecc = m
    else:
        lo, hi = m, min(m + e, math.pi)
        # starting guess (third-order in e for small e, pi-ward for large e)
        ecc = m + e * math.sin(m) / max(1.0 - math.sin(m + e) + math.sin(m), 1e-3)
        if not lo < ecc < hi:
            ecc = 0.5 * (lo + hi)
        for _ in range(max_iter):
            s, c = math.sin(ecc), math.cos(ecc)
            f = ecc - e * s - m
            if f > 0.0:
                hi = ecc
            elif f < 0.0:
                lo = ecc
            else:
                break
            step = f / (1.0 - e * c)
            new = ecc - step
            if not lo <= new <= hi:  # Newton left the bracket: bisect instead
                new = 0.5 * (lo + hi)
                step = ecc - new
            ecc = new
            if abs(step) <= tol or hi - lo <= tol:
                break
        else:  # pragma: no cover - the bracket halves at worst, 100 iterations is far more than enough
            raise RuntimeError(f"Kepler solver did not converge for M = {m_full!r}, e = {e!r}")
    if flip:
        ecc = TWO_PI - ecc
    return ecc + turns * TWO_PI


def true_from_eccentric(eccentric_anomaly: float, eccentricity: float) -> float:
    """True anomaly (rad) from eccentric anomaly E (rad), same revolution as E."""
    e, ecc = float(eccentricity), float(eccentric_anomaly)
    return 2.0 * math.atan2(math.sqrt(1.0 + e) * math.sin(ecc / 2.0), math.sqrt(1.0 - e) * math.cos(ecc / 2.0))


def perifocal_to_eci(raan: float, inclination: float, arg_perigee: float) -> np.ndarray:
    """Rotation matrix C_eci_pqw (3x3) whose columns are the perifocal P, Q, W axes in ECI.

    raan (Ω), inclination (i), arg_perigee (ω) in rad: C = R3(Ω) R1(i) R3(ω) as active rotations.
    P points to perigee, W along the angular momentum.
    """
    so, co = math.sin(raan), math.cos(raan)
    si, ci = math.sin(inclination), math.cos(inclination)
    sw, cw = math.sin(arg_perigee), math.cos(arg_perigee)
    return np.array(
        [
            [co * cw - so * sw * ci, -co * sw - so * cw * ci, so * si],
            [so * cw + co * sw * ci, -so * sw + co * cw * ci, -co * si],
            [sw * si, cw * si, ci],
        ]
    )


def coe_to_rv(
    semi_latus_rectum: float,
    eccentricity: float,
    inclination: float,
    raan: float,
    arg_perigee: float,
    true_anomaly: float,
    mu: float = MU_EARTH,
) -> tuple[np.ndarray, np.ndarray]:
    """Classical elements -> ECI position (m) and velocity (m/s); two-body (Vallado's COE2RV).

    semi_latus_rectum p in m, angles in rad, mu in m^3/s^2. Works for 0 <= e < 1 (and e >= 1
    where the true anomaly is reachable); circular/equatorial orbits take ω = 0 / Ω = 0 as given.
    """
    p, e, nu = float(semi_latus_rectum), float(eccentricity), float(true_anomaly)
    cn, sn = math.cos(nu), math.sin(nu)
    r_pqw = np.array([cn, sn, 0.0]) * (p / (1.0 + e * cn))
    v_pqw = np.array([-sn, e + cn, 0.0]) * math.sqrt(mu / p)
    c = perifocal_to_eci(raan, inclination, arg_perigee)
    return c @ r_pqw, c @ v_pqw


def j2_secular_rates(
    semi_major_axis: float,
    eccentricity: float,
    inclination: float,
    mu: float = MU_EARTH,
    body_radius: float = R_EARTH,
    j2: float = J2_EARTH,
) -> tuple[float, float, float]:
    """First-order secular J2 rates (rad/s): (dΩ/dt, dω/dt, dM/dt).

    With n = sqrt(mu/a^3), p = a(1 - e^2), k = J2 (R/p)^2 (Vallado, Fundamentals of
    Astrodynamics, 4th ed., eqs. 9-41):
        dΩ/dt = -3/2 n k cos i
        dω/dt =  3/4 n k (4 - 5 sin^2 i)
        dM/dt =  n + 3/4 n k sqrt(1 - e^2) (2 - 3 sin^2 i)
    Inputs in m, unitless, rad, m^3/s^2, m, unitless.
    """
    a, e, i = float(semi_major_axis), float(eccentricity), float(inclination)
    n = math.sqrt(mu / a**3)
    p = a * (1.0 - e * e)
    k = j2 * (body_radius / p) ** 2
    s2 = math.sin(i) ** 2
    raan_rate = -1.5 * n * k * math.cos(i)
    argp_rate = 0.75 * n * k * (4.0 - 5.0 * s2)
    mean_rate = n + 0.75 * n * k * math.sqrt(1.0 - e * e) * (2.0 - 3.0 * s2)
    return raan_rate, argp_rate, mean_rate


class KeplerOrbit:
    """A Keplerian ellipse about the Earth, optionally with J2 secular drift of Ω, ω and M.

    Elements (mean elements at t = 0): semi_major_axis a (m), eccentricity e, inclination i,
    (checked as in :func:`check_elements`, except that the perigee may be below the surface),
    raan Ω, arg_perigee ω, mean_anomaly M0 (rad). With ``j2`` the angles drift linearly at the
    rates of :func:`j2_secular_rates`; a, e, i stay constant. The position at time t is the
    two-body ellipse of the drifted elements; velocity and acceleration returned by
    :meth:`state` are the exact time derivatives of that position (so the LVLH frame built from
    them is kinematically consistent), which with J2 includes the frame drift
    (|Ω̇| r ≈ 7 m/s for the ISS); without J2 they are the two-body velocity and -mu r/|r|^3.
    """

    def __init__(
        self,
        semi_major_axis: float,
        eccentricity: float,
        inclination: float,
        raan: float,
        arg_perigee: float,
        mean_anomaly: float,
        j2: bool = False,
        mu: float = MU_EARTH,
        body_radius: float = R_EARTH,
        j2_coefficient: float = J2_EARTH,
    ):
        check_elements(semi_major_axis, eccentricity, inclination, min_perigee=None)
        self.a, self.e, self.i = float(semi_major_axis), float(eccentricity), float(inclination)
        self.raan0, self.argp0, self.m0 = float(raan), float(arg_perigee), float(mean_anomaly)
        self.mu = float(mu)
        self.n = math.sqrt(self.mu / self.a**3)
        if j2:
            self.raan_rate, self.argp_rate, self.mean_rate = j2_secular_rates(
                self.a, self.e, self.i, self.mu, body_radius, j2_coefficient
            )
        else:
            self.raan_rate, self.argp_rate, self.mean_rate = 0.0, 0.0, self.n
        self._b_over_a = math.sqrt(1.0 - self.e * self.e)
        self._sin_i, self._cos_i = math.sin(self.i), math.cos(self.i)

    @property
    def period(self) -> float:
        """Anomalistic period 2*pi / (dM/dt), s."""
        return TWO_PI / self.mean_rate

    def elements(self, t: float) -> tuple[float, float, float]:
        """(Ω, ω, M) in rad at t seconds after t = 0 (M not reduced modulo 2*pi)."""
        return (self.raan0 + self.raan_rate * t, self.argp0 + self.argp_rate * t, self.m0 + self.mean_rate * t)

    def state(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position (m), velocity (m/s), acceleration (m/s^2) in ECI at t seconds after t = 0."""
        r, v, acc = self.state_tuples(t)
        return np.array(r), np.array(v), np.array(acc)

    def state_tuples(self, t: float) -> tuple[Vector3, Vector3, Vector3]:
        """:meth:`state` as three tuples of floats (called every step: 3-vectors in plain floats
        cost a fraction of numpy's per-call overhead)."""
        raan, argp, m = self.elements(float(t))
        a, e, b_over_a = self.a, self.e, self._b_over_a
        ecc = solve_kepler(m, e)
        se, ce = math.sin(ecc), math.cos(ecc)
        radius = a * (1.0 - e * ce)
        # perifocal (P, Q) coordinates of r and of its first two derivatives with respect to M
        # (two-body: d/dt = n d/dM); the W coordinate is zero
        rp, rq = a * (ce - e), a * b_over_a * se
        scale = a * a / radius
        dp, dq = -se * scale, b_over_a * ce * scale
        scale = -((a / radius) ** 3)
        ddp, ddq = rp * scale, rq * scale
        # P and Q axes in ECI: the first two columns of perifocal_to_eci(raan, i, argp)
        so, co = math.sin(raan), math.cos(raan)
        sw, cw = math.sin(argp), math.cos(argp)
        si, ci = self._sin_i, self._cos_i
        px, py, pz = co * cw - so * sw * ci, so * cw + co * sw * ci, sw * si
        qx, qy, qz = -co * sw - so * cw * ci, -so * sw + co * cw * ci, cw * si
        n = self.mean_rate
        n2 = n * n
        r = (px * rp + qx * rq, py * rp + qy * rq, pz * rp + qz * rq)
        # velocity and acceleration relative to the drifting perifocal frame
        u = ((px * dp + qx * dq) * n, (py * dp + qy * dq) * n, (pz * dp + qz * dq) * n)
        a_rel = ((px * ddp + qx * ddq) * n2, (py * ddp + qy * ddq) * n2, (pz * ddp + qz * ddq) * n2)
        raan_rate, argp_rate = self.raan_rate, self.argp_rate
        if raan_rate == 0.0 and argp_rate == 0.0:
            return r, u, a_rel
        # perifocal frame rate omega = dΩ/dt k + dω/dt W (W = (so si, -co si, ci)) and its
        # derivative alpha = dω/dt dΩ/dt (k × W)
        w_axis = (so * si, -co * si, ci)
        omega = (argp_rate * w_axis[0], argp_rate * w_axis[1], raan_rate + argp_rate * w_axis[2])
        spin = argp_rate * raan_rate
        alpha = (-spin * w_axis[1], spin * w_axis[0], 0.0)
        omega_r = cross_tuples(omega, r)
        v = (omega_r[0] + u[0], omega_r[1] + u[1], omega_r[2] + u[2])
        # acc = alpha × r + omega × (omega × r) + 2 omega × u + a_rel, with the middle terms as omega × (v + u)
        alpha_r = cross_tuples(alpha, r)
        frame_terms = cross_tuples(omega, (v[0] + u[0], v[1] + u[1], v[2] + u[2]))
        acc = (
            alpha_r[0] + frame_terms[0] + a_rel[0],
            alpha_r[1] + frame_terms[1] + a_rel[1],
            alpha_r[2] + frame_terms[2] + a_rel[2],
        )
        return r, v, acc
