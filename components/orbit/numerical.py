"""Cowell's method: the orbit's position and velocity integrated under a sum of accelerations. Plain
classes, no I/O, no wall clock; SI units, ECI = GCRF axes.

    d r/dt = v,   d v/dt = sum_k a_k(t, r, v)

integrated by the classical fixed-step Runge-Kutta method of order 4 on a grid t_j = j h from the
run's start (h = ``step``). The state is kept on the grid only, so the trajectory does not depend
on when it is sampled: a time between grid points is reached by one partial step from the last
grid point, not stored. Deterministic: the same inputs give the same bits.

The terms (each an :class:`AccelerationTerm`, each published as ``a_<name>_eci``):

| term | acceleration | frame | model |
|---|---|---|---|
| ``point_mass`` | -mu r/abs(r)^3 | ECI | the field's GM |
| ``harmonics`` | C^T a_harm(C r), C = C_itrf_gcrf | ITRF -> ECI | :class:`components.space.gravity.GravityField` (degrees 1..N) |
| ``sun``, ``moon`` | mu_3 ((s - r)/abs(s - r)^3 - s/abs(s)^3) (Battin's form) | ECI | :func:`components.space.gravity.third_body_acceleration`, s from the ephemeris |
| ``drag`` | -1/2 rho Cd A/m abs(v_rel) v_rel, v_rel = v - omega_E z x r | ECI | cannonball; rho from a :data:`Density`: exponential (h = abs(r) - R_E) or NRLMSISE-00 / MSIS 2.1 (WGS 84 geodetic, at UTC) |
| ``srp`` | -nu P_1AU (AU/abs(d))^2 Cr A/m d/abs(d), d = s - r | ECI | cannonball (:mod:`components.space.srp`), nu by :mod:`components.space.eclipse` |

What a term may use at time t is an :class:`Instant`: t (s since the run's start), the TT date,
C_itrf_gcrf and the Sun's and Moon's positions (m, ECI, from the Earth's centre). The Earth's
rotation is :class:`components.space.earth.EarthRotation` (its slow C_cirs_gcrf factor evaluated
once per grid step, at the step's start, the Earth rotation angle at every stage).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from components.constants import EARTH_RATE, NS_PER_S, R_EARTH


@dataclass(frozen=True)
class Instant:
    """What the accelerations share at one time: ``t_s`` (s since the run's start), ``tt`` (TT
    two-part Julian date), ``c_itrf_gcrf`` (3x3, or None when no term needs it), ``sun_eci``, ``moon_eci`` (m, Earth's centre ->
    body, GCRF; None when no term asked for them)."""

    t_s: float
    tt: tuple[float, float]
    c_itrf_gcrf: np.ndarray | None
    sun_eci: np.ndarray | None
    moon_eci: np.ndarray | None


class AccelerationTerm(Protocol):
    """One acceleration of the orbit (the interface drag and SRP models plug into).

    ``name``: the output ``a_<name>_eci``; ``needs``: which of "sun", "moon", "earth_rotation" the
    :class:`Instant` must carry (without "earth_rotation" in any term, ``c_itrf_gcrf`` is None); ``acceleration(instant, r_eci, v_eci)`` -> m/s^2, ECI (r in m, v in m/s, ECI)."""

    name: str
    needs: frozenset[str]

    def acceleration(self, instant: Instant, r_eci: np.ndarray, v_eci: np.ndarray) -> np.ndarray: ...


Density = Callable[[Instant, np.ndarray], float]
"""An atmosphere for :class:`Drag`: density (kg/m^3) at ``r_eci`` (m) at the instant."""


class PointMass:
    name = "point_mass"
    needs: frozenset[str] = frozenset()

    def __init__(self, mu: float):
        self.mu = float(mu)

    def acceleration(self, instant, r_eci, v_eci):
        x, y, z = float(r_eci[0]), float(r_eci[1]), float(r_eci[2])
        r2 = x * x + y * y + z * z
        k = -self.mu / (r2 * math.sqrt(r2))
        return np.array([k * x, k * y, k * z])


class Harmonics:
    """The field's degrees 1..N (orders to M), evaluated in ITRF and turned to ECI."""

    name, needs = "harmonics", frozenset(("earth_rotation",))

    def __init__(self, field):
        self.field = field

    def acceleration(self, instant, r_eci, v_eci):
        c = instant.c_itrf_gcrf
        return c.T @ self.field.perturbation(c @ r_eci)


class ThirdBody:
    """The Sun's or the Moon's pull on the orbit relative to the Earth's centre (``body``: sun | moon)."""

    def __init__(self, body: str, mu: float):
        self.name, self.needs, self.mu = body, frozenset((body,)), float(mu)

    def acceleration(self, instant, r_eci, v_eci):
        from components.space.gravity import third_body_acceleration

        return third_body_acceleration(r_eci, instant.sun_eci if self.name == "sun" else instant.moon_eci, self.mu)


class Drag:
    """Cannonball drag -1/2 rho(r) Cd A/m |v_rel| v_rel, v_rel = v - EARTH_RATE z x r (an atmosphere
    turning with the Earth about ECI z, as the dynamics' drag on links). ``needs``: what the
    density reads from the :class:`Instant` (``earth_rotation`` for NRLMSISE-00)."""

    name = "drag"

    def __init__(
        self,
        density: Density,
        cd: float,
        area: float,
        mass: float,
        earth_rate: float = EARTH_RATE,
        needs: frozenset[str] = frozenset(),
    ):
        self.density, self.k, self.earth_rate = density, 0.5 * cd * area / mass, float(earth_rate)
        self.needs = frozenset(needs)

    def acceleration(self, instant, r_eci, v_eci):
        w = self.earth_rate
        v_rel = np.array([v_eci[0] + w * r_eci[1], v_eci[1] - w * r_eci[0], v_eci[2]])
        rho = self.density(instant, r_eci)
        return (-rho * self.k * math.sqrt(v_rel @ v_rel)) * v_rel


def exponential_density(atmosphere) -> Density:
    """An exponential atmosphere (:class:`components.space.atmosphere.ExponentialAtmosphere`: the
    table or one layer) as a :data:`Density`: altitude above a sphere of radius R_EARTH (its bands
    in plain floats: a scalar call is ~10x cheaper than its numpy form)."""
    from bisect import bisect_right

    bases, densities, scales = (atmosphere.h0.tolist(), atmosphere.rho0.tolist(), atmosphere.scale.tolist())

    def density(instant, r_eci):
        altitude = math.sqrt(float(r_eci @ r_eci)) - R_EARTH
        k = min(max(bisect_right(bases, altitude) - 1, 0), len(bases) - 1)
        return densities[k] * math.exp(-(altitude - bases[k]) / scales[k])

    return density


def msis_density(model, rotation) -> Density:
    """NRLMSISE-00 / NRLMSIS 2.1 (:class:`components.space.atmosphere.Nrlmsise00`) as a
    :data:`Density`: r_itrf = C_itrf_gcrf r_eci (the instant's), its WGS 84 geodetic latitude,
    longitude and height, at the UTC of the instant (``rotation``: the run's
    :class:`components.space.earth.EarthRotation`). Needs ``earth_rotation``; ~130 us a call."""
    from components.space.earth import geodetic_from_ecef

    def density(instant, r_eci):
        latitude, longitude, height = geodetic_from_ecef(instant.c_itrf_gcrf @ r_eci)
        return float(model.density_geodetic(rotation.utc_tt(instant.t_s)[0], latitude, longitude, height))

    return density


class CannonballSrp:
    """Cannonball solar radiation pressure -nu P Cr A/m s_hat (:mod:`components.space.srp`), nu the
    illumination factor of ``eclipse`` (:mod:`components.space.eclipse`: none, cylindrical by the
    Earth, conical by the Earth and the Moon), s_hat from the spacecraft to the Sun. ``flux`` (W/m^2
    at 1 AU), ``au`` and the radii (m) default to the project's constants (Basilisk's are given in
    its cross-check)."""

    name = "srp"

    def __init__(
        self,
        cr: float,
        area: float,
        mass: float,
        eclipse: str = "conical",
        *,
        flux: float | None = None,
        au: float | None = None,
        r_sun: float | None = None,
        r_earth: float = R_EARTH,
        r_moon: float | None = None,
    ):
        from components.space import eclipse as shadow
        from components.space import srp

        if eclipse not in shadow.MODELS:
            raise ValueError(f"eclipse: expected one of {', '.join(shadow.MODELS)}, got {eclipse!r}")
        self.model, self.with_moon = shadow.MODELS[eclipse], eclipse == "conical"
        self.needs = frozenset(("sun", "moon") if self.with_moon else ("sun",))
        self.cr_area_per_mass = float(cr) * float(area) / float(mass)
        self.p_1au = srp.pressure_1au(srp.SOLAR_FLUX if flux is None else flux)
        self.au = srp.AU if au is None else float(au)
        self.radii = (
            shadow.R_SUN if r_sun is None else float(r_sun),
            float(r_earth),
            shadow.R_MOON if r_moon is None else float(r_moon),
        )
        self._illumination, self._cannonball = shadow.illumination_nb, srp.cannonball_nb
        self._no_moon = np.zeros(3)

    def illumination(self, instant, r_eci) -> float:
        """nu at r_eci (1 full sun, 0 umbra)."""
        moon = instant.moon_eci if self.with_moon else self._no_moon
        return self._illumination(r_eci, instant.sun_eci, moon, self.with_moon, self.model, *self.radii)

    def pressure(self, sun_eci, r_eci, nu: float) -> np.ndarray:
        """The acceleration (m/s^2) at r_eci with the Sun at sun_eci (m, ECI) and illumination nu."""
        a = np.zeros(3)
        if nu > 0.0:
            self._cannonball(sun_eci - r_eci, self.cr_area_per_mass, self.p_1au, self.au, nu, a)
        return a

    def acceleration(self, instant, r_eci, v_eci):
        return self.pressure(instant.sun_eci, r_eci, self.illumination(instant, r_eci))


class Surroundings:
    """The :class:`Instant` at a time: Earth rotation and, when asked, the Sun and the Moon.

    ``rotation`` is an :class:`components.space.earth.EarthRotation`; ``sun``, ``moon`` callables
    of TT (two-part JD) -> m, GCRF (or None); ``rotate``: whether C_itrf_gcrf is wanted (a term
    needs "earth_rotation"). The Sun and the Moon are remembered for the last few times (a step's
    last stage is the next step's first)."""

    def __init__(self, rotation, sun=None, moon=None, rotate: bool = True):
        self.rotation, self.sun, self.moon, self.rotate = rotation, sun, moon, rotate
        self._c2i_at: float | None = None
        self._c2i = np.eye(3)
        self._bodies: dict[float, tuple] = {}

    def hold_intermediate(self, t_s: float) -> None:
        """Evaluate C_cirs_gcrf at t_s and use it until the next call (a grid step's start)."""
        if self.rotate and t_s != self._c2i_at:
            self._c2i_at, self._c2i = t_s, self.rotation.intermediate(t_s)

    def at(self, t_s: float) -> Instant:
        tt = self.rotation.tt(t_s)
        bodies = self._bodies.get(t_s)
        if bodies is None:
            bodies = (None if self.sun is None else self.sun(tt), None if self.moon is None else self.moon(tt))
            if len(self._bodies) > 4:
                self._bodies.clear()
            self._bodies[t_s] = bodies
        return Instant(t_s, tt, self.rotation.matrix(t_s, self._c2i) if self.rotate else None, bodies[0], bodies[1])


class CowellPropagator:
    """r, v under ``terms`` by fixed-step RK4 on a grid of ``step_ns`` (integer ns) from t = 0.

    ``r0``, ``v0``: m, m/s, ECI at t = 0. ``state_at(t_ns)`` -> (r, v) at any t_ns >= the grid
    point reached (the grid advances; a time between grid points is a partial step from it)."""

    def __init__(self, r0, v0, terms, step_ns: int, surroundings: Surroundings):
        if step_ns <= 0:
            raise ValueError(f"step: expected > 0 ns, got {step_ns}")
        self.terms = list(terms)
        self.step_ns = int(step_ns)
        self.surroundings = surroundings
        self.t_ns = 0
        self.r = np.array(r0, dtype=np.float64)
        self.v = np.array(v0, dtype=np.float64)

    def accelerations(self, t_s: float, r, v) -> dict[str, np.ndarray]:
        """Each term's acceleration (m/s^2, ECI) at t_s, r, v."""
        instant = self.surroundings.at(t_s)
        return {term.name: term.acceleration(instant, r, v) for term in self.terms}

    def total(self, t_s: float, r, v) -> np.ndarray:
        instant = self.surroundings.at(t_s)
        a = np.zeros(3)
        for term in self.terms:
            a += term.acceleration(instant, r, v)
        return a

    def _rk4(self, t_ns: int, r, v, h_ns: int):
        t, h = t_ns / NS_PER_S, h_ns / NS_PER_S
        self.surroundings.hold_intermediate(t)
        mid = (t_ns + h_ns / 2) / NS_PER_S
        end = (t_ns + h_ns) / NS_PER_S
        k1v, k1a = v, self.total(t, r, v)
        k2v = v + 0.5 * h * k1a
        k2a = self.total(mid, r + 0.5 * h * k1v, k2v)
        k3v = v + 0.5 * h * k2a
        k3a = self.total(mid, r + 0.5 * h * k2v, k3v)
        k4v = v + h * k3a
        k4a = self.total(end, r + h * k3v, k4v)
        return (
            r + (h / 6.0) * (k1v + 2.0 * k2v + 2.0 * k3v + k4v),
            v + (h / 6.0) * (k1a + 2.0 * k2a + 2.0 * k3a + k4a),
        )

    def state_at(self, t_ns: int) -> tuple[np.ndarray, np.ndarray]:
        """(r, v) at run time t_ns (m, m/s, ECI); t_ns must not precede the grid point reached."""
        if t_ns < self.t_ns:
            raise ValueError(f"orbit.numerical: t = {t_ns} ns precedes the state held ({self.t_ns} ns)")
        while self.t_ns + self.step_ns <= t_ns:
            self.r, self.v = self._rk4(self.t_ns, self.r, self.v, self.step_ns)
            self.t_ns += self.step_ns
        if t_ns == self.t_ns:
            return self.r.copy(), self.v.copy()
        return self._rk4(self.t_ns, self.r, self.v, t_ns - self.t_ns)
